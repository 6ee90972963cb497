//! Extractors whose rejections are [`ApiError`]s, so every malformed
//! request is answered in the one error shape.

use std::future::poll_fn;
use std::pin::pin;
use std::task::Poll;
use std::time::Duration;

use axum::body::{Body, Bytes, HttpBody};
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::header::CONTENT_TYPE;
use axum::http::request::Parts;
use serde::de::DeserializeOwned;

use super::error::ApiError;

/// How the service reads request bodies (`drawcal serve --max-upload-bytes`
/// and `--client-timeout-secs`), put into every request's extensions by
/// [`super::router`]: the 413 and 408 answers say what the limit is and
/// how to change it.
#[derive(Debug, Clone, Copy)]
pub struct BodyPolicy {
    /// Largest accepted request body (bytes).
    pub max_upload_bytes: usize,
    /// Longest pause allowed while the body arrives.
    pub idle_timeout: Duration,
    /// Longest the whole body may take to arrive.
    pub deadline: Duration,
}

impl BodyPolicy {
    /// The message of the 413 answer to a request on `path`: the limit,
    /// how to raise it, and how to split what that route takes.
    pub fn too_large_message(&self, path: &str) -> String {
        let split = if path.ends_with("/poses") {
            "send the poses in several batches (each POST to /sessions/{id}/poses appends)"
        } else if path == "/compensate" {
            "split the targets over several requests"
        } else {
            "send a smaller body"
        };
        format!(
            "request body too large: the service accepts at most {} bytes ({}) per request; raise the limit by starting it with a larger --max-upload-bytes (environment DRAWCAL_MAX_UPLOAD_BYTES), or {split}",
            self.max_upload_bytes,
            human_bytes(self.max_upload_bytes)
        )
    }
}

/// A byte count in MiB or KiB (two decimals at most).
fn human_bytes(n: usize) -> String {
    let (value, unit) = if n >= 1 << 20 {
        (n as f64 / (1u64 << 20) as f64, "MiB")
    } else if n >= 1 << 10 {
        (n as f64 / 1024.0, "KiB")
    } else {
        return format!("{n} B");
    };
    let text = format!("{value:.2}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    format!("{text} {unit}")
}

/// The request body as bytes, with the body limit answered as 413.
pub struct RawBody {
    /// `Content-Type` (lower case, parameters dropped), if any.
    pub content_type: Option<String>,
    /// The body.
    pub bytes: Bytes,
}

impl<S: Send + Sync> FromRequest<S> for RawBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, _state: &S) -> Result<Self, Self::Rejection> {
        let content_type = req
            .headers()
            .get(CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .map(|v| {
                v.split(';')
                    .next()
                    .unwrap_or("")
                    .trim()
                    .to_ascii_lowercase()
            });
        // The router puts the policy into every request.
        let policy = req
            .extensions()
            .get::<BodyPolicy>()
            .copied()
            .ok_or_else(|| ApiError::Internal("no body policy on the request".into()))?;
        let path = req.uri().path().to_owned();
        let bytes = read_body(req.into_body(), &policy, &path).await?;
        Ok(RawBody {
            content_type,
            bytes,
        })
    }
}

/// Read a whole body under `policy`: over the size limit is 413 (at once
/// when `Content-Length` says so, before a byte of the body is read, so a
/// client that sent `Expect: 100-continue` need not send it), a pause
/// longer than the idle timeout or a body slower than the deadline is 408.
///
/// Ours rather than a timeout middleware: a timer is armed only while the
/// body is actually waited for, so the usual small body that arrives with
/// its headers costs no timer at all (tower-http's body timeouts cost the
/// single-target `/compensate` about 9% of its throughput).
async fn read_body(body: Body, policy: &BodyPolicy, path: &str) -> Result<Bytes, ApiError> {
    let too_large = || ApiError::PayloadTooLarge(policy.too_large_message(path));
    let timed_out = || {
        ApiError::RequestTimeout(
            "the request body stopped arriving or took too long \
             (drawcal serve --client-timeout-secs)"
                .into(),
        )
    };
    // The declared length (Content-Length), if any; within the limit here.
    let declared = body.size_hint().lower();
    if declared > policy.max_upload_bytes as u64 {
        return Err(too_large());
    }
    let deadline = tokio::time::Instant::now() + policy.deadline;
    let mut body = pin!(body);
    let mut first: Option<Bytes> = None;
    let mut rest: Vec<u8> = Vec::new();
    let mut len = 0usize;
    loop {
        // A frame that is already here needs no timer.
        let frame = match poll_fn(|cx| Poll::Ready(body.as_mut().poll_frame(cx))).await {
            Poll::Ready(frame) => frame,
            Poll::Pending => {
                let wake = deadline.min(tokio::time::Instant::now() + policy.idle_timeout);
                tokio::time::timeout_at(wake, poll_fn(|cx| body.as_mut().poll_frame(cx)))
                    .await
                    .map_err(|_| timed_out())?
            }
        };
        let Some(frame) = frame else { break };
        let frame = frame.map_err(|e| ApiError::BadRequest(format!("reading the body: {e}")))?;
        let Ok(data) = frame.into_data() else {
            continue; // trailers
        };
        len += data.len();
        if len > policy.max_upload_bytes {
            return Err(too_large());
        }
        // One frame (the usual case) is kept as it came, without a copy.
        match &first {
            None if rest.is_empty() => first = Some(data),
            _ => {
                if let Some(f) = first.take() {
                    rest.reserve(declared as usize);
                    rest.extend_from_slice(&f);
                }
                rest.extend_from_slice(&data);
            }
        }
    }
    Ok(first.unwrap_or_else(|| Bytes::from(rest)))
}

/// Is this a JSON media type?
pub fn is_json(ct: Option<&str>) -> bool {
    matches!(ct, Some(c) if c == "application/json" || c.ends_with("+json"))
}

/// `bytes` without a leading UTF-8 byte-order mark (a file saved by a
/// Windows editor and posted as is): it is not part of the document.
pub fn without_bom(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes)
}

/// Parse JSON bytes: syntax errors are 400 `malformed_json`, type and
/// shape errors 422 `invalid_input` naming the field path (a struct given
/// as an array among them, at any depth).
pub fn parse_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let bytes = without_bom(bytes);
    // JSON writes a control character only as an escape (`\u0000`, `\n`;
    // a raw one is a syntax error): rare, so only a body that has one is
    // walked.
    if has_control_escape(bytes)
        && let Ok(v) = serde_json::from_slice::<serde_json::Value>(bytes)
        && let Some(field) = control_path(&v, String::new())
    {
        return Err(ApiError::Invalid {
            message: CONTROL_MESSAGE.into(),
            field: Some(field),
            row: None,
        });
    }
    // The common case in one pass; only a failed parse pays for the
    // classification below (it is on the /compensate hot path). Structs
    // are read from objects only ([`super::strict`]).
    if let Ok(v) = super::strict::from_slice::<T>(bytes) {
        return Ok(v);
    }
    // Syntax first, so that a truncated document is always "malformed" even
    // when its beginning already has the wrong shape.
    if let Err(e) = serde_json::from_slice::<serde::de::IgnoredAny>(bytes) {
        return Err(ApiError::MalformedJson(format!("malformed JSON: {e}")));
    }
    let de = &mut serde_json::Deserializer::from_slice(bytes);
    match serde_path_to_error::deserialize::<_, T>(super::strict::Strict(de)) {
        Ok(v) => Ok(v),
        Err(e) => {
            let path = e.path().to_string();
            let inner = e.into_inner();
            use serde_json::error::Category;
            // A field missing at the top level has the path "."; serde's
            // message names it.
            let field = (path != "." && !path.is_empty())
                .then_some(path)
                .or_else(|| {
                    let m = inner.to_string();
                    let rest = m.strip_prefix("missing field `")?;
                    Some(rest[..rest.find('`')?].to_string())
                });
            match inner.classify() {
                Category::Io => Err(ApiError::MalformedJson(format!("malformed JSON: {inner}"))),
                // The syntax pass above succeeded, so a "syntax" error here
                // is the shape: a fixed-length array (a point, an angle
                // triple) given more elements than it has, or a number
                // past f64 (1e999) where a number is read.
                Category::Syntax | Category::Eof => Err(ApiError::Invalid {
                    message: if inner.to_string().starts_with("number out of range") {
                        format!("not a finite number ({inner})")
                    } else {
                        format!("more elements than expected ({inner})")
                    },
                    field,
                    row: None,
                }),
                Category::Data => Err(ApiError::Invalid {
                    message: crate::model::with_key_hint(&inner.to_string()),
                    field,
                    row: None,
                }),
            }
        }
    }
}

/// Parse a JSON body that must be an object, as every struct body is
/// documented: serde also reads a struct from an array (`["SN", 1]` as
/// its fields in order, `[]` as all defaults), which no route takes.
pub fn parse_json_object<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let first = without_bom(bytes).iter().find(|b| !b.is_ascii_whitespace());
    // Malformed JSON stays malformed (400), whatever it begins with.
    if first == Some(&b'[')
        && serde_json::from_slice::<serde::de::IgnoredAny>(without_bom(bytes)).is_ok()
    {
        return Err(ApiError::Invalid {
            message: "the body is a JSON object ({ ... }), not an array".into(),
            field: None,
            row: None,
        });
    }
    parse_json(bytes)
}

/// Why a text with a control character is refused.
const CONTROL_MESSAGE: &str =
    "contains a control character (a NUL, a line break, a tab...), which no text field accepts";

/// True when JSON text `bytes` may hold a control character: an escape
/// that writes one (`\u0000`-`\u009f`, `\n`, `\t`...), or a C1 control
/// written raw (UTF-8 `C2 80`-`C2 9F`, which JSON allows).
fn has_control_escape(bytes: &[u8]) -> bool {
    bytes.windows(2).enumerate().any(|(i, w)| {
        (w[0] == 0xC2 && (0x80..=0x9F).contains(&w[1]))
            || (w[0] == b'\\'
                && (matches!(w[1], b'b' | b'f' | b'n' | b'r' | b't')
                    || (w[1] == b'u' && bytes.get(i + 2..i + 4).is_some_and(|h| h == b"00"))))
    })
}

/// The path (`a.b[2]`) of the first string of `v` holding a control
/// character, or of the object key that does.
fn control_path(v: &serde_json::Value, at: String) -> Option<String> {
    use serde_json::Value;
    let control = |s: &str| s.chars().any(char::is_control);
    match v {
        Value::String(s) if control(s) => Some(if at.is_empty() { ".".into() } else { at }),
        Value::Array(a) => a
            .iter()
            .enumerate()
            .find_map(|(i, x)| control_path(x, format!("{at}[{i}]"))),
        Value::Object(m) => m.iter().find_map(|(k, x)| {
            let here = if at.is_empty() {
                k.clone()
            } else {
                format!("{at}.{k}")
            };
            if control(k) {
                return Some(here);
            }
            control_path(x, here)
        }),
        _ => None,
    }
}

/// The name (decoded) of the first query parameter whose name or value
/// holds a control character once percent-decoded: C0 and DEL
/// (`%00`-`%1F`, `%7F`) and C1 (`%C2%80`-`%C2%9F`), as in JSON bodies.
/// Only a query with an escape that may write one is decoded.
fn query_control(query: &str) -> Option<String> {
    let b = query.as_bytes();
    let may = b.windows(3).any(|w| {
        w[0] == b'%'
            && (matches!(w[1], b'0' | b'1')
                || (w[1] == b'7' && matches!(w[2], b'f' | b'F'))
                || (matches!(w[1], b'c' | b'C') && w[2] == b'2'))
    });
    if !may {
        return None;
    }
    let decode = |s: &str| {
        let s = s.replace('+', " ");
        percent_decode(&s)
    };
    query.split('&').find_map(|pair| {
        let (name, value) = pair.split_once('=').unwrap_or((pair, ""));
        let (name, value) = (decode(name), decode(value));
        (name.chars().any(char::is_control) || value.chars().any(char::is_control)).then_some(name)
    })
}

/// `%XX` escapes decoded (invalid UTF-8 replaced, an incomplete escape
/// kept as it is).
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match (
            b[i],
            b.get(i + 1).copied().and_then(hex),
            b.get(i + 2).copied().and_then(hex),
        ) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (c, _, _) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// A JSON body (`Content-Type: application/json` required).
pub struct ApiJson<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned> FromRequest<S> for ApiJson<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        let body = RawBody::from_request(req, state).await?;
        if !is_json(body.content_type.as_deref()) {
            return Err(ApiError::UnsupportedMediaType(format!(
                "expected Content-Type: application/json, got {}",
                body.content_type.as_deref().unwrap_or("none")
            )));
        }
        parse_json_object(&body.bytes).map(ApiJson)
    }
}

/// The numeric id in the path.
pub struct Id(pub i64);

impl<S: Send + Sync> FromRequestParts<S> for Id {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        let axum::extract::Path(raw) =
            axum::extract::Path::<String>::from_request_parts(parts, state)
                .await
                .map_err(|r| ApiError::BadRequest(r.body_text()))?;
        // Digits only: `+1` or ` 1` is not the id 1.
        raw.bytes()
            .all(|b| b.is_ascii_digit())
            .then(|| raw.parse::<i64>().ok())
            .flatten()
            .map(Id)
            .ok_or_else(|| ApiError::BadRequest(format!("'{raw}' is not a valid id (an integer)")))
    }
}

/// A query string.
pub struct ApiQuery<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned> FromRequestParts<S> for ApiQuery<T> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        let query = parts.uri.query().unwrap_or("");
        if let Some(name) = query_control(query) {
            return Err(ApiError::Invalid {
                message: CONTROL_MESSAGE.into(),
                field: Some(name),
                row: None,
            });
        }
        axum::extract::Query::<T>::from_request_parts(parts, state)
            .await
            .map(|q| ApiQuery(q.0))
            .map_err(|r| ApiError::BadRequest(r.body_text()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_too_long_fixed_array_is_invalid_input_naming_the_field() {
        #[derive(serde::Deserialize, Debug)]
        struct T {
            #[allow(dead_code)]
            xyz_mm: [f64; 3],
        }
        match parse_json::<T>(br#"{"xyz_mm": [1, 2, 3, 4]}"#) {
            Err(ApiError::Invalid { field, message, .. }) => {
                assert_eq!(field.as_deref(), Some("xyz_mm"));
                assert!(message.contains("more elements than expected"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        // Real syntax errors stay malformed JSON.
        assert!(matches!(
            parse_json::<T>(br#"{"xyz_mm": [1, 2, 3"#),
            Err(ApiError::MalformedJson(_))
        ));
    }

    #[test]
    fn a_struct_body_given_as_an_array_is_refused() {
        #[derive(serde::Deserialize, Debug)]
        struct T {
            #[allow(dead_code)]
            serial_number: String,
            #[allow(dead_code)]
            model_id: i64,
        }
        // serde alone reads the array as the struct.
        assert!(serde_json::from_str::<T>(r#"["SN", 1]"#).is_ok());
        for body in [
            &br#"["SN", 1]"#[..],
            &b" \n[]"[..],
            &b"\xEF\xBB\xBF[\"SN\", 1]"[..],
        ] {
            match parse_json_object::<T>(body) {
                Err(ApiError::Invalid { message, field, .. }) => {
                    assert!(message.contains("not an array"), "{message}");
                    assert_eq!(field, None);
                }
                other => panic!("{other:?}"),
            }
        }
        assert!(parse_json_object::<T>(br#"{"serial_number": "SN", "model_id": 1}"#).is_ok());
        // A truncated array is malformed JSON, as any truncated document.
        assert!(matches!(
            parse_json_object::<T>(b"[1,2"),
            Err(ApiError::MalformedJson(_))
        ));
    }

    #[test]
    fn query_control_characters_are_found_decoded_c0_del_and_c1() {
        assert_eq!(query_control("site=%C2%84"), Some("site".into()));
        assert_eq!(query_control("a=1&line=x%00y"), Some("line".into()));
        assert_eq!(query_control("a=1&b=%7f"), Some("b".into()));
        assert_eq!(query_control("n%0Aame=1"), Some("n\name".into()));
        // Text that is not a control character: é (%C3%A9), NBSP
        // (%C2%A0), a literal %, and no escape at all.
        for ok in [
            "site=%C3%A9",
            "site=%C2%A0",
            "site=100%",
            "site=plant-1&line=2",
        ] {
            assert_eq!(query_control(ok), None, "{ok}");
        }
    }

    #[test]
    fn the_limit_is_said_in_bytes_and_mib_with_the_flag() {
        let limit = BodyPolicy {
            max_upload_bytes: 16 * 1024 * 1024,
            idle_timeout: Duration::from_secs(30),
            deadline: Duration::from_secs(300),
        };
        let m = limit.too_large_message("/sessions/3/poses");
        assert!(
            m.contains("16777216 bytes (16 MiB)") && m.contains("--max-upload-bytes"),
            "{m}"
        );
        // What to split depends on the route.
        assert!(m.contains("poses in several batches"), "{m}");
        let m = limit.too_large_message("/compensate");
        assert!(m.contains("targets over several requests"), "{m}");
        assert!(!m.contains("poses"), "{m}");
        let m = limit.too_large_message("/models");
        assert!(m.contains("a smaller body") && !m.contains("poses"), "{m}");
        assert_eq!(human_bytes(64 * 1024), "64 KiB");
        assert_eq!(human_bytes(1536 * 1024), "1.5 MiB");
        assert_eq!(human_bytes(100), "100 B");
    }
}
