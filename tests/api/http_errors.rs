//! Requests hyper cannot parse (a malformed request line, a bad
//! `Content-Length`, a request target or header section too large) are
//! answered in the error shape like every other error: the status, a JSON
//! body `{error, message}`, and the connection closed.

use std::time::Duration;

use serde_json::Value;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::helpers::TestApp;

/// Send `request` raw and read the whole answer (the server must close).
async fn raw(app: &TestApp, request: &[u8]) -> String {
    let mut tcp = TcpStream::connect(app.base.trim_start_matches("http://"))
        .await
        .expect("connect");
    tcp.write_all(request).await.expect("send");
    let mut got = Vec::new();
    tokio::time::timeout(Duration::from_secs(10), tcp.read_to_end(&mut got))
        .await
        .expect("the server must close the connection")
        .ok();
    String::from_utf8_lossy(&got).into_owned()
}

/// The answer has `status`, a JSON content type, says it closes, and its
/// body is the error shape with `code`; the body.
fn assert_json_error(answer: &str, status: u16, code: &str) -> Value {
    let (head, body) = answer
        .split_once("\r\n\r\n")
        .unwrap_or_else(|| panic!("no complete answer: {answer:?}"));
    let first = head.lines().next().unwrap_or("");
    assert!(
        first.starts_with(&format!("HTTP/1.1 {status} ")),
        "status {status} expected: {head}"
    );
    let head = format!("{}\r\n", head.to_ascii_lowercase());
    assert!(
        head.contains("\r\ncontent-type: application/json\r\n"),
        "{head}"
    );
    assert!(head.contains("\r\nconnection: close\r\n"), "{head}");
    assert!(
        head.contains(&format!("\r\ncontent-length: {}\r\n", body.len())),
        "{head} / {body}"
    );
    let v: Value =
        serde_json::from_str(body).unwrap_or_else(|e| panic!("not JSON ({e}): {body:?}"));
    assert_eq!(v["error"], code, "{v}");
    assert!(v["message"].as_str().is_some_and(|m| !m.is_empty()), "{v}");
    v
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unparsable_requests_get_json_errors() {
    let app = TestApp::spawn("http-errors").await;

    // A request line that is not HTTP.
    let a = raw(&app, b"NOT A REQUEST LINE\r\n\r\n").await;
    assert_json_error(&a, 400, "bad_request");

    // A method with a character no token has.
    let a = raw(&app, b"G(T /health HTTP/1.1\r\nHost: localhost\r\n\r\n").await;
    assert_json_error(&a, 400, "bad_request");

    // A Content-Length that is not a number, and two that disagree.
    for cl in [
        "Content-Length: abc\r\n",
        "Content-Length: 5\r\nContent-Length: 7\r\n",
    ] {
        let req = format!(
            "POST /rigs HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n{cl}\r\n{{}}"
        );
        let a = raw(&app, req.as_bytes()).await;
        assert_json_error(&a, 400, "bad_request");
    }

    // A header line without a colon.
    let a = raw(
        &app,
        b"GET /health HTTP/1.1\r\nHost: localhost\r\nno colon here\r\n\r\n",
    )
    .await;
    assert_json_error(&a, 400, "bad_request");

    // A request target over 64 KiB: 414.
    let req = format!(
        "GET /robots?x={} HTTP/1.1\r\nHost: localhost\r\n\r\n",
        "a".repeat(70_000)
    );
    let a = raw(&app, req.as_bytes()).await;
    assert_json_error(&a, 414, "uri_too_long");

    // More header fields than the service reads: 431.
    let mut req = String::from("GET /health HTTP/1.1\r\nHost: localhost\r\n");
    for i in 0..150 {
        req.push_str(&format!("X-Field-{i}: {i}\r\n"));
    }
    req.push_str("\r\n");
    let a = raw(&app, req.as_bytes()).await;
    assert_json_error(&a, 431, "header_too_large");

    // A pipelined good request before a bad one: the first is answered
    // as usual, the second in the error shape.
    let a = raw(
        &app,
        b"GET /health HTTP/1.1\r\nHost: localhost\r\n\r\nNOT A REQUEST LINE\r\n\r\n",
    )
    .await;
    let second = a
        .match_indices("HTTP/1.1 ")
        .nth(1)
        .map(|(i, _)| &a[i..])
        .unwrap_or_else(|| panic!("two answers expected: {a}"));
    assert!(a.starts_with("HTTP/1.1 200 "), "{a}");
    assert_json_error(second, 400, "bad_request");

    // The service still serves.
    let r = app.client.get(app.url("/health")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    app.stop().await;
}
