//! Pose plans run in the background (`POST /plans`): each on a blocking
//! thread, at most a fixed number at once, under a lease renewed in the
//! store while it waits and while it runs.
//!
//! Unlike identification jobs, a plan is not claimed from a queue by any
//! replica: it runs in the process that accepted it. A plan is a few
//! seconds of work and the same seed gives the same plan, so a plan whose
//! process stops before it ends is not resumed: once its lease runs out it
//! reads as failed ([`crate::store::PLAN_INTERRUPTED`]) and the client
//! submits it again. Finished plans stay in the store.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::Semaphore;
use tokio::task::JoinHandle;

use crate::model::{Rig, Robot};
use crate::plan::{self, PlanOptions};
use crate::store::{PlanEnd, Store, now_ms};

/// Everything the planner needs, checked by the handler.
pub struct PlanInput {
    /// The nominal robot.
    pub robot: Robot,
    /// The rig.
    pub rig: Rig,
    /// The planner's options.
    pub options: PlanOptions,
}

/// The plans running or waiting in this process.
#[derive(Clone)]
pub struct Plans {
    store: Store,
    permits: Arc<Semaphore>,
    lease: Duration,
    runner: Arc<str>,
    tasks: Arc<Mutex<Vec<JoinHandle<()>>>>,
}

impl Plans {
    /// At most `concurrency` plans at once, each leased for `lease`.
    pub fn new(store: Store, concurrency: usize, lease: Duration) -> Plans {
        let host = std::env::var("HOSTNAME").unwrap_or_else(|_| "host".into());
        Plans {
            store,
            permits: Arc::new(Semaphore::new(concurrency.max(1))),
            lease,
            runner: format!(
                "{host}-{}-{}-plans",
                std::process::id(),
                now_ms() % 1_000_000
            )
            .into(),
            tasks: Arc::new(Mutex::new(Vec::new())),
        }
    }

    /// This process's name as the plans' runner.
    pub fn runner(&self) -> &str {
        &self.runner
    }

    /// The lease (ms) a plan is stored with.
    pub fn lease_ms(&self) -> i64 {
        self.lease.as_millis() as i64
    }

    /// Run the stored plan `id` (queued, leased to [`Plans::runner`]).
    pub fn submit(&self, id: i64, input: PlanInput) {
        let me = self.clone();
        let span = tracing::info_span!("plan", plan_id = id);
        let task = tokio::spawn(tracing::Instrument::instrument(me.run(id, input), span));
        let mut tasks = self.tasks.lock().unwrap_or_else(|e| e.into_inner());
        tasks.retain(|t| !t.is_finished());
        tasks.push(task);
    }

    /// Let the plans running or waiting finish within `grace`; those that
    /// do not are dropped (their lease runs out: they read as interrupted).
    pub async fn shutdown(&self, grace: Duration) {
        let tasks = std::mem::take(&mut *self.tasks.lock().unwrap_or_else(|e| e.into_inner()));
        let aborts: Vec<_> = tasks.iter().map(JoinHandle::abort_handle).collect();
        let all = async {
            for t in tasks {
                let _ = t.await;
            }
        };
        if tokio::time::timeout(grace, all).await.is_err() {
            tracing::warn!("plans still unfinished at the end of the shutdown grace are dropped");
            for a in aborts {
                a.abort();
            }
        }
    }

    async fn renew(&self, id: i64) -> bool {
        match self
            .store
            .renew_plan(id, &self.runner, self.lease_ms())
            .await
        {
            Ok(held) => held,
            Err(e) => {
                // A passing database error: the lease may survive it.
                tracing::warn!(error = %e, "renewing the plan's lease failed");
                true
            }
        }
    }

    async fn run(self, id: i64, input: PlanInput) {
        // As often as a job's heartbeat: well inside the lease.
        let beat = (self.lease / 3).clamp(Duration::from_millis(50), Duration::from_millis(500));
        let acquire = self.permits.clone().acquire_owned();
        tokio::pin!(acquire);
        let _permit = loop {
            tokio::select! {
                p = &mut acquire => match p {
                    Ok(p) => break p,
                    Err(_) => return,
                },
                _ = tokio::time::sleep(beat) => if !self.renew(id).await {
                    tracing::warn!("plan no longer held while waiting; dropped");
                    return;
                },
            }
        };
        match self
            .store
            .start_plan(id, &self.runner, self.lease_ms())
            .await
        {
            Ok(true) => tracing::info!("plan started"),
            Ok(false) => {
                tracing::warn!("plan no longer held; not run");
                return;
            }
            Err(e) => {
                tracing::error!(error = %e, "starting the plan failed");
                return;
            }
        }
        let mut handle = tokio::task::spawn_blocking(move || {
            plan::plan(&input.robot, &input.rig, &input.options)
        });
        let result = loop {
            tokio::select! {
                r = &mut handle => break r,
                _ = tokio::time::sleep(beat) => if !self.renew(id).await {
                    // Marked interrupted meanwhile (a stalled process): the
                    // result would not be stored.
                    tracing::warn!("plan's lease lost while it ran");
                },
            }
        };
        let end = match result {
            Ok(Ok(plan)) => match serde_json::to_string(&plan) {
                Ok(plan_json) => PlanEnd::Succeeded { plan_json },
                Err(e) => PlanEnd::Failed {
                    error: format!("plan not serialisable: {e}"),
                    field: None,
                },
            },
            Ok(Err(e)) => PlanEnd::Failed {
                field: match &e {
                    crate::Error::Input { field, .. } => field.clone(),
                    _ => None,
                },
                error: e.to_string(),
            },
            Err(join) => {
                tracing::error!(error = %join, "the planner panicked");
                PlanEnd::Failed {
                    error: "internal error: the planner panicked".into(),
                    field: None,
                }
            }
        };
        match self.store.finish_plan(id, &self.runner, &end).await {
            Ok(true) => tracing::info!(
                state = if matches!(end, PlanEnd::Succeeded { .. }) {
                    "succeeded"
                } else {
                    "failed"
                },
                "plan ended"
            ),
            Ok(false) => tracing::warn!("plan ended after its lease was lost: not stored"),
            Err(e) => tracing::error!(error = %e, "storing the plan failed"),
        }
    }
}
