//! Key management and the audit log (admin): create a key (its secret is in
//! this answer only), list keys without their secrets, revoke one; who did
//! what and when, as JSON or CSV.

use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::auth::{Caller, Role, new_secret};
use super::calibrations::{Format, csv_table, text_cell};
use super::error::{ApiError, ErrorBody};
use super::extract::{ApiJson, ApiQuery, Id};
use super::{ApiResult, AppState, PageParams, Paged};
use crate::store::{AuditRec, KeyRec, NewKey, Store};

/// A key to create.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateKey {
    /// Who will hold it (1 to 100 characters, unique): what it does is
    /// recorded under this name. Trimmed; not blank.
    #[schema(min_length = 1, max_length = 100)]
    pub name: String,
    /// `reader`, `operator`, `engineer` or `admin`.
    pub role: String,
    /// When it stops working (RFC 3339, e.g. `2027-06-30T00:00:00Z`);
    /// never when absent.
    #[serde(default)]
    pub expires_at: Option<String>,
    /// The sites it is limited to (robots' `site`); every site when absent
    /// or empty. Not for admin keys.
    #[serde(default)]
    pub sites: Vec<String>,
}

/// A created key: the stored record and the key itself, shown this once.
#[derive(Debug, Serialize, ToSchema)]
pub struct CreatedKey {
    /// The key as stored (without its secret).
    pub key: KeyRec,
    /// The key to send as `Authorization: Bearer <secret>`; not stored,
    /// not shown again.
    pub secret: String,
}

/// Create a key and record who did (the same checks as `drawcal keys
/// create`).
pub async fn create(
    store: &Store,
    actor: &str,
    name: &str,
    role: &str,
    expires_at: Option<String>,
    sites: &[String],
) -> ApiResult<CreatedKey> {
    if name.trim().is_empty() || name.chars().count() > 100 {
        return Err(ApiError::invalid("name", "1 to 100 characters"));
    }
    let name = name.trim();
    let role: Role = role
        .parse()
        .map_err(|m: String| ApiError::invalid("role", m))?;
    // Stored as the store writes times, so that it compares as text.
    let expires_at = match expires_at {
        Some(at) => Some(
            crate::store::time::normalize_bound(&at, false).ok_or_else(|| {
                ApiError::invalid(
                    "expires_at",
                    "a date (2027-06-30) or an RFC 3339 time (2027-06-30T00:00:00Z)",
                )
            })?,
        ),
        None => None,
    };
    let mut limited: Vec<String> = Vec::new();
    for raw in sites {
        let s = raw.trim();
        if s.is_empty()
            || raw.chars().count() > 100
            || s.contains(',')
            || s.chars().any(char::is_control)
        {
            return Err(ApiError::invalid(
                "sites",
                format!(
                    "a site is 1 to 100 characters without commas or control characters, got {s:?}"
                ),
            ));
        }
        if !limited.iter().any(|l| l == s) {
            limited.push(s.to_string());
        }
    }
    if role == Role::Admin && !limited.is_empty() {
        return Err(ApiError::invalid(
            "sites",
            "an admin key manages every key and the audit log: it is not limited to sites",
        ));
    }
    let fresh = new_secret().map_err(ApiError::Internal)?;
    let key = store
        .create_key(
            &NewKey {
                name: name.to_string(),
                role: role.as_str().to_string(),
                sites: limited.join(","),
                prefix: fresh.prefix,
                secret_hash: fresh.hash,
                expires_at,
            },
            actor,
        )
        .await?;
    Ok(CreatedKey {
        key,
        secret: fresh.secret,
    })
}

/// Make sure the admin key `secret` exists (a deployment's first key, from
/// the environment): created, named `bootstrap-admin-<prefix>`, unless a
/// key already has it; refused when shorter than 32 characters or revoked.
pub async fn ensure_admin(
    store: &Store,
    secret: &str,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    if secret.chars().count() < 32 {
        return Err("the bootstrap admin key must have at least 32 characters \
                    (drawcal keys create prints one)"
            .into());
    }
    let hash = super::auth::hash(secret);
    match store.key_by_hash(&hash).await? {
        Some(k) if k.revoked_at.is_some() => {
            Err(format!("the bootstrap admin key ('{}') was revoked", k.name).into())
        }
        Some(_) => Ok(()),
        None => {
            let prefix: String = secret.chars().take(12).collect();
            let key = store
                .create_key(
                    &NewKey {
                        name: format!("bootstrap-admin-{prefix}"),
                        role: Role::Admin.as_str().into(),
                        sites: String::new(),
                        prefix,
                        secret_hash: hash,
                        expires_at: None,
                    },
                    "service start (DRAWCAL_ADMIN_KEY)",
                )
                .await?;
            tracing::info!(key = %key.name, "bootstrap admin key created");
            Ok(())
        }
    }
}

/// Create an API key; its secret is in this answer only.
#[utoipa::path(post, path = "/keys", tag = "keys",
    request_body = CreateKey,
    responses(
        (status = 201, description = "Created", body = CreatedKey),
        (status = 401, description = "No valid key", body = ErrorBody),
        (status = 403, description = "Not an admin key", body = ErrorBody),
        (status = 409, description = "Name taken", body = ErrorBody),
        (status = 422, description = "Bad name, role or expiry", body = ErrorBody)))]
pub async fn create_key(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    ApiJson(k): ApiJson<CreateKey>,
) -> ApiResult<(StatusCode, Json<CreatedKey>)> {
    let created = create(
        &app.store,
        &caller.name,
        &k.name,
        &k.role,
        k.expires_at,
        &k.sites,
    )
    .await?;
    app.keys.clear();
    Ok((StatusCode::CREATED, Json(created)))
}

/// Every key, without its secret.
#[utoipa::path(get, path = "/keys", tag = "keys",
    responses(
        (status = 200, description = "Keys, oldest first", body = Vec<KeyRec>),
        (status = 401, description = "No valid key", body = ErrorBody),
        (status = 403, description = "Not an admin key", body = ErrorBody)))]
pub async fn list_keys(State(app): State<AppState>) -> ApiResult<Json<Vec<KeyRec>>> {
    Ok(Json(app.store.list_keys().await?))
}

/// Revoke a key: from now on it is refused (401).
#[utoipa::path(post, path = "/keys/{id}/revoke", tag = "keys",
    params(("id" = i64, Path, description = "Key id")),
    responses(
        (status = 200, description = "Revoked", body = KeyRec),
        (status = 401, description = "No valid key", body = ErrorBody),
        (status = 403, description = "Not an admin key", body = ErrorBody),
        (status = 404, description = "No such key", body = ErrorBody)))]
pub async fn revoke_key(
    State(app): State<AppState>,
    Extension(caller): Extension<Caller>,
    Id(id): Id,
) -> ApiResult<Json<KeyRec>> {
    let key = app.store.revoke_key(id, &caller.name).await?;
    app.keys.clear();
    Ok(Json(key))
}

/// Audit query.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct AuditParams {
    /// Items per page, 1..=1000 (default 50; JSON only).
    #[param(minimum = 1, maximum = 1000)]
    pub limit: Option<i64>,
    /// Items to skip (default 0; JSON only).
    #[param(minimum = 0, maximum = 9223372036854775807_i64)]
    pub offset: Option<i64>,
    /// `json` (default) or `csv` (every entry).
    pub format: Option<Format>,
}

/// Who did what and when, newest first: activations, rollbacks, job
/// enqueues and cancels, uploads, key changes.
#[utoipa::path(get, path = "/audit", tag = "keys",
    params(AuditParams),
    responses(
        (status = 200, description = "Audit log", content((Paged<AuditRec> = "application/json"), (String = "text/csv"))),
        (status = 400, description = "Bad query", body = ErrorBody),
        (status = 401, description = "No valid key", body = ErrorBody),
        (status = 403, description = "Not an admin key", body = ErrorBody)))]
pub async fn list_audit(
    State(app): State<AppState>,
    ApiQuery(q): ApiQuery<AuditParams>,
) -> ApiResult<Response> {
    // Checked whatever the format (CSV has every entry).
    let page = PageParams {
        limit: q.limit,
        offset: q.offset,
    }
    .page()?;
    if q.format == Some(Format::Csv) {
        let (rows, _) = app
            .store
            .list_audit(crate::store::Page {
                limit: i64::MAX / 2,
                offset: 0,
            })
            .await?;
        return csv_table(
            &["id", "at", "actor", "action", "target", "detail"],
            rows.into_iter().map(|r| {
                vec![
                    r.id.to_string(),
                    r.at,
                    text_cell(&r.actor),
                    r.action,
                    r.target,
                    text_cell(&r.detail),
                ]
            }),
        );
    }
    let (items, total) = app.store.list_audit(page).await?;
    Ok(Json(Paged::new(items, total, page)).into_response())
}
