//! What connections may take, so that abusive clients cannot take the
//! service down for the others:
//!
//! - **the descriptor limit** is raised to its hard limit at start
//!   ([`raise_descriptor_limit`]), and the connections served at once are
//!   capped below it ([`default_max_connections`], `--max-connections`);
//!   past the cap a new connection is answered 503 `unavailable` at once
//!   and closed ([`refuse`]), instead of failing `accept` and leaving
//!   every client waiting;
//! - **a write timeout** ([`WriteTimeout`]): a connection whose client
//!   stops reading its answer for longer than the client timeout is
//!   closed, and the answer it held is freed;
//! - **a budget of large answers in flight** ([`AnswerBudget`]): answers
//!   over [`LARGE_ANSWER_BYTES`] together hold at most
//!   `--max-answer-bytes-in-flight`; past it a request for another is
//!   answered 503 with `Retry-After`, so that clients that request large
//!   pose files and never read them cannot pin the machine's memory;
//! - **every HTTP-level error in the error shape** ([`JsonParseErrors`]):
//!   what hyper answers by itself to a request it cannot parse (400, 414,
//!   431, with an empty body) leaves as a JSON [`super::ErrorBody`] like
//!   every other error.

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use axum::body::{Body, Bytes, HttpBody};
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use tokio::io::{AsyncRead, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use super::ApiError;

/// Descriptors kept for the database pool, the log and the listener.
const RESERVED_DESCRIPTORS: u64 = 128;

/// Raise the soft limit on open descriptors to the hard limit; the soft
/// limit after it (`None` where it cannot be read).
pub fn raise_descriptor_limit() -> Option<u64> {
    #[cfg(unix)]
    {
        let mut lim = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: getrlimit/setrlimit write/read the struct passed, nothing else.
        unsafe {
            if libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) != 0 {
                return None;
            }
            if lim.rlim_cur < lim.rlim_max {
                let raised = libc::rlimit {
                    rlim_cur: lim.rlim_max,
                    rlim_max: lim.rlim_max,
                };
                if libc::setrlimit(libc::RLIMIT_NOFILE, &raised) == 0 {
                    lim.rlim_cur = lim.rlim_max;
                }
            }
        }
        Some(lim.rlim_cur as u64)
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// The default connection cap under a descriptor limit of `limit`: all
/// but the reserved descriptors, at most 16,384 (idle connections cost a
/// few kilobytes each; the budget bounds what answers hold).
pub fn default_max_connections(limit: Option<u64>) -> usize {
    let limit = limit.unwrap_or(1024);
    limit.saturating_sub(RESERVED_DESCRIPTORS).clamp(16, 16_384) as usize
}

/// A complete HTTP/1.1 answer carrying `err` in the error shape (the
/// status and body [`ApiError`] gives it, `extra` header lines), after
/// which the connection closes: the connection layer's answers, written
/// where there is no router to answer.
pub fn raw_answer(err: &ApiError, extra: &[(&str, &str)]) -> Vec<u8> {
    let (status, _) = err.status_code();
    let body = serde_json::to_string(&err.body()).expect("an error body serialises");
    let mut answer = format!(
        "HTTP/1.1 {} {}\r\ncontent-type: application/json\r\nx-content-type-options: nosniff\r\nconnection: close\r\ncontent-length: {}\r\n",
        status.as_u16(),
        status.canonical_reason().unwrap_or(""),
        body.len()
    );
    for (name, value) in extra {
        answer.push_str(&format!("{name}: {value}\r\n"));
    }
    answer.push_str("\r\n");
    answer.push_str(&body);
    answer.into_bytes()
}

/// Answer a connection past the cap: 503 with a JSON body, then close,
/// without reading its request (it may never send one).
pub async fn refuse(mut tcp: tokio::net::TcpStream, max_connections: usize) {
    let answer = raw_answer(
        &ApiError::Unavailable(format!(
            "the service is serving its {max_connections} connections at most (--max-connections); retry shortly"
        )),
        &[("retry-after", "1")],
    );
    let _ = tokio::time::timeout(Duration::from_secs(1), async {
        let _ = tcp.write_all(&answer).await;
        let _ = tcp.shutdown().await;
    })
    .await;
}

/// The heads hyper writes by itself, with no body, when it cannot parse a
/// request (`hyper::proto::h1::role::Server::on_error`), and the error
/// each stands for.
const HYPER_PARSE_ERRORS: [(&[u8], fn() -> ApiError); 3] = [
    (b"HTTP/1.1 400 Bad Request\r\n", || {
        ApiError::BadRequest(
            "the request is not HTTP/1.1 the service can read: a malformed request line, \
             header or Content-Length"
                .into(),
        )
    }),
    (b"HTTP/1.1 414 URI Too Long\r\n", || {
        ApiError::UriTooLong("the request target is longer than 65,534 bytes".into())
    }),
    (b"HTTP/1.1 431 Request Header Fields Too Large\r\n", || {
        ApiError::HeaderTooLarge(
            "the request header is larger than the service reads (about 400 KiB, at most 100 fields)"
                .into(),
        )
    }),
];

/// If `buf` starts with one of hyper's own parse-error heads: its length
/// and the answer in the error shape to send instead.
///
/// Exact for this service: such a head has no `content-type`, and every
/// 400 the router gives has one (a JSON [`ApiError`]); no answer body the
/// service sends (JSON, validated CSV, its page's HTML and scripts) can
/// start with a status line.
fn hyper_parse_error(buf: &[u8]) -> Option<(usize, Vec<u8>)> {
    let (_, error) = HYPER_PARSE_ERRORS
        .iter()
        .find(|(line, _)| buf.starts_with(line))?;
    let end = buf.windows(4).position(|w| w == b"\r\n\r\n")? + 4;
    let head = String::from_utf8_lossy(&buf[..end]).to_ascii_lowercase();
    if head.contains("\r\ncontent-type:") || !head.contains("\r\ncontent-length: 0\r\n") {
        return None;
    }
    Some((end, raw_answer(&error(), &[])))
}

/// An I/O stream on which hyper's own answers to requests it cannot parse
/// (400 for a malformed request line, header or `Content-Length`; 414 for
/// a request target over 64 KiB; 431 for a header section over hyper's
/// buffer or field count), a bare head with an empty body, are replaced
/// by the same status with a JSON [`super::ErrorBody`] ([`raw_answer`]).
/// hyper closes the connection after them.
pub struct JsonParseErrors<S> {
    inner: S,
    /// An answer replacing one of hyper's, and how much of it is written.
    pending: Vec<u8>,
    written: usize,
}

impl<S> JsonParseErrors<S> {
    /// `inner` with hyper's parse-error answers in the error shape.
    pub fn new(inner: S) -> Self {
        JsonParseErrors {
            inner,
            pending: Vec::new(),
            written: 0,
        }
    }
}

impl<S: AsyncWrite + Unpin> JsonParseErrors<S> {
    /// Write what is left of a replacing answer.
    fn poll_pending(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        while self.written < self.pending.len() {
            let n = match Pin::new(&mut self.inner).poll_write(cx, &self.pending[self.written..]) {
                Poll::Ready(Ok(n)) => n,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Pending => return Poll::Pending,
            };
            if n == 0 {
                return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
            }
            self.written += n;
        }
        self.pending.clear();
        self.written = 0;
        Poll::Ready(Ok(()))
    }

    /// hyper's head of `len` bytes is taken (as if written); `answer`
    /// goes in its place, now or at the next write or flush.
    fn replace(
        &mut self,
        cx: &mut Context<'_>,
        len: usize,
        answer: Vec<u8>,
    ) -> Poll<io::Result<usize>> {
        self.pending = answer;
        self.written = 0;
        match self.poll_pending(cx) {
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            _ => Poll::Ready(Ok(len)),
        }
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for JsonParseErrors<S> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for JsonParseErrors<S> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        std::task::ready!(this.poll_pending(cx))?;
        match hyper_parse_error(buf) {
            Some((len, answer)) => this.replace(cx, len, answer),
            None => Pin::new(&mut this.inner).poll_write(cx, buf),
        }
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        std::task::ready!(this.poll_pending(cx))?;
        // hyper queues each head as a slice of its own: one of its error
        // heads first is replaced; one after other slices (a pipelined
        // answer before it) waits for the next write.
        let Some(first) = bufs.iter().position(|b| !b.is_empty()) else {
            return Poll::Ready(Ok(0));
        };
        if let Some((len, answer)) = hyper_parse_error(&bufs[first]) {
            return this.replace(cx, len, answer);
        }
        let upto = bufs[first + 1..]
            .iter()
            .position(|b| hyper_parse_error(b).is_some())
            .map_or(bufs.len(), |i| first + 1 + i);
        Pin::new(&mut this.inner).poll_write_vectored(cx, &bufs[..upto])
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        std::task::ready!(this.poll_pending(cx))?;
        Pin::new(&mut this.inner).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        std::task::ready!(this.poll_pending(cx))?;
        Pin::new(&mut this.inner).poll_shutdown(cx)
    }
}

/// An I/O stream whose writes fail with `TimedOut` when the peer has
/// accepted nothing for `timeout` (it stopped reading): hyper then closes
/// the connection and drops what it was sending.
pub struct WriteTimeout<S> {
    inner: S,
    timeout: Duration,
    stalled: Option<Pin<Box<tokio::time::Sleep>>>,
}

impl<S> WriteTimeout<S> {
    /// `inner` with writes that may stall for at most `timeout`.
    pub fn new(inner: S, timeout: Duration) -> Self {
        WriteTimeout {
            inner,
            timeout,
            stalled: None,
        }
    }

    /// The write is pending: since when (a timer armed at the first
    /// pending poll since the last progress), and has that been too long.
    fn pending<T>(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<T>> {
        let timeout = self.timeout;
        let timer = self
            .stalled
            .get_or_insert_with(|| Box::pin(tokio::time::sleep(timeout)));
        match timer.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "the client stopped reading its answer",
            ))),
            Poll::Pending => Poll::Pending,
        }
    }

    fn progress<T>(&mut self, r: Poll<io::Result<T>>, cx: &mut Context<'_>) -> Poll<io::Result<T>> {
        match r {
            Poll::Ready(v) => {
                self.stalled = None;
                Poll::Ready(v)
            }
            Poll::Pending => self.pending(cx),
        }
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for WriteTimeout<S> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for WriteTimeout<S> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_write(cx, buf);
        this.progress(r, cx)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_write_vectored(cx, bufs);
        this.progress(r, cx)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_flush(cx);
        this.progress(r, cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_shutdown(cx);
        this.progress(r, cx)
    }
}

/// Answers at least this large draw on the [`AnswerBudget`].
pub const LARGE_ANSWER_BYTES: u64 = 256 * 1024;

/// The bytes large answers may hold in memory together, in KiB permits.
#[derive(Debug, Clone)]
pub struct AnswerBudget {
    kib: Arc<Semaphore>,
    total_bytes: u64,
}

impl AnswerBudget {
    /// A budget of `total_bytes`.
    pub fn new(total_bytes: u64) -> Self {
        let kib = (total_bytes / 1024).clamp(1, Semaphore::MAX_PERMITS as u64 / 2);
        AnswerBudget {
            kib: Arc::new(Semaphore::new(kib as usize)),
            total_bytes,
        }
    }

    /// Hold `bytes` of the budget until the permit is dropped, if there is
    /// room for them.
    fn take(&self, bytes: u64) -> Option<OwnedSemaphorePermit> {
        let kib = (bytes.div_ceil(1024)).min(self.total_bytes / 1024).max(1) as u32;
        self.kib.clone().try_acquire_many_owned(kib).ok()
    }
}

/// The middleware: a large answer holds its share of the budget until it
/// has been sent (or its connection closed); with no room, 503.
pub async fn budget(State(budget): State<AnswerBudget>, req: Request, next: Next) -> Response {
    let response = next.run(req).await;
    let size = response.body().size_hint().exact().unwrap_or(0);
    if size < LARGE_ANSWER_BYTES {
        return response;
    }
    match budget.take(size) {
        Some(permit) => {
            let (parts, body) = response.into_parts();
            Response::from_parts(
                parts,
                Body::new(Budgeted {
                    body,
                    rest: Bytes::new(),
                    _permit: permit,
                }),
            )
        }
        None => {
            let mut refused = ApiError::Unavailable(format!(
                "the service is sending as many large answers as it holds at once \
                 ({} MiB, --max-answer-bytes-in-flight); retry shortly",
                budget.total_bytes >> 20
            ))
            .into_response();
            refused.headers_mut().insert(
                axum::http::header::RETRY_AFTER,
                axum::http::HeaderValue::from_static("1"),
            );
            refused
        }
    }
}

/// A body holding its share of the budget while it lives, handed to hyper
/// in slices: hyper asks for the next one only once it has written the
/// ones before, so the last slice (and the permit) goes when the answer
/// is nearly all sent, not when hyper has buffered it.
struct Budgeted {
    body: Body,
    rest: Bytes,
    _permit: OwnedSemaphorePermit,
}

/// The slices a budgeted answer is handed over in.
const SLICE_BYTES: usize = 64 * 1024;

impl HttpBody for Budgeted {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Bytes>, axum::Error>>> {
        let this = self.get_mut();
        loop {
            if !this.rest.is_empty() {
                let n = this.rest.len().min(SLICE_BYTES);
                return Poll::Ready(Some(Ok(http_body::Frame::data(this.rest.split_to(n)))));
            }
            match Pin::new(&mut this.body).poll_frame(cx) {
                Poll::Ready(Some(Ok(frame))) => match frame.into_data() {
                    Ok(data) => this.rest = data,
                    Err(other) => return Poll::Ready(Some(Ok(other))),
                },
                other => return other,
            }
        }
    }

    fn is_end_stream(&self) -> bool {
        self.rest.is_empty() && self.body.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        let inner = self.body.size_hint();
        let rest = self.rest.len() as u64;
        let mut hint = http_body::SizeHint::new();
        hint.set_lower(inner.lower() + rest);
        if let Some(upper) = inner.upper() {
            hint.set_upper(upper + rest);
        }
        hint
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cap_stays_under_the_descriptor_limit() {
        assert_eq!(default_max_connections(Some(1024)), 896);
        assert_eq!(default_max_connections(Some(1 << 20)), 16_384);
        assert_eq!(default_max_connections(Some(100)), 16);
        assert_eq!(default_max_connections(None), 896);
    }

    #[test]
    fn only_hypers_bare_parse_error_heads_are_replaced() {
        let hyper = b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-length: 0\r\ndate: Wed, 02 Dec 2026 20:00:00 GMT\r\n\r\n";
        let (len, answer) = hyper_parse_error(hyper).expect("replaced");
        assert_eq!(len, hyper.len());
        let answer = String::from_utf8(answer).unwrap();
        assert!(answer.starts_with("HTTP/1.1 431 "), "{answer}");
        assert!(answer.contains(r#""error":"header_too_large""#), "{answer}");
        // The router's errors carry a content type and a body.
        let routed = b"HTTP/1.1 400 Bad Request\r\ncontent-type: application/json\r\ncontent-length: 42\r\n\r\n";
        assert!(hyper_parse_error(routed).is_none());
        assert!(hyper_parse_error(br#"{"error":"bad_request"}"#).is_none());
        assert!(hyper_parse_error(b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n").is_none());
    }

    #[test]
    fn the_budget_refuses_past_its_total_and_frees_on_drop() {
        let b = AnswerBudget::new(1 << 20);
        let first = b.take(700 * 1024).expect("room");
        assert!(b.take(400 * 1024).is_none(), "1,100 KiB > 1 MiB");
        drop(first);
        assert!(b.take(400 * 1024).is_some());
        // One answer larger than the whole budget still goes, alone.
        assert!(b.take(5 << 20).is_some());
    }
}
