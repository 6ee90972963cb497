//! The schema migrations of each backend, embedded in the binary.
//!
//! Listed here rather than by `sqlx::migrate!`, whose macros crate
//! compiles both database drivers a second time for the compiler's host
//! (see `record`). The checksums are the same as the macro's (SHA-384 of
//! the SQL), so databases it migrated open unchanged; a test checks the
//! lists against the files in `migrations/`.

use std::borrow::Cow;

use sqlx::SqlStr;
use sqlx::migrate::{Migration, MigrationType, Migrator};

/// One migration file: version, description (the file name's rest, `_` as
/// spaces, as sqlx reads it) and SQL.
type File = (i64, &'static str, &'static str);

const SQLITE: &[File] = &[
    (
        1,
        "initial",
        include_str!("../../migrations/sqlite/0001_initial.sql"),
    ),
    (
        2,
        "api keys",
        include_str!("../../migrations/sqlite/0002_api_keys.sql"),
    ),
    (
        3,
        "job interruptions",
        include_str!("../../migrations/sqlite/0003_job_interruptions.sql"),
    ),
    (
        4,
        "fleet history",
        include_str!("../../migrations/sqlite/0004_fleet_history.sql"),
    ),
    (
        5,
        "plans",
        include_str!("../../migrations/sqlite/0005_plans.sql"),
    ),
];

const POSTGRES: &[File] = &[
    (
        1,
        "initial",
        include_str!("../../migrations/postgres/0001_initial.sql"),
    ),
    (
        2,
        "api keys",
        include_str!("../../migrations/postgres/0002_api_keys.sql"),
    ),
    (
        3,
        "job interruptions",
        include_str!("../../migrations/postgres/0003_job_interruptions.sql"),
    ),
    (
        4,
        "fleet history",
        include_str!("../../migrations/postgres/0004_fleet_history.sql"),
    ),
    (
        5,
        "plans",
        include_str!("../../migrations/postgres/0005_plans.sql"),
    ),
];

fn migrator(files: &[File]) -> Migrator {
    Migrator::with_migrations(
        files
            .iter()
            .map(|&(version, description, sql)| {
                Migration::new(
                    version,
                    Cow::Borrowed(description),
                    MigrationType::Simple,
                    SqlStr::from_static(sql),
                    sql.starts_with("-- no-transaction"),
                )
            })
            .collect(),
    )
}

/// The SQLite schema's migrations.
pub(super) fn sqlite() -> Migrator {
    migrator(SQLITE)
}

/// The PostgreSQL schema's migrations.
pub(super) fn postgres() -> Migrator {
    migrator(POSTGRES)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every file of `migrations/<dir>` is listed, with sqlx's version and
    /// description, and only those.
    fn listed_as_on_disk(dir: &str, files: &[File]) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("migrations")
            .join(dir);
        let mut on_disk: Vec<(i64, String, String)> = std::fs::read_dir(&path)
            .unwrap()
            .map(|e| {
                let e = e.unwrap();
                let name = e.file_name().to_string_lossy().into_owned();
                let (version, rest) = name.split_once('_').unwrap();
                let description = rest.strip_suffix(".sql").unwrap().replace('_', " ");
                let sql = std::fs::read_to_string(e.path()).unwrap();
                (version.parse().unwrap(), description, sql)
            })
            .collect();
        on_disk.sort();
        let listed: Vec<(i64, String, String)> = files
            .iter()
            .map(|&(v, d, s)| (v, d.to_string(), s.to_string()))
            .collect();
        assert_eq!(
            listed, on_disk,
            "src/store/migrations.rs lists migrations/{dir}"
        );
    }

    #[test]
    fn every_migration_file_is_listed() {
        listed_as_on_disk("sqlite", SQLITE);
        listed_as_on_disk("postgres", POSTGRES);
    }

    /// The checksum sqlx's `migrate!` stored: SHA-384 of the SQL (a known
    /// digest, so a database the macro migrated opens unchanged).
    #[test]
    fn checksums_are_sqlx_migrate_s() {
        let m = Migration::new(
            1,
            Cow::Borrowed("x"),
            MigrationType::Simple,
            SqlStr::from_static("abc"),
            false,
        );
        let hex: String = m.checksum.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(
            hex,
            "cb00753f45a35e8bb5a03d699ac65007272c32ab0eded1631a8b605a43ff5bed\
             8086072ba1e7cc2358baeca134c825a7"
        );
        assert_eq!(sqlite().iter().count(), SQLITE.len());
    }
}
