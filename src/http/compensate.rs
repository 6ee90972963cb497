//! `POST /compensate`: corrected joint targets from a robot's calibration.
//!
//! Compensators are built once per calibration (calibrations are immutable)
//! and cached. The solves run on blocking threads; a large batch is split
//! across the cores.

use std::collections::HashSet;
use std::sync::Arc;

use axum::Json;
use axum::extract::State;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::extract::ApiJson;
use super::{ApiError, ApiResult, AppState, ErrorBody, MAX_COMPENSATE_TARGETS};
use crate::compensate::{Compensated, CompensationStatus, Compensator};
use crate::identify::report::Report;
use crate::model::{Target, TargetKind};

/// A built compensator and what it came from.
pub struct Cached {
    /// The engine's compensator.
    pub compensator: Compensator,
    /// Calibration id.
    pub calibration_id: i64,
    /// Its version.
    pub version: i64,
    /// Its robot.
    pub robot_id: i64,
}

/// One target: nominal joints (`q_deg`) or a point of T in the robot base
/// frame (`xyz_mm`, optionally with the flange orientation `rpy_deg`).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TargetIn {
    /// Id, unique in the request.
    pub target: String,
    /// Nominal joint angles (deg), one per joint.
    #[serde(default)]
    pub q_deg: Option<Vec<f64>>,
    /// Wanted position of T in the robot base frame (mm).
    #[serde(default)]
    pub xyz_mm: Option<[f64; 3]>,
    /// Wanted flange orientation, roll-pitch-yaw (deg), with `xyz_mm` only.
    #[serde(default)]
    pub rpy_deg: Option<[f64; 3]>,
}

/// What to compensate, and with which calibration.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CompensateRequest {
    /// Robot.
    pub robot_id: i64,
    /// Calibration to use (default: the robot's active one).
    #[serde(default)]
    pub calibration_id: Option<i64>,
    /// Also hold the flange orientation (the nominal one for joint targets,
    /// `rpy_deg` for Cartesian ones). Default false: position of T only.
    #[serde(default)]
    pub orientation: bool,
    /// One target (give this or `targets`).
    #[serde(default)]
    pub target: Option<TargetIn>,
    /// A batch of up to 10,000 targets (answered in order).
    #[serde(default)]
    pub targets: Option<Vec<TargetIn>>,
}

/// Outcome of one target.
#[derive(Debug, Serialize, ToSchema)]
pub struct CompensatedOut {
    /// Target id.
    pub target: String,
    /// Joint angles to send (deg); null unless `status` is `ok`.
    pub q_deg: Option<Vec<f64>>,
    /// Distance from the calibrated model's T to the target (mm).
    pub residual_mm: Option<f64>,
    /// Solver iterations.
    pub iterations: usize,
    /// `ok`, `unreachable` or `joint_limit`.
    pub status: StatusOut,
    /// Why, when not ok.
    pub message: Option<String>,
}

/// Per-target outcome.
#[derive(Debug, Serialize, ToSchema, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum StatusOut {
    /// Compensated joints found within the limits.
    Ok,
    /// No joints put T on the target.
    Unreachable,
    /// The joints that reach it violate a joint limit.
    JointLimit,
}

impl From<Compensated> for CompensatedOut {
    fn from(c: Compensated) -> Self {
        CompensatedOut {
            target: c.target,
            q_deg: c.q_deg,
            residual_mm: c.residual_mm.filter(|r| r.is_finite()),
            iterations: c.iterations,
            status: match c.status {
                CompensationStatus::Ok => StatusOut::Ok,
                CompensationStatus::Unreachable => StatusOut::Unreachable,
                CompensationStatus::JointLimit => StatusOut::JointLimit,
            },
            message: c.message,
        }
    }
}

/// The answer: which calibration produced the joints, and one result per
/// target in request order.
#[derive(Debug, Serialize, ToSchema)]
pub struct CompensateResponse {
    /// Robot.
    pub robot_id: i64,
    /// Calibration used.
    pub calibration_id: i64,
    /// Its version.
    pub version: i64,
    /// Targets with status `ok`.
    pub n_ok: usize,
    /// One per target, in order.
    pub results: Vec<CompensatedOut>,
}

fn check_target(i: usize, t: TargetIn, dof: usize, batch: bool) -> ApiResult<Target> {
    let at = |f: &str| {
        if batch {
            format!("targets[{i}].{f}")
        } else {
            format!("target.{f}")
        }
    };
    let bad = |f: &str, m: String| ApiError::Invalid {
        message: m,
        field: Some(at(f)),
        row: Some(i + 1),
    };
    if t.target.is_empty() || t.target.len() > 200 {
        return Err(bad("target", "an id of 1 to 200 characters".into()));
    }
    let kind = match (t.q_deg, t.xyz_mm) {
        (Some(q), None) => {
            if t.rpy_deg.is_some() {
                return Err(bad("rpy_deg", "only with xyz_mm".into()));
            }
            if q.len() != dof {
                return Err(bad(
                    "q_deg",
                    format!("{} angles for a robot with {dof} joints", q.len()),
                ));
            }
            if q.iter().any(|v| !v.is_finite()) {
                return Err(bad("q_deg", "angles must be finite".into()));
            }
            TargetKind::Joints { q_deg: q }
        }
        (None, Some(xyz)) => {
            if xyz.iter().any(|v| !v.is_finite()) {
                return Err(bad("xyz_mm", "coordinates must be finite".into()));
            }
            if t.rpy_deg.is_some_and(|r| r.iter().any(|v| !v.is_finite())) {
                return Err(bad("rpy_deg", "angles must be finite".into()));
            }
            TargetKind::Cartesian {
                xyz_mm: xyz,
                rpy_deg: t.rpy_deg,
            }
        }
        (Some(_), Some(_)) => return Err(bad("q_deg", "give q_deg or xyz_mm, not both".into())),
        (None, None) => {
            return Err(bad(
                "q_deg",
                "give q_deg (nominal joints) or xyz_mm (a point)".into(),
            ));
        }
    };
    Ok(Target {
        target: t.target,
        kind,
    })
}

/// The robot's active calibration id (cached for at most
/// [`super::ACTIVE_CACHE_TTL`]); not found if the robot does not exist.
async fn active_calibration(app: &AppState, robot_id: i64) -> ApiResult<Option<i64>> {
    if let Some((active, at)) = app
        .active
        .read()
        .ok()
        .and_then(|m| m.get(&robot_id).copied())
    {
        if at.elapsed() < super::ACTIVE_CACHE_TTL {
            return Ok(active);
        }
    }
    let robot = app.store.get_robot(robot_id).await?;
    if let Ok(mut m) = app.active.write() {
        m.insert(
            robot_id,
            (robot.active_calibration_id, std::time::Instant::now()),
        );
    }
    Ok(robot.active_calibration_id)
}

/// The compensator of a calibration, from the cache or built (off the
/// runtime) and cached.
async fn compensator(app: &AppState, calibration_id: i64) -> ApiResult<Arc<Cached>> {
    if let Some(c) = app
        .compensators
        .read()
        .ok()
        .and_then(|m| m.get(&calibration_id).cloned())
    {
        return Ok(c);
    }
    let cal = app.store.get_calibration(calibration_id).await?;
    let text = app.store.calibration_report(calibration_id).await?;
    let built = tokio::task::spawn_blocking(move || -> ApiResult<Compensator> {
        let report: Report = serde_json::from_str(&text)
            .map_err(|e| ApiError::Internal(format!("stored report: {e}")))?;
        Compensator::from_report(&report)
            .map_err(|e| ApiError::Internal(format!("compensator: {e}")))
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    let cached = Arc::new(Cached {
        compensator: built,
        calibration_id,
        version: cal.version,
        robot_id: cal.robot_id,
    });
    if let Ok(mut m) = app.compensators.write() {
        m.insert(calibration_id, cached.clone());
    }
    Ok(cached)
}

/// Compensate targets for a robot with its active calibration (or a named
/// one). Per-target failures (unreachable, joint limit) are reported in the
/// results; they never fail the batch.
#[utoipa::path(post, path = "/compensate", tag = "compensation", request_body = CompensateRequest,
    responses(
        (status = 200, description = "Results, in order", body = CompensateResponse),
        (status = 400, description = "Malformed JSON", body = ErrorBody),
        (status = 404, description = "No such robot", body = ErrorBody),
        (status = 409, description = "The robot has no active calibration", body = ErrorBody),
        (status = 413, description = "Body too large", body = ErrorBody),
        (status = 415, description = "Not JSON", body = ErrorBody),
        (status = 422, description = "Invalid target (row = 1-based position), too many targets, or a calibration of another robot", body = ErrorBody)))]
pub async fn compensate(
    State(app): State<AppState>,
    ApiJson(req): ApiJson<CompensateRequest>,
) -> ApiResult<Json<CompensateResponse>> {
    let (inputs, batch) = match (req.target, req.targets) {
        (Some(t), None) => (vec![t], false),
        (None, Some(ts)) => (ts, true),
        (Some(_), Some(_)) => {
            return Err(ApiError::invalid(
                "targets",
                "give target or targets, not both",
            ));
        }
        (None, None) => {
            return Err(ApiError::invalid(
                "targets",
                "give target (one) or targets (a batch)",
            ));
        }
    };
    if inputs.is_empty() {
        return Err(ApiError::invalid("targets", "the batch is empty"));
    }
    if inputs.len() > MAX_COMPENSATE_TARGETS {
        return Err(ApiError::invalid(
            "targets",
            format!(
                "{} targets: at most {MAX_COMPENSATE_TARGETS} per request",
                inputs.len()
            ),
        ));
    }
    let active = active_calibration(&app, req.robot_id).await?;
    let calibration_id = match req.calibration_id {
        Some(c) => c,
        None => active.ok_or_else(|| {
            ApiError::Conflict(format!(
                "robot {} has no active calibration: activate one or name calibration_id",
                req.robot_id
            ))
        })?,
    };
    let cached = match compensator(&app, calibration_id).await {
        Err(ApiError::NotFound(_)) => {
            return Err(ApiError::invalid(
                "calibration_id",
                format!("no calibration {calibration_id}"),
            ));
        }
        other => other?,
    };
    if cached.robot_id != req.robot_id {
        return Err(ApiError::invalid(
            "calibration_id",
            format!(
                "calibration {calibration_id} belongs to robot {}, not {}",
                cached.robot_id, req.robot_id
            ),
        ));
    }
    let dof = cached.compensator.dof();
    let mut seen = HashSet::with_capacity(inputs.len());
    let mut targets = Vec::with_capacity(inputs.len());
    for (i, t) in inputs.into_iter().enumerate() {
        let t = check_target(i, t, dof, batch)?;
        if !seen.insert(t.target.clone()) {
            return Err(ApiError::Invalid {
                message: format!("target id '{}' appears twice", t.target),
                field: Some(if batch {
                    format!("targets[{i}].target")
                } else {
                    "target.target".into()
                }),
                row: Some(i + 1),
            });
        }
        targets.push(t);
    }
    let orientation = req.orientation;
    let c = cached.clone();
    let threads = solve_threads(targets.len());
    let results = app
        .compute
        .run(move || solve_all(&c.compensator, &targets, orientation, threads))
        .await
        .ok_or_else(|| ApiError::Internal("compensation failed (see the log)".into()))?;
    let results: Vec<CompensatedOut> = results.into_iter().map(Into::into).collect();
    let n_ok = results.iter().filter(|r| r.status == StatusOut::Ok).count();
    Ok(Json(CompensateResponse {
        robot_id: req.robot_id,
        calibration_id: cached.calibration_id,
        version: cached.version,
        n_ok,
        results,
    }))
}

/// Threads for a batch: one for small batches, one per core for large ones.
fn solve_threads(n_targets: usize) -> usize {
    if n_targets < 256 {
        1
    } else {
        super::compute_threads()
    }
}

/// Solve in order, split across `threads` threads.
fn solve_all(
    comp: &Compensator,
    targets: &[Target],
    orientation: bool,
    threads: usize,
) -> Vec<Compensated> {
    if threads < 2 {
        return crate::compensate::compensate_all(comp, targets, orientation);
    }
    let chunk = targets.len().div_ceil(threads);
    std::thread::scope(|s| {
        let handles: Vec<_> = targets
            .chunks(chunk)
            .map(|part| s.spawn(move || crate::compensate::compensate_all(comp, part, orientation)))
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    })
}
