//! `GET /calibrations/{id}/export?format=urdf|robot-json|csv|extra-targets`:
//! a stored calibration's model out to the controller, as `drawcal export`
//! writes it (the core's [`crate::export`]).

use axum::Extension;
use axum::extract::State;
use axum::http::header::{CONTENT_DISPOSITION, CONTENT_TYPE};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa::{IntoParams, ToSchema};

use super::auth::Caller;
use super::extract::{ApiQuery, Id};
use super::{ApiError, ApiResult, AppState, ErrorBody};
use crate::export::{self, ExportFormat};
use crate::report::Report;

/// What the export writes.
#[derive(Debug, Clone, Copy, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ExportFormatParam {
    /// The calibrated model as a URDF (world = the rig frame, tool0, tcp).
    Urdf,
    /// The calibrated robot.json, with the identified tool point.
    RobotJson,
    /// One row per parameter: nominal, calibrated, deviation, sigma.
    Csv,
    /// The extra poses the verdict suggests, as targets.csv (409 when the
    /// calibration suggests none).
    ExtraTargets,
}

/// Export query.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
#[serde(deny_unknown_fields)]
pub struct ExportQuery {
    /// What to write.
    pub format: ExportFormatParam,
}

impl From<ExportFormatParam> for ExportFormat {
    fn from(f: ExportFormatParam) -> Self {
        match f {
            ExportFormatParam::Urdf => ExportFormat::Urdf,
            ExportFormatParam::RobotJson => ExportFormat::RobotJson,
            ExportFormatParam::Csv => ExportFormat::Csv,
            ExportFormatParam::ExtraTargets => ExportFormat::ExtraTargets,
        }
    }
}

/// A calibration's model as a URDF, robot.json or a table of deviations,
/// or the extra poses its verdict suggests as targets.csv; the same text
/// as `drawcal export`, as an attachment.
#[utoipa::path(get, path = "/calibrations/{id}/export", tag = "calibrations",
    params(("id" = i64, Path, description = "Calibration id"), ExportQuery),
    responses(
        (status = 200, description = "The export", content(
            (String = "application/xml"), (serde_json::Value = "application/json"), (String = "text/csv"))),
        (status = 400, description = "Bad id or query", body = ErrorBody),
        (status = 404, description = "No such calibration", body = ErrorBody),
        (status = 409, description = "extra-targets of a calibration that suggests no extra poses", body = ErrorBody)))]
pub async fn export_calibration(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
    ApiQuery(q): ApiQuery<ExportQuery>,
) -> ApiResult<Response> {
    let calibration = app.store.get_calibration(id).await?;
    caller.check_robot(&app, calibration.robot_id).await?;
    let text = app.store.calibration_report(id).await?;
    let format = ExportFormat::from(q.format);
    let out = tokio::task::spawn_blocking(move || -> Result<String, ApiError> {
        let report = Report::from_json(&text)
            .map_err(|e| ApiError::Internal(format!("stored report {id}: {e}")))?;
        // A fine request of a calibration that has none to give: the
        // resource's state, not the query, is what refuses it.
        let none = report
            .extra_poses
            .as_ref()
            .is_none_or(|x| x.poses.is_empty());
        if matches!(format, ExportFormat::ExtraTargets) && none {
            return Err(ApiError::Conflict(format!(
                "calibration {id} suggests no extra poses: its poses determine every parameter \
                 any pose of this rig could"
            )));
        }
        Ok(export::export(&report, format)?)
    })
    .await
    .map_err(|e| ApiError::Internal(format!("export task: {e}")))??;
    let filename = format!(
        "attachment; filename=\"calibration-{id}{}.{}\"",
        if matches!(format, ExportFormat::ExtraTargets) {
            "-extra-targets"
        } else {
            ""
        },
        format.extension()
    );
    Ok((
        [
            (CONTENT_TYPE, format.content_type().to_string()),
            (CONTENT_DISPOSITION, filename),
        ],
        out,
    )
        .into_response())
}
