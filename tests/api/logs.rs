//! Structured logs from the real binary: `--log-format json` (and
//! `DRAWCAL_LOG_FORMAT`) writes one JSON object per line, and every line
//! logged while a request is handled carries its request id.

use std::process::{Child, Command, Stdio};
use std::time::Duration;

use serde_json::Value;

use crate::helpers::fresh_dir;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn serve(dir: &std::path::Path, port: u16, args: &[&str], env: &[(&str, &str)]) -> Child {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_drawcal"));
    cmd.arg("serve")
        .args(args)
        .env_remove("DRAWCAL_LOG_FORMAT")
        .env_remove("RUST_LOG")
        .env(
            "DATABASE_URL",
            format!("sqlite://{}", dir.join("drawcal.db").display()),
        )
        .env("DRAWCAL_LISTEN", format!("127.0.0.1:{port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::from(
            std::fs::File::create(dir.join("server.log")).unwrap(),
        ));
    cmd.env("DRAWCAL_ADMIN_KEY", crate::helpers::TEST_ADMIN_KEY);
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.spawn().expect("start the drawcal binary")
}

/// Start, make two requests (one answered 404), stop with SIGTERM; the
/// request ids the answers carried and the log text.
async fn run_once(args: &[&str], env: &[(&str, &str)]) -> (Vec<String>, String) {
    let dir = fresh_dir("logs");
    let port = free_port();
    let mut child = serve(&dir, port, args, env);
    let base = format!("http://127.0.0.1:{port}");
    let client = crate::helpers::client_with_key(crate::helpers::TEST_ADMIN_KEY);
    let mut ready = false;
    for _ in 0..300 {
        if let Ok(r) = client.get(format!("{base}/ready")).send().await {
            if r.status() == 200 {
                ready = true;
                break;
            }
        }
        if let Some(st) = child.try_wait().unwrap() {
            panic!(
                "server exited early: {st}: {}",
                std::fs::read_to_string(dir.join("server.log")).unwrap_or_default()
            );
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(ready, "server not ready");
    let mut ids = Vec::new();
    for path in ["/health", "/robots/424242"] {
        let r = client.get(format!("{base}{path}")).send().await.unwrap();
        ids.push(r.headers()["x-request-id"].to_str().unwrap().to_string());
    }
    let st = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    assert!(child.wait().unwrap().success(), "graceful exit");
    let log = std::fs::read_to_string(dir.join("server.log")).unwrap();
    (ids, log)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn json_logs_carry_the_request_id_on_every_request_line() {
    let (ids, log) = run_once(&["--log-format", "json"], &[]).await;
    assert!(
        log.contains("log_format=json"),
        "the flag is printed: {log}"
    );
    // Every line, the start-up banner included, is a JSON object.
    let lines: Vec<Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect();
    assert!(
        lines.iter().all(|v| v["level"].is_string()
            && v["timestamp"].is_string()
            && v["fields"].is_object())
    );
    for id in &ids {
        let of_request: Vec<&Value> = lines
            .iter()
            .filter(|v| v["span"]["request_id"].as_str() == Some(id.as_str()))
            .collect();
        assert!(
            !of_request.is_empty(),
            "a log line for request {id} in\n{log}"
        );
        for v in &of_request {
            assert_eq!(v["span"]["name"], "request");
            assert!(
                v["span"]["uri"].is_string() && v["span"]["method"] == "GET",
                "{v}"
            );
        }
        // The response line with its status.
        assert!(
            of_request.iter().any(|v| v["fields"]["status"].is_number()),
            "{of_request:?}"
        );
    }
    // Lines outside any request have no request span.
    assert!(
        lines
            .iter()
            .any(|v| v["fields"]["message"] == "listening" && v["span"].is_null())
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn log_format_from_the_environment_and_text_by_default() {
    let (ids, log) = run_once(&[], &[("DRAWCAL_LOG_FORMAT", "json")]).await;
    assert!(log.contains("log_format=json"), "{log}");
    assert!(
        log.lines()
            .filter_map(|l| serde_json::from_str::<Value>(l).ok())
            .any(|v| v["span"]["request_id"] == ids[0].as_str())
    );
    let (ids, log) = run_once(&[], &[]).await;
    assert!(log.contains("log_format=text"), "{log}");
    let line = log
        .lines()
        .find(|l| l.contains(&format!("request_id={}", ids[1])))
        .unwrap_or_else(|| panic!("a text line with request_id={}: {log}", ids[1]));
    assert!(serde_json::from_str::<Value>(line).is_err());
    assert!(line.contains("status=404"), "{line}");
}
