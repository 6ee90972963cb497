//! The browser page: `GET /` (and its script) from assets embedded in the
//! binary, and `GET /calibrations/{id}/report.html`, the calibration report
//! rendered by [`crate::report_html`] (the same HTML as
//! `drawcal report --html`), which the page shows in its calibration view.
//!
//! The page is plain HTML and JavaScript with no framework, no CDN and no
//! build step; every number it shows comes from the API.

use axum::Extension;
use axum::Router;
use axum::extract::State;
use axum::http::header::{CACHE_CONTROL, CONTENT_TYPE};
use axum::response::{IntoResponse, Response};
use axum::routing::get;

use super::auth::Caller;
use super::extract::Id;
use super::{ApiError, ApiResult, AppState, ErrorBody};
use crate::report::Report;
use crate::report_html::{self, PoseColumns};

/// The page (HTML and CSS).
pub const INDEX_HTML: &str = include_str!("ui/index.html");
/// The page's script.
pub const APP_JS: &str = include_str!("ui/app.js");

/// The page's routes, outside the API (not in openapi.yaml): `/` and
/// `/ui/app.js`.
pub fn routes() -> Router<AppState> {
    Router::new()
        .route("/", get(index))
        .route("/ui/app.js", get(app_js))
}

async fn index() -> Response {
    (
        [
            (CONTENT_TYPE, "text/html; charset=utf-8"),
            (CACHE_CONTROL, "no-cache"),
        ],
        INDEX_HTML,
    )
        .into_response()
}

async fn app_js() -> Response {
    (
        [
            (CONTENT_TYPE, "text/javascript; charset=utf-8"),
            (CACHE_CONTROL, "no-cache"),
        ],
        APP_JS,
    )
        .into_response()
}

/// A calibration's report as one self-contained HTML page: the paper's
/// Tables 3/4, per-pose errors, residuals against each recorded variable
/// of the session's poses, findings, parameters with 1-sigma and the fixed
/// list, with inline SVG plots.
#[utoipa::path(get, path = "/calibrations/{id}/report.html", tag = "calibrations",
    params(("id" = i64, Path, description = "Calibration id")),
    responses(
        (status = 200, description = "The report as HTML", body = String, content_type = "text/html"),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such calibration", body = ErrorBody)))]
pub async fn calibration_report_html(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
) -> ApiResult<Response> {
    let calibration = app.store.get_calibration(id).await?;
    caller.check_robot(&app, calibration.robot_id).await?;
    let text = app.store.calibration_report(id).await?;
    // The session's poses give the residual plots their x axes; a report
    // still renders without them.
    let poses_csv = match app.store.get_session(calibration.session_id).await {
        Ok(s) => match (&s.columns, app.store.pose_batches(s.id).await) {
            (Some(c), Ok(b)) => Some(crate::jobs::session_csv(c, &b)),
            _ => None,
        },
        Err(_) => None,
    };
    let title = format!(
        "{} calibration v{} (#{})",
        calibration.serial_number, calibration.version, calibration.id
    );
    let html = tokio::task::spawn_blocking(move || -> Result<String, String> {
        let report = Report::from_json(&text).map_err(|e| e.to_string())?;
        let poses = poses_csv.and_then(|c| PoseColumns::from_csv(c.as_bytes()).ok());
        Ok(report_html::render(&report, &title, poses.as_ref()))
    })
    .await
    .map_err(|e| ApiError::Internal(format!("render task: {e}")))?
    .map_err(ApiError::Internal)?;
    Ok(([(CONTENT_TYPE, "text/html; charset=utf-8")], html).into_response())
}
