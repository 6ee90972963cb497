//! Calibration sessions, pose uploads and identification jobs.
//!
//! Poses arrive as the DATA_FORMAT CSV (`Content-Type: text/csv`) or as a
//! JSON array of objects keyed like the CSV columns. Both are turned into
//! one table and validated by the engine's own `Dataset::from_csv`, together
//! with the poses already stored, before anything is written: one
//! validation path, and a bad upload stores nothing.

use std::collections::HashMap;

use axum::extract::State;
use axum::http::header::{CONTENT_TYPE, LOCATION};
use axum::http::{HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::auth::Caller;
use super::error::{BODY_TIMEOUT_408, BODY_TOO_LARGE_413};
use super::extract::{ApiJson, ApiQuery, Id, RawBody, is_json, parse_json, without_bom};
use super::limits::{Action, queue_has_room};
use super::resources::{stored_rig, stored_robot};
use super::{ApiError, ApiResult, AppState, ErrorBody, PageParams, Paged};
use crate::jobs::{JobOptions, session_csv};
use crate::model::{Dataset, Rig, Robot};
use crate::store::{JobRec, SessionRec, StoreError};

/// A session to open.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateSession {
    /// Robot measured.
    pub robot_id: i64,
    /// Rig used.
    pub rig_id: i64,
    /// Free-form name, at most 200 characters.
    #[serde(default)]
    #[schema(max_length = 200)]
    pub name: Option<String>,
}

/// Open a calibration session for a robot and a rig.
#[utoipa::path(post, path = "/sessions", tag = "sessions", request_body = CreateSession,
    responses(
        (status = 201, description = "Opened", body = SessionRec),
        (status = 400, description = "Malformed JSON", body = ErrorBody),
        (status = 408, description = BODY_TIMEOUT_408, body = ErrorBody),
        (status = 413, description = BODY_TOO_LARGE_413, body = ErrorBody),
        (status = 415, description = "Not JSON", body = ErrorBody),
        (status = 422, description = "Invalid field, unknown robot or rig", body = ErrorBody)))]
pub async fn create_session(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    ApiJson(s): ApiJson<CreateSession>,
) -> ApiResult<(StatusCode, Json<SessionRec>)> {
    if s.name.as_ref().is_some_and(|n| n.chars().count() > 200) {
        return Err(ApiError::invalid("name", "at most 200 characters"));
    }
    match app.store.get_robot(s.robot_id).await {
        Err(StoreError::NotFound { .. }) => {
            return Err(ApiError::invalid(
                "robot_id",
                format!("no robot {}", s.robot_id),
            ));
        }
        Err(e) => return Err(e.into()),
        Ok(robot) => caller.check_site(&format!("robot {}", s.robot_id), robot.site.as_deref())?,
    }
    if let Err(StoreError::NotFound { .. }) = app.store.get_rig(s.rig_id).await {
        return Err(ApiError::invalid("rig_id", format!("no rig {}", s.rig_id)));
    }
    let rec = app
        .store
        .create_session(s.robot_id, s.rig_id, s.name.as_deref())
        .await?;
    Ok((StatusCode::CREATED, Json(rec)))
}

/// Session list filter.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct SessionFilter {
    /// Only this robot's sessions.
    pub robot_id: Option<i64>,
}

/// List sessions.
#[utoipa::path(get, path = "/sessions", tag = "sessions", params(SessionFilter, PageParams),
    responses(
        (status = 200, description = "A page", body = Paged<SessionRec>),
        (status = 400, description = "Bad query", body = ErrorBody),
        (status = 422, description = "Bad page", body = ErrorBody)))]
pub async fn list_sessions(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    ApiQuery(f): ApiQuery<SessionFilter>,
    ApiQuery(p): ApiQuery<PageParams>,
) -> ApiResult<Json<Paged<SessionRec>>> {
    let page = p.page()?;
    match f.robot_id {
        Some(r) => caller.check_robot(&app, r).await?,
        None => caller.check_unlimited("the list of sessions without robot_id")?,
    }
    let (items, total) = app.store.list_sessions(f.robot_id, page).await?;
    Ok(Json(Paged::new(items, total, page)))
}

/// One session.
#[utoipa::path(get, path = "/sessions/{id}", tag = "sessions",
    params(("id" = i64, Path, description = "Session id")),
    responses(
        (status = 200, description = "The session", body = SessionRec),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such session", body = ErrorBody)))]
pub async fn get_session(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
) -> ApiResult<Json<SessionRec>> {
    let session = app.store.get_session(id).await?;
    caller.check_robot(&app, session.robot_id).await?;
    Ok(Json(session))
}

/// One pose as JSON: keys are the CSV columns, values numbers or strings.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
#[schema(example = json!({"pose": "1", "q1_deg": 10.0, "q2_deg": -20.0, "q3_deg": 5.0, "q4_deg": 0.0, "q5_deg": 30.0, "q6_deg": 0.0, "l1_mm": 812.4, "l2_mm": 790.1, "l3_mm": 905.7, "l4_mm": 880.2, "split": "train"}))]
#[schema(value_type = Object)]
pub struct PoseRow(pub serde_json::Map<String, serde_json::Value>);

/// Result of an upload.
#[derive(Debug, Serialize, ToSchema)]
pub struct UploadResult {
    /// Poses added by this upload.
    pub added: i64,
    /// The session after the upload.
    pub session: SessionRec,
}

/// Uploaded poses as a table of strings.
struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

/// Read an uploaded poses.csv as it is sent (before it is merged with the
/// session's columns): the engine's reader, so a semicolon-separated file,
/// text that is not UTF-8 and a short or long row are refused here, named by
/// their row in this upload, exactly as `drawcal identify` names them.
fn table_from_csv(bytes: &[u8]) -> ApiResult<Table> {
    let (mut rdr, headers) = crate::model::csv_with_header(bytes)?;
    let header: Vec<String> = headers.iter().map(str::to_string).collect();
    let mut rows = Vec::new();
    for (i, rec) in rdr.records().enumerate() {
        let rec = crate::model::csv_record(i + 1, rec, &headers)?;
        rows.push(rec.iter().map(str::to_string).collect());
    }
    Ok(Table { header, rows })
}

/// One element of an uploaded JSON array: an object's entries in order,
/// a key given twice kept twice (`serde_json::Map` would keep the last one
/// silently), or anything else (refused by its row).
enum JsonPose {
    Object(Vec<(String, serde_json::Value)>),
    NotAnObject,
}

impl<'de> serde::Deserialize<'de> for JsonPose {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visit;
        impl<'de> serde::de::Visitor<'de> for Visit {
            type Value = JsonPose;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a pose object")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut m: A,
            ) -> Result<JsonPose, A::Error> {
                let mut entries = Vec::new();
                while let Some(e) = m.next_entry::<String, serde_json::Value>()? {
                    entries.push(e);
                }
                Ok(JsonPose::Object(entries))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut s: A,
            ) -> Result<JsonPose, A::Error> {
                while s.next_element::<serde::de::IgnoredAny>()?.is_some() {}
                Ok(JsonPose::NotAnObject)
            }
            fn visit_bool<E>(self, _: bool) -> Result<JsonPose, E> {
                Ok(JsonPose::NotAnObject)
            }
            fn visit_i64<E>(self, _: i64) -> Result<JsonPose, E> {
                Ok(JsonPose::NotAnObject)
            }
            fn visit_u64<E>(self, _: u64) -> Result<JsonPose, E> {
                Ok(JsonPose::NotAnObject)
            }
            fn visit_f64<E>(self, _: f64) -> Result<JsonPose, E> {
                Ok(JsonPose::NotAnObject)
            }
            fn visit_str<E>(self, _: &str) -> Result<JsonPose, E> {
                Ok(JsonPose::NotAnObject)
            }
            fn visit_unit<E>(self) -> Result<JsonPose, E> {
                Ok(JsonPose::NotAnObject)
            }
        }
        d.deserialize_any(Visit)
    }
}

fn table_from_json(bytes: &[u8]) -> ApiResult<Table> {
    // One pass when the upload is an array; only a failed one pays for
    // telling malformed JSON from a body that is not an array.
    let items: Vec<JsonPose> = match serde_json::from_slice(without_bom(bytes)) {
        Ok(items) => items,
        Err(_) => {
            let value: serde_json::Value = parse_json(bytes)?;
            if !value.is_array() {
                return Err(ApiError::Invalid {
                    message: "expected a JSON array of pose objects".into(),
                    field: None,
                    row: None,
                });
            }
            parse_json(bytes)?
        }
    };
    let mut header: Vec<String> = Vec::new();
    let mut index: HashMap<String, usize> = HashMap::new();
    let mut cells: Vec<Vec<(usize, String)>> = Vec::with_capacity(items.len());
    for (i, item) in items.into_iter().enumerate() {
        let row = i + 1;
        let JsonPose::Object(map) = item else {
            return Err(ApiError::Invalid {
                message: "expected an object keyed by column name".into(),
                field: None,
                row: Some(row),
            });
        };
        let mut out: Vec<(usize, String)> = Vec::with_capacity(map.len());
        for (k, v) in map {
            let text = match v {
                serde_json::Value::Number(n) => n.to_string(),
                serde_json::Value::String(s) => s,
                serde_json::Value::Null => String::new(),
                other => {
                    return Err(ApiError::Invalid {
                        message: format!("expected a number or a string, got {other}"),
                        field: Some(k),
                        row: Some(row),
                    });
                }
            };
            let col = *index.entry(k.clone()).or_insert_with(|| {
                header.push(k.clone());
                header.len() - 1
            });
            if out.iter().any(|(c, _)| *c == col) {
                return Err(ApiError::Invalid {
                    message: "key appears twice in this pose".into(),
                    field: Some(k),
                    row: Some(row),
                });
            }
            out.push((col, text));
        }
        cells.push(out);
    }
    let rows = cells
        .into_iter()
        .map(|cs| {
            let mut r = vec![String::new(); header.len()];
            for (c, t) in cs {
                r[c] = t;
            }
            r
        })
        .collect();
    Ok(Table { header, rows })
}

fn csv_line(fields: &[String]) -> ApiResult<String> {
    let mut w = csv::WriterBuilder::new().from_writer(Vec::new());
    w.write_record(fields)
        .map_err(|e| ApiError::Internal(e.to_string()))?;
    let bytes = w
        .into_inner()
        .map_err(|e| ApiError::Internal(e.to_string()))?;
    let mut s = String::from_utf8(bytes).map_err(|e| ApiError::Internal(e.to_string()))?;
    while s.ends_with('\n') || s.ends_with('\r') {
        s.pop();
    }
    Ok(s)
}

fn csv_body(rows: &[Vec<String>]) -> ApiResult<String> {
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    for r in rows {
        w.write_record(r)
            .map_err(|e| ApiError::Internal(e.to_string()))?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| ApiError::Internal(e.to_string()))?;
    String::from_utf8(bytes).map_err(|e| ApiError::Internal(e.to_string()))
}

/// Load a session's robot model and rig.
async fn robot_and_rig(app: &AppState, session: &SessionRec) -> ApiResult<(Robot, Rig)> {
    let robot_rec = app.store.get_robot(session.robot_id).await?;
    let model = app.store.get_model(robot_rec.model_id).await?;
    let robot = stored_robot(&model, ", a robot and a new session")?;
    let rig_rec = app.store.get_rig(session.rig_id).await?;
    let rig = stored_rig(&rig_rec, " and a new session")?;
    Ok((robot, rig))
}

/// Add poses to a session, all at once or in batches. Every row (with the
/// rows stored before) is validated first; a bad upload stores nothing and
/// the answer names the row (`row`: 1-based in this upload, counted after
/// the header, as `drawcal identify` counts it) and, for a bad cell, the
/// column (`field`); a row with too few or too many cells has no `field`.
/// A CSV separated by `;` or tabs is refused with `field: header`. Joint
/// angles that only look like radians are stored; the identification
/// warns about them in the report's `warnings`.
#[utoipa::path(post, path = "/sessions/{id}/poses", tag = "sessions",
    params(("id" = i64, Path, description = "Session id")),
    request_body(
        description = "Poses: DATA_FORMAT.md poses.csv, or a JSON array of objects keyed like its columns. Batches after the first must have the same columns.",
        content(
            (String = "text/csv"),
            (Vec<PoseRow> = "application/json"))),
    responses(
        (status = 200, description = "Stored", body = UploadResult),
        (status = 400, description = "Malformed JSON or bad id", body = ErrorBody),
        (status = 404, description = "No such session", body = ErrorBody),
        (status = 409, description = "Another upload was stored meanwhile, or the session's stored model or rig no longer passes validation (stored by an earlier version)", body = ErrorBody),
        (status = 429, description = "The key is over its uploads a minute (`--max-uploads-per-minute`): error `too_many_requests`, `Retry-After` in seconds", body = ErrorBody, headers(("Retry-After" = u64, description = "Seconds until a retry can succeed"))),
        (status = 408, description = BODY_TIMEOUT_408, body = ErrorBody),
        (status = 413, description = BODY_TOO_LARGE_413, body = ErrorBody),
        (status = 415, description = "Neither text/csv nor application/json", body = ErrorBody),
        (status = 422, description = "A bad row or column (named)", body = ErrorBody)))]
pub async fn upload_poses(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
    body: RawBody,
) -> ApiResult<Json<UploadResult>> {
    let session = app.store.get_session(id).await?;
    caller.check_robot(&app, session.robot_id).await?;
    app.limits.take(&caller.name, Action::Upload)?;
    let table = upload_table(&body)?;
    // Columns: the first batch fixes them; later batches must match (in any order).
    let (header, rows) = match &session.columns {
        None => (table.header, table.rows),
        Some(cols) => in_session_columns(cols, table)?,
    };
    let columns = csv_line(&header)?;
    let body_csv = csv_body(&rows)?;
    let n_new = rows.len() as i64;
    validate_with_stored(&app, &session, &columns, &body_csv).await?;
    let session = app
        .store
        .append_poses(id, session.n_batches, &columns, &body_csv, n_new)
        .await?;
    tracing::info!(
        session_id = id,
        added = n_new,
        total = session.n_poses,
        "poses stored"
    );
    app.store
        .audit(
            &caller.name,
            "upload_poses",
            &format!("session {id}"),
            &format!("{n_new} poses ({} in all)", session.n_poses),
        )
        .await?;
    Ok(Json(UploadResult {
        added: n_new,
        session,
    }))
}

/// The uploaded table (CSV or JSON by content type), with rows and named,
/// distinct columns.
fn upload_table(body: &RawBody) -> ApiResult<Table> {
    let table = match body.content_type.as_deref() {
        Some("text/csv") => table_from_csv(&body.bytes)?,
        ct if is_json(ct) => table_from_json(&body.bytes)?,
        other => {
            return Err(ApiError::UnsupportedMediaType(format!(
                "poses are uploaded as text/csv or application/json, got {}",
                other.unwrap_or("none")
            )));
        }
    };
    if table.rows.is_empty() {
        return Err(ApiError::Invalid {
            message: "the upload holds no poses".into(),
            field: None,
            row: None,
        });
    }
    let mut seen = std::collections::HashSet::new();
    for h in &table.header {
        if h.is_empty() {
            return Err(ApiError::invalid("header", "empty column name"));
        }
        if !seen.insert(h.as_str()) {
            return Err(ApiError::invalid(h.clone(), "column appears twice"));
        }
    }
    Ok(table)
}

/// A later batch's rows in the session's column order (`cols`, fixed by
/// the first batch); its columns must be the same set.
#[allow(clippy::type_complexity)]
fn in_session_columns(cols: &str, table: Table) -> ApiResult<(Vec<String>, Vec<Vec<String>>)> {
    let existing = table_from_csv(format!("{cols}\n").as_bytes())?.header;
    let pos: HashMap<&str, usize> = table
        .header
        .iter()
        .enumerate()
        .map(|(i, h)| (h.as_str(), i))
        .collect();
    let missing: Vec<&str> = existing
        .iter()
        .map(String::as_str)
        .filter(|c| !pos.contains_key(c))
        .collect();
    let extra: Vec<&str> = table
        .header
        .iter()
        .map(String::as_str)
        .filter(|c| !existing.iter().any(|e| e == c))
        .collect();
    if !missing.is_empty() || !extra.is_empty() {
        return Err(ApiError::invalid(
            "header",
            format!(
                "a batch must have the session's columns ({cols}); missing: [{}], extra: [{}]",
                missing.join(", "),
                extra.join(", ")
            ),
        ));
    }
    let order: Vec<usize> = existing.iter().map(|c| pos[c.as_str()]).collect();
    let rows = table
        .rows
        .into_iter()
        .map(|r| {
            order
                .iter()
                .map(|&i| r.get(i).cloned().unwrap_or_default())
                .collect()
        })
        .collect();
    Ok((existing, rows))
}

/// The stored poses and the new batch validated together, off the
/// runtime: a bad new row is a 422 naming its row within the batch; stored
/// rows that no longer validate (the robot or rig changed) are a 409.
async fn validate_with_stored(
    app: &AppState,
    session: &SessionRec,
    columns: &str,
    body_csv: &str,
) -> ApiResult<()> {
    let (robot, rig) = robot_and_rig(app, session).await?;
    let mut batches = app.store.pose_batches(session.id).await?;
    batches.push(body_csv.to_string());
    let full = session_csv(columns, &batches);
    let existing_rows = session.n_poses as usize;
    let checked = tokio::task::spawn_blocking(move || {
        Dataset::from_csv(full.as_bytes(), &robot, &rig).map(|_| ())
    })
    .await
    .map_err(|e| ApiError::Internal(format!("validation task: {e}")))?;
    checked.map_err(|e| match e {
        crate::Error::Input {
            field,
            row: Some(r),
            message,
        } if r > existing_rows => ApiError::Invalid {
            message,
            field,
            row: Some(r - existing_rows),
        },
        crate::Error::Input {
            row: Some(_),
            message,
            ..
        } => ApiError::Conflict(format!(
            "the poses already stored no longer validate with this robot and rig: {message}"
        )),
        other => other.into(),
    })
}

/// The session's poses as one CSV (DATA_FORMAT.md poses.csv).
#[utoipa::path(get, path = "/sessions/{id}/poses", tag = "sessions",
    params(("id" = i64, Path, description = "Session id")),
    responses(
        (status = 200, description = "poses.csv", body = String, content_type = "text/csv"),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such session", body = ErrorBody)))]
pub async fn get_poses(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
) -> ApiResult<Response> {
    let session = app.store.get_session(id).await?;
    caller.check_robot(&app, session.robot_id).await?;
    let batches = app.store.pose_batches(id).await?;
    let text = match &session.columns {
        Some(c) => session_csv(c, &batches),
        None => String::new(),
    };
    Ok(([(CONTENT_TYPE, "text/csv")], text).into_response())
}

/// Queue an identification of the session's poses. Answers at once with
/// the job; poll `GET /jobs/{id}`.
#[utoipa::path(post, path = "/sessions/{id}/jobs", tag = "jobs",
    params(("id" = i64, Path, description = "Session id")),
    request_body(content = Option<JobOptions>, content_type = "application/json", description = "Options (optional; an empty body takes the defaults)"),
    responses(
        (status = 202, description = "Queued", body = JobRec, headers(("Location" = String, description = "The job's URL"))),
        (status = 400, description = "Malformed JSON or bad id", body = ErrorBody),
        (status = 404, description = "No such session", body = ErrorBody),
        (status = 408, description = BODY_TIMEOUT_408, body = ErrorBody),
        (status = 413, description = BODY_TOO_LARGE_413, body = ErrorBody),
        (status = 409, description = "The session's stored model or rig no longer passes validation (stored by an earlier version)", body = ErrorBody),
        (status = 429, description = "The key is over its jobs a minute (`--max-jobs-per-minute`), or the queue is full (`--max-queued-jobs`): error `too_many_requests`, `Retry-After` in seconds", body = ErrorBody, headers(("Retry-After" = u64, description = "Seconds until a retry can succeed"))),
        (status = 415, description = "Body not JSON", body = ErrorBody),
        (status = 422, description = "Bad options, or the session has no poses", body = ErrorBody)))]
pub async fn enqueue_job(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
    body: RawBody,
) -> ApiResult<Response> {
    let options: JobOptions = if body.bytes.iter().all(u8::is_ascii_whitespace) {
        JobOptions::default()
    } else if is_json(body.content_type.as_deref()) {
        // serde reads a struct from an array too (`[]` as all defaults):
        // the options are an object (or null), as documented.
        let first = without_bom(&body.bytes)
            .iter()
            .find(|b| !b.is_ascii_whitespace());
        if first == Some(&b'[') {
            return Err(ApiError::Invalid {
                message: "job options are a JSON object (or null), not an array".into(),
                field: None,
                row: None,
            });
        }
        parse_json::<Option<JobOptions>>(&body.bytes)?.unwrap_or_default()
    } else {
        return Err(ApiError::UnsupportedMediaType(
            "job options are JSON (application/json)".into(),
        ));
    };
    options
        .validate()
        .map_err(|(f, m)| ApiError::invalid(f, m))?;
    let session = app.store.get_session(id).await?;
    caller.check_robot(&app, session.robot_id).await?;
    if session.n_poses == 0 {
        return Err(ApiError::Invalid {
            message: format!("session {id} has no poses: upload some first"),
            field: None,
            row: None,
        });
    }
    // Refused now rather than failing in the worker: a model or rig stored
    // by an earlier version that today's checks refuse is the client's to
    // replace (409), as on upload.
    let (robot, rig) = robot_and_rig(&app, &session).await?;
    // Held parameters name this robot's joints: checked now, not in the
    // worker.
    let layout = crate::kinematics::Layout {
        n_joints: robot.dof(),
        n_strings: rig.n_strings(),
    };
    crate::identify::held(layout, &options.to_identify())?;
    // Counted after the request is known good: a refused request costs
    // the key nothing.
    app.limits.take(&caller.name, Action::Job)?;
    queue_has_room(&app).await?;
    let opts = serde_json::to_string(&options).map_err(|e| ApiError::Internal(e.to_string()))?;
    let job = app
        .store
        .create_job(id, session.robot_id, &opts, app.jobs.max_attempts())
        .await?;
    app.jobs.wake();
    app.store
        .audit(
            &caller.name,
            "enqueue_job",
            &format!("job {}", job.id),
            &format!("session {id}"),
        )
        .await?;
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&format!("/jobs/{}", job.id)) {
        headers.insert(LOCATION, v);
    }
    Ok((StatusCode::ACCEPTED, headers, Json(job)).into_response())
}

/// Job list filters.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct JobFilter {
    /// Only this session's jobs.
    pub session_id: Option<i64>,
    /// Only jobs in this state (`queued`, `running`, `succeeded`, `failed`, `cancelled`).
    #[param(pattern = "^(queued|running|succeeded|failed|cancelled)$")]
    pub state: Option<String>,
}

/// List jobs.
#[utoipa::path(get, path = "/jobs", tag = "jobs", params(JobFilter, PageParams),
    responses(
        (status = 200, description = "A page", body = Paged<JobRec>),
        (status = 400, description = "Bad query", body = ErrorBody),
        (status = 422, description = "Bad page or state", body = ErrorBody)))]
pub async fn list_jobs(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    ApiQuery(f): ApiQuery<JobFilter>,
    ApiQuery(p): ApiQuery<PageParams>,
) -> ApiResult<Json<Paged<JobRec>>> {
    let page = p.page()?;
    match f.session_id {
        Some(s) if !caller.sites.is_empty() => {
            let session = app.store.get_session(s).await?;
            caller.check_robot(&app, session.robot_id).await?;
        }
        Some(_) => {}
        None => caller.check_unlimited("the list of jobs without session_id")?,
    }
    if let Some(s) = &f.state {
        if !["queued", "running", "succeeded", "failed", "cancelled"].contains(&s.as_str()) {
            return Err(ApiError::invalid("state", format!("unknown state '{s}'")));
        }
    }
    let (items, total) = app
        .store
        .list_jobs(f.session_id, f.state.as_deref(), page)
        .await?;
    Ok(Json(Paged::new(items, total, page)))
}

/// One job: state, stage, progress, error, and the calibration it made.
#[utoipa::path(get, path = "/jobs/{id}", tag = "jobs",
    params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "The job", body = JobRec),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such job", body = ErrorBody)))]
pub async fn get_job(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
) -> ApiResult<Json<JobRec>> {
    let job = app.store.get_job(id).await?;
    caller.check_robot(&app, job.robot_id).await?;
    Ok(Json(job))
}

/// Cancel a job: a queued one at once, a running one at the engine's next
/// check.
#[utoipa::path(post, path = "/jobs/{id}/cancel", tag = "jobs",
    params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 202, description = "Cancelled or cancellation requested", body = JobRec),
        (status = 400, description = "Bad id", body = ErrorBody),
        (status = 404, description = "No such job", body = ErrorBody),
        (status = 409, description = "The job has already ended", body = ErrorBody)))]
pub async fn cancel_job(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
) -> ApiResult<(StatusCode, Json<JobRec>)> {
    let robot_id = app.store.get_job(id).await?.robot_id;
    caller.check_robot(&app, robot_id).await?;
    let job = app.store.request_cancel(id).await?;
    app.store
        .audit(&caller.name, "cancel_job", &format!("job {id}"), "")
        .await?;
    Ok((StatusCode::ACCEPTED, Json(job)))
}
