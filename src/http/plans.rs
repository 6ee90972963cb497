//! Pose plans (`POST /plans`): `drawcal plan` as a background job of the
//! service. The request names a robot model (or a robot, whose model it
//! is) and a rig, with the planner's options; the answer is the plan's id
//! and state at once (202), and `GET /plans/{id}` gives, when it is done,
//! the same plan as the CLI writes: the poses, the report and targets.csv.
//!
//! Everything the planner would refuse is checked here first, so that a bad
//! option is a 422 naming it rather than a failed plan; the planner runs in
//! this process ([`crate::jobs::plans`]).

use axum::extract::State;
use axum::http::header::{CONTENT_TYPE, LOCATION};
use axum::http::{HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::auth::Caller;
use super::error::{BODY_TIMEOUT_408, BODY_TOO_LARGE_413};
use super::extract::{ApiJson, Id};
use super::limits::{Action, queue_has_room};
use super::resources::{stored_rig, stored_robot};
use super::{ApiError, ApiResult, AppState, ErrorBody};
use crate::jobs::plans::PlanInput;
use crate::model::{Rig, Robot};
use crate::plan::{self, KeepOut, PlanOptions, Workspace};
use crate::store::{NewPlan, PlanRec, StoreError};

/// A box the arm, the tool and the strings stay out of (robot base frame).
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PlanKeepOut {
    /// Smallest x, y, z (mm).
    #[schema(min_items = 3, max_items = 3)]
    pub min_mm: [f64; 3],
    /// Largest x, y, z (mm); not below `min_mm` on any axis.
    #[schema(min_items = 3, max_items = 3)]
    pub max_mm: [f64; 3],
}

/// Where poses may go, beyond the joint limits (all optional).
#[derive(Debug, Clone, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PlanWorkspace {
    /// Floor height in the robot base frame (mm): every joint frame, the
    /// flange and T stay above it.
    #[serde(default)]
    pub floor_z_mm: Option<f64>,
    /// Boxes the links, the tool and the strings stay out of.
    #[serde(default)]
    #[schema(max_items = 100)] // plan::MAX_KEEP_OUT
    pub keep_out: Vec<PlanKeepOut>,
    /// Shortest string reading allowed (mm; default 100).
    #[serde(default)]
    #[schema(minimum = 0.0, maximum = 100000.0)]
    pub min_string_mm: Option<f64>,
    /// Distance kept from the end of the sensor's range (mm; default 50).
    #[serde(default)]
    #[schema(minimum = 0.0, maximum = 100000.0)]
    pub range_margin_mm: Option<f64>,
    /// Distance kept from the plane of coplanar anchors (mm; default 100).
    #[serde(default)]
    #[schema(minimum = 0.0, maximum = 100000.0)]
    pub anchor_plane_clearance_mm: Option<f64>,
    /// Distance kept between a string and the arm's links (mm; default 30).
    #[serde(default)]
    #[schema(minimum = 0.0, maximum = 100000.0)]
    pub string_clearance_mm: Option<f64>,
}

/// A plan to make: a robot model or a robot (its model), a rig, and the
/// options of `drawcal plan`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"robot_id": 1, "rig_id": 1, "n_poses": 30, "workspace": {"floor_z_mm": -50.0, "keep_out": [{"min_mm": [300, -200, -50], "max_mm": [600, 200, 100]}]}, "effects": ["joint_compliance"]}))]
pub struct CreatePlan {
    /// Robot model to plan for (give this or `robot_id`).
    #[serde(default)]
    pub model_id: Option<i64>,
    /// Robot to plan for: its model, and a key limited to sites must reach
    /// its site (give this or `model_id`).
    #[serde(default)]
    pub robot_id: Option<i64>,
    /// Rig (a string rig must give `base_in_rig`).
    pub rig_id: i64,
    /// Poses to choose for the identification.
    #[schema(minimum = 3, maximum = 2000)]
    pub n_poses: usize,
    /// Random valid check poses added and marked `test`, at most `n_poses`
    /// (default max(5, n_poses / 4)).
    #[serde(default)]
    #[schema(minimum = 0, maximum = 2000)]
    pub n_check: Option<usize>,
    /// Where poses may go.
    #[serde(default)]
    pub workspace: PlanWorkspace,
    /// Effects the poses must also determine: `joint_compliance`,
    /// `backlash`, `joint_scale`, `sensor_scale`, `cable_sag`, `base_tilt`,
    /// `link_bending` (the last two need link masses).
    #[serde(default)]
    #[schema(max_items = 7)]
    pub effects: Vec<String>,
    /// Valid candidate poses to choose from (default 10000), at least four
    /// per pose planned.
    #[serde(default)]
    #[schema(minimum = 100, maximum = 200000)]
    pub candidates: Option<usize>,
    /// Seed of the draws (default 1): the same request gives the same plan.
    #[serde(default)]
    pub seed: Option<u64>,
    /// Noise of one reading (mm; default 0.02 for strings with the
    /// resolution's quantisation, 0.03 per coordinate for a tracker).
    #[serde(default)]
    #[schema(exclusive_minimum = 0.0, exclusive_maximum = 100.0)]
    pub noise_mm: Option<f64>,
    /// Where the tour starts, one angle per joint (deg; default all zero).
    #[serde(default)]
    pub home_deg: Option<Vec<f64>>,
    /// A payload at T (kg) some poses carry, with `joint_compliance` among
    /// the effects: the plan chooses which poses carry it and visits the
    /// unloaded ones first; targets.csv gains a `payload_kg` column.
    #[serde(default)]
    #[schema(exclusive_minimum = 0.0, maximum = 5000.0)]
    pub payload_kg: Option<f64>,
}

impl CreatePlan {
    /// The planner's options. Every field is named (no `..`), so that an
    /// option added to the planner fails to compile here until the service
    /// takes it.
    fn options(&self) -> PlanOptions {
        let d = PlanOptions::new(self.n_poses);
        let w = &self.workspace;
        let dw = Workspace::default();
        PlanOptions {
            n_poses: self.n_poses,
            n_check: self.n_check,
            workspace: Workspace {
                floor_z_mm: w.floor_z_mm,
                keep_out: w
                    .keep_out
                    .iter()
                    .map(|b| KeepOut {
                        min_mm: b.min_mm,
                        max_mm: b.max_mm,
                    })
                    .collect(),
                min_string_mm: w.min_string_mm.unwrap_or(dw.min_string_mm),
                range_margin_mm: w.range_margin_mm.unwrap_or(dw.range_margin_mm),
                anchor_plane_clearance_mm: w
                    .anchor_plane_clearance_mm
                    .unwrap_or(dw.anchor_plane_clearance_mm),
                string_clearance_mm: w.string_clearance_mm.unwrap_or(dw.string_clearance_mm),
            },
            effects: self.effects.clone(),
            candidates: self.candidates.unwrap_or(d.candidates),
            seed: self.seed.unwrap_or(d.seed),
            noise_mm: self.noise_mm,
            home_deg: self.home_deg.clone(),
            payload_kg: self.payload_kg,
        }
    }
}

/// The planner's own check of the options, the rig and the boxes (cheap:
/// no poses drawn), so that a bad option is refused before the plan is
/// queued; a rig the planner cannot use is the request's `rig_id`.
fn check_options(robot: &Robot, rig: &Rig, o: &PlanOptions) -> ApiResult<()> {
    plan::check(robot, rig, o).map_err(|e| match e {
        crate::Error::Input { field, message, .. } => {
            let field = match field.as_deref() {
                Some(f) if f.starts_with("rig.json") => "rig_id".into(),
                Some(f) => f.to_string(),
                None => "rig_id".into(),
            };
            ApiError::invalid(field, message)
        }
        other => other.into(),
    })?;
    Ok(())
}

/// One planned pose, in visiting order.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct PlanPose {
    /// Id (`p01`..., `c01`... for check poses).
    pub id: String,
    /// Nominal joint targets (deg).
    pub q_deg: Vec<f64>,
    /// `train` (chosen for the identification) or `test` (a check pose).
    pub split: String,
    /// Payload at T (kg) when the plan plans one: 0 or the payload.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload_kg: Option<f64>,
}

/// A plan: its request, its state and, once it succeeded, the plan as
/// `drawcal plan` writes it.
#[derive(Debug, Serialize, ToSchema)]
pub struct PlanOut {
    /// Id.
    pub id: i64,
    /// `queued`, `running`, `succeeded` or `failed`.
    pub state: String,
    /// Robot model planned for.
    pub model_id: i64,
    /// Robot the request named, if it named one.
    pub robot_id: Option<i64>,
    /// Rig.
    pub rig_id: i64,
    /// The planner's options, defaults filled in.
    #[schema(value_type = Object)]
    pub options: serde_json::Value,
    /// Why it failed (a plan interrupted by a stopped service says so).
    pub error: Option<String>,
    /// The option a failure names, if it names one.
    pub error_field: Option<String>,
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
    /// The poses in visiting order (once succeeded).
    pub poses: Option<Vec<PlanPose>>,
    /// The plan's report (once succeeded): the JSON `drawcal plan` writes
    /// beside targets.csv (`format` "drawcal plan v1": predicted 1-sigma
    /// per parameter, predicted held-out RMS, against random poses, by N,
    /// what no pose can determine).
    #[schema(value_type = Option<Object>)]
    pub report: Option<serde_json::Value>,
    /// targets.csv (once succeeded): `target,q1_deg..qn_deg,split` (with
    /// `payload_kg` before `split` when a payload is planned), as
    /// `GET /plans/{id}/targets.csv` gives it.
    pub targets_csv: Option<String>,
}

/// The stored plan's poses and report, parsed.
fn stored_plan(rec: &PlanRec) -> ApiResult<Option<plan::Plan>> {
    match &rec.result {
        Some(json) if rec.state == "succeeded" => serde_json::from_str(json)
            .map(Some)
            .map_err(|e| ApiError::Internal(format!("stored plan {}: {e}", rec.id))),
        _ => Ok(None),
    }
}

fn answer(rec: PlanRec) -> ApiResult<PlanOut> {
    let options = serde_json::from_str(&rec.options)
        .map_err(|e| ApiError::Internal(format!("stored plan {} options: {e}", rec.id)))?;
    let plan = stored_plan(&rec)?;
    let (poses, report, targets_csv) = match plan {
        Some(p) => {
            let csv = p.targets_csv();
            let report = serde_json::to_value(&p.report)
                .map_err(|e| ApiError::Internal(format!("plan report: {e}")))?;
            let poses = p
                .poses
                .into_iter()
                .map(|q| PlanPose {
                    id: q.id,
                    q_deg: q.q_deg,
                    split: q.split,
                    payload_kg: q.payload_kg,
                })
                .collect();
            (Some(poses), Some(report), Some(csv))
        }
        None => (None, None, None),
    };
    Ok(PlanOut {
        id: rec.id,
        state: rec.state,
        model_id: rec.model_id,
        robot_id: rec.robot_id,
        rig_id: rec.rig_id,
        options,
        error: rec.error,
        error_field: rec.error_field,
        created_by: rec.created_by,
        created_at: rec.created_at,
        updated_at: rec.updated_at,
        started_at: rec.started_at,
        finished_at: rec.finished_at,
        poses,
        report,
        targets_csv,
    })
}

/// The model a plan request names: `model_id`, or the model of
/// `robot_id` after the key's site check (exactly one of the two).
async fn model_of(
    app: &AppState,
    caller: &Caller,
    req: &CreatePlan,
) -> ApiResult<(i64, Option<i64>)> {
    Ok(match (req.model_id, req.robot_id) {
        (Some(_), Some(_)) => {
            return Err(ApiError::invalid(
                "robot_id",
                "give model_id or robot_id, not both (a robot's model is its model_id)",
            ));
        }
        (None, None) => {
            return Err(ApiError::invalid(
                "model_id",
                "give the robot model (model_id) or a robot (robot_id) to plan for",
            ));
        }
        (Some(m), None) => (m, None),
        (None, Some(r)) => match app.store.get_robot(r).await {
            Err(StoreError::NotFound { .. }) => {
                return Err(ApiError::invalid("robot_id", format!("no robot {r}")));
            }
            Err(e) => return Err(e.into()),
            Ok(robot) => {
                caller.check_site(&format!("robot {r}"), robot.site.as_deref())?;
                (robot.model_id, Some(r))
            }
        },
    })
}

/// Plan the poses of a calibration session (`drawcal plan` as a job):
/// answers at once with the plan's id and state; poll `GET /plans/{id}`.
/// Plans share the identification jobs' rate per key
/// (`--max-jobs-per-minute`) and queue bound (`--max-queued-jobs`, plans
/// waiting counted with jobs queued), and run at most `--workers` at once
/// in the process that took them. A plan queued or running when its
/// service stops is not resumed: it reads as failed (`interrupted`);
/// submit it again.
#[utoipa::path(post, path = "/plans", tag = "plans", request_body = CreatePlan,
    responses(
        (status = 202, description = "Queued", body = PlanOut, headers(("Location" = String, description = "The plan's URL"))),
        (status = 400, description = "Malformed JSON", body = ErrorBody),
        (status = 408, description = BODY_TIMEOUT_408, body = ErrorBody),
        (status = 409, description = "The stored model or rig no longer passes validation (stored by an earlier version)", body = ErrorBody),
        (status = 413, description = BODY_TOO_LARGE_413, body = ErrorBody),
        (status = 415, description = "Not JSON", body = ErrorBody),
        (status = 422, description = "A bad option, an unknown model, robot or rig (named in `field`), or a string rig without `base_in_rig`", body = ErrorBody),
        (status = 429, description = "The key is over its jobs a minute (`--max-jobs-per-minute`), or the queue is full (`--max-queued-jobs`): error `too_many_requests`, `Retry-After` in seconds", body = ErrorBody, headers(("Retry-After" = u64, description = "Seconds until a retry can succeed")))))]
pub async fn create_plan(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    ApiJson(req): ApiJson<CreatePlan>,
) -> ApiResult<Response> {
    let (model_id, robot_id) = model_of(&app, &caller, &req).await?;
    let model = match app.store.get_model(model_id).await {
        Err(StoreError::NotFound { .. }) => {
            return Err(ApiError::invalid(
                "model_id",
                format!("no robot model {model_id}"),
            ));
        }
        other => other?,
    };
    let rig_rec = match app.store.get_rig(req.rig_id).await {
        Err(StoreError::NotFound { .. }) => {
            return Err(ApiError::invalid(
                "rig_id",
                format!("no rig {}", req.rig_id),
            ));
        }
        other => other?,
    };
    let robot = stored_robot(&model, "")?;
    let rig = stored_rig(&rig_rec, "")?;
    let options = req.options();
    check_options(&robot, &rig, &options)?;
    // Counted after the request is known good, as a job's.
    app.limits.take(&caller.name, Action::Job)?;
    queue_has_room(&app).await?;
    let options_json =
        serde_json::to_string(&options).map_err(|e| ApiError::Internal(e.to_string()))?;
    let rec = app
        .store
        .create_plan(
            &NewPlan {
                model_id,
                robot_id,
                rig_id: rig_rec.id,
                options: options_json,
                runner: app.plans.runner().to_string(),
                created_by: caller.name.clone(),
            },
            app.plans.lease_ms(),
        )
        .await?;
    app.plans.submit(
        rec.id,
        PlanInput {
            robot,
            rig,
            options,
        },
    );
    app.store
        .audit(
            &caller.name,
            "create_plan",
            &format!("plan {}", rec.id),
            &match robot_id {
                Some(r) => format!("robot {r}, rig {}, {} poses", rig_rec.id, req.n_poses),
                None => format!(
                    "model {model_id}, rig {}, {} poses",
                    rig_rec.id, req.n_poses
                ),
            },
        )
        .await?;
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&format!("/plans/{}", rec.id)) {
        headers.insert(LOCATION, v);
    }
    Ok((StatusCode::ACCEPTED, headers, Json(answer(rec)?)).into_response())
}

/// The plan, after the key's site check (a plan for a robot is at the
/// robot's site; a plan for a model, like the model, at none).
async fn reachable_plan(app: &AppState, caller: &Caller, id: i64) -> ApiResult<PlanRec> {
    let rec = app.store.get_plan(id).await?;
    if let Some(r) = rec.robot_id {
        caller.check_robot(app, r).await?;
    }
    Ok(rec)
}

/// One plan: its state and, once it succeeded, the poses, the report and
/// targets.csv.
#[utoipa::path(get, path = "/plans/{id}", tag = "plans",
    params(("id" = i64, Path, description = "Plan id")),
    responses(
        (status = 200, description = "The plan", body = PlanOut),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such plan", body = ErrorBody)))]
pub async fn get_plan(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
) -> ApiResult<Json<PlanOut>> {
    Ok(Json(answer(reachable_plan(&app, &caller, id).await?)?))
}

/// A succeeded plan's targets.csv (`target,q1_deg..qn_deg,split`, the
/// poses in visiting order): what `drawcal plan --out` writes, and what
/// `drawcal simulate --targets` takes.
#[utoipa::path(get, path = "/plans/{id}/targets.csv", tag = "plans",
    params(("id" = i64, Path, description = "Plan id")),
    responses(
        (status = 200, description = "targets.csv", body = String, content_type = "text/csv"),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such plan", body = ErrorBody),
        (status = 409, description = "The plan has not succeeded (queued, running or failed)", body = ErrorBody)))]
pub async fn get_plan_targets(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
) -> ApiResult<Response> {
    let rec = reachable_plan(&app, &caller, id).await?;
    let Some(plan) = stored_plan(&rec)? else {
        return Err(ApiError::Conflict(format!(
            "plan {id} is {}: targets.csv exists once it has succeeded",
            rec.state
        )));
    };
    Ok(([(CONTENT_TYPE, "text/csv")], plan.targets_csv()).into_response())
}
