//! Calibrations, activation and fleet history.

use axum::extract::State;
use axum::http::header::CONTENT_TYPE;
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::auth::Caller;
use super::error::{BODY_TIMEOUT_408, BODY_TOO_LARGE_413};
use super::extract::{ApiJson, ApiQuery, Id};
use super::{ApiError, ApiResult, AppState, ErrorBody, PageParams, Paged};
use crate::report::Report;
use crate::store::time::normalize_bound;
use crate::store::{ActivationRec, CalibrationFilter, CalibrationRec, Page};

/// Output format of history lists.
#[derive(Debug, Clone, Copy, Default, Deserialize, ToSchema, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// JSON (default).
    #[default]
    Json,
    /// CSV, one row per calibration.
    Csv,
}

/// Fleet history filters.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct HistoryFilter {
    /// Only this robot.
    pub robot_id: Option<i64>,
    /// Only this robot model.
    pub model_id: Option<i64>,
    /// Only robots at this site.
    pub site: Option<String>,
    /// Only robots on this line.
    pub line: Option<String>,
    /// Created on or after (`YYYY-MM-DD` or `YYYY-MM-DDTHH:MM:SS[.fff]Z`).
    pub from: Option<String>,
    /// Created on or before (`YYYY-MM-DD`, inclusive, or a UTC timestamp).
    pub to: Option<String>,
    /// Held-out RMS after calibration at most this (mm, 0 or more).
    #[param(minimum = 0.0)]
    pub max_test_rms_mm: Option<f64>,
    /// Held-out RMS after calibration at least this (mm, 0 or more).
    #[param(minimum = 0.0)]
    pub min_test_rms_mm: Option<f64>,
    /// `json` (default) or `csv`.
    pub format: Option<Format>,
}

impl HistoryFilter {
    fn to_store(&self) -> ApiResult<CalibrationFilter> {
        let bound = |name: &str, v: &Option<String>, end: bool| -> ApiResult<Option<String>> {
            match v {
                None => Ok(None),
                Some(s) => normalize_bound(s, end).map(Some).ok_or_else(|| {
                    ApiError::invalid(
                        name,
                        format!("'{s}' is not YYYY-MM-DD or YYYY-MM-DDTHH:MM:SSZ"),
                    )
                }),
            }
        };
        for (name, v) in [
            ("max_test_rms_mm", self.max_test_rms_mm),
            ("min_test_rms_mm", self.min_test_rms_mm),
        ] {
            if v.is_some_and(|x| !x.is_finite() || x < 0.0) {
                return Err(ApiError::invalid(name, "must be a finite length >= 0"));
            }
        }
        Ok(CalibrationFilter {
            robot_id: self.robot_id,
            model_id: self.model_id,
            site: self.site.clone(),
            line: self.line.clone(),
            from: bound("from", &self.from, false)?,
            to: bound("to", &self.to, true)?,
            max_test_rms_mm: self.max_test_rms_mm,
            min_test_rms_mm: self.min_test_rms_mm,
        })
    }
}

fn opt_num(x: Option<f64>) -> String {
    x.map(|v| format!("{v:.4}")).unwrap_or_default()
}

/// A free-text cell as a spreadsheet reads it safely: text a user typed
/// (serial number, site, line, cell) that begins like a formula (`=`, `+`,
/// `-`, `@`, tab, carriage return) gets a leading `'`, so an MES export
/// opened in a spreadsheet shows it instead of running it.
pub(super) fn text_cell(s: &str) -> String {
    if s.starts_with(['=', '+', '-', '@', '\t', '\r']) {
        format!("'{s}")
    } else {
        s.to_string()
    }
}

/// A `text/csv` answer: `header`, then one record per row.
pub(super) fn csv_table(
    header: &[&str],
    rows: impl IntoIterator<Item = Vec<String>>,
) -> ApiResult<Response> {
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    let err = |e: csv::Error| ApiError::Internal(e.to_string());
    w.write_record(header).map_err(err)?;
    for row in rows {
        w.write_record(&row).map_err(err)?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| ApiError::Internal(e.to_string()))?;
    Ok(([(CONTENT_TYPE, "text/csv")], bytes).into_response())
}

fn csv_response(rows: &[CalibrationRec]) -> ApiResult<Response> {
    csv_table(
        &[
            "calibration_id",
            "robot_id",
            "serial_number",
            "model_id",
            "site",
            "line",
            "cell",
            "version",
            "created_at",
            "method",
            "n_poses",
            "n_test",
            "test_rms_before_mm",
            "test_rms_after_mm",
            "train_rms_after_mm",
            "effects",
            "active",
            "session_id",
            "job_id",
        ],
        rows.iter().map(|c| {
            vec![
                c.id.to_string(),
                c.robot_id.to_string(),
                text_cell(&c.serial_number),
                c.model_id.to_string(),
                text_cell(c.site.as_deref().unwrap_or_default()),
                text_cell(c.line.as_deref().unwrap_or_default()),
                text_cell(c.cell.as_deref().unwrap_or_default()),
                c.version.to_string(),
                c.created_at.clone(),
                c.method.clone(),
                c.n_poses.to_string(),
                c.n_test.to_string(),
                opt_num(c.test_rms_before_mm),
                opt_num(c.test_rms_after_mm),
                opt_num(c.train_rms_after_mm),
                c.effects.replace(',', ";"),
                c.active.to_string(),
                c.session_id.to_string(),
                c.job_id.to_string(),
            ]
        }),
    )
}

/// The fleet's calibrations, filtered by robot, model, site, line, date
/// range and held-out accuracy; JSON or CSV (`format=csv`, every match, no
/// paging).
#[utoipa::path(get, path = "/calibrations", tag = "fleet", params(HistoryFilter, PageParams),
    responses(
        (status = 200, description = "A page of calibrations (JSON) or all of them (CSV)",
            content((Paged<CalibrationRec> = "application/json"), (String = "text/csv"))),
        (status = 400, description = "Bad query", body = ErrorBody),
        (status = 422, description = "Bad filter value", body = ErrorBody)))]
pub async fn list_calibrations(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    ApiQuery(f): ApiQuery<HistoryFilter>,
    ApiQuery(p): ApiQuery<PageParams>,
) -> ApiResult<Response> {
    let mut filter = f.to_store()?;
    filter.site = caller.site_filter(filter.site)?;
    // Checked whatever the format: CSV has every match, but a page out of
    // range is a bad request either way.
    let page = p.page()?;
    if f.format == Some(Format::Csv) {
        let (rows, _) = app
            .store
            .list_calibrations(
                &filter,
                Page {
                    limit: i64::MAX / 2,
                    offset: 0,
                },
            )
            .await?;
        return csv_response(&rows);
    }
    let (items, total) = app.store.list_calibrations(&filter, page).await?;
    Ok(Json(Paged::new(items, total, page)).into_response())
}

/// A calibration with its whole report.
#[derive(Debug, Serialize, ToSchema)]
pub struct CalibrationOut {
    /// Summary.
    pub calibration: CalibrationRec,
    /// The engine's report: parameters with uncertainties, before/after
    /// statistics, findings, the calibrated robot.json.
    #[schema(value_type = Object)]
    pub report: serde_json::Value,
}

/// One calibration (immutable), with its report.
#[utoipa::path(get, path = "/calibrations/{id}", tag = "calibrations",
    params(("id" = i64, Path, description = "Calibration id")),
    responses(
        (status = 200, description = "The calibration", body = CalibrationOut),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such calibration", body = ErrorBody)))]
pub async fn get_calibration(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
) -> ApiResult<Json<CalibrationOut>> {
    let calibration = app.store.get_calibration(id).await?;
    caller.check_robot(&app, calibration.robot_id).await?;
    let text = app.store.calibration_report(id).await?;
    let report = serde_json::from_str(&text).map_err(|e| ApiError::Internal(e.to_string()))?;
    Ok(Json(CalibrationOut {
        calibration,
        report,
    }))
}

/// One point of a robot's accuracy history.
#[derive(Debug, Serialize, ToSchema)]
pub struct AccuracyPoint {
    /// Calibration.
    pub calibration_id: i64,
    /// Its version.
    pub version: i64,
    /// When it was made.
    pub created_at: String,
    /// Held-out RMS, nominal model (mm).
    pub test_rms_before_mm: Option<f64>,
    /// Held-out RMS, calibrated (mm).
    pub test_rms_after_mm: Option<f64>,
    /// Physical effects found.
    pub effects: Vec<String>,
    /// Active now.
    pub active: bool,
}

/// A robot's accuracy over time.
#[derive(Debug, Serialize, ToSchema)]
pub struct Accuracy {
    /// Robot.
    pub robot_id: i64,
    /// Its serial number.
    pub serial_number: String,
    /// One point per calibration, oldest first.
    pub history: Vec<AccuracyPoint>,
}

/// Accuracy query.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct FormatParam {
    /// `json` (default) or `csv`.
    pub format: Option<Format>,
}

/// A robot's accuracy over time: held-out RMS before and after each
/// calibration and the effects found.
#[utoipa::path(get, path = "/robots/{id}/accuracy", tag = "fleet",
    params(("id" = i64, Path, description = "Robot id"), FormatParam),
    responses(
        (status = 200, description = "History", content((Accuracy = "application/json"), (String = "text/csv"))),
        (status = 400, description = "Bad id or query", body = ErrorBody),
        (status = 404, description = "No such robot", body = ErrorBody)))]
pub async fn robot_accuracy(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
    ApiQuery(q): ApiQuery<FormatParam>,
) -> ApiResult<Response> {
    let robot = app.store.get_robot(id).await?;
    caller.check_site(&format!("robot {id}"), robot.site.as_deref())?;
    let filter = CalibrationFilter {
        robot_id: Some(id),
        ..Default::default()
    };
    let (rows, _) = app
        .store
        .list_calibrations(
            &filter,
            Page {
                limit: i64::MAX / 2,
                offset: 0,
            },
        )
        .await?;
    if q.format == Some(Format::Csv) {
        return csv_response(&rows);
    }
    let history = rows
        .into_iter()
        .map(|c| AccuracyPoint {
            effects: c.effect_names(),
            calibration_id: c.id,
            version: c.version,
            created_at: c.created_at,
            test_rms_before_mm: c.test_rms_before_mm,
            test_rms_after_mm: c.test_rms_after_mm,
            active: c.active,
        })
        .collect();
    Ok(Json(Accuracy {
        robot_id: id,
        serial_number: robot.serial_number,
        history,
    })
    .into_response())
}

/// Make a calibration the robot's active one.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Activate {
    /// Calibration of this robot.
    pub calibration_id: i64,
    /// Why (recorded with the key's name, the actor; trimmed, not blank).
    #[schema(min_length = 1, max_length = 2000)]
    pub reason: String,
}

/// Roll back to the calibration active before the current one.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Rollback {
    /// Why (recorded with the key's name, the actor; trimmed, not blank).
    #[schema(min_length = 1, max_length = 2000)]
    pub reason: String,
}

/// Drop the cached active calibration of a robot (see
/// [`super::cache::CompensationCache::forget_active`]).
fn forget_active(app: &AppState, robot_id: i64) {
    app.cache.forget_active(robot_id);
}

fn check_reason(reason: &str) -> ApiResult<()> {
    if reason.trim().is_empty() || reason.chars().count() > 2000 {
        return Err(ApiError::invalid(
            "reason",
            "say why (1 to 2000 characters)",
        ));
    }
    Ok(())
}

/// Activate a calibration for its robot (recorded with who and why).
#[utoipa::path(post, path = "/robots/{id}/activate", tag = "activation",
    params(("id" = i64, Path, description = "Robot id")),
    request_body = Activate,
    responses(
        (status = 200, description = "Activated", body = ActivationRec),
        (status = 400, description = "Malformed JSON or bad id", body = ErrorBody),
        (status = 404, description = "No such robot", body = ErrorBody),
        (status = 409, description = "Already active", body = ErrorBody),
        (status = 408, description = BODY_TIMEOUT_408, body = ErrorBody),
        (status = 413, description = BODY_TOO_LARGE_413, body = ErrorBody),
        (status = 415, description = "Not JSON", body = ErrorBody),
        (status = 422, description = "Unknown calibration, another robot's, a missing reason, or a calibration that may not drive the robot: its held-out RMS not below the nominal model's (or no held-out poses), or a correction beyond the service's bounds (`--max-angle-correction-deg`, `--max-length-correction-mm`, `--max-tool-correction-mm`); the message names each rule broken, its bound and by how much", body = ErrorBody)))]
pub async fn activate(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
    ApiJson(a): ApiJson<Activate>,
) -> ApiResult<Json<ActivationRec>> {
    check_reason(&a.reason)?;
    caller.check_robot(&app, id).await?;
    app.store.get_robot(id).await?;
    match app.store.get_calibration(a.calibration_id).await {
        Err(crate::store::StoreError::NotFound { .. }) => {
            return Err(ApiError::invalid(
                "calibration_id",
                format!("no calibration {}", a.calibration_id),
            ));
        }
        Err(e) => return Err(e.into()),
        Ok(c) if c.robot_id != id => {
            return Err(ApiError::invalid(
                "calibration_id",
                format!(
                    "calibration {} belongs to robot {}, not {id}",
                    c.id, c.robot_id
                ),
            ));
        }
        Ok(_) => {}
    }
    let text = app.store.calibration_report(a.calibration_id).await?;
    let bounds = app.activation_bounds;
    let refused = tokio::task::spawn_blocking(move || {
        Report::from_json(&text).map(|r| crate::report::activation::refusals(&r, &bounds))
    })
    .await
    .map_err(|e| ApiError::Internal(format!("activation check task: {e}")))?
    .map_err(|e| ApiError::Internal(format!("stored report: {e}")))?;
    if !refused.is_empty() {
        return Err(ApiError::invalid(
            "calibration_id",
            format!(
                "calibration {} may not drive the robot: {}",
                a.calibration_id,
                refused.join("; ")
            ),
        ));
    }
    let rec = app
        .store
        .set_active(
            id,
            Some(a.calibration_id),
            "activate",
            &caller.name,
            a.reason.trim(),
        )
        .await;
    forget_active(&app, id);
    Ok(Json(rec?))
}

/// Roll back to the calibration that was active before the current one
/// (or to the nominal model if there was none).
#[utoipa::path(post, path = "/robots/{id}/rollback", tag = "activation",
    params(("id" = i64, Path, description = "Robot id")),
    request_body = Rollback,
    responses(
        (status = 200, description = "Rolled back", body = ActivationRec),
        (status = 400, description = "Malformed JSON or bad id", body = ErrorBody),
        (status = 404, description = "No such robot", body = ErrorBody),
        (status = 409, description = "Nothing to roll back", body = ErrorBody),
        (status = 408, description = BODY_TIMEOUT_408, body = ErrorBody),
        (status = 413, description = BODY_TOO_LARGE_413, body = ErrorBody),
        (status = 415, description = "Not JSON", body = ErrorBody),
        (status = 422, description = "Missing reason", body = ErrorBody)))]
pub async fn rollback(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
    ApiJson(r): ApiJson<Rollback>,
) -> ApiResult<Json<ActivationRec>> {
    check_reason(&r.reason)?;
    caller.check_robot(&app, id).await?;
    let previous = app.store.previous_active(id).await?;
    let rec = app
        .store
        .set_active(id, previous, "rollback", &caller.name, r.reason.trim())
        .await;
    forget_active(&app, id);
    Ok(Json(rec?))
}

/// A robot's activations and rollbacks, newest first.
#[utoipa::path(get, path = "/robots/{id}/activations", tag = "activation",
    params(("id" = i64, Path, description = "Robot id"), PageParams),
    responses(
        (status = 200, description = "A page", body = Paged<ActivationRec>),
        (status = 400, description = "Bad id or query", body = ErrorBody),
        (status = 404, description = "No such robot", body = ErrorBody),
        (status = 422, description = "Bad page", body = ErrorBody)))]
pub async fn list_activations(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
    ApiQuery(p): ApiQuery<PageParams>,
) -> ApiResult<Json<Paged<ActivationRec>>> {
    let page = p.page()?;
    caller.check_robot(&app, id).await?;
    let (items, total) = app.store.list_activations(id, page).await?;
    Ok(Json(Paged::new(items, total, page)))
}

#[cfg(test)]
mod tests {
    use super::text_cell;

    #[test]
    fn formula_like_text_is_quoted_for_spreadsheets() {
        assert_eq!(text_cell("=1+1"), "'=1+1");
        assert_eq!(text_cell("@SUM(A1)"), "'@SUM(A1)");
        assert_eq!(text_cell("-2"), "'-2");
        assert_eq!(text_cell("plant-1"), "plant-1");
        assert_eq!(text_cell(""), "");
    }
}
