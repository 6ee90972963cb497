//! Persistence: the only code in drawcal that speaks SQL.
//!
//! One interface, [`Store`], with two backends: SQLite (the default, one
//! file in WAL mode) and PostgreSQL (for fleets: several replicas on one
//! database, several workers claiming jobs safely with `SKIP LOCKED`).
//!
//! Both backends run the *same* query text (`$N` placeholders work in
//! sqlx-sqlite too): the queries live once in `queries.rs`, which each backend
//! module includes with its own database type and its few dialect strings
//! (the job claim). Column types are chosen so that rows decode identically
//! on both: integers are 64-bit, timestamps are RFC 3339 UTC text with
//! milliseconds (which sort lexicographically), leases are epoch
//! milliseconds, JSON documents are text. Every timestamp is made in Rust
//! and bound as a parameter, so no SQL dialect's `now()` is needed.
//!
//! Migrations live in `migrations/sqlite` and `migrations/postgres` with the
//! same version numbers (a test checks that).

mod migrations;
mod plans;
mod postgres;
mod record;
mod sqlite;
mod sqlite_export;
pub mod time;

use serde::Serialize;
use thiserror::Error;
use utoipa::ToSchema;

use record::record;

pub use plans::{NewPlan, PLAN_INTERRUPTED, PlanEnd, PlanRec};
pub use time::{now_ms, now_rfc3339};

/// Result alias for the store.
pub type Result<T, E = StoreError> = std::result::Result<T, E>;

/// What the store can fail with. Mapped to HTTP statuses in one place
/// (`http::error`).
#[derive(Debug, Error)]
pub enum StoreError {
    /// No row with that id.
    #[error("{what} {id} not found")]
    NotFound {
        /// Kind of resource (`robot`, `session`...).
        what: &'static str,
        /// The id asked for.
        id: i64,
    },
    /// A uniqueness rule or a state rule refused the change.
    #[error("{0}")]
    Conflict(String),
    /// The database URL is not one this build can serve.
    #[error("unsupported database url '{0}' (use sqlite://PATH or postgres://...)")]
    UnsupportedUrl(String),
    /// Migrations failed.
    #[error("migration failed: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    /// Any other database failure (never shown to clients in detail).
    #[error("database error: {0}")]
    Db(sqlx::Error),
}

impl From<sqlx::Error> for StoreError {
    fn from(e: sqlx::Error) -> Self {
        if let sqlx::Error::Database(d) = &e {
            if d.is_unique_violation() {
                return StoreError::Conflict(format!(
                    "already exists ({})",
                    d.constraint().unwrap_or("unique constraint")
                ));
            }
        }
        StoreError::Db(e)
    }
}

/// A page of a list.
#[derive(Debug, Clone, Copy)]
pub struct Page {
    /// At most this many items.
    pub limit: i64,
    /// Skip this many.
    pub offset: i64,
}

record! {
    /// A nominal robot model (robot.json).
    #[derive(Debug, Clone, Serialize, ToSchema)]
    pub struct ModelRec {
        /// Id.
        pub id: i64,
        /// Name (from robot.json unless given).
        pub name: String,
        /// Number of joints.
        pub dof: i64,
        /// The robot.json text as uploaded.
        #[serde(skip)]
        pub robot_json: String,
        /// Creation time (RFC 3339 UTC).
        pub created_at: String,
    }
}

record! {
    /// A robot of the fleet.
    #[derive(Debug, Clone, Serialize, ToSchema)]
    pub struct RobotRec {
        /// Id.
        pub id: i64,
        /// Serial number, unique.
        pub serial_number: String,
        /// Its model.
        pub model_id: i64,
        /// Site tag.
        pub site: Option<String>,
        /// Line tag.
        pub line: Option<String>,
        /// Cell tag.
        pub cell: Option<String>,
        /// The calibration in use, if any.
        pub active_calibration_id: Option<i64>,
        /// Creation time.
        pub created_at: String,
        /// Last change.
        pub updated_at: String,
    }
}

/// New robot fields.
#[derive(Debug, Clone)]
pub struct NewRobot {
    /// Serial number.
    pub serial_number: String,
    /// Model id (must exist).
    pub model_id: i64,
    /// Site tag.
    pub site: Option<String>,
    /// Line tag.
    pub line: Option<String>,
    /// Cell tag.
    pub cell: Option<String>,
}

record! {
    /// A measurement rig (rig.json).
    #[derive(Debug, Clone, Serialize, ToSchema)]
    pub struct RigRec {
        /// Id.
        pub id: i64,
        /// Name.
        pub name: String,
        /// Number of drawstrings (0 for a point instrument).
        pub n_strings: i64,
        /// The rig.json text as uploaded.
        #[serde(skip)]
        pub rig_json: String,
        /// Creation time.
        pub created_at: String,
    }
}

record! {
    /// A calibration session: a robot, a rig and recorded poses.
    #[derive(Debug, Clone, Serialize, ToSchema)]
    pub struct SessionRec {
        /// Id.
        pub id: i64,
        /// Robot measured.
        pub robot_id: i64,
        /// Rig used.
        pub rig_id: i64,
        /// Free-form name.
        pub name: Option<String>,
        /// Poses stored so far.
        pub n_poses: i64,
        /// Upload batches stored so far.
        pub n_batches: i64,
        /// CSV header of the stored poses (fixed by the first batch).
        pub columns: Option<String>,
        /// Creation time.
        pub created_at: String,
        /// Last change.
        pub updated_at: String,
    }
}

record! {
    /// An identification job.
    #[derive(Debug, Clone, Serialize, ToSchema)]
    pub struct JobRec {
        /// Id.
        pub id: i64,
        /// Session identified.
        pub session_id: i64,
        /// Robot of the session.
        pub robot_id: i64,
        /// Options (JSON text).
        #[serde(skip)]
        pub options: String,
        /// `queued`, `running`, `succeeded`, `failed` or `cancelled`.
        pub state: String,
        /// Current stage, as the engine reports it.
        pub stage: Option<String>,
        /// Progress in [0, 1].
        pub progress: f64,
        /// Runs that failed by themselves (the engine panicked, the store
        /// could not be read or written): such a failure runs the job again
        /// until `max_attempts`. A refusal of the data ends it at once.
        pub attempts: i64,
        /// Failed runs allowed before it is given up.
        pub max_attempts: i64,
        /// Times its worker stopped under it (the process died, or lost the
        /// lease) before it finished: not attempts, since a restart is not
        /// the job's fault; given up after the service's
        /// `--job-max-interruptions`. A graceful shutdown's hand-back is
        /// neither.
        pub interruptions: i64,
        /// Worker holding the lease.
        #[serde(skip)]
        pub locked_by: Option<String>,
        /// Lease expiry (epoch ms).
        #[serde(skip)]
        pub locked_until_ms: Option<i64>,
        /// Cancellation was asked for.
        pub cancel_requested: bool,
        /// Why it failed; for a job cancelled as it finished (its progress at
        /// 100 %), that its result was not stored.
        pub error: Option<String>,
        /// The calibration it produced.
        pub calibration_id: Option<i64>,
        /// Creation time.
        pub created_at: String,
        /// Last change.
        pub updated_at: String,
        /// When a worker last started it.
        pub started_at: Option<String>,
        /// When it ended.
        pub finished_at: Option<String>,
    }
}

record! {
    /// Summary of a calibration (the report itself is fetched separately).
    #[derive(Debug, Clone, Serialize, ToSchema)]
    pub struct CalibrationRec {
        /// Id.
        pub id: i64,
        /// Robot calibrated.
        pub robot_id: i64,
        /// Robot serial number.
        pub serial_number: String,
        /// Robot model.
        pub model_id: i64,
        /// Robot site tag.
        pub site: Option<String>,
        /// Robot line tag.
        pub line: Option<String>,
        /// Robot cell tag.
        pub cell: Option<String>,
        /// Session the data came from.
        pub session_id: i64,
        /// Job that produced it.
        pub job_id: i64,
        /// Version number, per robot, from 1.
        pub version: i64,
        /// Identification method.
        pub method: String,
        /// Poses used (train + test).
        pub n_poses: i64,
        /// Held-out poses.
        pub n_test: i64,
        /// Held-out RMS with the nominal model (mm).
        pub test_rms_before_mm: Option<f64>,
        /// Held-out RMS with the calibrated model (mm).
        pub test_rms_after_mm: Option<f64>,
        /// Training RMS with the calibrated model (mm).
        pub train_rms_after_mm: Option<f64>,
        /// Physical effects found: stored comma separated, answered as a list
        /// (`[]` for none), as `/robots/{id}/accuracy` answers them.
        #[serde(serialize_with = "effect_list")]
        #[schema(value_type = Vec<String>)]
        pub effects: String,
        /// Whether it is the robot's active calibration now.
        pub active: bool,
        /// Creation time.
        pub created_at: String,
    }
}

impl CalibrationRec {
    /// The effects found, one name each (none for an empty column).
    pub fn effect_names(&self) -> Vec<String> {
        split_effects(&self.effects)
    }
}

/// One exported calibration as the database holds it, borrowed: its text
/// points into the database driver's buffers and is valid for one call of
/// [`ExportSink::row`], so that an export need not copy a row into owned
/// strings to write it somewhere else. The fields are [`CalibrationRec`]'s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationRow<'a> {
    /// Id.
    pub id: i64,
    /// Robot calibrated.
    pub robot_id: i64,
    /// Robot serial number.
    pub serial_number: &'a str,
    /// Robot model.
    pub model_id: i64,
    /// Robot site tag.
    pub site: Option<&'a str>,
    /// Robot line tag.
    pub line: Option<&'a str>,
    /// Robot cell tag.
    pub cell: Option<&'a str>,
    /// Session the data came from.
    pub session_id: i64,
    /// Job that produced it.
    pub job_id: i64,
    /// Version number, per robot, from 1.
    pub version: i64,
    /// Identification method.
    pub method: &'a str,
    /// Poses used (train + test).
    pub n_poses: i64,
    /// Held-out poses.
    pub n_test: i64,
    /// Held-out RMS with the nominal model (mm).
    pub test_rms_before_mm: Option<f64>,
    /// Held-out RMS with the calibrated model (mm).
    pub test_rms_after_mm: Option<f64>,
    /// Training RMS with the calibrated model (mm).
    pub train_rms_after_mm: Option<f64>,
    /// Physical effects found, as stored: comma separated.
    pub effects: &'a str,
    /// Whether it is the robot's active calibration now.
    pub active: bool,
    /// Creation time.
    pub created_at: &'a str,
}

impl CalibrationRow<'_> {
    /// The row, owned.
    pub fn to_rec(&self) -> CalibrationRec {
        CalibrationRec {
            id: self.id,
            robot_id: self.robot_id,
            serial_number: self.serial_number.to_string(),
            model_id: self.model_id,
            site: self.site.map(str::to_string),
            line: self.line.map(str::to_string),
            cell: self.cell.map(str::to_string),
            session_id: self.session_id,
            job_id: self.job_id,
            version: self.version,
            method: self.method.to_string(),
            n_poses: self.n_poses,
            n_test: self.n_test,
            test_rms_before_mm: self.test_rms_before_mm,
            test_rms_after_mm: self.test_rms_after_mm,
            train_rms_after_mm: self.train_rms_after_mm,
            effects: self.effects.to_string(),
            active: self.active,
            created_at: self.created_at.to_string(),
        }
    }
}

impl CalibrationRec {
    /// The record as a borrowed row (what an [`ExportSink`] takes).
    pub fn as_row(&self) -> CalibrationRow<'_> {
        CalibrationRow {
            id: self.id,
            robot_id: self.robot_id,
            serial_number: &self.serial_number,
            model_id: self.model_id,
            site: self.site.as_deref(),
            line: self.line.as_deref(),
            cell: self.cell.as_deref(),
            session_id: self.session_id,
            job_id: self.job_id,
            version: self.version,
            method: &self.method,
            n_poses: self.n_poses,
            n_test: self.n_test,
            test_rms_before_mm: self.test_rms_before_mm,
            test_rms_after_mm: self.test_rms_after_mm,
            train_rms_after_mm: self.train_rms_after_mm,
            effects: &self.effects,
            active: self.active,
            created_at: &self.created_at,
        }
    }
}

/// Where the rows of an export go ([`Store::export_calibrations`]): it
/// takes each row as the database driver holds it, on the thread that
/// reads them (on SQLite a blocking thread of its own, on PostgreSQL the
/// runtime's), and hands out what it made of them a piece at a time (a
/// piece of CSV, a batch of records), so that the export's memory is a
/// piece or two, whatever its size.
pub trait ExportSink: Send + 'static {
    /// What is handed out.
    type Piece: Send + 'static;
    /// Take the next row (oldest first).
    fn row(&mut self, row: &CalibrationRow<'_>);
    /// A piece to hand out now, if one is ready; asked after every row.
    fn ready(&mut self) -> Option<Self::Piece>;
    /// What is left after the last row, if anything.
    fn finish(&mut self) -> Option<Self::Piece>;
}

/// Rows kept as records, handed out [`RecordBatches::ROWS`] at a time
/// ([`Store::stream_calibrations`]).
struct RecordBatches(Vec<CalibrationRec>);

impl RecordBatches {
    /// Rows a batch: one hand-over (and at most one thread wake-up) per
    /// batch, not per row; a batch is a few tens of KB.
    const ROWS: usize = 256;
}

impl ExportSink for RecordBatches {
    type Piece = Vec<CalibrationRec>;
    fn row(&mut self, row: &CalibrationRow<'_>) {
        self.0.push(row.to_rec());
    }
    fn ready(&mut self) -> Option<Vec<CalibrationRec>> {
        (self.0.len() >= Self::ROWS)
            .then(|| std::mem::replace(&mut self.0, Vec::with_capacity(Self::ROWS)))
    }
    fn finish(&mut self) -> Option<Vec<CalibrationRec>> {
        (!self.0.is_empty()).then(|| std::mem::take(&mut self.0))
    }
}

fn split_effects(stored: &str) -> Vec<String> {
    stored
        .split(',')
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .collect()
}

fn effect_list<S: serde::Serializer>(stored: &str, s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(split_effects(stored))
}

record! {
    /// An API key as stored: never its secret, only the secret's SHA-256
    /// and its first characters (to tell keys apart in a list).
    #[derive(Debug, Clone, Serialize, ToSchema)]
    pub struct KeyRec {
        /// Id.
        pub id: i64,
        /// Who holds it (unique): the name recorded as the actor of what
        /// is done with it.
        pub name: String,
        /// `reader`, `operator`, `engineer` or `admin`.
        pub role: String,
        /// Sites it is limited to, comma separated (empty: every site).
        pub sites: String,
        /// The key's first characters (`dck_ab12...`).
        pub prefix: String,
        /// SHA-256 of the key (hex).
        #[serde(skip)]
        pub secret_hash: String,
        /// Creation time.
        pub created_at: String,
        /// When it stops working, if ever.
        pub expires_at: Option<String>,
        /// When it was revoked, if it was.
        pub revoked_at: Option<String>,
    }
}

record! {
    /// One entry of the audit log: who did what, when.
    #[derive(Debug, Clone, Serialize, ToSchema)]
    pub struct AuditRec {
        /// Id (increasing).
        pub id: i64,
        /// When (RFC 3339 UTC).
        pub at: String,
        /// The key's name that did it.
        pub actor: String,
        /// What (`activate`, `rollback`, `cancel_job`, `enqueue_job`,
        /// `upload_poses`, `create_key`, `revoke_key`...).
        pub action: String,
        /// On what (`robot 3`, `job 12`, `key 2`...).
        pub target: String,
        /// More, in words.
        pub detail: String,
    }
}

/// A new calibration, written with the job's success in one transaction.
#[derive(Debug, Clone)]
pub struct NewCalibration {
    /// Method name.
    pub method: String,
    /// Poses used.
    pub n_poses: i64,
    /// Held-out poses.
    pub n_test: i64,
    /// Held-out RMS before (mm).
    pub test_rms_before_mm: Option<f64>,
    /// Held-out RMS after (mm).
    pub test_rms_after_mm: Option<f64>,
    /// Training RMS after (mm).
    pub train_rms_after_mm: Option<f64>,
    /// Effects found, comma separated.
    pub effects: String,
    /// The whole report (JSON).
    pub report_json: String,
}

/// Filters on the fleet's calibrations.
#[derive(Debug, Clone, Default)]
pub struct CalibrationFilter {
    /// Robot id.
    pub robot_id: Option<i64>,
    /// Model id.
    pub model_id: Option<i64>,
    /// Site tag.
    pub site: Option<String>,
    /// Line tag.
    pub line: Option<String>,
    /// Created at or after (RFC 3339 text).
    pub from: Option<String>,
    /// Created at or before (RFC 3339 text).
    pub to: Option<String>,
    /// Held-out RMS after at most (mm).
    pub max_test_rms_mm: Option<f64>,
    /// Held-out RMS after at least (mm).
    pub min_test_rms_mm: Option<f64>,
}

record! {
    /// An activation or rollback, as recorded.
    #[derive(Debug, Clone, Serialize, ToSchema)]
    pub struct ActivationRec {
        /// Id.
        pub id: i64,
        /// Robot.
        pub robot_id: i64,
        /// `activate` or `rollback`.
        pub action: String,
        /// Calibration active after the change (none: the nominal model).
        pub calibration_id: Option<i64>,
        /// Calibration active before the change.
        pub previous_calibration_id: Option<i64>,
        /// Who did it.
        pub actor: String,
        /// Why.
        pub reason: String,
        /// When.
        pub created_at: String,
    }
}

/// The database behind the service.
#[derive(Clone, Debug)]
pub enum Store {
    /// A SQLite file (WAL mode).
    Sqlite(sqlite::Backend),
    /// A PostgreSQL database.
    Postgres(postgres::Backend),
}

/// Forward a method call to whichever backend is in use.
macro_rules! dispatch {
    ($self:ident . $method:ident ( $($arg:expr),* )) => {
        match $self {
            Store::Sqlite(b) => b.$method($($arg),*).await,
            Store::Postgres(b) => b.$method($($arg),*).await,
        }
    };
}

impl Store {
    /// Open (creating if needed) and migrate the database named by `url`:
    /// `sqlite://PATH` (or `sqlite:PATH`) or `postgres://...`.
    pub async fn connect(url: &str) -> Result<Self> {
        if url.starts_with("sqlite:") {
            Ok(Store::Sqlite(sqlite::Backend::connect(url).await?))
        } else if url.starts_with("postgres://") || url.starts_with("postgresql://") {
            Ok(Store::Postgres(postgres::Backend::connect(url).await?))
        } else {
            Err(StoreError::UnsupportedUrl(url.to_string()))
        }
    }

    /// Wrap an existing SQLite pool (already migrated), e.g. from `#[sqlx::test]`.
    pub fn from_sqlite_pool(pool: sqlx::SqlitePool) -> Self {
        Store::Sqlite(sqlite::Backend::new(pool))
    }

    /// Wrap an existing PostgreSQL pool (already migrated).
    pub fn from_pg_pool(pool: sqlx::PgPool) -> Self {
        Store::Postgres(postgres::Backend::new(pool))
    }

    /// Backend name (`sqlite` or `postgres`).
    pub fn backend(&self) -> &'static str {
        match self {
            Store::Sqlite(_) => "sqlite",
            Store::Postgres(_) => "postgres",
        }
    }

    /// A trivial query: is the database answering?
    pub async fn ping(&self) -> Result<()> {
        dispatch!(self.ping())
    }

    /// Close the pool.
    pub async fn close(&self) {
        match self {
            Store::Sqlite(b) => b.pool.close().await,
            Store::Postgres(b) => b.pool.close().await,
        }
    }

    /// Store a robot model.
    pub async fn create_model(&self, name: &str, dof: i64, robot_json: &str) -> Result<ModelRec> {
        dispatch!(self.create_model(name, dof, robot_json))
    }
    /// One robot model.
    pub async fn get_model(&self, id: i64) -> Result<ModelRec> {
        dispatch!(self.get_model(id))
    }
    /// A page of robot models and the total count.
    pub async fn list_models(&self, page: Page) -> Result<(Vec<ModelRec>, i64)> {
        dispatch!(self.list_models(page))
    }

    /// Store a robot (its model must exist).
    pub async fn create_robot(&self, r: &NewRobot) -> Result<RobotRec> {
        dispatch!(self.create_robot(r))
    }
    /// One robot.
    pub async fn get_robot(&self, id: i64) -> Result<RobotRec> {
        dispatch!(self.get_robot(id))
    }
    /// A page of robots, optionally filtered by model, site and line.
    pub async fn list_robots(
        &self,
        model_id: Option<i64>,
        site: Option<&str>,
        line: Option<&str>,
        page: Page,
    ) -> Result<(Vec<RobotRec>, i64)> {
        dispatch!(self.list_robots(model_id, site, line, page))
    }

    /// Store a rig.
    pub async fn create_rig(&self, name: &str, n_strings: i64, rig_json: &str) -> Result<RigRec> {
        dispatch!(self.create_rig(name, n_strings, rig_json))
    }
    /// One rig.
    pub async fn get_rig(&self, id: i64) -> Result<RigRec> {
        dispatch!(self.get_rig(id))
    }
    /// A page of rigs.
    pub async fn list_rigs(&self, page: Page) -> Result<(Vec<RigRec>, i64)> {
        dispatch!(self.list_rigs(page))
    }

    /// Open a session for a robot and a rig (both must exist).
    pub async fn create_session(
        &self,
        robot_id: i64,
        rig_id: i64,
        name: Option<&str>,
    ) -> Result<SessionRec> {
        dispatch!(self.create_session(robot_id, rig_id, name))
    }
    /// One session.
    pub async fn get_session(&self, id: i64) -> Result<SessionRec> {
        dispatch!(self.get_session(id))
    }
    /// A page of sessions, optionally of one robot.
    pub async fn list_sessions(
        &self,
        robot_id: Option<i64>,
        page: Page,
    ) -> Result<(Vec<SessionRec>, i64)> {
        dispatch!(self.list_sessions(robot_id, page))
    }

    /// Append a validated batch of poses. `expected_batches` is the session's
    /// batch count the caller validated against: if another upload got in
    /// first the append is refused with [`StoreError::Conflict`], so a batch
    /// is never stored unvalidated against what precedes it. `columns` is the
    /// CSV header, `body` the CSV records (no header) in that column order.
    pub async fn append_poses(
        &self,
        session_id: i64,
        expected_batches: i64,
        columns: &str,
        body: &str,
        n_rows: i64,
    ) -> Result<SessionRec> {
        dispatch!(self.append_poses(session_id, expected_batches, columns, body, n_rows))
    }
    /// The stored pose batches' CSV bodies, in upload order.
    pub async fn pose_batches(&self, session_id: i64) -> Result<Vec<String>> {
        dispatch!(self.pose_batches(session_id))
    }

    /// Queue an identification job.
    pub async fn create_job(
        &self,
        session_id: i64,
        robot_id: i64,
        options_json: &str,
        max_attempts: i64,
    ) -> Result<JobRec> {
        dispatch!(self.create_job(session_id, robot_id, options_json, max_attempts))
    }
    /// One job.
    pub async fn get_job(&self, id: i64) -> Result<JobRec> {
        dispatch!(self.get_job(id))
    }
    /// A page of jobs, optionally of one session and/or in one state.
    pub async fn list_jobs(
        &self,
        session_id: Option<i64>,
        state: Option<&str>,
        page: Page,
    ) -> Result<(Vec<JobRec>, i64)> {
        dispatch!(self.list_jobs(session_id, state, page))
    }
    /// Ask for cancellation: a queued job is cancelled at once, a running one
    /// is flagged (its worker sees the flag at the next heartbeat). A job that
    /// has ended is a conflict.
    pub async fn request_cancel(&self, id: i64) -> Result<JobRec> {
        dispatch!(self.request_cancel(id))
    }
    /// Claim the oldest runnable job (queued, or running with an expired
    /// lease: an interruption) for `worker`, leased for `lease_ms` on the
    /// database's clock. A job whose lease expired for the
    /// `max_interruptions`-th time is failed instead ("abandoned").
    pub async fn claim_job(
        &self,
        worker: &str,
        lease_ms: i64,
        max_interruptions: i64,
    ) -> Result<Option<JobRec>> {
        dispatch!(self.claim_job(worker, lease_ms, max_interruptions))
    }
    /// Extend the lease by `lease_ms` from now (the database's clock) and
    /// record progress. Returns `None` if the worker no longer holds the
    /// job, else whether cancellation was requested.
    pub async fn heartbeat(
        &self,
        id: i64,
        worker: &str,
        lease_ms: i64,
        stage: Option<&str>,
        progress: f64,
    ) -> Result<Option<bool>> {
        dispatch!(self.heartbeat(id, worker, lease_ms, stage, progress))
    }
    /// A run of the job failed by itself: count the attempt and, when
    /// `retry` (a failure another run may not repeat) and attempts remain,
    /// queue it again; else end it failed. `error` is recorded either way.
    /// `None` if the worker no longer holds the job.
    pub async fn fail_job(
        &self,
        id: i64,
        worker: &str,
        error: &str,
        retry: bool,
    ) -> Result<Option<JobRec>> {
        dispatch!(self.fail_job(id, worker, error, retry))
    }
    /// Record the calibration and mark the job succeeded, in one transaction.
    /// Fails with a conflict if the worker lost its lease.
    pub async fn complete_job(
        &self,
        id: i64,
        worker: &str,
        cal: &NewCalibration,
    ) -> Result<CalibrationRec> {
        dispatch!(self.complete_job(id, worker, cal))
    }
    /// End a job the worker holds: `failed` (with `error`) or `cancelled`.
    pub async fn finish_job(
        &self,
        id: i64,
        worker: &str,
        state: &str,
        error: Option<&str>,
    ) -> Result<bool> {
        dispatch!(self.finish_job(id, worker, state, error))
    }
    /// Hand a job back to the queue (graceful shutdown); the claim is not
    /// counted as an attempt.
    pub async fn requeue_job(&self, id: i64, worker: &str) -> Result<bool> {
        dispatch!(self.requeue_job(id, worker))
    }

    /// One calibration's summary.
    pub async fn get_calibration(&self, id: i64) -> Result<CalibrationRec> {
        dispatch!(self.get_calibration(id))
    }
    /// One calibration's full report (JSON text).
    pub async fn calibration_report(&self, id: i64) -> Result<String> {
        dispatch!(self.calibration_report(id))
    }
    /// The fleet's calibrations, filtered, oldest first.
    pub async fn list_calibrations(
        &self,
        f: &CalibrationFilter,
        page: Page,
    ) -> Result<(Vec<CalibrationRec>, i64)> {
        dispatch!(self.list_calibrations(f, page))
    }
    /// Every calibration the filter matches, oldest first, read from the
    /// database as the stream is polled: one query, no count, one row in
    /// memory at a time, so that an export of any size holds little. The
    /// stream holds a pool connection until it ends or is dropped, so at
    /// most half the pool's connections serve such streams at once (the
    /// others are for everything else, however slowly exports are read);
    /// past that this waits for one to end.
    pub async fn stream_calibrations(
        &self,
        f: &CalibrationFilter,
    ) -> futures_util::stream::BoxStream<'static, Result<CalibrationRec>> {
        use futures_util::StreamExt;
        let batches = RecordBatches(Vec::with_capacity(RecordBatches::ROWS));
        self.export_calibrations(f, batches)
            .await
            .flat_map(|batch| {
                futures_util::stream::iter(match batch {
                    Ok(rows) => rows.into_iter().map(Ok).collect::<Vec<_>>(),
                    Err(e) => vec![Err(e)],
                })
            })
            .boxed()
    }
    /// Every calibration the filter matches, oldest first, written into
    /// `sink` as the database reads them, on the thread that reads them;
    /// the stream hands out the sink's pieces as they are ready, then what
    /// is left, or ends with a failure (after which it has nothing more).
    /// The query, its bounds on memory and on exports in flight, are
    /// [`Store::stream_calibrations`]'s (which is this, with records for
    /// pieces). On SQLite the reader thread waits, holding its connection,
    /// while the pieces are not taken (it stays at most two ahead); on
    /// PostgreSQL the rows are read as the stream is polled.
    pub async fn export_calibrations<S: ExportSink>(
        &self,
        f: &CalibrationFilter,
        sink: S,
    ) -> futures_util::stream::BoxStream<'static, Result<S::Piece>> {
        dispatch!(self.export_calibrations(f, sink))
    }
    /// The database's plan of [`Store::stream_calibrations`]'s query for a
    /// filter, one line a step (as [`Store::explain_calibrations`]).
    pub async fn explain_calibration_export(&self, f: &CalibrationFilter) -> Result<Vec<String>> {
        dispatch!(self.explain_calibration_export(f))
    }
    /// The database's plan of [`Store::list_calibrations`]'s two queries
    /// (the page and its count) for a filter, one line a step: `EXPLAIN
    /// QUERY PLAN` on SQLite, `EXPLAIN` on PostgreSQL. For the fleet-scale
    /// figures (BENCHMARKS.md) and the test that the history filters use
    /// indexes.
    pub async fn explain_calibrations(
        &self,
        f: &CalibrationFilter,
        page: Page,
    ) -> Result<Vec<String>> {
        dispatch!(self.explain_calibrations(f, page))
    }
    /// Make `calibration_id` (which must belong to the robot; `None`: the
    /// nominal model) the robot's active calibration and record it, in
    /// the activation history and the audit log, as done by `actor`.
    pub async fn set_active(
        &self,
        robot_id: i64,
        calibration_id: Option<i64>,
        action: &str,
        actor: &str,
        reason: &str,
    ) -> Result<ActivationRec> {
        dispatch!(self.set_active(robot_id, calibration_id, action, actor, reason))
    }
    /// The calibration active before the current one, following the
    /// activation history (for rollback). `Ok(None)` if the robot had no
    /// calibration before; a conflict if there is nothing to roll back.
    pub async fn previous_active(&self, robot_id: i64) -> Result<Option<i64>> {
        dispatch!(self.previous_active(robot_id))
    }
    /// A robot's activation history, newest first.
    pub async fn list_activations(
        &self,
        robot_id: i64,
        page: Page,
    ) -> Result<(Vec<ActivationRec>, i64)> {
        dispatch!(self.list_activations(robot_id, page))
    }
    /// Store a new key (its secret's hash), with its audit entry by
    /// `actor`; a taken name is a conflict.
    pub async fn create_key(&self, k: &NewKey, actor: &str) -> Result<KeyRec> {
        dispatch!(self.create_key(k, actor))
    }
    /// The key whose secret hashes to `secret_hash`, revoked or not.
    pub async fn key_by_hash(&self, secret_hash: &str) -> Result<Option<KeyRec>> {
        dispatch!(self.key_by_hash(secret_hash))
    }
    /// Every key, oldest first.
    pub async fn list_keys(&self) -> Result<Vec<KeyRec>> {
        dispatch!(self.list_keys())
    }
    /// Revoke a key (again: no change), with its audit entry by `actor`.
    pub async fn revoke_key(&self, id: i64, actor: &str) -> Result<KeyRec> {
        dispatch!(self.revoke_key(id, actor))
    }
    /// Append to the audit log (activations and key changes write theirs
    /// in their own transaction).
    pub async fn audit(&self, actor: &str, action: &str, target: &str, detail: &str) -> Result<()> {
        dispatch!(self.audit(actor, action, target, detail))
    }
    /// A page of the audit log, newest first, and the total count.
    pub async fn list_audit(&self, page: Page) -> Result<(Vec<AuditRec>, i64)> {
        dispatch!(self.list_audit(page))
    }
}

/// A new API key.
#[derive(Debug, Clone)]
pub struct NewKey {
    /// Who holds it (unique).
    pub name: String,
    /// Its role.
    pub role: String,
    /// Sites, comma separated (empty: every site).
    pub sites: String,
    /// The key's first characters.
    pub prefix: String,
    /// SHA-256 of the key (hex).
    pub secret_hash: String,
    /// When it stops working (RFC 3339), if ever.
    pub expires_at: Option<String>,
}
