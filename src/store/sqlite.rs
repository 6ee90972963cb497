//! The SQLite backend: one file, WAL mode, foreign keys on, a busy timeout.
//! Writes that read first run in `BEGIN IMMEDIATE` transactions so that two
//! writers never deadlock on a lock upgrade.

use std::str::FromStr;
use std::time::Duration;

use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

// The shared queries (and the column-list macros the dialect strings use).
/// The database's clock (epoch ms), which every lease is written and read
/// on: replicas' own clocks may disagree.
macro_rules! db_now_ms {
    () => {
        "CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER)"
    };
}

include!("queries.rs");
include!("plan_queries.rs");

type Db = sqlx::Sqlite;

/// A SQLite database.
#[derive(Clone, Debug)]
pub struct Backend {
    pub(super) pool: sqlx::Pool<Db>,
    /// Exports in flight (see `Backend::new`).
    exports: std::sync::Arc<tokio::sync::Semaphore>,
}

/// Claim the oldest runnable job. SQLite has one writer at a time, so a
/// single `UPDATE ... WHERE id = (SELECT ...)` is atomic.
const CLAIM_SQL: &str = concat!(
    "UPDATE jobs SET state = 'running', locked_by = $1, locked_until_ms = ",
    db_now_ms!(),
    " + $2, interruptions = interruptions + CASE WHEN state = 'running' THEN 1 ELSE 0 END, \
     started_at = $3, updated_at = $3 WHERE id = (SELECT id FROM jobs WHERE state = 'queued' \
     OR (state = 'running' AND locked_until_ms < ",
    db_now_ms!(),
    " AND interruptions + 1 < $4) ORDER BY id LIMIT 1) RETURNING ",
    job_cols!()
);

/// Read the robot's model inside a write transaction (IMMEDIATE already
/// holds the database's write lock).
const LOCK_ROBOT_SQL: &str = "SELECT model_id FROM robots WHERE id = $1";

/// A condition on `c.robot_id` that repeats the robot conditions `conds`
/// (on `robots`), for an export's planner: none here, SQLite's plan starts
/// from the robots' index already.
fn robot_ids_condition(_conds: &str) -> Option<String> {
    None
}

/// Whether a filtered export reads the matching ids first, from the
/// filter's indexes alone, and then their rows in id order, rather than
/// the matching rows and then sorting them. Here it does: in id order the
/// rows' lookups walk the table's leaves one after the other, and no whole
/// rows are sorted; a site's 5,000 rows at 100,000 calibrations were 589
/// page fetches so, against 10,323 by the site's robots and a sort of the
/// rows (BENCHMARKS.md, "Fleet scale").
const EXPORT_IDS_FIRST: bool = true;

/// How a query's plan is asked for.
const EXPLAIN: &str = "EXPLAIN QUERY PLAN";

/// `EXPLAIN QUERY PLAN`'s rows (id, parent, notused, detail) as lines, each
/// step indented under its parent.
fn explain_lines(rows: &[sqlx::sqlite::SqliteRow]) -> super::Result<Vec<String>> {
    use sqlx::Row;
    let mut depth = std::collections::HashMap::new();
    let mut out = Vec::new();
    for row in rows {
        let id: i64 = row.try_get(0)?;
        let parent: i64 = row.try_get(1)?;
        let detail: String = row.try_get(3)?;
        let d = depth.get(&parent).map_or(0, |d| d + 1);
        depth.insert(id, d);
        out.push(format!("{}{detail}", "  ".repeat(d)));
    }
    Ok(out)
}

impl Backend {
    /// Open (creating the file if needed) and migrate.
    pub async fn connect(url: &str) -> super::Result<Self> {
        let opts = SqliteConnectOptions::from_str(url)
            .map_err(super::StoreError::Db)?
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Normal)
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(10))
            // Rows a statement's thread may read ahead of the reader (sqlx's
            // default is 50): every time the queue fills, the two threads
            // take turns, which on a busy machine costs a scheduler slice
            // each; a site's 5,000-row export had store times up to 560-600
            // ms with 50, 110-130 ms with 1,000 (BENCHMARKS.md, "Fleet
            // scale"; the export reads SQLite directly since, the other
            // lists still go through this queue). Rows are small (about 150
            // bytes of values).
            .row_buffer_size(1000);
        let pool = SqlitePoolOptions::new()
            .max_connections(8)
            .connect_with(opts)
            .await
            .map_err(super::StoreError::Db)?;
        super::migrations::sqlite().run(&pool).await?;
        Ok(Backend::new(pool))
    }

    async fn begin_write(&self) -> sqlx::Result<sqlx::Transaction<'static, Db>> {
        self.pool.begin_with("BEGIN IMMEDIATE").await
    }

    /// `Store::export_calibrations`: the export query run on a blocking
    /// thread straight on SQLite's handle, its rows written into `sink`
    /// there as they are stepped to (`super::sqlite_export` says why).
    pub async fn export_calibrations<S: ExportSink>(
        &self,
        f: &CalibrationFilter,
        sink: S,
    ) -> futures_util::stream::BoxStream<'static, Result<S::Piece>> {
        use super::sqlite_export::{Arg, read_calibrations};
        use futures_util::StreamExt;
        let (sql, args) = calibration_export_sql(f);
        let args: Vec<Arg> = args
            .iter()
            .map(|a| match a {
                FilterArg::Int(v) => Arg::Int(*v),
                FilterArg::Text(v) => Arg::Text(v.to_string()),
                FilterArg::Real(v) => Arg::Real(*v),
            })
            .collect();
        // The semaphore is never closed.
        let permit = self.exports.clone().acquire_owned().await.ok();
        let pool = self.pool.clone();
        // Two pieces in flight: the reader thread stays a piece ahead of
        // the answer, and waits (holding its connection) while the client
        // is slow to read.
        let (tx, rx) = tokio::sync::mpsc::channel(2);
        tokio::spawn(async move {
            // Held until the rows are all sent or the reader is gone.
            let _permit = permit;
            let mut conn = match pool.acquire().await {
                Ok(c) => c,
                Err(e) => {
                    let _ = tx.send(Err(e.into())).await;
                    return;
                }
            };
            let runtime = tokio::runtime::Handle::current();
            let failed = tx.clone();
            let read = tokio::task::spawn_blocking(move || {
                // The connection's own thread waits while this one holds
                // its handle; the statement is finalized before the lock
                // is given back.
                match runtime.block_on(conn.lock_handle()) {
                    Ok(mut locked) => {
                        read_calibrations(locked.as_raw_handle(), &sql, &args, sink, &tx)
                    }
                    Err(e) => {
                        let _ = tx.blocking_send(Err(e.into()));
                    }
                }
            })
            .await;
            if let Err(e) = read {
                let _ = failed
                    .send(Err(StoreError::Db(sqlx::Error::Protocol(format!(
                        "sqlite export thread: {e}"
                    )))))
                    .await;
            }
        });
        futures_util::stream::unfold(rx, |mut rx| async move {
            rx.recv().await.map(|piece| (piece, rx))
        })
        .boxed()
    }
}
