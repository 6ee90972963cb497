//! Slow and stalled clients are cut off after the client timeout, so they
//! cannot hold connections and buffers for ever; ordinary clients are not
//! affected.

use std::time::{Duration, Instant};

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::helpers::{Options, TestApp};

const TIMEOUT: Duration = Duration::from_secs(1);

async fn app() -> TestApp {
    TestApp::spawn_with(
        "slow",
        Options {
            client_timeout: TIMEOUT,
            idle_timeout: TIMEOUT,
            ..Options::default()
        },
    )
    .await
}

async fn connect(app: &TestApp) -> TcpStream {
    TcpStream::connect(app.base.trim_start_matches("http://"))
        .await
        .expect("connect")
}

/// Everything the server sends until it closes the connection; panics if
/// it keeps it open past `within`.
async fn read_until_closed(tcp: &mut TcpStream, within: Duration) -> String {
    let mut got = Vec::new();
    tokio::time::timeout(within, tcp.read_to_end(&mut got))
        .await
        .expect("the server must close the connection")
        .ok();
    String::from_utf8_lossy(&got).into_owned()
}

/// The head of a `POST /rigs` announcing a JSON body of `length` bytes,
/// with the app's admin key and `extra` header lines.
async fn post_rig_head(app: &TestApp, tcp: &mut TcpStream, length: usize, extra: &str) {
    let head = format!(
        "POST /rigs HTTP/1.1\r\nHost: localhost\r\nAuthorization: Bearer {}\r\nContent-Type: application/json\r\nContent-Length: {length}\r\n{extra}\r\n",
        app.admin_key
    );
    tcp.write_all(head.as_bytes()).await.unwrap();
}

/// An answer after which the server closes the connection says so.
fn assert_says_close(answer: &str) {
    assert!(
        answer.to_ascii_lowercase().contains("connection: close"),
        "{answer}"
    );
}

#[tokio::test]
async fn headers_sent_a_byte_at_a_time_are_cut_off() {
    let app = app().await;
    let mut tcp = connect(&app).await;
    let started = Instant::now();
    // Half a request line, then a trickle that never completes the headers.
    tcp.write_all(b"GET /health HTTP/1.1\r\nHost: localhost\r\n")
        .await
        .unwrap();
    let trickle = async {
        for _ in 0..20 {
            tokio::time::sleep(Duration::from_millis(200)).await;
            if tcp.write_all(b"X").await.is_err() {
                break;
            }
        }
    };
    trickle.await;
    let answer = read_until_closed(&mut tcp, Duration::from_secs(5)).await;
    assert!(
        !answer.contains("200 OK"),
        "an incomplete request must not be answered: {answer}"
    );
    assert!(started.elapsed() < Duration::from_secs(10));

    // A silent connection (never a byte) is closed too.
    let mut idle = connect(&app).await;
    read_until_closed(&mut idle, Duration::from_secs(5)).await;

    // Ordinary requests go on being served.
    assert_eq!(app.get("/health").await.status(), 200);
    app.stop().await;
}

#[tokio::test]
async fn a_stalled_body_is_answered_408_and_stores_nothing() {
    let app = app().await;
    let body = r#"{"name": "stalled", "anchors_mm": [[0,0,0],[1000,0,0],[0,1000,0]], "r_mm": 10}"#;
    let mut tcp = connect(&app).await;
    post_rig_head(&app, &mut tcp, body.len(), "").await;
    // Half the body, then nothing.
    tcp.write_all(&body.as_bytes()[..body.len() / 2])
        .await
        .unwrap();
    let answer = read_until_closed(&mut tcp, Duration::from_secs(5)).await;
    assert!(
        answer.starts_with("HTTP/1.1 408"),
        "a stalled body is a 408: {answer}"
    );
    assert!(answer.contains("\"error\":\"request_timeout\""), "{answer}");
    assert!(answer.contains("--client-timeout-secs"), "{answer}");
    assert_says_close(&answer);

    let rigs: serde_json::Value = app.get("/rigs").await.json().await.unwrap();
    assert_eq!(rigs["items"].as_array().unwrap().len(), 0, "{rigs}");
    app.stop().await;
}

#[tokio::test]
async fn a_body_declared_too_large_is_refused_before_it_is_sent() {
    let app = TestApp::spawn_with(
        "slow",
        Options {
            max_upload_bytes: 1000,
            ..Options::default()
        },
    )
    .await;
    let mut tcp = connect(&app).await;
    // The client asks before sending: the answer is 413 at once, never
    // "100 Continue", and the body is never needed.
    post_rig_head(&app, &mut tcp, 5000, "Expect: 100-continue\r\n").await;
    let mut got = vec![0u8; 4096];
    let n = tokio::time::timeout(Duration::from_secs(5), tcp.read(&mut got))
        .await
        .expect("an answer without the body")
        .unwrap();
    let answer = String::from_utf8_lossy(&got[..n]);
    assert!(answer.starts_with("HTTP/1.1 413"), "{answer}");
    assert_says_close(&answer);
    app.stop().await;
}

#[tokio::test]
async fn a_trickled_body_is_cut_off_at_the_deadline() {
    let app = app().await;
    let mut tcp = connect(&app).await;
    let started = Instant::now();
    post_rig_head(&app, &mut tcp, 100_000, "").await;
    // A byte every 300 ms never trips the 1 s idle timeout, but the whole
    // body is due within ten of them.
    let (mut rd, mut wr) = tcp.into_split();
    let trickle = tokio::spawn(async move {
        while wr.write_all(b" ").await.is_ok() {
            tokio::time::sleep(Duration::from_millis(300)).await;
        }
    });
    let mut got = Vec::new();
    tokio::time::timeout(Duration::from_secs(20), rd.read_to_end(&mut got))
        .await
        .expect("cut off within the deadline")
        .ok();
    trickle.abort();
    let answer = String::from_utf8_lossy(&got);
    let took = started.elapsed();
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    assert!(
        took >= TIMEOUT * drawcal::http::BODY_DEADLINE_FACTOR - Duration::from_millis(100),
        "not before the deadline: {took:?}"
    );
    app.stop().await;
}

#[tokio::test]
async fn a_client_that_stops_reading_does_not_hold_up_the_shutdown() {
    let app = TestApp::spawn_with(
        "slow",
        Options {
            grace: Duration::from_secs(1),
            ..Options::default()
        },
    )
    .await;
    // Pipeline requests for the (large) page and never read the answers:
    // the server's writes block once the socket buffers are full.
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    let addr = app.base.trim_start_matches("http://").parse().unwrap();
    let mut tcp = socket.connect(addr).await.unwrap();
    let request = b"GET / HTTP/1.1\r\nHost: localhost\r\n\r\n".repeat(2000);
    tcp.write_all(&request).await.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    let started = Instant::now();
    tokio::time::timeout(Duration::from_secs(10), app.stop())
        .await
        .expect("shutdown must not wait on a client that does not read");
    assert!(started.elapsed() < Duration::from_secs(5));
    drop(tcp);
}

/// A client that connects with a tiny receive buffer (so that the server's
/// writes block soon), sends `request` and never reads.
async fn non_reader(app: &TestApp, request: &[u8]) -> TcpStream {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    let addr = app.base.trim_start_matches("http://").parse().unwrap();
    let mut tcp = socket.connect(addr).await.unwrap();
    tcp.write_all(request).await.unwrap();
    tcp
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_stops_reading_is_cut_off_and_frees_its_answer() {
    let app = TestApp::spawn_with(
        "nonreader",
        Options {
            client_timeout: TIMEOUT,
            max_upload_bytes: 4 << 20,
            // Room for one large answer at a time.
            max_answer_bytes_in_flight: 1 << 20,
            ..Options::default()
        },
    )
    .await;
    let ds = "real_ur10_ipa_grid";
    let (_, _, _, sid) = app.setup(ds, "NONREADER-1").await;
    app.upload_poses(sid, crate::helpers::read(ds, "poses.csv"))
        .await;
    let path = format!("/sessions/{sid}/poses");
    let request = format!(
        "GET {path} HTTP/1.1\r\nHost: localhost\r\nAuthorization: Bearer {}\r\n\r\n",
        app.admin_key
    )
    .repeat(8);
    let mut stalled = non_reader(&app, request.as_bytes()).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    // While it holds the budget, another large answer is refused at once
    // (memory stays bounded), and small ones are served.
    let r = app.get(&path).await;
    assert_eq!(r.status(), 503, "the budget held by the stalled client");
    assert_eq!(app.get("/health").await.status(), 200);
    // Past the write timeout the stalled connection is closed: it got a
    // fraction of its eight answers.
    tokio::time::sleep(TIMEOUT * 3).await;
    let got = read_until_closed(&mut stalled, Duration::from_secs(5)).await;
    assert!(
        got.matches("HTTP/1.1 200").count() < 8,
        "the server kept writing to a client that did not read"
    );
    // And the budget is free again.
    let r = app.get(&path).await;
    assert_eq!(r.status(), 200);
    assert!(r.text().await.unwrap().len() > 1 << 20);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn past_the_connection_cap_a_new_connection_is_refused_cleanly() {
    let app = TestApp::spawn_with(
        "conncap",
        Options {
            max_connections: Some(4),
            ..Options::default()
        },
    )
    .await;
    let mut idle = Vec::new();
    for _ in 0..4 {
        idle.push(connect(&app).await);
    }
    tokio::time::sleep(Duration::from_millis(100)).await;
    let mut fifth = connect(&app).await;
    let answer = read_until_closed(&mut fifth, Duration::from_secs(3)).await;
    assert!(answer.starts_with("HTTP/1.1 503"), "{answer}");
    assert!(
        answer.contains("\"error\":\"unavailable\"") && answer.contains("--max-connections"),
        "{answer}"
    );
    // Idle connections that go free their slots.
    drop(idle);
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(app.get("/health").await.status(), 200);
    app.stop().await;
}
