//! Robot models, robots and rigs.

use axum::Extension;
use axum::Json;
use axum::extract::State;
use axum::http::StatusCode;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::auth::Caller;
use super::error::{BODY_TIMEOUT_408, BODY_TOO_LARGE_413};
use super::extract::{ApiJson, ApiQuery, Id, RawBody, is_json, parse_json_object};
use super::{ApiError, ApiResult, AppState, ErrorBody, PageParams, Paged};
use crate::model::{Rig, Robot};
use crate::store::{ModelRec, NewRobot, RigRec, RobotRec};

/// Optional name for an uploaded document.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct NameParam {
    /// Name to store, at most 200 characters (default: the document's own
    /// `name`, or `rig N`).
    #[param(max_length = 200)]
    pub name: Option<String>,
}

/// A robot model with its robot.json.
#[derive(Debug, Serialize, ToSchema)]
pub struct ModelOut {
    /// Summary.
    #[serde(flatten)]
    pub model: ModelRec,
    /// The nominal kinematics, as robot.json (DATA_FORMAT.md).
    #[schema(value_type = Object)]
    pub robot: serde_json::Value,
}

/// A rig with its rig.json.
#[derive(Debug, Serialize, ToSchema)]
pub struct RigOut {
    /// Summary.
    #[serde(flatten)]
    pub rig: RigRec,
    /// The rig, as rig.json (DATA_FORMAT.md).
    #[schema(value_type = Object)]
    pub rig_json: serde_json::Value,
}

fn json_body(body: &RawBody) -> ApiResult<()> {
    if is_json(body.content_type.as_deref()) {
        Ok(())
    } else {
        Err(ApiError::UnsupportedMediaType(format!(
            "expected Content-Type: application/json, got {}",
            body.content_type.as_deref().unwrap_or("none")
        )))
    }
}

fn check_name(name: &str) -> ApiResult<()> {
    if name.chars().count() > 200 {
        return Err(ApiError::invalid("name", "at most 200 characters"));
    }
    Ok(())
}

fn model_out(m: ModelRec) -> ApiResult<ModelOut> {
    let robot =
        serde_json::from_str(&m.robot_json).map_err(|e| ApiError::Internal(e.to_string()))?;
    Ok(ModelOut { model: m, robot })
}

fn rig_out(r: RigRec) -> ApiResult<RigOut> {
    let rig_json =
        serde_json::from_str(&r.rig_json).map_err(|e| ApiError::Internal(e.to_string()))?;
    Ok(RigOut { rig: r, rig_json })
}

/// Upload a nominal robot model: the body is robot.json itself.
#[utoipa::path(post, path = "/models", tag = "models", params(NameParam),
    request_body(content = super::documents::RobotJson, content_type = "application/json", description = "robot.json (DATA_FORMAT.md)"),
    responses(
        (status = 201, description = "Stored", body = ModelOut),
        (status = 400, description = "Malformed JSON", body = ErrorBody),
        (status = 408, description = BODY_TIMEOUT_408, body = ErrorBody),
        (status = 413, description = BODY_TOO_LARGE_413, body = ErrorBody),
        (status = 415, description = "Not JSON", body = ErrorBody),
        (status = 422, description = "Invalid robot.json (field named)", body = ErrorBody)))]
pub async fn create_model(
    State(app): State<AppState>,
    ApiQuery(q): ApiQuery<NameParam>,
    body: RawBody,
) -> ApiResult<(StatusCode, Json<ModelOut>)> {
    json_body(&body)?;
    let robot: Robot = parse_json_object(&body.bytes)?;
    robot.validate()?;
    let name = q.name.unwrap_or_else(|| robot.name.clone());
    check_name(&name)?;
    let text = serde_json::to_string(&robot).map_err(|e| ApiError::Internal(e.to_string()))?;
    let m = app
        .store
        .create_model(&name, robot.dof() as i64, &text)
        .await?;
    Ok((StatusCode::CREATED, Json(model_out(m)?)))
}

/// List robot models.
#[utoipa::path(get, path = "/models", tag = "models", params(PageParams),
    responses(
        (status = 200, description = "A page", body = Paged<ModelRec>),
        (status = 400, description = "Bad query", body = ErrorBody),
        (status = 422, description = "Bad page", body = ErrorBody)))]
pub async fn list_models(
    State(app): State<AppState>,
    ApiQuery(p): ApiQuery<PageParams>,
) -> ApiResult<Json<Paged<ModelRec>>> {
    let page = p.page()?;
    let (items, total) = app.store.list_models(page).await?;
    Ok(Json(Paged::new(items, total, page)))
}

/// One robot model with its robot.json.
#[utoipa::path(get, path = "/models/{id}", tag = "models",
    params(("id" = i64, Path, description = "Model id")),
    responses(
        (status = 200, description = "The model", body = ModelOut),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such model", body = ErrorBody)))]
pub async fn get_model(State(app): State<AppState>, Id(id): Id) -> ApiResult<Json<ModelOut>> {
    Ok(Json(model_out(app.store.get_model(id).await?)?))
}

/// A robot to register.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateRobot {
    /// Serial number, unique in the fleet (trimmed; not blank).
    #[schema(min_length = 1, max_length = 100)]
    pub serial_number: String,
    /// Robot model id.
    pub model_id: i64,
    /// Site tag.
    #[serde(default)]
    #[schema(max_length = 100)]
    pub site: Option<String>,
    /// Line tag.
    #[serde(default)]
    #[schema(max_length = 100)]
    pub line: Option<String>,
    /// Cell tag.
    #[serde(default)]
    #[schema(max_length = 100)]
    pub cell: Option<String>,
}

/// Register a robot of the fleet.
#[utoipa::path(post, path = "/robots", tag = "robots", request_body = CreateRobot,
    responses(
        (status = 201, description = "Stored", body = RobotRec),
        (status = 400, description = "Malformed JSON", body = ErrorBody),
        (status = 409, description = "Serial number taken", body = ErrorBody),
        (status = 408, description = BODY_TIMEOUT_408, body = ErrorBody),
        (status = 413, description = BODY_TOO_LARGE_413, body = ErrorBody),
        (status = 415, description = "Not JSON", body = ErrorBody),
        (status = 422, description = "Invalid field or unknown model", body = ErrorBody)))]
pub async fn create_robot(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    ApiJson(r): ApiJson<CreateRobot>,
) -> ApiResult<(StatusCode, Json<RobotRec>)> {
    let serial = r.serial_number.trim().to_string();
    if serial.is_empty() || r.serial_number.chars().count() > 100 {
        return Err(ApiError::invalid("serial_number", "1 to 100 characters"));
    }
    caller.check_site(&format!("robot '{serial}'"), r.site.as_deref())?;
    for (f, v) in [("site", &r.site), ("line", &r.line), ("cell", &r.cell)] {
        if v.as_ref().is_some_and(|s| s.chars().count() > 100) {
            return Err(ApiError::invalid(f, "at most 100 characters"));
        }
    }
    if let Err(crate::store::StoreError::NotFound { .. }) = app.store.get_model(r.model_id).await {
        return Err(ApiError::invalid(
            "model_id",
            format!("no robot model {}", r.model_id),
        ));
    }
    let rec = app
        .store
        .create_robot(&NewRobot {
            serial_number: serial.clone(),
            model_id: r.model_id,
            site: r.site,
            line: r.line,
            cell: r.cell,
        })
        .await
        .map_err(|e| match e {
            crate::store::StoreError::Conflict(_) => {
                ApiError::Conflict(format!("a robot with serial number '{serial}' exists"))
            }
            other => other.into(),
        })?;
    Ok((StatusCode::CREATED, Json(rec)))
}

/// Robot list filters.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct RobotFilter {
    /// Only this model.
    pub model_id: Option<i64>,
    /// Only this site.
    pub site: Option<String>,
    /// Only this line.
    pub line: Option<String>,
}

/// List the fleet's robots.
#[utoipa::path(get, path = "/robots", tag = "robots", params(RobotFilter, PageParams),
    responses(
        (status = 200, description = "A page", body = Paged<RobotRec>),
        (status = 400, description = "Bad query", body = ErrorBody),
        (status = 422, description = "Bad page", body = ErrorBody)))]
pub async fn list_robots(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    ApiQuery(f): ApiQuery<RobotFilter>,
    ApiQuery(p): ApiQuery<PageParams>,
) -> ApiResult<Json<Paged<RobotRec>>> {
    let page = p.page()?;
    let site = caller.site_filter(f.site)?;
    let (items, total) = app
        .store
        .list_robots(f.model_id, site.as_deref(), f.line.as_deref(), page)
        .await?;
    Ok(Json(Paged::new(items, total, page)))
}

/// One robot.
#[utoipa::path(get, path = "/robots/{id}", tag = "robots",
    params(("id" = i64, Path, description = "Robot id")),
    responses(
        (status = 200, description = "The robot", body = RobotRec),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such robot", body = ErrorBody)))]
pub async fn get_robot(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
) -> ApiResult<Json<RobotRec>> {
    let robot = app.store.get_robot(id).await?;
    caller.check_site(&format!("robot {id}"), robot.site.as_deref())?;
    Ok(Json(robot))
}

/// Upload a rig: the body is rig.json itself.
#[utoipa::path(post, path = "/rigs", tag = "rigs", params(NameParam),
    request_body(content = super::documents::RigJson, content_type = "application/json", description = "rig.json (DATA_FORMAT.md)"),
    responses(
        (status = 201, description = "Stored", body = RigOut),
        (status = 400, description = "Malformed JSON", body = ErrorBody),
        (status = 408, description = BODY_TIMEOUT_408, body = ErrorBody),
        (status = 413, description = BODY_TOO_LARGE_413, body = ErrorBody),
        (status = 415, description = "Not JSON", body = ErrorBody),
        (status = 422, description = "Invalid rig.json (field named)", body = ErrorBody)))]
pub async fn create_rig(
    State(app): State<AppState>,
    ApiQuery(q): ApiQuery<NameParam>,
    body: RawBody,
) -> ApiResult<(StatusCode, Json<RigOut>)> {
    json_body(&body)?;
    let rig: Rig = parse_json_object(&body.bytes)?;
    rig.validate()?;
    let name = q
        .name
        .unwrap_or_else(|| format!("rig with {} anchors", rig.n_strings()));
    check_name(&name)?;
    let text = serde_json::to_string(&rig).map_err(|e| ApiError::Internal(e.to_string()))?;
    let r = app
        .store
        .create_rig(&name, rig.n_strings() as i64, &text)
        .await?;
    Ok((StatusCode::CREATED, Json(rig_out(r)?)))
}

/// List rigs.
#[utoipa::path(get, path = "/rigs", tag = "rigs", params(PageParams),
    responses(
        (status = 200, description = "A page", body = Paged<RigRec>),
        (status = 400, description = "Bad query", body = ErrorBody),
        (status = 422, description = "Bad page", body = ErrorBody)))]
pub async fn list_rigs(
    State(app): State<AppState>,
    ApiQuery(p): ApiQuery<PageParams>,
) -> ApiResult<Json<Paged<RigRec>>> {
    let page = p.page()?;
    let (items, total) = app.store.list_rigs(page).await?;
    Ok(Json(Paged::new(items, total, page)))
}

/// One rig with its rig.json.
#[utoipa::path(get, path = "/rigs/{id}", tag = "rigs",
    params(("id" = i64, Path, description = "Rig id")),
    responses(
        (status = 200, description = "The rig", body = RigOut),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such rig", body = ErrorBody)))]
pub async fn get_rig(State(app): State<AppState>, Id(id): Id) -> ApiResult<Json<RigOut>> {
    Ok(Json(rig_out(app.store.get_rig(id).await?)?))
}

/// A stored model as the engine reads it. A model stored by an earlier
/// version may fail checks added since: that is the client's to replace
/// (409, with `then`: what to register after it), not a server fault.
pub(super) fn stored_robot(model: &ModelRec, then: &str) -> ApiResult<Robot> {
    Robot::from_json(&model.robot_json).map_err(|e| {
        ApiError::Conflict(format!(
            "stored robot model {} no longer passes validation ({e}): register a corrected model{then}",
            model.id
        ))
    })
}

/// A stored rig as the engine reads it (see [`stored_robot`]).
pub(super) fn stored_rig(rig: &RigRec, then: &str) -> ApiResult<Rig> {
    Rig::from_json(&rig.rig_json).map_err(|e| {
        ApiError::Conflict(format!(
            "stored rig {} no longer passes validation ({e}): register a corrected rig{then}",
            rig.id
        ))
    })
}
