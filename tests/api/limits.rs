//! Limits against abusive clients: a key's rates of uploads and job
//! submissions, and the job queue's bound, answered 429 with Retry-After.

use std::sync::Arc;
use std::sync::atomic::AtomicUsize;
use std::time::Duration;

use drawcal::http::limits::LimitConfig;
use reqwest::header::RETRY_AFTER;

use crate::helpers::{Options, TestApp, err_json, read, slow_job_fn};

const DS: &str = "er3a_paper_like";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_key_over_its_rates_is_told_when_to_retry() {
    let app = TestApp::spawn_with(
        "rates",
        Options {
            job_fn: slow_job_fn(1, Duration::from_millis(1), Arc::new(AtomicUsize::new(0))),
            limits: LimitConfig {
                uploads_per_minute: 2,
                jobs_per_minute: 1,
                ..LimitConfig::default()
            },
            ..Options::default()
        },
    )
    .await;
    let (_, _, _, sid) = app.setup(DS, "RATE-1").await;
    let poses = read(DS, "poses.csv");
    app.upload_poses(sid, poses.clone()).await;
    // An upload costs the key its token before it is read (reading is what
    // a flood would cost): a refused one counts too.
    let r = app
        .post_raw(
            &format!("/sessions/{sid}/poses"),
            Some("text/csv"),
            poses.clone(),
        )
        .await;
    err_json(r, 422, "invalid_input").await;
    let r = app
        .post_raw(
            &format!("/sessions/{sid}/poses"),
            Some("text/csv"),
            poses.clone(),
        )
        .await;
    assert_eq!(r.headers()[RETRY_AFTER], "30", "two a minute: one per 30 s");
    let e = err_json(r, 429, "too_many_requests").await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("--max-uploads-per-minute"),
        "{e}"
    );
    let jobs = format!("/sessions/{sid}/jobs");
    assert_eq!(app.post_raw(&jobs, None, "").await.status(), 202);
    let r = app.post_raw(&jobs, None, "").await;
    assert_eq!(r.headers()[RETRY_AFTER], "60");
    err_json(r, 429, "too_many_requests").await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_job_queue_is_bounded() {
    let app = TestApp::spawn_with(
        "queue",
        Options {
            // One job runs for a while; the queue holds one more.
            job_fn: slow_job_fn(
                200,
                Duration::from_millis(50),
                Arc::new(AtomicUsize::new(0)),
            ),
            limits: LimitConfig {
                max_queued_jobs: 1,
                ..LimitConfig::default()
            },
            ..Options::default()
        },
    )
    .await;
    let (_, _, _, sid) = app.setup(DS, "QUEUE-1").await;
    app.upload_poses(sid, read(DS, "poses.csv")).await;
    let jobs = format!("/sessions/{sid}/jobs");
    assert_eq!(app.post_raw(&jobs, None, "").await.status(), 202);
    // Wait until the first runs, so that the next one is the queue's.
    for _ in 0..200 {
        let j: serde_json::Value = app.get("/jobs?state=running").await.json().await.unwrap();
        if j["total"] == 1 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    assert_eq!(app.post_raw(&jobs, None, "").await.status(), 202);
    let r = app.post_raw(&jobs, None, "").await;
    let e = err_json(r, 429, "too_many_requests").await;
    assert!(
        e["message"].as_str().unwrap().contains("--max-queued-jobs"),
        "{e}"
    );
    app.stop().await;
}
