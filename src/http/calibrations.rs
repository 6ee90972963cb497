//! Calibrations, activation and fleet history.

use axum::body::{Body, Bytes};
use axum::extract::State;
use axum::http::header::CONTENT_TYPE;
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use futures_util::stream::BoxStream;
use futures_util::{StreamExt, TryStreamExt};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::auth::Caller;
use super::error::{BODY_TIMEOUT_408, BODY_TOO_LARGE_413};
use super::extract::{ApiJson, ApiQuery, Id};
use super::{ApiError, ApiResult, AppState, ErrorBody, PageParams, Paged};
use crate::report::Report;
use crate::store::time::normalize_bound;
use crate::store::{ActivationRec, CalibrationFilter, CalibrationRec, CalibrationRow, StoreError};

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

/// A free-text cell as a spreadsheet reads it safely: text a user typed
/// (serial number, site, line, cell) that begins like a formula (`=`, `+`,
/// `-`, `@`, tab, carriage return) gets a leading `'`, so an MES export
/// opened in a spreadsheet shows it instead of running it.
pub(super) fn text_cell(s: &str) -> String {
    let mut cell = String::new();
    push_text_cell(&mut cell, s);
    cell
}

/// What a cell may not begin with unguarded: a spreadsheet reads such text
/// as a formula.
const FORMULA_STARTS: [char; 6] = ['=', '+', '-', '@', '\t', '\r'];

/// [`text_cell`] appended to `cell` (no allocation per cell).
fn push_text_cell(cell: &mut String, s: &str) {
    if s.starts_with(FORMULA_STARTS) {
        cell.push('\'');
    }
    cell.push_str(s);
}

/// `v` as `format!("{v:.4}")` writes it, byte for byte, without its cost
/// where that is safe. The standard formatting rounds the exact binary value
/// (ties to even) and is exact at any size, which takes a bignum algorithm
/// for many values: in a 5,000-row export it was a fifth of the runtime
/// thread's time (BENCHMARKS.md, "Fleet scale"). Here `v * 10^4` is rounded
/// as a float instead: for `0 <= v * 10^4 < 2^40` the product is within
/// 2^-13 of the exact one, so it rounds as the exact value does unless its
/// fraction is within 10^-3 of one half; those values, negative ones (and
/// `-0.0`), huge ones, NaN and infinities take the standard path.
fn push_fixed4(s: &mut Vec<u8>, v: f64) {
    use std::io::Write;
    const LIMIT: f64 = (1u64 << 40) as f64;
    let x = v * 10_000.0;
    // False for NaN and +inf; the sign test refuses -0.0 and negatives.
    if v.is_sign_positive() && x < LIMIT && (x - x.floor() - 0.5).abs() > 1e-3 {
        let n = x.round() as u64;
        let frac = n % 10_000;
        let digits = [frac / 1000, frac / 100 % 10, frac / 10 % 10, frac % 10];
        s.extend_from_slice(itoa::Buffer::new().format(n / 10_000).as_bytes());
        s.push(b'.');
        s.extend(digits.map(|d| b'0' + d as u8));
    } else {
        // Writing to a `Vec` cannot fail.
        let _ = write!(s, "{v:.4}");
    }
}

/// The one CSV dialect of the service's answers: the csv crate's defaults
/// (quotes only where needed), records ended by `\n`.
fn csv_writer(buf: Vec<u8>) -> csv::Writer<Vec<u8>> {
    csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(buf)
}

fn csv_error(e: impl std::fmt::Display) -> ApiError {
    ApiError::Internal(format!("writing CSV: {e}"))
}

/// `header`, then one record per row, as CSV.
fn csv_bytes(header: &[&str], rows: impl IntoIterator<Item = Vec<String>>) -> ApiResult<Vec<u8>> {
    let mut w = csv_writer(Vec::new());
    w.write_record(header).map_err(csv_error)?;
    for row in rows {
        w.write_record(&row).map_err(csv_error)?;
    }
    w.into_inner().map_err(csv_error)
}

/// A `text/csv` answer: `header`, then one record per row.
pub(super) fn csv_table(
    header: &[&str],
    rows: impl IntoIterator<Item = Vec<String>>,
) -> ApiResult<Response> {
    let bytes = csv_bytes(header, rows)?;
    Ok(([(CONTENT_TYPE, "text/csv")], bytes).into_response())
}

/// The columns of a calibrations CSV, in order.
const CALIBRATION_COLUMNS: [&str; 19] = [
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
];

/// CSV bytes gathered before they go to the connection as one piece: big
/// enough that a piece's framing and write cost little per row (about
/// 250 rows), small enough that an export holds little memory whatever
/// its size. An export that fits in one piece is answered whole, with its
/// length.
const CSV_CHUNK_BYTES: usize = 32 * 1024;

/// Calibrations written as CSV, a piece of [`CSV_CHUNK_BYTES`] at a time,
/// on the thread that reads them ([`crate::store::ExportSink`]): straight
/// from the row the database driver holds into the piece's bytes, no
/// `String` per cell or per row. The dialect is [`csv_writer`]'s, written
/// here by hand (its rules are few: a cell holding `,`, `"`, `\r` or `\n`
/// is quoted, with its quotes doubled; `,` between cells, `\n` after a
/// record); tests compare the bytes with that writer's over awkward and
/// random text.
struct CalibrationCsv {
    buf: Vec<u8>,
}

impl CalibrationCsv {
    /// A writer that has written the header.
    fn new() -> Self {
        let mut csv = CalibrationCsv {
            buf: Vec::with_capacity(CSV_CHUNK_BYTES + 1024),
        };
        for (i, name) in CALIBRATION_COLUMNS.iter().enumerate() {
            if i > 0 {
                csv.buf.push(b',');
            }
            csv.cell(false, name);
        }
        csv.buf.push(b'\n');
        csv
    }

    /// A text cell: after the formula guard's `'` if `guard` and `s` begins
    /// like a formula ([`push_text_cell`]), quoted if it must be.
    fn cell(&mut self, guard: bool, s: &str) {
        let quote = guard && s.starts_with(FORMULA_STARTS);
        let bytes = s.as_bytes();
        if bytes
            .iter()
            .any(|&b| matches!(b, b',' | b'"' | b'\r' | b'\n'))
        {
            self.buf.push(b'"');
            if quote {
                self.buf.push(b'\'');
            }
            let mut parts = bytes.split(|&b| b == b'"');
            if let Some(first) = parts.next() {
                self.buf.extend_from_slice(first);
            }
            for part in parts {
                self.buf.extend_from_slice(b"\"\"");
                self.buf.extend_from_slice(part);
            }
            self.buf.push(b'"');
        } else {
            if quote {
                self.buf.push(b'\'');
            }
            self.buf.extend_from_slice(bytes);
        }
    }

    /// An integer cell, then the separator.
    fn int(&mut self, v: i64) {
        self.buf
            .extend_from_slice(itoa::Buffer::new().format(v).as_bytes());
        self.buf.push(b',');
    }

    /// A held-out or training RMS cell (`{:.4}`, empty when absent), then
    /// the separator.
    fn num(&mut self, v: Option<f64>) {
        if let Some(v) = v {
            push_fixed4(&mut self.buf, v);
        }
        self.buf.push(b',');
    }

    /// The effects' cell, then the separator: the stored list with `;`
    /// between its names instead of `,` (as before), which needs no quotes,
    /// so the cell is quoted only for what else it holds.
    fn effects(&mut self, stored: &str) {
        let bytes = stored.as_bytes();
        if bytes.iter().any(|&b| matches!(b, b'"' | b'\r' | b'\n')) {
            self.buf.push(b'"');
            for &b in bytes {
                match b {
                    b',' => self.buf.push(b';'),
                    b'"' => self.buf.extend_from_slice(b"\"\""),
                    b => self.buf.push(b),
                }
            }
            self.buf.push(b'"');
        } else {
            for (i, name) in bytes.split(|&b| b == b',').enumerate() {
                if i > 0 {
                    self.buf.push(b';');
                }
                self.buf.extend_from_slice(name);
            }
        }
        self.buf.push(b',');
    }

    /// A text cell, then the separator.
    fn text(&mut self, guard: bool, s: &str) {
        self.cell(guard, s);
        self.buf.push(b',');
    }
}

impl crate::store::ExportSink for CalibrationCsv {
    type Piece = Bytes;

    /// One calibration's record, its cells in [`CALIBRATION_COLUMNS`]'
    /// order: the serial number and the robot's tags behind the formula
    /// guard, the RMS figures as `{:.4}`, the effects' list with `;`
    /// between its names.
    fn row(&mut self, c: &CalibrationRow<'_>) {
        self.int(c.id);
        self.int(c.robot_id);
        self.text(true, c.serial_number);
        self.int(c.model_id);
        for t in [c.site, c.line, c.cell] {
            self.text(true, t.unwrap_or_default());
        }
        self.int(c.version);
        self.text(false, c.created_at);
        self.text(false, c.method);
        self.int(c.n_poses);
        self.int(c.n_test);
        self.num(c.test_rms_before_mm);
        self.num(c.test_rms_after_mm);
        self.num(c.train_rms_after_mm);
        // A list inside a cell: `;` between the effects, as before (`;`
        // needs no quotes, so the cell needs them only for what else it
        // holds).
        self.effects(c.effects);
        self.buf
            .extend_from_slice(if c.active { b"true," } else { b"false," });
        self.int(c.session_id);
        self.int(c.job_id);
        // The last cell's separator becomes the record's end.
        if let Some(last) = self.buf.last_mut() {
            *last = b'\n';
        }
    }

    fn ready(&mut self) -> Option<Bytes> {
        (self.buf.len() >= CSV_CHUNK_BYTES).then(|| {
            Bytes::from(std::mem::replace(
                &mut self.buf,
                Vec::with_capacity(CSV_CHUNK_BYTES + 1024),
            ))
        })
    }

    fn finish(&mut self) -> Option<Bytes> {
        (!self.buf.is_empty()).then(|| Bytes::from(std::mem::take(&mut self.buf)))
    }
}

/// A calibrations CSV's pieces as the store hands them out.
type CsvPieces = BoxStream<'static, Result<Bytes, StoreError>>;

/// A `text/csv` answer of calibrations, written as the store reads them
/// ([`CalibrationCsv`]), a piece of [`CSV_CHUNK_BYTES`] at a time: memory
/// stays bounded however many rows match, and the first bytes leave
/// before the last row is read. The first piece is taken before the answer
/// starts, so a query that fails is an error answer (its status chosen
/// where every error's is); a failure after that can only end the answer
/// early: the connection is closed mid-body, which a client sees as an
/// incomplete answer, never as a complete shorter CSV. Only the last piece
/// can be shorter than [`CSV_CHUNK_BYTES`], so a short first piece is the
/// whole answer, which is sent with its length.
async fn calibrations_csv(mut pieces: CsvPieces) -> ApiResult<Response> {
    let Some(first) = pieces.next().await else {
        return Err(ApiError::Internal(
            "CSV export: the store handed out nothing, not even the header".into(),
        ));
    };
    let first = first?;
    if first.len() < CSV_CHUNK_BYTES {
        return Ok(([(CONTENT_TYPE, "text/csv")], first).into_response());
    }
    let rest = pieces.map(|piece| {
        piece.map_err(|e| {
            tracing::error!(error = %e, "CSV export cut short");
            ApiError::from(e)
        })
    });
    let body = futures_util::stream::once(std::future::ready(Ok::<_, ApiError>(first))).chain(rest);
    Ok(([(CONTENT_TYPE, "text/csv")], Body::from_stream(body)).into_response())
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
        let pieces = app
            .store
            .export_calibrations(&filter, CalibrationCsv::new());
        return calibrations_csv(pieces.await).await;
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
    if q.format == Some(Format::Csv) {
        let pieces = app
            .store
            .export_calibrations(&filter, CalibrationCsv::new());
        return calibrations_csv(pieces.await).await;
    }
    let rows: Vec<CalibrationRec> = app
        .store
        .stream_calibrations(&filter)
        .await
        .try_collect()
        .await?;
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
    use super::*;
    use axum::body::HttpBody;

    #[test]
    fn formula_like_text_is_quoted_for_spreadsheets() {
        assert_eq!(text_cell("=1+1"), "'=1+1");
        assert_eq!(text_cell("@SUM(A1)"), "'@SUM(A1)");
        assert_eq!(text_cell("-2"), "'-2");
        assert_eq!(text_cell("plant-1"), "plant-1");
        assert_eq!(text_cell(""), "");
    }

    /// The fast `{:.4}` is the standard one for every kind of value: ties
    /// of the fifth decimal (exact in binary, as 1/32), values a hair either
    /// side of one, whole numbers, tiny and huge ones, the limit of the fast
    /// path, negative ones, -0.0, NaN and infinities, and a million values
    /// drawn over the whole range of positive doubles and of plausible RMS
    /// figures.
    #[test]
    fn fixed4_is_the_standard_formatting() {
        let check = |v: f64| {
            let mut s = Vec::new();
            push_fixed4(&mut s, v);
            assert_eq!(
                String::from_utf8_lossy(&s),
                format!("{v:.4}"),
                "{v:e} ({:#x})",
                v.to_bits()
            );
        };
        let mut special = vec![
            0.0,
            -0.0,
            1.0,
            0.5,
            0.03125,
            0.96875,
            1.0 / 1024.0,
            12345.678_95,
            1e-5,
            5e-5,
            4.9999e-5,
            0.00015,
            0.99995,
            9.99995,
            f64::MIN_POSITIVE,
            5e-324,
            (1u64 << 40) as f64 / 1e4,
            (1u64 << 40) as f64,
            1e300,
            f64::MAX,
            -1.5,
            -1e-9,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        // Every exact tie n/32 (the fifth decimal a 5), and its neighbours.
        for k in 0..20_000u32 {
            let v = f64::from(k) / 32.0;
            special.extend([
                v,
                f64::from_bits(v.to_bits() + 1),
                f64::from_bits(v.to_bits().max(1) - 1),
            ]);
        }
        // Halfway cases of the decimal grid, a few ulps apart.
        for k in 0..20_000u32 {
            let v = (f64::from(k) + 0.5) / 1e4;
            for d in -3i64..=3 {
                special.push(f64::from_bits((v.to_bits() as i64 + d) as u64));
            }
        }
        special.into_iter().for_each(check);
        let mut z = 0x1234_5678_9abc_def0_u64;
        let mut next = || {
            z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut x = z;
            x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            x ^ (x >> 31)
        };
        for _ in 0..500_000 {
            // Any positive double (bit patterns), then a plausible figure.
            check(f64::from_bits(next() >> 1));
            check(
                (next() >> 11) as f64 / (1u64 << 53) as f64 * 10f64.powi((next() % 12) as i32 - 6),
            );
        }
    }

    /// Calibrations whose text needs quoting or the formula guard, numbers
    /// absent and present, effects none, one or several.
    fn awkward(n: usize) -> Vec<CalibrationRec> {
        let texts = [
            "plant-1",
            "=HYPERLINK(\"x\")",
            "a,b",
            "-2",
            "+1",
            "@SUM(A1)",
            "\tx",
            "\rx",
            "two\nlines",
            "say \"hi\"",
            "Zürich",
            "",
            " lead",
        ];
        let effects = ["", "joint_compliance", "joint_compliance,backlash,thermal"];
        (0..n)
            .map(|i| {
                let t = |k: usize| texts[(i + k) % texts.len()].to_string();
                CalibrationRec {
                    id: i as i64 + 1,
                    robot_id: (i % 7) as i64 + 1,
                    serial_number: t(0),
                    model_id: 3,
                    site: (i % 5 != 0).then(|| t(1)),
                    line: (i % 4 != 0).then(|| t(2)),
                    cell: (i % 3 != 0).then(|| t(3)),
                    session_id: 10 * i as i64,
                    job_id: i64::MAX - i as i64,
                    version: i as i64 / 7 + 1,
                    method: "lm".into(),
                    n_poses: 50,
                    n_test: 15,
                    test_rms_before_mm: (i % 6 != 0).then_some(0.123456789 * i as f64),
                    test_rms_after_mm: (i % 6 != 1).then_some(1e-5 / (i + 1) as f64),
                    train_rms_after_mm: (i % 6 != 2).then_some(12345.678_95),
                    effects: effects[i % 3].into(),
                    active: i % 2 == 0,
                    created_at: format!("2026-01-{:02}T00:00:00.000Z", i % 28 + 1),
                }
            })
            .collect()
    }

    /// The CSV as it was made before the export streamed: a `String` per
    /// cell, the whole table through [`csv_table`]'s writer.
    fn table(rows: &[CalibrationRec]) -> Vec<u8> {
        let num = |x: Option<f64>| x.map(|v| format!("{v:.4}")).unwrap_or_default();
        csv_bytes(
            &CALIBRATION_COLUMNS,
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
                    num(c.test_rms_before_mm),
                    num(c.test_rms_after_mm),
                    num(c.train_rms_after_mm),
                    c.effects.replace(',', ";"),
                    c.active.to_string(),
                    c.session_id.to_string(),
                    c.job_id.to_string(),
                ]
            }),
        )
        .unwrap()
    }

    /// The pieces of `rows` as the store hands them out
    /// (`Store::export_calibrations`): each row written into the sink, a
    /// piece handed out when it is ready, the rest at the end; a failure
    /// ends them.
    fn pieces(rows: Vec<Result<CalibrationRec, StoreError>>) -> Vec<Result<Bytes, StoreError>> {
        use crate::store::ExportSink;
        let mut csv = CalibrationCsv::new();
        let mut out = Vec::new();
        for row in rows {
            match row {
                Ok(c) => {
                    csv.row(&c.as_row());
                    out.extend(csv.ready().map(Ok));
                }
                Err(e) => {
                    out.push(Err(e));
                    return out;
                }
            }
        }
        out.extend(csv.finish().map(Ok));
        out
    }

    /// The CSV of `rows`, written by the export's writer.
    fn written(rows: &[CalibrationRec]) -> Vec<u8> {
        let pieces = pieces(rows.iter().cloned().map(Ok).collect());
        let n = pieces.len();
        for (i, p) in pieces.iter().enumerate() {
            let len = p.as_ref().unwrap().len();
            assert!(
                i + 1 == n || len >= CSV_CHUNK_BYTES,
                "piece {i} of {n}: {len} bytes"
            );
        }
        pieces.into_iter().flat_map(|p| p.unwrap()).collect()
    }

    async fn answer(rows: Vec<Result<CalibrationRec, StoreError>>) -> ApiResult<Response> {
        calibrations_csv(futures_util::stream::iter(pieces(rows)).boxed()).await
    }

    /// The export's hand-written CSV is the csv crate's, whatever the text:
    /// every text column filled with random strings of the characters the
    /// dialect and the formula guard treat specially (`,`, `"`, `\r`,
    /// `\n`, `=`, `+`, `-`, `@`, tab, `;`), quotes, spaces and non-ASCII, of
    /// lengths 0 to 12; integers of every size and sign; figures present and
    /// absent, of any size.
    #[test]
    fn written_csv_is_the_csv_writer_on_random_text() {
        const BITS: [&str; 16] = [
            ",", "\"", "\r", "\n", "=", "+", "-", "@", "\t", ";", "'", " ", "a", "Zü", "日", "0",
        ];
        let mut z = 0x0dd5_eed5_u64;
        let mut next = move || {
            z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut x = z;
            x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            x ^ (x >> 31)
        };
        let text = |next: &mut dyn FnMut() -> u64| -> String {
            (0..next() % 13)
                .map(|_| BITS[(next() % BITS.len() as u64) as usize])
                .collect()
        };
        for round in 0..100 {
            let mut rows = awkward(40);
            for c in &mut rows {
                let int = |x: u64| match x % 4 {
                    0 => x as i64,
                    1 => -((x >> 3) as i64),
                    2 => (x % 1000) as i64,
                    _ => [0, -1, i64::MIN, i64::MAX][(x >> 2) as usize % 4],
                };
                let num = |x: u64| {
                    (!x.is_multiple_of(5))
                        .then(|| f64::from_bits(x >> 2) * [1.0, 1e-300, -1.0][x as usize % 3])
                };
                c.id = int(next());
                c.robot_id = int(next());
                c.model_id = int(next());
                c.session_id = int(next());
                c.job_id = int(next());
                c.version = int(next());
                c.n_poses = int(next());
                c.n_test = int(next());
                c.serial_number = text(&mut next);
                c.site = (!next().is_multiple_of(4)).then(|| text(&mut next));
                c.line = (!next().is_multiple_of(4)).then(|| text(&mut next));
                c.cell = (!next().is_multiple_of(4)).then(|| text(&mut next));
                c.method = text(&mut next);
                c.effects = text(&mut next);
                c.created_at = text(&mut next);
                c.test_rms_before_mm = num(next());
                c.test_rms_after_mm = num(next());
                c.train_rms_after_mm = num(next());
                c.active = next().is_multiple_of(2);
            }
            assert_eq!(
                String::from_utf8_lossy(&written(&rows)),
                String::from_utf8_lossy(&table(&rows)),
                "round {round}"
            );
        }
    }

    /// The pieces of a large export: each but the last at least
    /// [`CSV_CHUNK_BYTES`] (so that a short first piece is the whole
    /// answer), together the table's bytes.
    #[test]
    fn a_large_export_is_written_in_full_pieces() {
        let rows = awkward(2_000);
        let all = pieces(rows.iter().cloned().map(Ok).collect());
        assert!(all.len() > 3, "{} pieces", all.len());
        assert_eq!(written(&rows), table(&rows));
    }

    /// Small exports are answered whole (with a length), large ones in
    /// pieces; either way the bytes are the table's, header included.
    #[tokio::test]
    async fn streamed_csv_is_the_whole_table_byte_for_byte() {
        for n in [0, 1, 13, 100, 2_000] {
            let rows = awkward(n);
            let want = table(&rows);
            let r = answer(rows.into_iter().map(Ok).collect()).await.unwrap();
            assert_eq!(r.headers()[CONTENT_TYPE], "text/csv");
            let sized = r.body().size_hint().exact().is_some();
            assert_eq!(
                sized,
                want.len() < CSV_CHUNK_BYTES,
                "{n} rows, {} bytes",
                want.len()
            );
            let got = axum::body::to_bytes(r.into_body(), usize::MAX)
                .await
                .unwrap();
            assert_eq!(
                String::from_utf8_lossy(&got),
                String::from_utf8_lossy(&want),
                "{n} rows"
            );
        }
    }

    /// A store failure before the first piece is an error answer; after
    /// it, the body fails (the connection is cut) instead of ending as if
    /// the CSV were whole.
    #[tokio::test]
    async fn a_failure_is_an_error_answer_or_a_cut_body() {
        let fail = || Err(StoreError::Conflict("gone".into()));
        let r = answer(vec![fail()]).await;
        assert!(matches!(r, Err(ApiError::Conflict(_))), "{r:?}");
        let mut rows: Vec<_> = awkward(2_000).into_iter().map(Ok).collect();
        rows.push(fail());
        let r = answer(rows).await.unwrap();
        assert!(
            axum::body::to_bytes(r.into_body(), usize::MAX)
                .await
                .is_err()
        );
    }
}
