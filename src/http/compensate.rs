//! `POST /compensate`: corrected joint targets from a robot's calibration.
//!
//! Compensators are built once per calibration (calibrations are immutable)
//! and cached ([`super::cache`]). A request of a few joint targets is
//! solved inline (see [`INLINE_MAX_JOINT_TARGETS`]); anything larger runs
//! on the compute threads, a large batch split across the cores. Targets arrive as JSON or
//! targets.csv; the answer is JSON or compensated.csv (`Accept: text/csv`),
//! written by the engine's own [`crate::model::compensated::write_csv`].
//!
//! A calibration that accepted thermal expansion driven by the temperature
//! is compensated at `temp_c` when the request gives one (default: the
//! calibration's reference temperature): the cached compensator stays at
//! the reference and each such request works on a copy moved to its
//! temperature (a clone of a few parameter vectors). Likewise a calibration
//! that accepted a joint compliance is compensated with `payload_kg` (the
//! payload at T) when the request gives one (default: the calibration
//! session's median payload). Both, and the approach for a backlash, go
//! through the engine's [`crate::compensate::Conditions`], as on the
//! command line.

use std::collections::HashSet;
use std::sync::Arc;

use axum::Extension;
use axum::Json;
use axum::extract::State;
use axum::http::header::{ACCEPT, CONTENT_TYPE};
use axum::http::{HeaderMap, HeaderName, HeaderValue};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::auth::Caller;
use super::error::{BODY_TIMEOUT_408, BODY_TOO_LARGE_413};
use super::extract::{ApiQuery, RawBody, is_json, parse_json_object};
use super::{ApiError, ApiResult, AppState, ErrorBody, MAX_COMPENSATE_TARGETS};
use crate::compensate::{
    Approach, Compensated, CompensationStatus, Compensator, ConditionNames, Conditions,
    ConditionsUsed,
};
use crate::model::compensated::write_csv;
use crate::model::targets::targets_from_csv;
use crate::model::{Target, TargetKind};

pub use super::cache::Cached;

/// One target: nominal joints (`q_deg`) or a point of T in the robot base
/// frame (`xyz_mm`, optionally with the flange orientation `rpy_deg`).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TargetIn {
    /// Id, unique in the request (1 to 200 characters).
    #[schema(min_length = 1, max_length = 200)]
    pub target: String,
    /// Nominal joint angles (deg), one per joint.
    #[serde(default)]
    pub q_deg: Option<Vec<f64>>,
    /// Wanted position of T in the robot base frame (mm).
    #[serde(default)]
    #[schema(min_items = 3, max_items = 3)]
    pub xyz_mm: Option<[f64; 3]>,
    /// Wanted flange orientation, roll-pitch-yaw (deg), with `xyz_mm` only.
    #[serde(default)]
    #[schema(min_items = 3, max_items = 3)]
    pub rpy_deg: Option<[f64; 3]>,
}

/// The API's name of an approach: serde's, as the JSON answer has it (the
/// `X-Approach-Used` header, the schema's values).
fn approach_name(a: Approach) -> &'static str {
    match a {
        Approach::Positive => "positive",
        Approach::Negative => "negative",
        Approach::InOrder => "in_order",
    }
}

// The API's schema of the engine's `Approach`, written here so that the
// engine's type carries no API text; named `ApproachIn`, as it always was.
impl utoipa::PartialSchema for Approach {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        utoipa::openapi::ObjectBuilder::new()
            .schema_type(utoipa::openapi::schema::Type::String)
            .description(Some(
                "How the joints arrive at the targets, for a calibration with a backlash.",
            ))
            .enum_values(Some(Approach::ALL.map(approach_name)))
            .into()
    }
}

impl ToSchema for Approach {
    fn name() -> std::borrow::Cow<'static, str> {
        "ApproachIn".into()
    }
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
    #[schema(min_items = 1, max_items = 10000)] // MAX_COMPENSATE_TARGETS
    pub targets: Option<Vec<TargetIn>>,
    /// Temperature the robot runs at (°C, -50 to 150). Used when the
    /// calibration accepted thermal expansion driven by the temperature
    /// (default: its reference temperature, the geometry as calibrated);
    /// ignored otherwise (`temp_c_used` is then null).
    #[serde(default)]
    #[schema(minimum = -50.0, maximum = 150.0)] // TEMP_C_RANGE
    pub temp_c: Option<f64>,
    /// Payload the robot carries at T (kg, 0 to 5000). Used when the
    /// calibration accepted a joint compliance (default: its session's
    /// median payload, 0 if it recorded none); ignored otherwise
    /// (`payload_kg_used` is then null).
    #[serde(default)]
    #[schema(minimum = 0.0, maximum = 5000.0)] // MAX_PAYLOAD_KG
    pub payload_kg: Option<f64>,
    /// How the joints arrive at the targets. Used when the calibration
    /// accepted a backlash (default `positive`); ignored otherwise
    /// (`approach_used` is then null).
    #[serde(default)]
    pub approach: Option<Approach>,
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
    /// `ok`, `unreachable`, `joint_limit` or `joint_change`.
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
    /// A joint target whose compensation would move a joint further from
    /// the taught one than the bound allows (the message says which and
    /// how far): never sent silently.
    JointChange,
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
                CompensationStatus::JointChange => StatusOut::JointChange,
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
    /// Temperature (°C) the calibrated geometry was taken at: the request's
    /// `temp_c`, else the calibration's reference temperature, when the
    /// calibration has thermal expansion driven by the temperature; null
    /// when it has none (the temperature does not matter).
    pub temp_c_used: Option<f64>,
    /// Payload (kg at T) the joint compliance was evaluated with: the
    /// request's `payload_kg`, else the calibration session's, when the
    /// calibration has a compliance that depends on it; null otherwise.
    pub payload_kg_used: Option<f64>,
    /// How the joints were taken to arrive: the request's `approach`, else
    /// `positive`, when the calibration has a backlash; null otherwise.
    pub approach_used: Option<Approach>,
    /// Targets with status `ok`.
    pub n_ok: usize,
    /// One per target, in order.
    pub results: Vec<CompensatedOut>,
    /// What looks wrong in the targets but did not stop them, one sentence
    /// each (joint angles that look like radians); empty when nothing does.
    /// On text/csv answers: the `X-Warning` header.
    pub warnings: Vec<String>,
    /// What was made of the run-time conditions, one sentence each, as
    /// the command line says them: a condition given that this calibration
    /// does not use (`temp_c is not used: ...`), one it uses that was not
    /// given (its default), an effect compensation leaves out, one applied.
    /// On text/csv answers: the `X-Note` header.
    pub notes: Vec<String>,
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
    if t.target.is_empty() || t.target.chars().count() > 200 {
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

/// Query parameters of `POST /compensate`, for a `text/csv` body only (a
/// JSON body carries them itself).
#[derive(Debug, Default, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
#[serde(deny_unknown_fields)]
pub struct CompensateQuery {
    /// Robot (required with a `text/csv` body).
    pub robot_id: Option<i64>,
    /// Calibration to use (default: the robot's active one).
    pub calibration_id: Option<i64>,
    /// Also hold the flange orientation (default false).
    pub orientation: Option<bool>,
    /// Temperature the robot runs at (°C, -50 to 150), for a calibration
    /// with thermal expansion driven by the temperature (default: its
    /// reference temperature).
    #[param(minimum = -50.0, maximum = 150.0)]
    pub temp_c: Option<f64>,
    /// Payload the robot carries at T (kg, 0 to 5000), for a calibration
    /// with a joint compliance (default: its session's median payload).
    #[param(minimum = 0.0, maximum = 5000.0)]
    pub payload_kg: Option<f64>,
    /// How the joints arrive at the targets, for a calibration with a
    /// backlash (default `positive`).
    pub approach: Option<Approach>,
}

impl CompensateQuery {
    /// The first option given, by name (to name it in an error).
    fn first_given(&self) -> Option<&'static str> {
        [
            ("robot_id", self.robot_id.is_some()),
            ("calibration_id", self.calibration_id.is_some()),
            ("orientation", self.orientation.is_some()),
            ("temp_c", self.temp_c.is_some()),
            ("payload_kg", self.payload_kg.is_some()),
            ("approach", self.approach.is_some()),
        ]
        .into_iter()
        .find_map(|(name, given)| given.then_some(name))
    }
}

/// How the API names the compensation conditions in its errors: by their
/// fields.
const CONDITION_NAMES: ConditionNames = ConditionNames {
    temp_c: "temp_c",
    payload_kg: "payload_kg",
    approach: "approach",
};

/// The targets as they arrived: JSON objects (checked against the robot
/// once its calibration is known) or a targets.csv body.
enum Inputs {
    Json { targets: Vec<TargetIn>, batch: bool },
    Csv(axum::body::Bytes),
}

/// Does the client ask for compensated.csv? Each of CSV and JSON gets the
/// quality (`q`, default 1) of the most specific media range that covers it
/// in `Accept` (`text/csv` over `text/*` over `*/*`; `application/json` or
/// `+json` over `application/*` over `*/*`); CSV when its quality is
/// positive and higher than JSON's, or equal and listed first. JSON
/// otherwise (also with no `Accept`). Errors are always JSON.
fn wants_csv(headers: &HeaderMap) -> bool {
    // (specificity, q, position) of the best match so far.
    type Best = Option<(u8, f64, usize)>;
    let mut csv: Best = None;
    let mut json: Best = None;
    let mut pos = 0;
    let better = |best: &mut Best, spec: u8, q: f64, pos: usize| {
        if best.is_none_or(|(s, _, _)| spec > s) {
            *best = Some((spec, q, pos));
        }
    };
    for value in headers.get_all(ACCEPT) {
        let Ok(value) = value.to_str() else { continue };
        for range in value.split(',') {
            let mut parts = range.split(';');
            let media = parts.next().unwrap_or("").trim().to_ascii_lowercase();
            let q = parts
                .filter_map(|p| p.trim().strip_prefix("q=")?.trim().parse::<f64>().ok())
                .next_back()
                .unwrap_or(1.0);
            match media.as_str() {
                "text/csv" => better(&mut csv, 3, q, pos),
                "text/*" => better(&mut csv, 2, q, pos),
                "application/json" => better(&mut json, 3, q, pos),
                m if m.starts_with("application/") && m.ends_with("+json") => {
                    better(&mut json, 3, q, pos)
                }
                "application/*" => better(&mut json, 2, q, pos),
                "*/*" => {
                    better(&mut csv, 1, q, pos);
                    better(&mut json, 1, q, pos);
                }
                _ => {}
            }
            pos += 1;
        }
    }
    match (csv, json) {
        // Only an explicit CSV range (not a wildcard alone) asks for CSV.
        (Some((spec, qc, pc)), json) if spec >= 2 && qc > 0.0 => match json {
            None => true,
            Some((_, qj, pj)) => qc > qj || (qc == qj && pc < pj),
        },
        _ => false,
    }
}

/// Compensate targets for a robot with its active calibration (or a named
/// one). Per-target failures (unreachable, joint limit) are reported in the
/// results; they never fail the batch.
///
/// Targets come as JSON (`CompensateRequest`) or as DATA_FORMAT.md
/// targets.csv (`Content-Type: text/csv`, with `robot_id` and the options in
/// the query string). The answer is JSON unless `Accept` prefers `text/csv`:
/// then it is compensated.csv, in request order, with the calibration that
/// produced it in the `X-Calibration-Id` and `X-Calibration-Version`
/// headers (and `X-Temp-C-Used` when the calibration has thermal expansion
/// driven by the temperature, `X-Payload-Kg-Used` when it has a joint
/// compliance, `X-Approach-Used` when it has a backlash). Errors are always
/// JSON.
#[utoipa::path(post, path = "/compensate", tag = "compensation",
    params(CompensateQuery),
    request_body(
        description = "JSON, or DATA_FORMAT.md targets.csv (`target,q1_deg..qn_deg` or `target,x_mm,y_mm,z_mm[,roll_deg,pitch_deg,yaw_deg]`) with `robot_id` in the query string.",
        content(
            (CompensateRequest = "application/json"),
            (String = "text/csv"))),
    responses(
        (status = 200, description = "Results, in order: JSON, or with `Accept: text/csv` DATA_FORMAT.md compensated.csv (`target,q1_deg..qn_deg,residual_mm,iterations,status,message`)",
            content(
                (CompensateResponse = "application/json"),
                (String = "text/csv")),
            headers(
                ("x-calibration-id" = i64, description = "Calibration used (on text/csv answers; JSON has it in the body)"),
                ("x-calibration-version" = i64, description = "Its version (on text/csv answers)"),
                ("x-temp-c-used" = f64, description = "Temperature (°C) the geometry was taken at, on text/csv answers when the calibration has thermal expansion driven by the temperature (JSON: `temp_c_used`)"),
                ("x-payload-kg-used" = f64, description = "Payload (kg at T) the joint compliance was evaluated with, on text/csv answers when the calibration has a compliance that depends on it (JSON: `payload_kg_used`)"),
                ("x-approach-used" = String, description = "`positive`, `negative` or `in_order`: how the joints were taken to arrive, on text/csv answers when the calibration has a backlash (JSON: `approach_used`)"),
                ("x-warning" = String, description = "What looks wrong in the targets but did not stop them (joint angles that look like radians), one header each, on text/csv answers (JSON: `warnings`)"),
                ("x-note" = String, description = "What was made of the run-time conditions (a condition given that the calibration does not use, a default taken, an effect left out), one header each, on text/csv answers (JSON: `notes`)"))),
        (status = 400, description = "Malformed JSON or query string", body = ErrorBody),
        (status = 404, description = "No such robot", body = ErrorBody),
        (status = 409, description = "The robot has no active calibration", body = ErrorBody),
        (status = 408, description = BODY_TIMEOUT_408, body = ErrorBody),
        (status = 413, description = BODY_TOO_LARGE_413, body = ErrorBody),
        (status = 415, description = "Neither application/json nor text/csv", body = ErrorBody),
        (status = 422, description = "Invalid target (row = 1-based position or CSV row), too many targets, temp_c not a temperature from -50 to 150 C, payload_kg not from 0 to 5000 kg, a calibration of another robot, or robot_id missing with a CSV body", body = ErrorBody)))]
pub async fn compensate(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    headers: HeaderMap,
    ApiQuery(query): ApiQuery<CompensateQuery>,
    body: RawBody,
) -> ApiResult<Response> {
    let csv_out = wants_csv(&headers);
    let req = read_request(query, body)?;
    // A bad value is refused before the store is read.
    req.conditions.check(CONDITION_NAMES)?;
    caller.check_robot(&app, req.robot_id).await?;
    let cached = calibration_for(&app, req.robot_id, req.calibration_id).await?;
    let dof = cached.compensator.dof();
    let targets = checked_targets(req.inputs, dof)?;
    let warnings: Vec<String> = crate::model::targets::radians_warning(&targets, dof)
        .into_iter()
        .collect();
    let applied = req.conditions.apply(&cached.compensator, CONDITION_NAMES)?;
    let (used, in_order) = (applied.used(), applied.in_order());
    let notes = applied.notes().iter().map(|n| n.text.clone()).collect();
    let adjusted = applied.into_changed();
    let results = solve(
        &app,
        cached.clone(),
        adjusted,
        targets,
        req.orientation,
        in_order,
    )
    .await?;
    let answer = Answer {
        robot_id: req.robot_id,
        calibration_id: cached.calibration_id,
        version: cached.version,
        used,
        warnings,
        notes,
    };
    if csv_out {
        csv_answer(answer, dof, &results)
    } else {
        Ok(json_answer(answer, results))
    }
}

/// A request as it arrived: the robot, the calibration named (if any), the
/// options and the targets, not yet checked against the robot.
struct Request {
    robot_id: i64,
    calibration_id: Option<i64>,
    orientation: bool,
    conditions: Conditions,
    inputs: Inputs,
}

/// The request from a JSON body (everything in it) or a targets.csv body
/// (the options in the query string).
fn read_request(query: CompensateQuery, body: RawBody) -> ApiResult<Request> {
    match body.content_type.as_deref() {
        ct if is_json(ct) => json_request(&query, &body.bytes),
        Some("text/csv") => {
            let robot_id = query.robot_id.ok_or_else(|| {
                ApiError::invalid(
                    "robot_id",
                    "a text/csv body needs robot_id in the query string (/compensate?robot_id=N)",
                )
            })?;
            Ok(Request {
                robot_id,
                calibration_id: query.calibration_id,
                orientation: query.orientation.unwrap_or(false),
                conditions: Conditions {
                    temp_c: query.temp_c,
                    payload_kg: query.payload_kg,
                    approach: query.approach,
                },
                inputs: Inputs::Csv(body.bytes),
            })
        }
        other => Err(ApiError::UnsupportedMediaType(format!(
            "targets are sent as application/json or text/csv, got {}",
            other.unwrap_or("none")
        ))),
    }
}

/// The request from a JSON body: one target or a batch, and no option in
/// the query string (it would be ignored, or contradict the body).
fn json_request(query: &CompensateQuery, bytes: &[u8]) -> ApiResult<Request> {
    if let Some(name) = query.first_given() {
        return Err(ApiError::invalid(
            name,
            format!(
                "with a JSON body, {name} (like robot_id, calibration_id, orientation, temp_c, payload_kg and approach) goes in the body, not the query string"
            ),
        ));
    }
    let req: CompensateRequest = parse_json_object(bytes)?;
    let (targets, batch) = match (req.target, req.targets) {
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
    check_count(targets.len())?;
    Ok(Request {
        robot_id: req.robot_id,
        calibration_id: req.calibration_id,
        orientation: req.orientation,
        conditions: Conditions {
            temp_c: req.temp_c,
            payload_kg: req.payload_kg,
            approach: req.approach,
        },
        inputs: Inputs::Json { targets, batch },
    })
}

/// The calibration named, else the robot's active one, with its
/// compensator. Not found when the robot does not exist; a conflict when
/// it has no active calibration and none is named; invalid when the one
/// named does not exist or is another robot's.
async fn calibration_for(
    app: &AppState,
    robot_id: i64,
    calibration_id: Option<i64>,
) -> ApiResult<Arc<Cached>> {
    let active = app.cache.active_calibration(&app.store, robot_id).await?;
    let calibration_id = match calibration_id {
        Some(c) => c,
        None => active.ok_or_else(|| {
            ApiError::Conflict(format!(
                "robot {robot_id} has no active calibration: activate one or name calibration_id"
            ))
        })?,
    };
    let cached = match app.cache.compensator(&app.store, calibration_id).await {
        Err(ApiError::NotFound(_)) => {
            return Err(ApiError::invalid(
                "calibration_id",
                format!("no calibration {calibration_id}"),
            ));
        }
        other => other?,
    };
    if cached.robot_id != robot_id {
        return Err(ApiError::invalid(
            "calibration_id",
            format!(
                "calibration {calibration_id} belongs to robot {}, not {robot_id}",
                cached.robot_id
            ),
        ));
    }
    Ok(cached)
}

/// The targets checked against a robot with `dof` joints.
fn checked_targets(inputs: Inputs, dof: usize) -> ApiResult<Vec<Target>> {
    match inputs {
        Inputs::Json { targets, batch } => json_targets(targets, dof, batch),
        Inputs::Csv(bytes) => {
            // targets.csv is parsed here, on the runtime: a few µs per row,
            // like the JSON parse of the same targets. An oversized batch is
            // refused by its line count first, before any parsing (a header
            // and MAX_COMPENSATE_TARGETS rows have at most MAX + 1 newlines).
            let newlines = bytes.iter().filter(|&&b| b == b'\n').count();
            if newlines > MAX_COMPENSATE_TARGETS + 1 {
                return Err(ApiError::invalid(
                    "targets",
                    format!(
                        "{} rows: at most {MAX_COMPENSATE_TARGETS} targets per request",
                        newlines - 1
                    ),
                ));
            }
            let targets = targets_from_csv(&bytes[..], dof)?;
            check_count(targets.len())?;
            Ok(targets)
        }
    }
}

/// What the answer says besides the rows: the calibration that produced
/// them and the conditions used.
struct Answer {
    robot_id: i64,
    calibration_id: i64,
    version: i64,
    used: ConditionsUsed,
    warnings: Vec<String>,
    notes: Vec<String>,
}

/// compensated.csv, with the rest of the answer in headers.
fn csv_answer(answer: Answer, dof: usize, results: &[Compensated]) -> ApiResult<Response> {
    let mut out = Vec::with_capacity(64 + results.len() * (16 + 14 * dof));
    write_csv(&mut out, dof, results)
        .map_err(|e| ApiError::Internal(format!("writing compensated.csv: {e}")))?;
    let mut resp = (
        [
            (CONTENT_TYPE, HeaderValue::from_static("text/csv")),
            (
                HeaderName::from_static("x-calibration-id"),
                HeaderValue::from(answer.calibration_id),
            ),
            (
                HeaderName::from_static("x-calibration-version"),
                HeaderValue::from(answer.version),
            ),
        ],
        out,
    )
        .into_response();
    for (name, value) in [
        ("x-temp-c-used", answer.used.temp_c_used),
        ("x-payload-kg-used", answer.used.payload_kg_used),
    ] {
        if let Some(v) = value.and_then(|v| HeaderValue::from_str(&v.to_string()).ok()) {
            resp.headers_mut().insert(HeaderName::from_static(name), v);
        }
    }
    for (name, lines) in [("x-warning", &answer.warnings), ("x-note", &answer.notes)] {
        for line in lines {
            if let Ok(v) = HeaderValue::from_str(line) {
                resp.headers_mut().append(HeaderName::from_static(name), v);
            }
        }
    }
    if let Some(a) = answer.used.approach_used {
        resp.headers_mut().insert(
            HeaderName::from_static("x-approach-used"),
            HeaderValue::from_static(approach_name(a)),
        );
    }
    Ok(resp)
}

/// The JSON answer.
fn json_answer(answer: Answer, results: Vec<Compensated>) -> Response {
    let results: Vec<CompensatedOut> = results.into_iter().map(Into::into).collect();
    let n_ok = results.iter().filter(|r| r.status == StatusOut::Ok).count();
    Json(CompensateResponse {
        robot_id: answer.robot_id,
        calibration_id: answer.calibration_id,
        version: answer.version,
        temp_c_used: answer.used.temp_c_used,
        payload_kg_used: answer.used.payload_kg_used,
        approach_used: answer.used.approach_used,
        n_ok,
        results,
        warnings: answer.warnings,
        notes: answer.notes,
    })
    .into_response()
}

/// A batch has 1 to [`MAX_COMPENSATE_TARGETS`] targets.
fn check_count(n: usize) -> ApiResult<()> {
    if n == 0 {
        return Err(ApiError::invalid("targets", "the batch is empty"));
    }
    if n > MAX_COMPENSATE_TARGETS {
        return Err(ApiError::invalid(
            "targets",
            format!("{n} targets: at most {MAX_COMPENSATE_TARGETS} per request"),
        ));
    }
    Ok(())
}

/// JSON targets checked against the robot's joints; ids unique.
fn json_targets(inputs: Vec<TargetIn>, dof: usize, batch: bool) -> ApiResult<Vec<Target>> {
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
    Ok(targets)
}

/// Requests of at most this many targets, all nominal joint targets, are
/// compensated inline on the async runtime's thread; anything larger, and
/// any Cartesian target, goes to the compute threads.
///
/// Why this is within "numerical work never runs on the async runtime's
/// threads": the rule is there so that solves cannot stall the runtime, and
/// a joint target is one short Newton solve from the taught angles — 2.7 µs
/// (position) or 4.7 µs (with orientation) in `cargo bench --bench engine`,
/// at most 50 iterations (about 50 µs) when it does not converge, so two
/// targets stay within the ~100 µs a task may run between awaits, while the hand-off to a compute thread and back (two
/// thread wake-ups) costs more than the solve and was the largest part of
/// the single-target latency under load (BENCHMARKS.md). A Cartesian target
/// runs up to 12 inverse-kinematics seeds (up to about a millisecond), so it
/// never runs inline.
pub const INLINE_MAX_JOINT_TARGETS: usize = 2;

fn runs_inline(targets: &[Target]) -> bool {
    targets.len() <= INLINE_MAX_JOINT_TARGETS
        && targets
            .iter()
            .all(|t| matches!(t.kind, TargetKind::Joints { .. }))
}

/// Compensate `targets` in order: inline when tiny (see
/// [`INLINE_MAX_JOINT_TARGETS`]), else on the compute threads.
/// `adjusted` replaces the cached compensator (another temperature).
/// `in_order`: the robot visits the targets in order and each joint
/// arrives from the previous target (a backlash): one after the other, on
/// one compute thread.
async fn solve(
    app: &AppState,
    cached: Arc<Cached>,
    adjusted: Option<Compensator>,
    targets: Vec<Target>,
    orientation: bool,
    in_order: bool,
) -> ApiResult<Vec<Compensated>> {
    if in_order {
        return app
            .compute
            .run(move || {
                let comp = adjusted.as_ref().unwrap_or(&cached.compensator);
                crate::compensate::compensate_in_order(comp, &targets, orientation)
            })
            .await
            .ok_or_else(|| ApiError::Internal("compensation failed (see the log)".into()));
    }
    if runs_inline(&targets) {
        return Ok(crate::compensate::compensate_all(
            adjusted.as_ref().unwrap_or(&cached.compensator),
            &targets,
            orientation,
        ));
    }
    let threads = solve_threads(targets.len());
    app.compute
        .run(move || {
            let comp = adjusted.as_ref().unwrap_or(&cached.compensator);
            solve_all(comp, &targets, orientation, threads)
        })
        .await
        .ok_or_else(|| ApiError::Internal("compensation failed (see the log)".into()))
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

#[cfg(test)]
mod tests {
    use super::*;

    fn joint(id: &str) -> Target {
        Target {
            target: id.into(),
            kind: TargetKind::Joints {
                q_deg: vec![0.0; 6],
            },
        }
    }

    #[test]
    fn only_a_few_joint_targets_run_inline() {
        let few: Vec<Target> = (0..INLINE_MAX_JOINT_TARGETS)
            .map(|i| joint(&i.to_string()))
            .collect();
        assert!(runs_inline(&few));
        let mut more = few.clone();
        more.push(joint("x"));
        assert!(!runs_inline(&more));
        let cartesian = vec![Target {
            target: "c".into(),
            kind: TargetKind::Cartesian {
                xyz_mm: [1.0, 2.0, 3.0],
                rpy_deg: None,
            },
        }];
        assert!(!runs_inline(&cartesian), "IK seeds never run inline");
    }

    #[test]
    fn the_approach_names_are_serdes() {
        for a in Approach::ALL {
            assert_eq!(serde_json::to_value(a).unwrap(), approach_name(a));
        }
    }

    #[test]
    fn accept_picks_csv_only_when_preferred() {
        let h = |v: &str| {
            let mut m = HeaderMap::new();
            m.insert(ACCEPT, HeaderValue::from_str(v).unwrap());
            m
        };
        assert!(wants_csv(&h("text/csv")));
        assert!(wants_csv(&h("text/html, text/csv;q=0.9, */*;q=0.1")));
        assert!(!wants_csv(&h("application/json, text/csv")));
        assert!(!wants_csv(&h("text/csv;q=0, */*")));
        assert!(!wants_csv(&h("*/*")));
        assert!(!wants_csv(&HeaderMap::new()));
        // Quality, not order, decides.
        assert!(wants_csv(&h("application/json;q=0.5, text/csv")));
        assert!(!wants_csv(&h("text/csv;q=0.4, application/json;q=0.8")));
        assert!(wants_csv(&h("text/csv, application/json")));
        // The most specific range sets the quality.
        assert!(!wants_csv(&h("text/*, text/csv;q=0")));
        assert!(wants_csv(&h("*/*;q=0.1, text/csv")));
        assert!(!wants_csv(&h("text/csv;q=0.1, */*")));
    }
}
