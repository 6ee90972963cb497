//! What a web page elsewhere cannot do through its user's browser: reach
//! the service under another host name (DNS rebinding), change anything
//! from another origin, post a form, frame the page, or get CORS answers
//! that were not configured.

use reqwest::header::{
    ACCESS_CONTROL_ALLOW_ORIGIN, CONTENT_SECURITY_POLICY, CONTENT_TYPE, HOST, ORIGIN,
    X_CONTENT_TYPE_OPTIONS,
};

use crate::helpers::{Options, TestApp, err_json, ok_json, read};

#[tokio::test]
async fn another_host_name_is_refused_but_health_answers_any() {
    let app = TestApp::spawn("host").await;
    let r = app
        .client
        .get(app.url("/robots"))
        .header(HOST, "rebound.evil.example")
        .send()
        .await
        .unwrap();
    let e = err_json(r, 421, "host_not_allowed").await;
    assert!(
        e["message"].as_str().unwrap().contains("--allowed-host"),
        "{e}"
    );
    // The page itself too (a rebinding page would read it).
    let r = app
        .client
        .get(app.url("/"))
        .header(HOST, "rebound.evil.example:8080")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 421);
    for probe in ["/health", "/ready"] {
        let r = app
            .client
            .get(app.url(probe))
            .header(HOST, "10.0.0.7:8080")
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200, "{probe}");
    }
    // The loopback names are allowed by default, with any port.
    let r = app
        .client
        .get(app.url("/robots"))
        .header(HOST, "localhost:1234")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    app.stop().await;
}

#[tokio::test]
async fn every_answer_forbids_framing_and_sniffing() {
    let app = TestApp::spawn("headers").await;
    for path in ["/", "/ui/app.js", "/health", "/robots", "/no/such/route"] {
        let r = app.get(path).await;
        let csp = r.headers()[CONTENT_SECURITY_POLICY].to_str().unwrap();
        assert!(
            csp.contains("frame-ancestors 'none'") && csp.contains("script-src 'self'"),
            "{path}: {csp}"
        );
        assert_eq!(r.headers()[X_CONTENT_TYPE_OPTIONS], "nosniff", "{path}");
        assert_eq!(r.headers()["x-frame-options"], "DENY", "{path}");
    }
    app.stop().await;
}

#[tokio::test]
async fn another_origin_cannot_change_anything_nor_post_a_form() {
    let app = TestApp::spawn("origin").await;
    let (_, _, _, sid) = app.setup("er3a_paper_like", "ORIGIN-1").await;
    app.upload_poses(sid, read("er3a_paper_like", "poses.csv"))
        .await;
    let jobs = app.url(&format!("/sessions/{sid}/jobs"));
    let r = app
        .client
        .post(&jobs)
        .header(ORIGIN, "https://evil.example")
        .send()
        .await
        .unwrap();
    let e = err_json(r, 403, "forbidden").await;
    assert!(
        e["message"].as_str().unwrap().contains("--cors-origin"),
        "{e}"
    );
    // Reading is not changing: a GET with a foreign Origin is answered
    // (without CORS headers, so the foreign page cannot read it).
    let r = app
        .client
        .get(app.url("/robots"))
        .header(ORIGIN, "https://evil.example")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert!(r.headers().get(ACCESS_CONTROL_ALLOW_ORIGIN).is_none());
    // A form's content types never reach a handler, whatever the route.
    for form in [
        "text/plain",
        "application/x-www-form-urlencoded",
        "multipart/form-data; boundary=x",
    ] {
        let r = app
            .client
            .post(&jobs)
            .header(CONTENT_TYPE, form)
            .body("a=b")
            .send()
            .await
            .unwrap();
        err_json(r, 415, "unsupported_media_type").await;
    }
    let none: Vec<serde_json::Value> = ok_json(app.get("/jobs").await, 200).await["items"]
        .as_array()
        .unwrap()
        .clone();
    assert!(none.is_empty(), "no job was queued: {none:?}");
    // The page's own requests (same origin) go through.
    let r = app
        .client
        .post(&jobs)
        .header(ORIGIN, app.base.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    app.stop().await;
}

#[tokio::test]
async fn cors_answers_only_the_configured_origins() {
    let app = TestApp::spawn("cors-none").await;
    let preflight = |app: &TestApp, origin: &str| {
        app.client
            .request(reqwest::Method::OPTIONS, app.url("/robots"))
            .header(ORIGIN, origin.to_string())
            .header("access-control-request-method", "GET")
            .header("access-control-request-headers", "authorization")
            .send()
    };
    let r = preflight(&app, "https://mes.example").await.unwrap();
    assert!(r.headers().get(ACCESS_CONTROL_ALLOW_ORIGIN).is_none());
    app.stop().await;

    let app = TestApp::spawn_with(
        "cors-some",
        Options {
            cors_origins: vec!["https://mes.example".into()],
            ..Options::default()
        },
    )
    .await;
    let r = preflight(&app, "https://mes.example").await.unwrap();
    assert_eq!(
        r.headers()[ACCESS_CONTROL_ALLOW_ORIGIN],
        "https://mes.example"
    );
    let r = preflight(&app, "https://evil.example").await.unwrap();
    assert!(r.headers().get(ACCESS_CONTROL_ALLOW_ORIGIN).is_none());
    // The configured origin may change things (with its key).
    let (_, _, _, sid) = app.setup("er3a_paper_like", "CORS-1").await;
    app.upload_poses(sid, read("er3a_paper_like", "poses.csv"))
        .await;
    let r = app
        .client
        .post(app.url(&format!("/sessions/{sid}/jobs")))
        .header(ORIGIN, "https://mes.example")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    assert_eq!(
        r.headers()[ACCESS_CONTROL_ALLOW_ORIGIN],
        "https://mes.example"
    );
    app.stop().await;
}
