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

/// Whether a filtered export reads the matching ids first and then their
/// rows in id order (SQLite's shape, `sqlite.rs`), rather than the rows
/// and then sorting them: not here, where the rows come from a bitmap scan
/// of the robots' ids (`robot_ids_condition`) and are sorted, which was not
/// measured against that shape.
const EXPORT_IDS_FIRST: bool = false;

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
    /// `Store::export_calibrations`: the export query's rows as sqlx reads
    /// them, each written into `sink` as it comes, borrowed from sqlx's row
    /// (`export_row`), on the runtime's thread.
    pub async fn export_calibrations<S: ExportSink>(
        &self,
        f: &CalibrationFilter,
        sink: S,
    ) -> futures_util::stream::BoxStream<'static, Result<S::Piece>> {
        use futures_util::StreamExt;
        let (sql, args) = calibration_export_sql(f);
        // The semaphore is never closed.
        let permit = self.exports.clone().acquire_owned().await.ok();
        // The pool's stream holds a clone of the pool and the query its
        // own copy of the bound values, so the stream outlives `self` and
        // `f`: it is polled by the answer's body, after the handler.
        let rows =
            bind_filter!(sqlx::query::<Db>(sqlx::AssertSqlSafe(sql)), args).fetch(&self.pool);
        // The permit is held as long as the stream.
        let checked = false;
        futures_util::stream::unfold(Some((rows, sink, permit, checked)), |state| async move {
            let (mut rows, mut sink, permit, mut checked) = state?;
            loop {
                match rows.next().await {
                    Some(Ok(row)) => {
                        // The columns' types once, then every row's values
                        // by position without asking again.
                        let read = if checked {
                            Ok(())
                        } else {
                            checked = true;
                            check_export_columns(&row)
                        };
                        if let Err(e) = read.and_then(|()| export_row(&row).map(|c| sink.row(&c))) {
                            return Some((Err(e.into()), None));
                        }
                        if let Some(piece) = sink.ready() {
                            return Some((Ok(piece), Some((rows, sink, permit, checked))));
                        }
                    }
                    Some(Err(e)) => return Some((Err(e.into()), None)),
                    None => return sink.finish().map(|piece| (Ok(piece), None)),
                }
            }
        })
        .boxed()
    }
}

/// Check that the export query's columns (`calibration_select!`'s, in
/// order) have the types [`export_row`] decodes, from a row's description,
/// which every row of the query shares. sqlx checks a column's type at
/// every value it decodes (`Row::try_get`, with its `PgType` clones and
/// comparisons): about a fifth of the server's time in a 5,000-row CSV,
/// 95,000 checks of the same 19 types (BENCHMARKS.md, "Fleet scale").
fn check_export_columns(row: &sqlx::postgres::PgRow) -> sqlx::Result<()> {
    use sqlx::postgres::PgTypeInfo;
    use sqlx::{Column, Row, Type, TypeInfo};
    let int = <i64 as Type<Db>>::compatible;
    let text = <&str as Type<Db>>::compatible;
    let real = <f64 as Type<Db>>::compatible;
    let boolean = <bool as Type<Db>>::compatible;
    let want: [fn(&PgTypeInfo) -> bool; 19] = [
        int, int, text, int, text, text, text, int, int, int, text, int, int, real, real, real,
        text, boolean, text,
    ];
    let columns = row.columns();
    if columns.len() != want.len() {
        return Err(sqlx::Error::Protocol(format!(
            "export: {} columns, not the {} expected",
            columns.len(),
            want.len()
        )));
    }
    for (c, ok) in columns.iter().zip(want) {
        if !ok(c.type_info()) {
            return Err(sqlx::Error::ColumnDecode {
                index: c.name().to_string(),
                source: format!("unexpected type {}", c.type_info().name()).into(),
            });
        }
    }
    Ok(())
}

/// A row of the export query (`calibration_select!`'s columns, in order),
/// borrowed from sqlx's row, its columns taken by position (by name, each
/// of the 19 was a hash lookup) and decoded without sqlx's check of their
/// types, which [`check_export_columns`] made once for the query. The store
/// suite compares every column with the paged list's rows, which are
/// decoded by name, checked.
fn export_row(row: &sqlx::postgres::PgRow) -> sqlx::Result<super::CalibrationRow<'_>> {
    use sqlx::Row;
    Ok(super::CalibrationRow {
        id: row.try_get_unchecked(0)?,
        robot_id: row.try_get_unchecked(1)?,
        serial_number: row.try_get_unchecked(2)?,
        model_id: row.try_get_unchecked(3)?,
        site: row.try_get_unchecked(4)?,
        line: row.try_get_unchecked(5)?,
        cell: row.try_get_unchecked(6)?,
        session_id: row.try_get_unchecked(7)?,
        job_id: row.try_get_unchecked(8)?,
        version: row.try_get_unchecked(9)?,
        method: row.try_get_unchecked(10)?,
        n_poses: row.try_get_unchecked(11)?,
        n_test: row.try_get_unchecked(12)?,
        test_rms_before_mm: row.try_get_unchecked(13)?,
        test_rms_after_mm: row.try_get_unchecked(14)?,
        train_rms_after_mm: row.try_get_unchecked(15)?,
        effects: row.try_get_unchecked(16)?,
        active: row.try_get_unchecked(17)?,
        created_at: row.try_get_unchecked(18)?,
    })
}
