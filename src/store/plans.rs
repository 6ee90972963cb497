//! Pose plans (`POST /plans`): the request, its state and, when done, the
//! plan as JSON. The planner runs in the process that took the request
//! (`jobs::plans`), under a lease it renews on the database's clock; a plan
//! whose lease runs out before it ends reads as failed
//! ([`PLAN_INTERRUPTED`]).

use serde::Serialize;
use utoipa::ToSchema;

use super::record::record;
use super::{Result, Store};

/// The `error` of a plan whose service stopped (or died) before it ended.
pub const PLAN_INTERRUPTED: &str = "interrupted: the service running this plan stopped before it finished; submit it again (the same seed gives the same plan)";

record! {
    /// A plan as stored (the plan itself is in `result`).
    #[derive(Debug, Clone, Serialize, ToSchema)]
    pub struct PlanRec {
        /// Id.
        pub id: i64,
        /// Robot model planned for.
        pub model_id: i64,
        /// Robot named by the request, if one was.
        pub robot_id: Option<i64>,
        /// Rig.
        pub rig_id: i64,
        /// The planner's options (JSON text, defaults filled in).
        #[serde(skip)]
        pub options: String,
        /// `queued`, `running`, `succeeded` or `failed`.
        pub state: String,
        /// Why it failed.
        pub error: Option<String>,
        /// The option a failure names, if it names one.
        pub error_field: Option<String>,
        /// The plan (JSON text) once it succeeded.
        #[serde(skip)]
        pub result: Option<String>,
        /// The process running it.
        #[serde(skip)]
        pub runner: Option<String>,
        /// Its lease's end (epoch ms, the database's clock).
        #[serde(skip)]
        pub lease_until_ms: Option<i64>,
        /// The key that asked for it.
        pub created_by: String,
        /// Creation time.
        pub created_at: String,
        /// Last change.
        pub updated_at: String,
        /// When the planner started on it.
        pub started_at: Option<String>,
        /// When it ended.
        pub finished_at: Option<String>,
    }
}

/// A plan to queue.
#[derive(Debug, Clone)]
pub struct NewPlan {
    /// Robot model.
    pub model_id: i64,
    /// Robot, if the request named one.
    pub robot_id: Option<i64>,
    /// Rig.
    pub rig_id: i64,
    /// The planner's options (JSON).
    pub options: String,
    /// The process that will run it (holds its lease).
    pub runner: String,
    /// The key's name.
    pub created_by: String,
}

/// How a plan ended.
#[derive(Debug, Clone)]
pub enum PlanEnd {
    /// With a plan (JSON).
    Succeeded {
        /// The plan: poses and report.
        plan_json: String,
    },
    /// With an error, naming the option it concerns if any.
    Failed {
        /// Why.
        error: String,
        /// The option.
        field: Option<String>,
    },
}

impl Store {
    /// Queue a plan, leased to `p.runner` for `lease_ms`.
    pub async fn create_plan(&self, p: &NewPlan, lease_ms: i64) -> Result<PlanRec> {
        match self {
            Store::Sqlite(b) => b.create_plan(p, lease_ms).await,
            Store::Postgres(b) => b.create_plan(p, lease_ms).await,
        }
    }
    /// One plan; an unfinished plan whose lease ran out is first marked
    /// failed ([`PLAN_INTERRUPTED`]).
    pub async fn get_plan(&self, id: i64) -> Result<PlanRec> {
        match self {
            Store::Sqlite(b) => b.get_plan(id).await,
            Store::Postgres(b) => b.get_plan(id).await,
        }
    }
    /// Plans waiting for the planner whose runner is alive.
    pub async fn count_queued_plans(&self) -> Result<i64> {
        match self {
            Store::Sqlite(b) => b.count_queued_plans().await,
            Store::Postgres(b) => b.count_queued_plans().await,
        }
    }
    /// Extend the lease by `lease_ms` from now; false if `runner` no
    /// longer holds an unfinished plan `id`.
    pub async fn renew_plan(&self, id: i64, runner: &str, lease_ms: i64) -> Result<bool> {
        match self {
            Store::Sqlite(b) => b.renew_plan(id, runner, lease_ms).await,
            Store::Postgres(b) => b.renew_plan(id, runner, lease_ms).await,
        }
    }
    /// Mark a queued plan running; false if `runner` no longer holds it.
    pub async fn start_plan(&self, id: i64, runner: &str, lease_ms: i64) -> Result<bool> {
        match self {
            Store::Sqlite(b) => b.start_plan(id, runner, lease_ms).await,
            Store::Postgres(b) => b.start_plan(id, runner, lease_ms).await,
        }
    }
    /// Record how a plan ended; false if `runner` no longer held it (it was
    /// marked interrupted meanwhile).
    pub async fn finish_plan(&self, id: i64, runner: &str, end: &PlanEnd) -> Result<bool> {
        match self {
            Store::Sqlite(b) => b.finish_plan(id, runner, end).await,
            Store::Postgres(b) => b.finish_plan(id, runner, end).await,
        }
    }
}
