//! The HTTP layer's one error type and its one mapping to responses.
//!
//! Every failure a handler can have becomes an [`ApiError`]; its
//! [`IntoResponse`] is the only place statuses are chosen. The body is always
//! `{ "error": code, "message": ..., "field"?: ..., "row"?: ... }`. Server-side
//! failures (database down, engine panic) are logged with their detail and
//! answered with a generic message.

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use thiserror::Error;
use utoipa::ToSchema;

use crate::store::StoreError;

/// OpenAPI description of the 408 of every route that reads a body.
pub const BODY_TIMEOUT_408: &str = "The body stopped arriving for longer than the client timeout, or did not all arrive within ten times it (`drawcal serve --client-timeout-secs`, environment `DRAWCAL_CLIENT_TIMEOUT_SECS`; default 30 s): error `request_timeout`; nothing is stored";

/// OpenAPI description of the 413 of every route that reads a body.
pub const BODY_TOO_LARGE_413: &str = "Body larger than the service accepts (`drawcal serve --max-upload-bytes`, environment `DRAWCAL_MAX_UPLOAD_BYTES`; default 16 MiB): error `payload_too_large`, whose message gives the limit in bytes and says how to raise it";

/// The error body of every 4xx and 5xx answer.
#[derive(Debug, Serialize, ToSchema)]
pub struct ErrorBody {
    /// Machine-readable code: `bad_request`, `malformed_json`,
    /// `invalid_input`, `not_found`, `conflict`, `payload_too_large`,
    /// `request_timeout`, `unsupported_media_type`, `method_not_allowed`,
    /// `unauthorized`, `forbidden`, `host_not_allowed`, `too_many_requests`,
    /// `uri_too_long`, `header_too_large`, `unavailable`, `internal`.
    pub error: String,
    /// What went wrong, for a human.
    pub message: String,
    /// The offending field or CSV column, where there is one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// The offending row (1-based, header excluded; for JSON arrays the
    /// 1-based element), where there is one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub row: Option<usize>,
}

/// Everything a request can fail with.
#[derive(Debug, Error)]
pub enum ApiError {
    /// A query string or path that cannot be parsed.
    #[error("{0}")]
    BadRequest(String),
    /// A body that is not JSON at all.
    #[error("{0}")]
    MalformedJson(String),
    /// Well-formed input that breaks a rule (wrong type, out of range, bad
    /// CSV cell...).
    #[error("{message}")]
    Invalid {
        /// What is wrong.
        message: String,
        /// Field or column.
        field: Option<String>,
        /// 1-based row.
        row: Option<usize>,
    },
    /// No API key, or one that is unknown, expired or revoked.
    #[error("{0}")]
    Unauthorized(String),
    /// A key whose role does not allow the route.
    #[error("{0}")]
    Forbidden(String),
    /// No such resource.
    #[error("{0}")]
    NotFound(String),
    /// The request contradicts the current state.
    #[error("{0}")]
    Conflict(String),
    /// Body over the limit.
    #[error("{0}")]
    PayloadTooLarge(String),
    /// The client stopped sending its body, or took too long over it.
    #[error("{0}")]
    RequestTimeout(String),
    /// Wrong or missing `Content-Type`.
    #[error("{0}")]
    UnsupportedMediaType(String),
    /// A `Host` header the service does not answer to (`--allowed-host`):
    /// a DNS-rebinding page, or a name not configured.
    #[error("{0}")]
    HostNotAllowed(String),
    /// Over a per-key rate or the job queue's bound: retry after
    /// `retry_after_s` seconds (the `Retry-After` header).
    #[error("{message}")]
    TooManyRequests {
        /// Which limit, and how to stay under it.
        message: String,
        /// Seconds until a retry can succeed.
        retry_after_s: u64,
    },
    /// Method not allowed on this path.
    #[error("method not allowed")]
    MethodNotAllowed,
    /// A request target longer than HTTP/1.1 parsing takes (found by the
    /// connection layer, [`super::conn::JsonParseErrors`]).
    #[error("{0}")]
    UriTooLong(String),
    /// A request header section over the connection's buffer or its field
    /// count (found by the connection layer).
    #[error("{0}")]
    HeaderTooLarge(String),
    /// A dependency (the database) is not answering.
    #[error("{0}")]
    Unavailable(String),
    /// A bug or an unexpected failure; the detail is logged, not returned.
    #[error("{0}")]
    Internal(String),
}

impl ApiError {
    /// An invalid field without a row.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        ApiError::Invalid {
            message: message.into(),
            field: Some(field.into()),
            row: None,
        }
    }

    /// Status and code, in one place.
    pub fn status_code(&self) -> (StatusCode, &'static str) {
        match self {
            ApiError::BadRequest(_) => (StatusCode::BAD_REQUEST, "bad_request"),
            ApiError::MalformedJson(_) => (StatusCode::BAD_REQUEST, "malformed_json"),
            ApiError::Invalid { .. } => (StatusCode::UNPROCESSABLE_ENTITY, "invalid_input"),
            ApiError::Unauthorized(_) => (StatusCode::UNAUTHORIZED, "unauthorized"),
            ApiError::Forbidden(_) => (StatusCode::FORBIDDEN, "forbidden"),
            ApiError::NotFound(_) => (StatusCode::NOT_FOUND, "not_found"),
            ApiError::Conflict(_) => (StatusCode::CONFLICT, "conflict"),
            ApiError::PayloadTooLarge(_) => (StatusCode::PAYLOAD_TOO_LARGE, "payload_too_large"),
            ApiError::RequestTimeout(_) => (StatusCode::REQUEST_TIMEOUT, "request_timeout"),
            ApiError::UnsupportedMediaType(_) => {
                (StatusCode::UNSUPPORTED_MEDIA_TYPE, "unsupported_media_type")
            }
            ApiError::HostNotAllowed(_) => (StatusCode::MISDIRECTED_REQUEST, "host_not_allowed"),
            ApiError::TooManyRequests { .. } => {
                (StatusCode::TOO_MANY_REQUESTS, "too_many_requests")
            }
            ApiError::MethodNotAllowed => (StatusCode::METHOD_NOT_ALLOWED, "method_not_allowed"),
            ApiError::UriTooLong(_) => (StatusCode::URI_TOO_LONG, "uri_too_long"),
            ApiError::HeaderTooLarge(_) => (
                StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
                "header_too_large",
            ),
            ApiError::Unavailable(_) => (StatusCode::SERVICE_UNAVAILABLE, "unavailable"),
            ApiError::Internal(_) => (StatusCode::INTERNAL_SERVER_ERROR, "internal"),
        }
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::NotFound { .. } => ApiError::NotFound(e.to_string()),
            StoreError::Conflict(m) => ApiError::Conflict(m),
            StoreError::Db(
                sqlx::Error::PoolTimedOut | sqlx::Error::PoolClosed | sqlx::Error::Io(_),
            ) => ApiError::Unavailable("the database is not answering".into()),
            other => ApiError::Internal(other.to_string()),
        }
    }
}

impl From<crate::Error> for ApiError {
    fn from(e: crate::Error) -> Self {
        match e {
            crate::Error::Input {
                field,
                row,
                message,
            } => ApiError::Invalid {
                message,
                field,
                row,
            },
            crate::Error::InsufficientData(m) => ApiError::Invalid {
                message: format!("insufficient data: {m}"),
                field: None,
                row: None,
            },
            crate::Error::Numerical(m) => ApiError::Invalid {
                message: format!("numerical failure: {m}"),
                field: None,
                row: None,
            },
            crate::Error::Cancelled => ApiError::Conflict("cancelled".into()),
        }
    }
}

impl ApiError {
    /// The JSON body of this error (an internal error's detail is not in it).
    pub fn body(&self) -> ErrorBody {
        let (_, code) = self.status_code();
        let message = match self {
            ApiError::Internal(_) => "internal error; see the server log".to_string(),
            other => other.to_string(),
        };
        let (field, row) = match self {
            ApiError::Invalid { field, row, .. } => (field.clone(), *row),
            _ => (None, None),
        };
        ErrorBody {
            error: code.to_string(),
            message,
            field,
            row,
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let (status, _) = self.status_code();
        match &self {
            ApiError::Internal(detail) => tracing::error!(error = %detail, "internal error"),
            ApiError::Unavailable(detail) => tracing::warn!(error = %detail, "unavailable"),
            _ => {}
        }
        let body = self.body();
        let mut response = (status, axum::Json(body)).into_response();
        if let ApiError::TooManyRequests { retry_after_s, .. } = &self {
            response.headers_mut().insert(
                axum::http::header::RETRY_AFTER,
                axum::http::HeaderValue::from(*retry_after_s),
            );
        }
        if matches!(
            self,
            ApiError::RequestTimeout(_) | ApiError::PayloadTooLarge(_)
        ) {
            // The rest of the body is not read, so the connection cannot
            // carry another request: say it closes (RFC 9110, 408).
            response.headers_mut().insert(
                axum::http::header::CONNECTION,
                axum::http::HeaderValue::from_static("close"),
            );
        }
        response
    }
}
