//! What a test needs from the machine (PostgreSQL, Chromium): a test whose
//! tool is missing fails and says what to install, unless the user asked to
//! skip it with the environment variable the README names, and then it says
//! so on the terminal (not in cargo's captured output). No test passes by
//! doing nothing without being told to.

use std::io::Write;
use std::path::{Path, PathBuf};

use sqlx::Connection;

/// When set (to anything but `0`), the PostgreSQL tests (store
/// conformance, the service on PostgreSQL) are skipped, visibly, if the
/// server cannot be reached.
pub const SKIP_POSTGRES: &str = "DRAWCAL_SKIP_POSTGRES";
/// When set (to anything but `0`), the browser test is skipped, visibly,
/// if chromium or chromedriver is missing.
pub const SKIP_BROWSER: &str = "DRAWCAL_SKIP_BROWSER";

/// Where the tools are looked for, and whether a missing one is skipped:
/// read from the environment by [`Machine::here`], given by the tests of
/// this module.
struct Machine {
    path: Option<String>,
    postgres_url: String,
    skip_postgres: bool,
    skip_browser: bool,
}

impl Machine {
    fn here() -> Machine {
        let asked = |var: &str| std::env::var_os(var).is_some_and(|v| v != "0");
        Machine {
            path: std::env::var("PATH").ok(),
            postgres_url: std::env::var("DATABASE_URL_POSTGRES")
                .unwrap_or_else(|_| "postgres://postgres@127.0.0.1:5432/test".into()),
            skip_postgres: asked(SKIP_POSTGRES),
            skip_browser: asked(SKIP_BROWSER),
        }
    }

    async fn postgres(&self, test: &str) -> Option<(String, sqlx::PgConnection)> {
        match sqlx::PgConnection::connect(&self.postgres_url).await {
            Ok(conn) => Some((self.postgres_url.clone(), conn)),
            Err(e) => {
                missing(
                    test,
                    &format!("PostgreSQL at {} ({e})", self.postgres_url),
                    "install and start PostgreSQL (Debian: apt-get install postgresql; \
                     .ci/run starts an installed one), or point DATABASE_URL_POSTGRES at a \
                     server whose user may create databases",
                    SKIP_POSTGRES,
                    self.skip_postgres,
                );
                None
            }
        }
    }

    fn browser(&self, test: &str) -> Option<(PathBuf, PathBuf)> {
        match (self.which("chromium"), self.which("chromedriver")) {
            (Some(c), Some(d)) => Some((c, d)),
            (c, d) => {
                let absent: Vec<&str> = [("chromium", c.is_none()), ("chromedriver", d.is_none())]
                    .into_iter()
                    .filter_map(|(n, gone)| gone.then_some(n))
                    .collect();
                missing(
                    test,
                    &format!("{} on the PATH", absent.join(" and ")),
                    "install them (Debian: apt-get install chromium chromium-driver; .ci/run \
                     does)",
                    SKIP_BROWSER,
                    self.skip_browser,
                );
                None
            }
        }
    }

    fn which(&self, name: &str) -> Option<PathBuf> {
        self.path
            .as_deref()?
            .split(':')
            .map(|d| Path::new(d).join(name))
            .find(|p| p.is_file())
    }
}

/// A missing tool: returns (the test is skipped, and says so on the
/// terminal: libtest captures `eprintln!` of a passing test, not writes to
/// the stderr handle) when `skip`, fails otherwise saying what to install.
fn missing(test: &str, why: &str, install: &str, var: &str, skip: bool) {
    assert!(
        skip,
        "{test} needs {why}: {install}; or set {var}=1 to skip it (it is then reported skipped)"
    );
    let _ = writeln!(
        std::io::stderr(),
        "SKIPPED {test}: it needs {why} ({var} is set; unset it to run the test)"
    );
}

/// The PostgreSQL server the tests use (`DATABASE_URL_POSTGRES`, default
/// the local `test` database) and a connection to it for creating the
/// test's own database; None when it cannot be reached and
/// [`SKIP_POSTGRES`] is set.
pub async fn postgres(test: &str) -> Option<(String, sqlx::PgConnection)> {
    Machine::here().postgres(test).await
}

/// chromium and chromedriver on the PATH; None when one is missing and
/// [`SKIP_BROWSER`] is set.
pub fn browser(test: &str) -> Option<(PathBuf, PathBuf)> {
    Machine::here().browser(test)
}

fn bare() -> Machine {
    Machine {
        path: Some("/nonexistent-drawcal-test".into()),
        // Port 1 on the loopback: nothing listens there.
        postgres_url: "postgres://postgres@127.0.0.1:1/test".into(),
        skip_postgres: false,
        skip_browser: false,
    }
}

fn panic_text(e: &(dyn std::any::Any + Send)) -> String {
    e.downcast_ref::<String>()
        .cloned()
        .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_default()
}

#[test]
fn a_missing_browser_fails_saying_what_to_install_unless_skipped() {
    let m = bare();
    let failed = std::panic::catch_unwind(|| m.browser("requires::self_check")).unwrap_err();
    let text = panic_text(&*failed);
    assert!(
        text.contains("chromium and chromedriver on the PATH")
            && text.contains("apt-get install chromium chromium-driver")
            && text.contains("DRAWCAL_SKIP_BROWSER=1"),
        "{text}"
    );
    let m = Machine {
        skip_browser: true,
        ..bare()
    };
    assert!(m.browser("requires::self_check").is_none());
}

#[tokio::test]
async fn an_unreachable_postgres_fails_saying_what_to_install_unless_skipped() {
    let failed = tokio::spawn(async { bare().postgres("requires::self_check").await.map(|_| ()) })
        .await
        .unwrap_err();
    let text = panic_text(&*failed.into_panic());
    assert!(
        text.contains("PostgreSQL at postgres://postgres@127.0.0.1:1/test")
            && text.contains("apt-get install postgresql")
            && text.contains("DRAWCAL_SKIP_POSTGRES=1"),
        "{text}"
    );
    let m = Machine {
        skip_postgres: true,
        ..bare()
    };
    assert!(m.postgres("requires::self_check").await.is_none());
}
