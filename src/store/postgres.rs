//! The PostgreSQL backend, for fleets: several replicas share one database
//! and claim jobs with `FOR UPDATE SKIP LOCKED`.

use sqlx::postgres::PgPoolOptions;

// The shared queries (and the column-list macros the dialect strings use).
/// The database's clock (epoch ms), which every lease is written and read
/// on: replicas' own clocks may disagree.
macro_rules! db_now_ms {
    () => {
        "CAST(EXTRACT(EPOCH FROM clock_timestamp()) * 1000 AS BIGINT)"
    };
}

include!("queries.rs");
include!("plan_queries.rs");

type Db = sqlx::Postgres;

/// A PostgreSQL database.
#[derive(Clone, Debug)]
pub struct Backend {
    pub(super) pool: sqlx::Pool<Db>,
    /// Exports in flight (see `Backend::new`).
    exports: std::sync::Arc<tokio::sync::Semaphore>,
}

/// Claim the oldest runnable job; concurrent claimers skip rows another
/// transaction has locked, so no two workers get the same job.
const CLAIM_SQL: &str = concat!(
    "UPDATE jobs SET state = 'running', locked_by = $1, locked_until_ms = ",
    db_now_ms!(),
    " + $2, interruptions = interruptions + CASE WHEN state = 'running' THEN 1 ELSE 0 END, \
     started_at = $3, updated_at = $3 WHERE id = (SELECT id FROM jobs WHERE state = 'queued' \
     OR (state = 'running' AND locked_until_ms < ",
    db_now_ms!(),
    " AND interruptions + 1 < $4) ORDER BY id LIMIT 1 \
     FOR UPDATE SKIP LOCKED) RETURNING ",
    job_cols!()
);

/// Lock the robot's row for the rest of the transaction (serialises version
/// numbering and activation per robot across replicas).
const LOCK_ROBOT_SQL: &str = "SELECT model_id FROM robots WHERE id = $1 FOR UPDATE";

/// A condition on `c.robot_id` that repeats the robot conditions `conds`
/// (on `robots`), for an export's planner. Given only the join, the planner
/// costs a site's 5,000 calibrations read through `calibrations_history`
/// as random reads and scans the whole table instead (65-72 ms at 100,000,
/// against 20-27 ms); the robots' ids as an array it cannot see into make
/// it an index condition (a bitmap scan of the site's rows).
fn robot_ids_condition(conds: &str) -> Option<String> {
    Some(format!(
        "c.robot_id = ANY(ARRAY(SELECT id FROM robots WHERE {conds}))"
    ))
}

/// How a query's plan is asked for.
const EXPLAIN: &str = "EXPLAIN";

/// `EXPLAIN`'s rows, one line of the plan each.
fn explain_lines(rows: &[sqlx::postgres::PgRow]) -> super::Result<Vec<String>> {
    use sqlx::Row;
    rows.iter()
        .map(|r| Ok(r.try_get::<String, _>(0)?))
        .collect()
}

impl Backend {
    /// Connect and migrate.
    pub async fn connect(url: &str) -> super::Result<Self> {
        let pool = PgPoolOptions::new()
            .max_connections(16)
            .connect(url)
            .await
            .map_err(super::StoreError::Db)?;
        super::migrations::postgres().run(&pool).await?;
        Ok(Backend::new(pool))
    }

    async fn begin_write(&self) -> sqlx::Result<sqlx::Transaction<'static, Db>> {
        self.pool.begin().await
    }
    /// `Store::stream_calibrations`: the export query's rows as sqlx reads
    /// them (on PostgreSQL a row costs little beyond the server's work).
    pub async fn stream_calibrations(
        &self,
        f: &CalibrationFilter,
    ) -> futures_util::stream::BoxStream<'static, Result<CalibrationRec>> {
        use futures_util::StreamExt;
        use sqlx::FromRow;
        let (sql, args) = calibration_export_sql(f);
        // The semaphore is never closed.
        let permit = self.exports.clone().acquire_owned().await.ok();
        // The pool's stream holds a clone of the pool and the query its
        // own copy of the bound values, so the stream outlives `self` and
        // `f`: it is polled by the answer's body, after the handler.
        bind_filter!(sqlx::query::<Db>(sqlx::AssertSqlSafe(sql)), args)
            .fetch(&self.pool)
            .map(move |row| {
                // Held as long as the stream.
                let _held = &permit;
                Ok(CalibrationRec::from_row(&row?)?)
            })
            .boxed()
    }
}
