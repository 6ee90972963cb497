// The store's queries, written once and compiled for each backend: this file
// is `include!`d by `sqlite.rs` and `postgres.rs`, which define `Db`,
// `Backend { pool }`, `begin_write`, and the dialect strings `CLAIM_SQL` and
// `LOCK_ROBOT_SQL`. Nothing else differs between the backends.

use super::{
    ActivationRec, AuditRec, CalibrationFilter, CalibrationRec, ExportSink, JobRec, KeyRec,
    ModelRec,
    NewCalibration, NewKey, NewRobot, Page, Result, RigRec, RobotRec, SessionRec, StoreError,
    now_rfc3339,
};

macro_rules! model_cols {
    () => {
        "id, name, dof, robot_json, created_at"
    };
}
macro_rules! robot_cols {
    () => {
        "id, serial_number, model_id, site, line, cell, active_calibration_id, created_at, updated_at"
    };
}
macro_rules! rig_cols {
    () => {
        "id, name, n_strings, rig_json, created_at"
    };
}
macro_rules! session_cols {
    () => {
        "id, robot_id, rig_id, name, n_poses, n_batches, columns, created_at, updated_at"
    };
}
macro_rules! job_cols {
    () => {
        "id, session_id, robot_id, options, state, stage, progress, attempts, max_attempts, \
         interruptions, locked_by, locked_until_ms, cancel_requested, error, calibration_id, created_at, \
         updated_at, started_at, finished_at"
    };
}
macro_rules! key_cols {
    () => {
        "id, name, role, sites, prefix, secret_hash, created_at, expires_at, revoked_at"
    };
}
macro_rules! calibration_select {
    () => {
        "SELECT c.id, c.robot_id, r.serial_number, c.model_id, r.site, r.line, r.cell, \
         c.session_id, c.job_id, c.version, c.method, c.n_poses, c.n_test, \
         c.test_rms_before_mm, c.test_rms_after_mm, c.train_rms_after_mm, c.effects, \
         CASE WHEN r.active_calibration_id = c.id THEN TRUE ELSE FALSE END AS active, \
         c.created_at FROM calibrations c JOIN robots r ON r.id = c.robot_id "
    };
}
/// A value of the history filter, bound in the order its condition was
/// written.
enum FilterArg<'a> {
    Int(i64),
    Text(&'a str),
    Real(f64),
}

/// The history filter as SQL: only the filters given, each a plain
/// comparison the planner can serve from an index (one text for every
/// filter, `($1 IS NULL OR c.robot_id = $1) AND ...`, was one plan for all
/// of them: a scan of every calibration), numbered `$1`... in the order of
/// the values returned. The conditions on the robot (site, line) come again
/// on their own, on `robots` without an alias (empty: a count need not
/// join `robots`).
fn calibration_filter<'a>(f: &'a CalibrationFilter) -> (String, Vec<FilterArg<'a>>, Vec<String>) {
    let mut conds: Vec<String> = Vec::new();
    let mut args: Vec<FilterArg<'a>> = Vec::new();
    let mut cond = |sql: &str, arg: FilterArg<'a>| {
        args.push(arg);
        conds.push(sql.replace('?', &format!("${}", args.len())));
    };
    if let Some(v) = f.robot_id {
        cond("c.robot_id = ?", FilterArg::Int(v));
    }
    if let Some(v) = f.model_id {
        cond("c.model_id = ?", FilterArg::Int(v));
    }
    if let Some(v) = &f.site {
        cond("r.site = ?", FilterArg::Text(v));
    }
    if let Some(v) = &f.line {
        cond("r.line = ?", FilterArg::Text(v));
    }
    if let Some(v) = &f.from {
        cond("c.created_at >= ?", FilterArg::Text(v));
    }
    if let Some(v) = &f.to {
        cond("c.created_at <= ?", FilterArg::Text(v));
    }
    if let Some(v) = f.max_test_rms_mm {
        cond("c.test_rms_after_mm <= ?", FilterArg::Real(v));
    }
    if let Some(v) = f.min_test_rms_mm {
        cond("c.test_rms_after_mm >= ?", FilterArg::Real(v));
    }
    let robots: Vec<String> = conds
        .iter()
        .filter_map(|c| c.strip_prefix("r."))
        .map(str::to_string)
        .collect();
    let sql = if conds.is_empty() {
        String::new()
    } else {
        format!("WHERE {} ", conds.join(" AND "))
    };
    (sql, args, robots)
}

/// Bind the history filter's values (`calibration_filter`) to a query.
macro_rules! bind_filter {
    ($q:expr, $args:expr) => {{
        let mut q = $q;
        for a in $args.iter() {
            q = match a {
                FilterArg::Int(v) => q.bind(*v),
                FilterArg::Text(v) => q.bind(*v),
                FilterArg::Real(v) => q.bind(*v),
            };
        }
        q
    }};
}

/// The SQL of the history list's page and of its count, for a filter.
fn calibration_list_sql(f: &CalibrationFilter) -> (String, String, Vec<FilterArg<'_>>) {
    let (filter, args, robots) = calibration_filter(f);
    let n = args.len();
    // Every calibration has its robot (a foreign key), so a query without
    // a condition on the robot need not join it.
    let from = if !robots.is_empty() {
        "FROM calibrations c JOIN robots r ON r.id = c.robot_id"
    } else {
        "FROM calibrations c"
    };
    // The page's ids first, from the indexes alone (`calibrations_history`
    // holds every filtered column), then only their rows: sorting whole
    // rows to keep 50 of a site's 5,000 read every one of them. With a
    // filter the ids are sorted as numbers (`c.id + 0`), so that no planner
    // walks the primary key in order hoping to meet the filter's rows
    // early: dates grow with ids, so a month of the fleet's history was
    // a walk through every calibration before it (PostgreSQL: 82 ms p99).
    let order = if args.is_empty() { "c.id" } else { "c.id + 0" };
    let page = format!(
        "{}WHERE c.id IN (SELECT c.id {from} {filter}ORDER BY {order} LIMIT ${} OFFSET ${}) \
         ORDER BY c.id",
        calibration_select!(),
        n + 1,
        n + 2
    );
    let count = format!("SELECT COUNT(*) {from} {filter}");
    (page, count, args)
}

/// The SQL of a history export: every row the filter matches, oldest
/// first, in one statement (no page to find, no count).
fn calibration_export_sql(f: &CalibrationFilter) -> (String, Vec<FilterArg<'_>>) {
    let (mut filter, args, robots) = calibration_filter(f);
    if !robots.is_empty() {
        if let Some(ids) = robot_ids_condition(&robots.join(" AND ")) {
            filter = format!("{filter}AND {ids} ");
        }
    }
    if args.is_empty() {
        // Every row is read anyway, in the primary key's order.
        return (format!("{}ORDER BY c.id", calibration_select!()), args);
    }
    if EXPORT_IDS_FIRST {
        // The matching ids from the filter's indexes, then their rows in
        // id order (as the page query does, without its page).
        let from = if robots.is_empty() {
            "FROM calibrations c"
        } else {
            "FROM calibrations c JOIN robots r ON r.id = c.robot_id"
        };
        return (
            format!(
                "{}WHERE c.id IN (SELECT c.id {from} {filter}) ORDER BY c.id",
                calibration_select!()
            ),
            args,
        );
    }
    // Sorted as numbers, for the page's reason above: the planner then
    // reads the matching rows from the filter's indexes and sorts them,
    // instead of walking the primary key through every calibration.
    (
        format!("{}{filter}ORDER BY c.id + 0", calibration_select!()),
        args,
    )
}

impl Backend {
    pub(super) fn new(pool: sqlx::Pool<Db>) -> Self {
        // An export holds a connection as long as its client takes to read
        // it (up to the write timeout, for one that stops): half the pool
        // at most, so that slow readers cannot starve the other routes.
        let exports = (pool.options().get_max_connections() as usize / 2).max(1);
        Backend {
            pool,
            exports: std::sync::Arc::new(tokio::sync::Semaphore::new(exports)),
        }
    }

    /// Is the database answering?
    pub async fn ping(&self) -> Result<()> {
        sqlx::query_scalar::<_, i64>("SELECT CAST(1 AS BIGINT)")
            .fetch_one(&self.pool)
            .await?;
        Ok(())
    }

    // ---- robot models -------------------------------------------------

    pub async fn create_model(&self, name: &str, dof: i64, robot_json: &str) -> Result<ModelRec> {
        Ok(sqlx::query_as::<_, ModelRec>(concat!(
            "INSERT INTO robot_models (name, dof, robot_json, created_at) VALUES ($1, $2, $3, $4) RETURNING ",
            model_cols!()
        ))
        .bind(name)
        .bind(dof)
        .bind(robot_json)
        .bind(now_rfc3339())
        .fetch_one(&self.pool)
        .await?)
    }

    pub async fn get_model(&self, id: i64) -> Result<ModelRec> {
        sqlx::query_as::<_, ModelRec>(concat!(
            "SELECT ",
            model_cols!(),
            " FROM robot_models WHERE id = $1"
        ))
        .bind(id)
        .fetch_optional(&self.pool)
        .await?
        .ok_or(StoreError::NotFound {
            what: "robot model",
            id,
        })
    }

    pub async fn list_models(&self, page: Page) -> Result<(Vec<ModelRec>, i64)> {
        let items = sqlx::query_as::<_, ModelRec>(concat!(
            "SELECT ",
            model_cols!(),
            " FROM robot_models ORDER BY id LIMIT $1 OFFSET $2"
        ))
        .bind(page.limit)
        .bind(page.offset)
        .fetch_all(&self.pool)
        .await?;
        let total = sqlx::query_scalar::<_, i64>("SELECT COUNT(*) FROM robot_models")
            .fetch_one(&self.pool)
            .await?;
        Ok((items, total))
    }

    // ---- robots -------------------------------------------------------

    pub async fn create_robot(&self, r: &NewRobot) -> Result<RobotRec> {
        let now = now_rfc3339();
        Ok(sqlx::query_as::<_, RobotRec>(concat!(
            "INSERT INTO robots (serial_number, model_id, site, line, cell, created_at, updated_at) \
             VALUES ($1, $2, $3, $4, $5, $6, $6) RETURNING ",
            robot_cols!()
        ))
        .bind(&r.serial_number)
        .bind(r.model_id)
        .bind(&r.site)
        .bind(&r.line)
        .bind(&r.cell)
        .bind(now)
        .fetch_one(&self.pool)
        .await?)
    }

    pub async fn get_robot(&self, id: i64) -> Result<RobotRec> {
        sqlx::query_as::<_, RobotRec>(concat!(
            "SELECT ",
            robot_cols!(),
            " FROM robots WHERE id = $1"
        ))
        .bind(id)
        .fetch_optional(&self.pool)
        .await?
        .ok_or(StoreError::NotFound { what: "robot", id })
    }

    pub async fn list_robots(
        &self,
        model_id: Option<i64>,
        site: Option<&str>,
        line: Option<&str>,
        page: Page,
    ) -> Result<(Vec<RobotRec>, i64)> {
        let items = sqlx::query_as::<_, RobotRec>(concat!(
            "SELECT ",
            robot_cols!(),
            " FROM robots WHERE ($1 IS NULL OR model_id = $1) AND ($2 IS NULL OR site = $2) \
             AND ($3 IS NULL OR line = $3) ORDER BY id LIMIT $4 OFFSET $5"
        ))
        .bind(model_id)
        .bind(site)
        .bind(line)
        .bind(page.limit)
        .bind(page.offset)
        .fetch_all(&self.pool)
        .await?;
        let total = sqlx::query_scalar::<_, i64>(
            "SELECT COUNT(*) FROM robots WHERE ($1 IS NULL OR model_id = $1) \
             AND ($2 IS NULL OR site = $2) AND ($3 IS NULL OR line = $3)",
        )
        .bind(model_id)
        .bind(site)
        .bind(line)
        .fetch_one(&self.pool)
        .await?;
        Ok((items, total))
    }

    // ---- rigs -----------------------------------------------------------

    pub async fn create_rig(&self, name: &str, n_strings: i64, rig_json: &str) -> Result<RigRec> {
        Ok(sqlx::query_as::<_, RigRec>(concat!(
            "INSERT INTO rigs (name, n_strings, rig_json, created_at) VALUES ($1, $2, $3, $4) RETURNING ",
            rig_cols!()
        ))
        .bind(name)
        .bind(n_strings)
        .bind(rig_json)
        .bind(now_rfc3339())
        .fetch_one(&self.pool)
        .await?)
    }

    pub async fn get_rig(&self, id: i64) -> Result<RigRec> {
        sqlx::query_as::<_, RigRec>(concat!("SELECT ", rig_cols!(), " FROM rigs WHERE id = $1"))
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
            .ok_or(StoreError::NotFound { what: "rig", id })
    }

    pub async fn list_rigs(&self, page: Page) -> Result<(Vec<RigRec>, i64)> {
        let items = sqlx::query_as::<_, RigRec>(concat!(
            "SELECT ",
            rig_cols!(),
            " FROM rigs ORDER BY id LIMIT $1 OFFSET $2"
        ))
        .bind(page.limit)
        .bind(page.offset)
        .fetch_all(&self.pool)
        .await?;
        let total = sqlx::query_scalar::<_, i64>("SELECT COUNT(*) FROM rigs")
            .fetch_one(&self.pool)
            .await?;
        Ok((items, total))
    }

    // ---- sessions and poses ---------------------------------------------

    pub async fn create_session(
        &self,
        robot_id: i64,
        rig_id: i64,
        name: Option<&str>,
    ) -> Result<SessionRec> {
        let now = now_rfc3339();
        Ok(sqlx::query_as::<_, SessionRec>(concat!(
            "INSERT INTO sessions (robot_id, rig_id, name, created_at, updated_at) \
             VALUES ($1, $2, $3, $4, $4) RETURNING ",
            session_cols!()
        ))
        .bind(robot_id)
        .bind(rig_id)
        .bind(name)
        .bind(now)
        .fetch_one(&self.pool)
        .await?)
    }

    pub async fn get_session(&self, id: i64) -> Result<SessionRec> {
        sqlx::query_as::<_, SessionRec>(concat!(
            "SELECT ",
            session_cols!(),
            " FROM sessions WHERE id = $1"
        ))
        .bind(id)
        .fetch_optional(&self.pool)
        .await?
        .ok_or(StoreError::NotFound {
            what: "session",
            id,
        })
    }

    pub async fn list_sessions(
        &self,
        robot_id: Option<i64>,
        page: Page,
    ) -> Result<(Vec<SessionRec>, i64)> {
        let items = sqlx::query_as::<_, SessionRec>(concat!(
            "SELECT ",
            session_cols!(),
            " FROM sessions WHERE ($1 IS NULL OR robot_id = $1) ORDER BY id LIMIT $2 OFFSET $3"
        ))
        .bind(robot_id)
        .bind(page.limit)
        .bind(page.offset)
        .fetch_all(&self.pool)
        .await?;
        let total = sqlx::query_scalar::<_, i64>(
            "SELECT COUNT(*) FROM sessions WHERE ($1 IS NULL OR robot_id = $1)",
        )
        .bind(robot_id)
        .fetch_one(&self.pool)
        .await?;
        Ok((items, total))
    }

    pub async fn append_poses(
        &self,
        session_id: i64,
        expected_batches: i64,
        columns: &str,
        body: &str,
        n_rows: i64,
    ) -> Result<SessionRec> {
        let now = now_rfc3339();
        let mut tx = self.begin_write().await?;
        let updated = sqlx::query_as::<_, SessionRec>(concat!(
            "UPDATE sessions SET columns = $2, n_poses = n_poses + $3, n_batches = n_batches + 1, \
             updated_at = $4 WHERE id = $1 AND n_batches = $5 RETURNING ",
            session_cols!()
        ))
        .bind(session_id)
        .bind(columns)
        .bind(n_rows)
        .bind(&now)
        .bind(expected_batches)
        .fetch_optional(&mut *tx)
        .await?;
        let Some(session) = updated else {
            drop(tx);
            // Either the session is gone or another batch got in first.
            self.get_session(session_id).await?;
            return Err(StoreError::Conflict(
                "another upload to this session was stored meanwhile; retry".into(),
            ));
        };
        sqlx::query(
            "INSERT INTO pose_batches (session_id, seq, n_rows, body, created_at) \
             VALUES ($1, $2, $3, $4, $5)",
        )
        .bind(session_id)
        .bind(session.n_batches)
        .bind(n_rows)
        .bind(body)
        .bind(&now)
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(session)
    }

    pub async fn pose_batches(&self, session_id: i64) -> Result<Vec<String>> {
        Ok(sqlx::query_scalar::<_, String>(
            "SELECT body FROM pose_batches WHERE session_id = $1 ORDER BY seq",
        )
        .bind(session_id)
        .fetch_all(&self.pool)
        .await?)
    }

    // ---- jobs -------------------------------------------------------------

    pub async fn create_job(
        &self,
        session_id: i64,
        robot_id: i64,
        options_json: &str,
        max_attempts: i64,
    ) -> Result<JobRec> {
        let now = now_rfc3339();
        Ok(sqlx::query_as::<_, JobRec>(concat!(
            "INSERT INTO jobs (session_id, robot_id, options, state, max_attempts, created_at, updated_at) \
             VALUES ($1, $2, $3, 'queued', $4, $5, $5) RETURNING ",
            job_cols!()
        ))
        .bind(session_id)
        .bind(robot_id)
        .bind(options_json)
        .bind(max_attempts)
        .bind(now)
        .fetch_one(&self.pool)
        .await?)
    }

    pub async fn get_job(&self, id: i64) -> Result<JobRec> {
        sqlx::query_as::<_, JobRec>(concat!("SELECT ", job_cols!(), " FROM jobs WHERE id = $1"))
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
            .ok_or(StoreError::NotFound { what: "job", id })
    }

    pub async fn list_jobs(
        &self,
        session_id: Option<i64>,
        state: Option<&str>,
        page: Page,
    ) -> Result<(Vec<JobRec>, i64)> {
        let items = sqlx::query_as::<_, JobRec>(concat!(
            "SELECT ",
            job_cols!(),
            " FROM jobs WHERE ($1 IS NULL OR session_id = $1) AND ($2 IS NULL OR state = $2) \
             ORDER BY id LIMIT $3 OFFSET $4"
        ))
        .bind(session_id)
        .bind(state)
        .bind(page.limit)
        .bind(page.offset)
        .fetch_all(&self.pool)
        .await?;
        let total = sqlx::query_scalar::<_, i64>(
            "SELECT COUNT(*) FROM jobs WHERE ($1 IS NULL OR session_id = $1) AND ($2 IS NULL OR state = $2)",
        )
        .bind(session_id)
        .bind(state)
        .fetch_one(&self.pool)
        .await?;
        Ok((items, total))
    }

    pub async fn request_cancel(&self, id: i64) -> Result<JobRec> {
        let now = now_rfc3339();
        let done = sqlx::query_as::<_, JobRec>(concat!(
            "UPDATE jobs SET state = 'cancelled', cancel_requested = TRUE, finished_at = $2, updated_at = $2 \
             WHERE id = $1 AND state = 'queued' RETURNING ",
            job_cols!()
        ))
        .bind(id)
        .bind(&now)
        .fetch_optional(&self.pool)
        .await?;
        if let Some(job) = done {
            return Ok(job);
        }
        let flagged = sqlx::query_as::<_, JobRec>(concat!(
            "UPDATE jobs SET cancel_requested = TRUE, updated_at = $2 \
             WHERE id = $1 AND state = 'running' RETURNING ",
            job_cols!()
        ))
        .bind(id)
        .bind(&now)
        .fetch_optional(&self.pool)
        .await?;
        if let Some(job) = flagged {
            return Ok(job);
        }
        let job = self.get_job(id).await?;
        Err(StoreError::Conflict(format!(
            "job {id} has already ended ({})",
            job.state
        )))
    }

    pub async fn claim_job(
        &self,
        worker: &str,
        lease_ms: i64,
        max_interruptions: i64,
    ) -> Result<Option<JobRec>> {
        let now = now_rfc3339();
        // Give up on jobs whose workers stopped under them too often (a job
        // that crashes its process must not crash every restart forever).
        // Expiry is read on the database's clock, as the lease was written.
        sqlx::query(concat!(
            "UPDATE jobs SET state = 'failed', interruptions = interruptions + 1, error = $2, \
             locked_by = NULL, locked_until_ms = NULL, finished_at = $3, updated_at = $3 \
             WHERE state = 'running' AND locked_until_ms < ",
            db_now_ms!(),
            " AND interruptions + 1 >= $1"
        ))
        .bind(max_interruptions)
        .bind(format!(
            "abandoned: the worker running it stopped before finishing {max_interruptions} times \
             (a job that crashes its process, or a service stopped without its shutdown grace \
             that often while it ran)"
        ))
        .bind(&now)
        .execute(&self.pool)
        .await?;
        Ok(sqlx::query_as::<_, JobRec>(CLAIM_SQL)
            .bind(worker)
            .bind(lease_ms)
            .bind(&now)
            .bind(max_interruptions)
            .fetch_optional(&self.pool)
            .await?)
    }

    pub async fn heartbeat(
        &self,
        id: i64,
        worker: &str,
        lease_ms: i64,
        stage: Option<&str>,
        progress: f64,
    ) -> Result<Option<bool>> {
        Ok(sqlx::query_scalar::<_, bool>(concat!(
            "UPDATE jobs SET locked_until_ms = ",
            db_now_ms!(),
            " + $3, stage = COALESCE($4, stage), progress = $5, \
             updated_at = $6 WHERE id = $1 AND locked_by = $2 AND state = 'running' \
             RETURNING cancel_requested"
        ))
        .bind(id)
        .bind(worker)
        .bind(lease_ms)
        .bind(stage)
        .bind(progress)
        .bind(now_rfc3339())
        .fetch_optional(&self.pool)
        .await?)
    }

    pub async fn complete_job(
        &self,
        id: i64,
        worker: &str,
        cal: &NewCalibration,
    ) -> Result<CalibrationRec> {
        let now = now_rfc3339();
        let mut tx = self.begin_write().await?;
        let held = sqlx::query_as::<_, (i64, i64)>(
            "SELECT robot_id, session_id FROM jobs WHERE id = $1 AND locked_by = $2 AND state = 'running'",
        )
        .bind(id)
        .bind(worker)
        .fetch_optional(&mut *tx)
        .await?;
        let Some((robot_id, session_id)) = held else {
            return Err(StoreError::Conflict(format!(
                "job {id} is no longer held by this worker"
            )));
        };
        let model_id = sqlx::query_scalar::<_, i64>(LOCK_ROBOT_SQL)
            .bind(robot_id)
            .fetch_one(&mut *tx)
            .await?;
        let version = sqlx::query_scalar::<_, i64>(
            "SELECT COALESCE(MAX(version), 0) + 1 FROM calibrations WHERE robot_id = $1",
        )
        .bind(robot_id)
        .fetch_one(&mut *tx)
        .await?;
        let cal_id = sqlx::query_scalar::<_, i64>(
            "INSERT INTO calibrations (robot_id, model_id, session_id, job_id, version, method, n_poses, \
             n_test, test_rms_before_mm, test_rms_after_mm, train_rms_after_mm, effects, created_at) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13) RETURNING id",
        )
        .bind(robot_id)
        .bind(model_id)
        .bind(session_id)
        .bind(id)
        .bind(version)
        .bind(&cal.method)
        .bind(cal.n_poses)
        .bind(cal.n_test)
        .bind(cal.test_rms_before_mm)
        .bind(cal.test_rms_after_mm)
        .bind(cal.train_rms_after_mm)
        .bind(&cal.effects)
        .bind(&now)
        .fetch_one(&mut *tx)
        .await?;
        // The report in a table of its own (migration 0004): history reads
        // never touch it.
        sqlx::query("INSERT INTO calibration_reports (calibration_id, report) VALUES ($1, $2)")
            .bind(cal_id)
            .bind(&cal.report_json)
            .execute(&mut *tx)
            .await?;
        sqlx::query(
            "UPDATE jobs SET state = 'succeeded', progress = 1, stage = 'done', calibration_id = $2, \
             locked_by = NULL, locked_until_ms = NULL, finished_at = $3, updated_at = $3 WHERE id = $1",
        )
        .bind(id)
        .bind(cal_id)
        .bind(&now)
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        self.get_calibration(cal_id).await
    }

    pub async fn finish_job(
        &self,
        id: i64,
        worker: &str,
        state: &str,
        error: Option<&str>,
    ) -> Result<bool> {
        let r = sqlx::query(
            "UPDATE jobs SET state = $3, error = $4, locked_by = NULL, locked_until_ms = NULL, \
             finished_at = $5, updated_at = $5 WHERE id = $1 AND locked_by = $2 AND state = 'running'",
        )
        .bind(id)
        .bind(worker)
        .bind(state)
        .bind(error)
        .bind(now_rfc3339())
        .execute(&self.pool)
        .await?;
        Ok(r.rows_affected() == 1)
    }

    pub async fn fail_job(
        &self,
        id: i64,
        worker: &str,
        error: &str,
        retry: bool,
    ) -> Result<Option<JobRec>> {
        // `attempts` on the right is the value before this update.
        Ok(sqlx::query_as::<_, JobRec>(concat!(
            "UPDATE jobs SET attempts = attempts + 1, error = $3, locked_by = NULL, \
             locked_until_ms = NULL, updated_at = $5, \
             state = CASE WHEN $4 AND attempts + 1 < max_attempts THEN 'queued' ELSE 'failed' END, \
             stage = CASE WHEN $4 AND attempts + 1 < max_attempts THEN 'queued again after a failure' ELSE stage END, \
             finished_at = CASE WHEN $4 AND attempts + 1 < max_attempts THEN NULL ELSE $5 END \
             WHERE id = $1 AND locked_by = $2 AND state = 'running' RETURNING ",
            job_cols!()
        ))
        .bind(id)
        .bind(worker)
        .bind(error)
        .bind(retry)
        .bind(now_rfc3339())
        .fetch_optional(&self.pool)
        .await?)
    }

    pub async fn requeue_job(&self, id: i64, worker: &str) -> Result<bool> {
        let r = sqlx::query(
            "UPDATE jobs SET state = 'queued', locked_by = NULL, locked_until_ms = NULL, \
             stage = 'requeued at shutdown', updated_at = $3 \
             WHERE id = $1 AND locked_by = $2 AND state = 'running'",
        )
        .bind(id)
        .bind(worker)
        .bind(now_rfc3339())
        .execute(&self.pool)
        .await?;
        Ok(r.rows_affected() == 1)
    }

    // ---- calibrations and activation --------------------------------------

    pub async fn get_calibration(&self, id: i64) -> Result<CalibrationRec> {
        sqlx::query_as::<_, CalibrationRec>(concat!(calibration_select!(), "WHERE c.id = $1"))
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
            .ok_or(StoreError::NotFound {
                what: "calibration",
                id,
            })
    }

    pub async fn calibration_report(&self, id: i64) -> Result<String> {
        sqlx::query_scalar::<_, String>("SELECT report FROM calibration_reports WHERE calibration_id = $1")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
            .ok_or(StoreError::NotFound {
                what: "calibration",
                id,
            })
    }

    pub async fn list_calibrations(
        &self,
        f: &CalibrationFilter,
        page: Page,
    ) -> Result<(Vec<CalibrationRec>, i64)> {
        let (page_sql, count_sql, args) = calibration_list_sql(f);
        let items = bind_filter!(
            sqlx::query_as::<_, CalibrationRec>(sqlx::AssertSqlSafe(page_sql)),
            args
        )
        .bind(page.limit)
        .bind(page.offset)
        .fetch_all(&self.pool)
        .await?;
        let total = bind_filter!(
            sqlx::query_scalar::<_, i64>(sqlx::AssertSqlSafe(count_sql)),
            args
        )
        .fetch_one(&self.pool)
        .await?;
        Ok((items, total))
    }

    pub async fn explain_calibration_export(&self, f: &CalibrationFilter) -> Result<Vec<String>> {
        let (sql, args) = calibration_export_sql(f);
        let mut out = vec![format!("-- export: {sql}")];
        let q = bind_filter!(
            sqlx::query(sqlx::AssertSqlSafe(format!("{EXPLAIN} {sql}"))),
            args
        );
        out.extend(explain_lines(&q.fetch_all(&self.pool).await?)?);
        Ok(out)
    }

    pub async fn explain_calibrations(&self, f: &CalibrationFilter, page: Page) -> Result<Vec<String>> {
        let (page_sql, count_sql, args) = calibration_list_sql(f);
        let mut out = Vec::new();
        for (what, sql, paged) in [("page", page_sql, true), ("count", count_sql, false)] {
            out.push(format!("-- {what}: {sql}"));
            let q = bind_filter!(
                sqlx::query(sqlx::AssertSqlSafe(format!("{EXPLAIN} {sql}"))),
                args
            );
            let q = if paged { q.bind(page.limit).bind(page.offset) } else { q };
            out.extend(explain_lines(&q.fetch_all(&self.pool).await?)?);
        }
        Ok(out)
    }

    pub async fn set_active(
        &self,
        robot_id: i64,
        calibration_id: Option<i64>,
        action: &str,
        actor: &str,
        reason: &str,
    ) -> Result<ActivationRec> {
        let now = now_rfc3339();
        let mut tx = self.begin_write().await?;
        let exists = sqlx::query_scalar::<_, i64>(LOCK_ROBOT_SQL)
            .bind(robot_id)
            .fetch_optional(&mut *tx)
            .await?;
        if exists.is_none() {
            return Err(StoreError::NotFound {
                what: "robot",
                id: robot_id,
            });
        }
        let previous = sqlx::query_scalar::<_, Option<i64>>(
            "SELECT active_calibration_id FROM robots WHERE id = $1",
        )
        .bind(robot_id)
        .fetch_one(&mut *tx)
        .await?;
        if let Some(cid) = calibration_id {
            let owner =
                sqlx::query_scalar::<_, i64>("SELECT robot_id FROM calibrations WHERE id = $1")
                    .bind(cid)
                    .fetch_optional(&mut *tx)
                    .await?;
            match owner {
                None => {
                    return Err(StoreError::NotFound {
                        what: "calibration",
                        id: cid,
                    });
                }
                Some(o) if o != robot_id => {
                    return Err(StoreError::Conflict(format!(
                        "calibration {cid} belongs to robot {o}, not robot {robot_id}"
                    )));
                }
                Some(_) => {}
            }
        }
        if action == "activate" && previous == calibration_id {
            return Err(StoreError::Conflict(format!(
                "calibration {} is already active",
                calibration_id
                    .map(|c| c.to_string())
                    .unwrap_or_else(|| "none".into())
            )));
        }
        sqlx::query("UPDATE robots SET active_calibration_id = $2, updated_at = $3 WHERE id = $1")
            .bind(robot_id)
            .bind(calibration_id)
            .bind(&now)
            .execute(&mut *tx)
            .await?;
        let rec = sqlx::query_as::<_, ActivationRec>(
            "INSERT INTO activations (robot_id, action, calibration_id, previous_calibration_id, actor, reason, created_at) \
             VALUES ($1, $2, $3, $4, $5, $6, $7) RETURNING id, robot_id, action, calibration_id, \
             previous_calibration_id, actor, reason, created_at",
        )
        .bind(robot_id)
        .bind(action)
        .bind(calibration_id)
        .bind(previous)
        .bind(actor)
        .bind(reason)
        .bind(&now)
        .fetch_one(&mut *tx)
        .await?;
        let what = calibration_id.map_or("the nominal model".to_string(), |c| format!("calibration {c}"));
        audit_in(&mut tx, actor, action, &format!("robot {robot_id}"), &format!("{what}: {reason}"))
            .await?;
        tx.commit().await?;
        Ok(rec)
    }

    pub async fn previous_active(&self, robot_id: i64) -> Result<Option<i64>> {
        self.get_robot(robot_id).await?;
        let history = sqlx::query_as::<_, (String, Option<i64>)>(
            "SELECT action, calibration_id FROM activations WHERE robot_id = $1 ORDER BY id",
        )
        .bind(robot_id)
        .fetch_all(&self.pool)
        .await?;
        // Activations push, rollbacks pop: the stack's top is what is active.
        let mut stack: Vec<Option<i64>> = Vec::new();
        for (action, cal) in history {
            if action == "rollback" {
                stack.pop();
            } else {
                stack.push(cal);
            }
        }
        match stack.len() {
            0 => Err(StoreError::Conflict(format!(
                "robot {robot_id} has no activation to roll back"
            ))),
            n => Ok(if n >= 2 { stack[n - 2] } else { None }),
        }
    }

    pub async fn list_activations(
        &self,
        robot_id: i64,
        page: Page,
    ) -> Result<(Vec<ActivationRec>, i64)> {
        self.get_robot(robot_id).await?;
        let items = sqlx::query_as::<_, ActivationRec>(
            "SELECT id, robot_id, action, calibration_id, previous_calibration_id, actor, reason, created_at \
             FROM activations WHERE robot_id = $1 ORDER BY id DESC LIMIT $2 OFFSET $3",
        )
        .bind(robot_id)
        .bind(page.limit)
        .bind(page.offset)
        .fetch_all(&self.pool)
        .await?;
        let total =
            sqlx::query_scalar::<_, i64>("SELECT COUNT(*) FROM activations WHERE robot_id = $1")
                .bind(robot_id)
                .fetch_one(&self.pool)
                .await?;
        Ok((items, total))
    }

    pub async fn create_key(&self, k: &NewKey, actor: &str) -> Result<KeyRec> {
        let mut tx = self.begin_write().await?;
        let taken = sqlx::query_scalar::<_, i64>("SELECT id FROM api_keys WHERE name = $1")
            .bind(&k.name)
            .fetch_optional(&mut *tx)
            .await?;
        if taken.is_some() {
            return Err(StoreError::Conflict(format!(
                "a key named '{}' exists (revoke it, or choose another name)",
                k.name
            )));
        }
        let key = sqlx::query_as::<_, KeyRec>(concat!(
            "INSERT INTO api_keys (name, role, sites, prefix, secret_hash, created_at, expires_at) \
             VALUES ($1, $2, $3, $4, $5, $6, $7) RETURNING ",
            key_cols!()
        ))
        .bind(&k.name)
        .bind(&k.role)
        .bind(&k.sites)
        .bind(&k.prefix)
        .bind(&k.secret_hash)
        .bind(now_rfc3339())
        .bind(&k.expires_at)
        .fetch_one(&mut *tx)
        .await?;
        audit_in(
            &mut tx,
            actor,
            "create_key",
            &format!("key {}", key.id),
            &format!("{} ({})", key.name, key.role),
        )
        .await?;
        tx.commit().await?;
        Ok(key)
    }

    pub async fn key_by_hash(&self, secret_hash: &str) -> Result<Option<KeyRec>> {
        Ok(sqlx::query_as::<_, KeyRec>(concat!(
            "SELECT ",
            key_cols!(),
            " FROM api_keys WHERE secret_hash = $1"
        ))
        .bind(secret_hash)
        .fetch_optional(&self.pool)
        .await?)
    }

    pub async fn list_keys(&self) -> Result<Vec<KeyRec>> {
        Ok(sqlx::query_as::<_, KeyRec>(concat!(
            "SELECT ",
            key_cols!(),
            " FROM api_keys ORDER BY id"
        ))
        .fetch_all(&self.pool)
        .await?)
    }

    pub async fn revoke_key(&self, id: i64, actor: &str) -> Result<KeyRec> {
        let mut tx = self.begin_write().await?;
        sqlx::query("UPDATE api_keys SET revoked_at = $1 WHERE id = $2 AND revoked_at IS NULL")
            .bind(now_rfc3339())
            .bind(id)
            .execute(&mut *tx)
            .await?;
        let key = sqlx::query_as::<_, KeyRec>(concat!(
            "SELECT ",
            key_cols!(),
            " FROM api_keys WHERE id = $1"
        ))
        .bind(id)
        .fetch_optional(&mut *tx)
        .await?
        .ok_or(StoreError::NotFound { what: "key", id })?;
        audit_in(&mut tx, actor, "revoke_key", &format!("key {id}"), &key.name).await?;
        tx.commit().await?;
        Ok(key)
    }

    pub async fn audit(&self, actor: &str, action: &str, target: &str, detail: &str) -> Result<()> {
        let mut tx = self.begin_write().await?;
        audit_in(&mut tx, actor, action, target, detail).await?;
        tx.commit().await?;
        Ok(())
    }

    pub async fn list_audit(&self, page: Page) -> Result<(Vec<AuditRec>, i64)> {
        let items = sqlx::query_as::<_, AuditRec>(
            "SELECT id, at, actor, action, target, detail FROM audit_log ORDER BY id DESC \
             LIMIT $1 OFFSET $2",
        )
        .bind(page.limit)
        .bind(page.offset)
        .fetch_all(&self.pool)
        .await?;
        let total = sqlx::query_scalar::<_, i64>("SELECT COUNT(*) FROM audit_log")
            .fetch_one(&self.pool)
            .await?;
        Ok((items, total))
    }
}

/// One entry of the audit log, inside the transaction of what it records
/// (the action and its entry commit together or not at all).
async fn audit_in(
    tx: &mut sqlx::Transaction<'static, Db>,
    actor: &str,
    action: &str,
    target: &str,
    detail: &str,
) -> Result<()> {
    sqlx::query("INSERT INTO audit_log (at, actor, action, target, detail) VALUES ($1, $2, $3, $4, $5)")
        .bind(now_rfc3339())
        .bind(actor)
        .bind(action)
        .bind(target)
        .bind(detail)
        .execute(&mut **tx)
        .await?;
    Ok(())
}
