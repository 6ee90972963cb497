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
    /// them, each decoded by position (`export_row`).
    pub async fn stream_calibrations(
        &self,
        f: &CalibrationFilter,
    ) -> futures_util::stream::BoxStream<'static, Result<CalibrationRec>> {
        use futures_util::StreamExt;
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
                Ok(export_row(&row?)?)
            })
            .boxed()
    }
}

/// A row of the export query (`calibration_select!`'s columns, in order),
/// its columns taken by position: by name, each of the 19 was a hash
/// lookup, about a tenth of the runtime thread's time in a 5,000-row CSV
/// (BENCHMARKS.md, "Fleet scale"). The store suite compares every column
/// with the paged list's rows, which are decoded by name.
fn export_row(row: &sqlx::postgres::PgRow) -> sqlx::Result<CalibrationRec> {
    use sqlx::Row;
    Ok(CalibrationRec {
        id: row.try_get(0)?,
        robot_id: row.try_get(1)?,
        serial_number: row.try_get(2)?,
        model_id: row.try_get(3)?,
        site: row.try_get(4)?,
        line: row.try_get(5)?,
        cell: row.try_get(6)?,
        session_id: row.try_get(7)?,
        job_id: row.try_get(8)?,
        version: row.try_get(9)?,
        method: row.try_get(10)?,
        n_poses: row.try_get(11)?,
        n_test: row.try_get(12)?,
        test_rms_before_mm: row.try_get(13)?,
        test_rms_after_mm: row.try_get(14)?,
        train_rms_after_mm: row.try_get(15)?,
        effects: row.try_get(16)?,
        active: row.try_get(17)?,
        created_at: row.try_get(18)?,
    })
}
