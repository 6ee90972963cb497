//! Identification jobs: a persistent queue in the store's `jobs` table and a
//! pool of workers that run the engine off the async runtime.
//!
//! A worker *claims* a job by taking a lease (`locked_by`, `locked_until_ms`)
//! and keeps it alive with a heartbeat that also records progress and reads
//! the cancel flag. The engine itself runs on `tokio::task::spawn_blocking`
//! and polls the flag through [`crate::identify::Progress`]. If the process
//! dies, the heartbeat stops, the lease expires, and the next claim (by this
//! process after a restart, or by another replica) runs the job again; the
//! result is written together with the job's success in one transaction.
//!
//! At graceful shutdown a running job gets a grace period to finish; after
//! that it is cancelled and handed back to the queue.
//!
//! What a job is allowed: `max_attempts` runs that fail by themselves in a
//! way another run may not repeat (the engine panicked, the store failed);
//! a refusal of the data fails it at once. A worker that stops under a
//! job (a killed process, a lost lease) is an *interruption*, counted apart
//! so that restarts of the service do not use up a job's attempts; after
//! `max_interruptions` of them the job is given up, so that a job that
//! crashes its process every time still ends, saying so. Leases are read
//! and written on the database's clock, never a host's.

pub mod plans;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use tokio::sync::{Notify, watch};
use utoipa::ToSchema;

use crate::identify::freeset::FreeSet;
use crate::identify::{IdentifyOptions, Method, Progress};
use crate::model::{Dataset, Rig, Robot};
use crate::pipeline;
use crate::report::Report;
use crate::store::{JobRec, NewCalibration, Store, now_ms};

/// Options of an identification job, as a client sends them (all optional).
#[derive(Debug, Clone, Default, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JobOptions {
    /// `lm` (default) or `paper`.
    #[serde(default)]
    pub method: Option<JobMethod>,
    /// Robust (Huber) loss with outlier flagging.
    #[serde(default)]
    pub robust: Option<bool>,
    /// Run the physics analysis (default true).
    #[serde(default)]
    pub physics: Option<bool>,
    /// Fraction held out when the poses carry no split, in (0, 0.9].
    #[serde(default)]
    #[schema(exclusive_minimum = 0.0, maximum = 0.9)]
    pub holdout_fraction: Option<f64>,
    /// Seed of the hold-out choice.
    #[serde(default)]
    pub seed: Option<u64>,
    /// Deviation (sigmas, 0 to 100; default 3) under which a nearly aliased
    /// joint parameter counts as undetermined and is held at nominal; 0
    /// keeps every parameter the structural identifiability test keeps.
    #[serde(default)]
    #[schema(minimum = 0.0, maximum = 100.0)]
    pub undetermined_z: Option<f64>,
    /// Joint parameters to hold at nominal whatever the data say (`j5.a`,
    /// `j2.theta`...); not with the paper's method.
    #[serde(default)]
    pub hold: Option<Vec<String>>,
    /// Calibrate even when every joint angle looks like radians (default
    /// false: such a job fails, saying why).
    #[serde(default)]
    pub force: Option<bool>,
    /// Also identify the rig's anchor coordinates (four strings or more;
    /// default false): the report gets `rig_anchors` and `calibrated_rig`.
    #[serde(default)]
    pub rig_anchors: Option<bool>,
    /// Which identifiable joint parameters to free (as `drawcal identify
    /// --free`): `auto` (default: chosen by cross-validation when the
    /// train poses are few), `all`, `lengths` (θ, a, d) or `offsets` (θ);
    /// the base pose, the tool point and the sensor parameters are free
    /// in every set. Not with the paper's method.
    #[serde(default)]
    pub free_set: Option<JobFreeSet>,
}

/// Which identifiable joint parameters a job frees.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, ToSchema, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum JobFreeSet {
    /// Chosen by cross-validation when the train poses are few, every
    /// identifiable parameter otherwise.
    Auto,
    /// Every identifiable parameter.
    All,
    /// The joint offsets θ, link lengths a and link offsets d.
    Lengths,
    /// The joint offsets θ alone.
    Offsets,
}

impl From<JobFreeSet> for FreeSet {
    fn from(f: JobFreeSet) -> Self {
        match f {
            JobFreeSet::Auto => FreeSet::Auto,
            JobFreeSet::All => FreeSet::All,
            JobFreeSet::Lengths => FreeSet::Lengths,
            JobFreeSet::Offsets => FreeSet::Offsets,
        }
    }
}

/// Identification method.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, ToSchema, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum JobMethod {
    /// Levenberg-Marquardt to convergence.
    Lm,
    /// The paper's one-step linearised method.
    Paper,
}

impl JobOptions {
    /// Check ranges; `Err((field, message))`.
    pub fn validate(&self) -> Result<(), (String, String)> {
        if let Some(h) = self.holdout_fraction {
            if !(h.is_finite() && h > 0.0 && h <= 0.9) {
                return Err((
                    "holdout_fraction".into(),
                    format!("must be in (0, 0.9], got {h}"),
                ));
            }
        }
        if let Some(z) = self.undetermined_z {
            if !(z.is_finite() && (0.0..=100.0).contains(&z)) {
                return Err((
                    "undetermined_z".into(),
                    format!("must be in [0, 100] sigmas, got {z}"),
                ));
            }
        }
        if self.method == Some(JobMethod::Paper)
            && matches!(
                self.free_set,
                Some(JobFreeSet::Lengths | JobFreeSet::Offsets)
            )
        {
            return Err((
                "free_set".into(),
                "the paper's method frees every identifiable parameter: use free_set all or \
                 auto, or method lm"
                    .into(),
            ));
        }
        Ok(())
    }

    /// The engine's options.
    pub fn to_pipeline(&self) -> pipeline::Options {
        pipeline::Options {
            identify: self.to_identify(),
            physics: self.physics.unwrap_or(true),
            force: self.force.unwrap_or(false),
            ..pipeline::Options::default()
        }
    }

    /// The geometric identification's options.
    pub fn to_identify(&self) -> IdentifyOptions {
        let mut o = IdentifyOptions::default();
        if let Some(m) = self.method {
            o.method = match m {
                JobMethod::Lm => Method::Lm,
                JobMethod::Paper => Method::Paper,
            };
        }
        if let Some(r) = self.robust {
            o.robust = r;
        }
        if let Some(h) = self.holdout_fraction {
            o.holdout_fraction = h;
        }
        if let Some(s) = self.seed {
            o.seed = s;
        }
        if let Some(z) = self.undetermined_z {
            o.undetermined_z = z;
        }
        if let Some(h) = &self.hold {
            o.hold = h.clone();
        }
        if let Some(r) = self.rig_anchors {
            o.rig_anchors = r;
        }
        if let Some(f) = self.free_set {
            o.free_set = f.into();
        }
        o
    }
}

/// Everything a job needs, loaded from the store.
pub struct JobInput {
    /// Nominal robot.
    pub robot: Robot,
    /// Rig.
    pub rig: Rig,
    /// The session's poses, validated.
    pub data: Dataset,
    /// Engine options.
    pub options: pipeline::Options,
}

/// The numerical work of a job (the engine's calibration, or a stand-in in
/// tests). Runs on a blocking thread.
pub type JobFn =
    Arc<dyn Fn(&JobInput, &dyn Progress) -> crate::Result<Report> + Send + Sync + 'static>;

/// The `error` of a job whose cancel arrived while the engine was finishing:
/// its progress reads 100 %, yet no calibration was stored.
pub const CANCELLED_AS_IT_FINISHED: &str =
    "cancel requested while the job finished: its result was not stored";

/// The engine's calibration ([`pipeline::calibrate`]) as a [`JobFn`].
pub fn engine_job_fn() -> JobFn {
    Arc::new(|input: &JobInput, progress: &dyn Progress| {
        pipeline::calibrate(
            &input.robot,
            &input.rig,
            &input.data,
            &input.options,
            progress,
        )
    })
}

/// Worker pool settings.
#[derive(Debug, Clone)]
pub struct JobConfig {
    /// Concurrent jobs in this process.
    pub workers: usize,
    /// Lease length; a job whose worker stopped is re-run this long after its
    /// last heartbeat.
    pub lease: Duration,
    /// How often an idle worker looks for work (it is also woken on enqueue).
    pub poll: Duration,
    /// How long a running job may go on after shutdown is asked before it is
    /// cancelled and handed back to the queue.
    pub shutdown_grace: Duration,
    /// Failed runs allowed per job before it is given up (stored with the
    /// job when it is queued).
    pub max_attempts: i64,
    /// Interruptions (its worker died or lost the lease) after which a job
    /// is given up.
    pub max_interruptions: i64,
}

impl Default for JobConfig {
    fn default() -> Self {
        JobConfig {
            workers: 1,
            lease: Duration::from_secs(15),
            poll: Duration::from_millis(500),
            shutdown_grace: Duration::from_secs(10),
            max_attempts: 3,
            max_interruptions: 10,
        }
    }
}

/// Longest interval between a running job's heartbeats (each also reads
/// the cancel flag and records progress).
const MAX_BEAT: Duration = Duration::from_millis(500);

/// Progress shared between the engine thread and the heartbeat.
struct JobProgress {
    cancel: AtomicBool,
    latest: Mutex<(String, f64)>,
}

impl Progress for JobProgress {
    fn update(&self, stage: &str, fraction: f64) {
        if let Ok(mut l) = self.latest.lock() {
            l.0.clear();
            l.0.push_str(stage);
            l.1 = if fraction.is_finite() {
                fraction.clamp(0.0, 1.0)
            } else {
                l.1
            };
        }
    }
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

/// Why a job failed: its text is what the job's `error` records.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// Its inputs could not be read from the store.
    #[error("loading inputs: {0}")]
    Store(#[from] crate::store::StoreError),
    /// Its calibration could not be written to the store.
    #[error("storing the calibration: {0}")]
    Saving(crate::store::StoreError),
    /// Its stored options do not parse.
    #[error("bad job options: {0}")]
    Options(serde_json::Error),
    /// The session's robot model is not a valid robot.json.
    #[error("robot model: {0}")]
    Robot(crate::Error),
    /// The session's rig is not a valid rig.json.
    #[error("rig: {0}")]
    Rig(crate::Error),
    /// The session's poses are not valid for its robot and rig.
    #[error("poses: {0}")]
    Poses(crate::Error),
    /// The engine refused the data or failed.
    #[error("{0}")]
    Engine(crate::Error),
    /// The report could not be written as JSON.
    #[error("report not serialisable: {0}")]
    Report(serde_json::Error),
    /// The engine panicked.
    #[error("internal error: the engine panicked")]
    Panicked,
}

impl JobError {
    /// True for a failure another run may not repeat (the store, a panic
    /// that may be a resource's): worth an attempt more. A refusal of the
    /// data or the options is the same every time.
    pub fn may_not_repeat(&self) -> bool {
        matches!(
            self,
            JobError::Store(_) | JobError::Saving(_) | JobError::Panicked
        )
    }
}

/// Load a job's robot, rig and poses.
pub async fn load_input(store: &Store, job: &JobRec) -> Result<JobInput, JobError> {
    let session = store.get_session(job.session_id).await?;
    let robot_rec = store.get_robot(session.robot_id).await?;
    let model = store.get_model(robot_rec.model_id).await?;
    let rig_rec = store.get_rig(session.rig_id).await?;
    let batches = store.pose_batches(session.id).await?;
    let options: JobOptions = serde_json::from_str(&job.options).map_err(JobError::Options)?;
    let robot = Robot::from_json(&model.robot_json).map_err(JobError::Robot)?;
    let rig = Rig::from_json(&rig_rec.rig_json).map_err(JobError::Rig)?;
    let columns = session.columns.unwrap_or_default();
    let csv = session_csv(&columns, &batches);
    let data = Dataset::from_csv(csv.as_bytes(), &robot, &rig).map_err(JobError::Poses)?;
    Ok(JobInput {
        robot,
        rig,
        data,
        options: options.to_pipeline(),
    })
}

/// A session's poses as one CSV text: the header, then every batch in order.
pub fn session_csv(columns: &str, batches: &[String]) -> String {
    let mut csv =
        String::with_capacity(columns.len() + 1 + batches.iter().map(String::len).sum::<usize>());
    csv.push_str(columns);
    csv.push('\n');
    for b in batches {
        csv.push_str(b);
    }
    csv
}

/// Figures for the calibration's summary row, from the report.
pub fn summarize(report: &Report, report_json: String) -> NewCalibration {
    let finite = |x: f64| x.is_finite().then_some(x);
    let stats = &report.stats;
    let mut effects: Vec<&str> = Vec::new();
    for f in &report.findings {
        if !effects.contains(&f.effect.as_str()) {
            effects.push(f.effect.as_str());
        }
    }
    NewCalibration {
        method: report.method.clone(),
        n_poses: (stats.train.n + stats.test.n) as i64,
        n_test: stats.test.n as i64,
        // No held-out poses: no held-out figure (the empty set's 0.0 would
        // rank as the fleet's most accurate calibration).
        test_rms_before_mm: finite(stats.test.before.rms_mm).filter(|_| stats.test.n > 0),
        test_rms_after_mm: finite(stats.test.after.rms_mm).filter(|_| stats.test.n > 0),
        train_rms_after_mm: finite(stats.train.after.rms_mm),
        effects: effects.join(","),
        report_json,
    }
}

/// The running pool: wake it on enqueue, stop it at shutdown.
#[derive(Clone)]
pub struct Jobs {
    max_attempts: i64,
    notify: Arc<Notify>,
    shutdown: watch::Sender<bool>,
    handles: Arc<Mutex<Vec<tokio::task::JoinHandle<()>>>>,
}

impl Jobs {
    /// Start `cfg.workers` workers on the current runtime.
    pub fn start(store: Store, cfg: JobConfig, job_fn: JobFn) -> Jobs {
        let notify = Arc::new(Notify::new());
        let (shutdown, rx) = watch::channel(false);
        let prefix = worker_prefix();
        let mut handles = Vec::new();
        for i in 0..cfg.workers {
            let w = Worker {
                name: format!("{prefix}-w{i}"),
                store: store.clone(),
                cfg: cfg.clone(),
                job_fn: job_fn.clone(),
                notify: notify.clone(),
                shutdown: rx.clone(),
            };
            handles.push(tokio::spawn(w.run()));
        }
        Jobs {
            max_attempts: cfg.max_attempts,
            notify,
            shutdown,
            handles: Arc::new(Mutex::new(handles)),
        }
    }

    /// Failed runs a job queued now is allowed ([`JobConfig::max_attempts`]).
    pub fn max_attempts(&self) -> i64 {
        self.max_attempts
    }

    /// A job was queued: wake an idle worker.
    pub fn wake(&self) {
        self.notify.notify_one();
    }

    /// Stop claiming, let running jobs finish within the grace period (then
    /// hand them back to the queue), and wait for the workers.
    pub async fn shutdown(&self) {
        let _ = self.shutdown.send(true);
        let handles = std::mem::take(&mut *self.handles.lock().expect("jobs handles lock"));
        for h in handles {
            let _ = h.await;
        }
    }
}

/// Host and process id plus a random-ish suffix: unique per process.
fn worker_prefix() -> String {
    let host = std::env::var("HOSTNAME").unwrap_or_else(|_| "host".into());
    let nonce = now_ms() % 1_000_000;
    format!("{host}-{}-{nonce}", std::process::id())
}

/// How watching a running job ended.
enum Watched {
    /// Another worker holds the job now: nothing more to record.
    LeaseLost,
    /// The engine ended: its result, and whether the shutdown's grace ran
    /// out (the job goes back to the queue).
    Ended {
        result: Result<crate::Result<Report>, tokio::task::JoinError>,
        handed_back: bool,
    },
}

struct Worker {
    name: String,
    store: Store,
    cfg: JobConfig,
    job_fn: JobFn,
    notify: Arc<Notify>,
    shutdown: watch::Receiver<bool>,
}

impl Worker {
    async fn run(mut self) {
        tracing::info!(worker = %self.name, "job worker started");
        loop {
            if *self.shutdown.borrow() {
                break;
            }
            let lease_ms = self.cfg.lease.as_millis() as i64;
            match self
                .store
                .claim_job(&self.name, lease_ms, self.cfg.max_interruptions)
                .await
            {
                Ok(Some(job)) => {
                    let id = job.id;
                    let span = tracing::info_span!("job", job_id = id, worker = %self.name);
                    let _ = tracing::Instrument::instrument(self.run_job(job), span).await;
                }
                Ok(None) => {
                    tokio::select! {
                        _ = self.notify.notified() => {}
                        _ = tokio::time::sleep(self.cfg.poll) => {}
                        _ = self.shutdown.changed() => {}
                    }
                }
                Err(e) => {
                    tracing::error!(worker = %self.name, error = %e, "claiming a job failed");
                    tokio::select! {
                        _ = tokio::time::sleep(Duration::from_secs(1)) => {}
                        _ = self.shutdown.changed() => {}
                    }
                }
            }
        }
        tracing::info!(worker = %self.name, "job worker stopped");
    }

    async fn run_job(&mut self, job: JobRec) {
        let id = job.id;
        tracing::info!(
            attempts = job.attempts,
            interruptions = job.interruptions,
            "job claimed"
        );
        if job.cancel_requested {
            self.finish(id, "cancelled", None).await;
            return;
        }
        let input = match load_input(&self.store, &job).await {
            Ok(i) => i,
            Err(reason) => {
                self.fail(id, reason).await;
                return;
            }
        };
        let progress = Arc::new(JobProgress {
            cancel: AtomicBool::new(false),
            latest: Mutex::new(("starting".into(), 0.0)),
        });
        let job_fn = self.job_fn.clone();
        let p = progress.clone();
        // The engine runs on a blocking thread, never on the runtime.
        let mut handle = tokio::task::spawn_blocking(move || job_fn(&input, &*p));

        let Watched::Ended {
            result,
            handed_back,
        } = self.watch(id, &mut handle, &progress).await
        else {
            return;
        };

        // A cancel asked for while the engine was finishing still wins: the
        // result is not stored (one last look at the flag).
        let cancel_at_end = matches!(result, Ok(Ok(_)))
            && !handed_back
            && matches!(
                self.store
                    .heartbeat(id, &self.name, self.cfg.lease.as_millis() as i64, None, 1.0)
                    .await,
                Ok(Some(true))
            );
        if cancel_at_end {
            tracing::info!("{CANCELLED_AS_IT_FINISHED}");
            self.finish(id, "cancelled", Some(CANCELLED_AS_IT_FINISHED))
                .await;
            return;
        }
        match result {
            Ok(Ok(report)) => {
                let json = match serde_json::to_string(&report) {
                    Ok(j) => j,
                    Err(e) => {
                        self.fail(id, JobError::Report(e)).await;
                        return;
                    }
                };
                let cal = summarize(&report, json);
                match self.store.complete_job(id, &self.name, &cal).await {
                    Ok(c) => {
                        tracing::info!(calibration_id = c.id, version = c.version, "job succeeded")
                    }
                    // Lost the lease meanwhile: the job is another worker's.
                    Err(crate::store::StoreError::Conflict(m)) => {
                        tracing::warn!(reason = %m, "calibration not stored")
                    }
                    Err(e) => self.fail(id, JobError::Saving(e)).await,
                }
            }
            Ok(Err(crate::Error::Cancelled)) if handed_back => {
                match self.store.requeue_job(id, &self.name).await {
                    Ok(_) => tracing::info!("job handed back to the queue"),
                    Err(e) => tracing::error!(error = %e, "requeue failed"),
                }
            }
            Ok(Err(crate::Error::Cancelled)) => self.finish(id, "cancelled", None).await,
            Ok(Err(e)) => self.fail(id, JobError::Engine(e)).await,
            Err(join) => {
                tracing::error!(error = %join, "the engine panicked");
                self.fail(id, JobError::Panicked).await
            }
        }
    }

    /// Keep the running job's lease alive and its progress recorded,
    /// pass a cancel to the engine, and at shutdown give it its grace
    /// period, until the engine ends (or the lease is lost to another
    /// worker).
    async fn watch(
        &mut self,
        id: i64,
        handle: &mut tokio::task::JoinHandle<crate::Result<Report>>,
        progress: &JobProgress,
    ) -> Watched {
        // Often enough that a cancel reaches the engine (and progress the
        // client) within half a second, not only at the lease's pace.
        let beat = (self.cfg.lease / 3).clamp(Duration::from_millis(50), MAX_BEAT);
        let mut lost_lease = false;
        let mut handed_back = false;
        let mut grace_deadline: Option<tokio::time::Instant> = None;
        let result = loop {
            let grace = async {
                match grace_deadline {
                    Some(d) => tokio::time::sleep_until(d).await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                r = &mut *handle => break r,
                _ = tokio::time::sleep(beat) => {
                    let (stage, frac) = progress.latest.lock().map(|l| l.clone()).unwrap_or_default();
                    let lease_ms = self.cfg.lease.as_millis() as i64;
                    match self.store.heartbeat(id, &self.name, lease_ms, Some(&stage), frac).await {
                        Ok(Some(cancel)) => if cancel { progress.cancel.store(true, Ordering::Relaxed) },
                        Ok(None) => {
                            tracing::warn!("lease lost; abandoning the job");
                            lost_lease = true;
                            progress.cancel.store(true, Ordering::Relaxed);
                        }
                        Err(e) => tracing::warn!(error = %e, "heartbeat failed"),
                    }
                }
                _ = self.shutdown.changed(), if grace_deadline.is_none() => {
                    tracing::info!(grace_s = self.cfg.shutdown_grace.as_secs_f64(), "shutdown: letting the job finish");
                    grace_deadline = Some(tokio::time::Instant::now() + self.cfg.shutdown_grace);
                }
                _ = grace => {
                    tracing::warn!("shutdown grace over: cancelling the job and handing it back");
                    handed_back = true;
                    progress.cancel.store(true, Ordering::Relaxed);
                    grace_deadline = Some(tokio::time::Instant::now() + Duration::from_secs(3600));
                }
            }
        };
        if lost_lease {
            Watched::LeaseLost
        } else {
            Watched::Ended {
                result,
                handed_back,
            }
        }
    }

    /// A run failed, with why: queued again if another run may not fail
    /// the same way and attempts remain, else ended.
    async fn fail(&self, id: i64, why: JobError) {
        let error = why.to_string();
        match self
            .store
            .fail_job(id, &self.name, &error, why.may_not_repeat())
            .await
        {
            Ok(Some(job)) if job.state == "queued" => {
                tracing::warn!(%error, attempts = job.attempts, "job run failed; queued again");
                self.notify.notify_one();
            }
            Ok(Some(job)) => tracing::info!(state = %job.state, %error, "job ended"),
            Ok(None) => tracing::warn!(%error, "job failed after its lease was lost"),
            Err(e) => tracing::error!(error = %e, "recording the job's failure failed"),
        }
    }

    async fn finish(&self, id: i64, state: &str, error: Option<&str>) {
        match self.store.finish_job(id, &self.name, state, error).await {
            Ok(_) => tracing::info!(state, error, "job ended"),
            Err(e) => tracing::error!(error = %e, "recording the job's end failed"),
        }
    }
}
