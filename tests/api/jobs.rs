//! The job machinery with a stand-in engine: progress, cancel, failure
//! reasons, and hand-back at graceful shutdown then pickup at restart.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use serde_json::json;

use crate::helpers::{Options, TestApp, err_json, ok_json, read, slow_job_fn};
use crate::openapi::validate_response;

const DS: &str = "er3a_paper_like";

async fn session_with_poses(app: &TestApp, serial: &str) -> i64 {
    let (_, _, _, sid) = app.setup(DS, serial).await;
    app.upload_poses(sid, read(DS, "poses.csv")).await;
    sid
}

async fn enqueue(app: &TestApp, sid: i64) -> i64 {
    let job = ok_json(
        app.post_raw(&format!("/sessions/{sid}/jobs"), None, "")
            .await,
        202,
    )
    .await;
    job["id"].as_i64().unwrap()
}

async fn wait_state(app: &TestApp, job: i64, state: &str) -> serde_json::Value {
    for _ in 0..600 {
        let j = ok_json(app.get(&format!("/jobs/{job}")).await, 200).await;
        if j["state"] == state {
            return j;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("job {job} never reached {state}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn progress_cancel_and_failure_reason() {
    let started = Arc::new(AtomicUsize::new(0));
    let app = TestApp::spawn_with(
        "cancel",
        Options {
            job_fn: slow_job_fn(400, Duration::from_millis(25), started.clone()),
            lease: Duration::from_millis(600),
            ..Options::default()
        },
    )
    .await;
    let sid = session_with_poses(&app, "JOB-1").await;
    let first = enqueue(&app, sid).await;
    let second = enqueue(&app, sid).await;

    // The first runs and reports progress; the second waits (one worker).
    wait_state(&app, first, "running").await;
    let mut progressed = false;
    for _ in 0..100 {
        let j = ok_json(app.get(&format!("/jobs/{first}")).await, 200).await;
        if j["progress"].as_f64().unwrap() > 0.0 && j["stage"] == "stand-in" {
            progressed = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert!(
        progressed,
        "progress reaches the job row through the heartbeat"
    );
    let q = ok_json(app.get(&format!("/jobs/{second}")).await, 200).await;
    assert_eq!(q["state"], "queued");

    // Cancel the queued one: at once.
    let c = validate_response(
        "post",
        "/jobs/{id}/cancel",
        app.post_raw(&format!("/jobs/{second}/cancel"), None, "")
            .await,
    )
    .await;
    assert_eq!(c["state"], "cancelled");
    // Cancel the running one: the engine sees the flag and stops.
    let c = ok_json(
        app.post_raw(&format!("/jobs/{first}/cancel"), None, "")
            .await,
        202,
    )
    .await;
    assert_eq!(c["cancel_requested"], true);
    let j = wait_state(&app, first, "cancelled").await;
    assert!(j["finished_at"].is_string());
    assert_eq!(j["calibration_id"], serde_json::Value::Null);
    // An ended job cannot be cancelled again.
    err_json(
        app.post_raw(&format!("/jobs/{first}/cancel"), None, "")
            .await,
        409,
        "conflict",
    )
    .await;
    assert_eq!(
        started.load(Ordering::SeqCst),
        1,
        "the cancelled queued job never ran"
    );

    // A job that fails says why.
    let third = enqueue(&app, sid).await;
    wait_state(&app, third, "running").await;
    let failed = app.wait_job(third, Duration::from_secs(60)).await;
    assert_eq!(failed["state"], "failed");
    assert!(
        failed["error"]
            .as_str()
            .unwrap()
            .contains("stand-in engine finished"),
        "{failed}"
    );
    let list = validate_response(
        "get",
        "/jobs",
        app.get(&format!("/jobs?session_id={sid}&state=cancelled"))
            .await,
    )
    .await;
    assert_eq!(list["total"], 2);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_hands_a_running_job_back_and_restart_runs_it() {
    let started = Arc::new(AtomicUsize::new(0));
    let app = TestApp::spawn_with(
        "handback",
        Options {
            job_fn: slow_job_fn(100_000, Duration::from_millis(10), started.clone()),
            grace: Duration::from_millis(300),
            ..Options::default()
        },
    )
    .await;
    let sid = session_with_poses(&app, "JOB-2").await;
    let job = enqueue(&app, sid).await;
    wait_state(&app, job, "running").await;
    let db = app.db_url.clone();
    app.stop().await; // graceful: grace period over, job handed back

    // Restart on the same database with a short stand-in: it is picked up.
    let started2 = Arc::new(AtomicUsize::new(0));
    let app = TestApp::spawn_on(
        &db,
        Options {
            job_fn: slow_job_fn(5, Duration::from_millis(10), started2.clone()),
            ..Options::default()
        },
    )
    .await;
    let j = app.wait_job(job, Duration::from_secs(60)).await;
    assert_eq!(
        started2.load(Ordering::SeqCst),
        1,
        "the restarted service ran the job"
    );
    assert_eq!(j["state"], "failed"); // the stand-in always ends in failure
    assert_eq!(
        (&j["attempts"], &j["interruptions"]),
        (&serde_json::Value::from(1), &serde_json::Value::from(0)),
        "the handed-back claim counted neither as an attempt nor as an interruption: {j}"
    );
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_that_panics_is_run_again_then_ends_saying_why() {
    let runs = Arc::new(AtomicUsize::new(0));
    let counted = runs.clone();
    let app = TestApp::spawn_with(
        "panics",
        Options {
            job_fn: Arc::new(move |_input, _progress| {
                counted.fetch_add(1, Ordering::SeqCst);
                panic!("a stand-in engine that always panics")
            }),
            ..Options::default()
        },
    )
    .await;
    let sid = session_with_poses(&app, "JOB-PANIC").await;
    let job = enqueue(&app, sid).await;
    let j = wait_state(&app, job, "failed").await;
    // A panic may be a resource's, not the data's: run again until the
    // attempts (3 in the test app, as by default) are used up.
    assert_eq!(runs.load(Ordering::SeqCst), 3, "{j}");
    assert_eq!((&j["attempts"], &j["max_attempts"]), (&json!(3), &json!(3)));
    assert_eq!(j["interruptions"], 0, "{j}");
    assert_eq!(j["error"], "internal error: the engine panicked", "{j}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn compensation_checks_targets_and_calibration_owner() {
    let app = TestApp::spawn("comp").await;
    let (_, robot_a, _, sid) = app.setup(DS, "COMP-A").await;
    app.upload_poses(sid, read(DS, "poses.csv")).await;
    let job = enqueue(&app, sid).await;
    let done = app.wait_job(job, Duration::from_secs(600)).await;
    assert_eq!(done["state"], "succeeded", "{done}");
    let cal = done["calibration_id"].as_i64().unwrap();
    let robot_b = ok_json(
        app.post_json(
            "/robots",
            &json!({"serial_number": "COMP-B", "model_id": 1}),
        )
        .await,
        201,
    )
    .await["id"]
        .as_i64()
        .unwrap();
    let before = app.snapshot().await;
    // Another robot's calibration: neither activation nor compensation.
    err_json(
        app.post_json(
            &format!("/robots/{robot_b}/activate"),
            &json!({"calibration_id": cal, "reason": "r"}),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    let e = err_json(
        app.post_json("/compensate", &json!({"robot_id": robot_b, "calibration_id": cal, "target": {"target": "t", "q_deg": [0, 0, 0, 0, 0, 0]}})).await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "calibration_id");
    // Wrong number of joints, non-finite values, both kinds, duplicates: row named.
    let bad = [
        (
            json!([{"target": "a", "q_deg": [0, 0, 0, 0, 0, 0]}, {"target": "b", "q_deg": [0, 0, 0]}]),
            "targets[1].q_deg",
            2,
        ),
        (
            json!([{"target": "a", "xyz_mm": [1, 2, 3]}, {"target": "a", "xyz_mm": [1, 2, 3]}]),
            "targets[1].target",
            2,
        ),
        (
            json!([{"target": "a", "xyz_mm": [1, 2, 3], "q_deg": [0, 0, 0, 0, 0, 0]}]),
            "targets[0].q_deg",
            1,
        ),
        (json!([{"target": "a"}]), "targets[0].q_deg", 1),
        (json!([]), "targets", 0),
    ];
    for (targets, field, row) in bad {
        let e = err_json(
            app.post_json(
                "/compensate",
                &json!({"robot_id": robot_a, "calibration_id": cal, "targets": targets}),
            )
            .await,
            422,
            "invalid_input",
        )
        .await;
        assert_eq!(e["field"], field, "{e}");
        if row > 0 {
            assert_eq!(e["row"], row, "{e}");
        }
    }
    let many: Vec<serde_json::Value> = (0..10_001)
        .map(|i| json!({"target": i.to_string(), "q_deg": [0, 0, 0, 0, 0, 0]}))
        .collect();
    let e = err_json(
        app.post_json(
            "/compensate",
            &json!({"robot_id": robot_a, "calibration_id": cal, "targets": many}),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "targets");
    assert_eq!(before, app.snapshot().await);
    // Joint-limit and unreachable targets are per-target results, never a failed batch.
    let out = ok_json(
        app.post_json(
            "/compensate",
            &json!({"robot_id": robot_a, "calibration_id": cal, "targets": [
                {"target": "in", "q_deg": [10, -20, 30, 0, 40, 0]},
                {"target": "limit", "q_deg": [169.99, -20, 30, 0, 40, 0]},
                {"target": "far", "xyz_mm": [0, 0, 9000]}
            ]}),
        )
        .await,
        200,
    )
    .await;
    let st: Vec<&str> = out["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["status"].as_str().unwrap())
        .collect();
    assert_eq!(st[0], "ok");
    assert_eq!(st[2], "unreachable");
    assert_eq!(
        out["n_ok"].as_u64().unwrap() as usize,
        st.iter().filter(|s| **s == "ok").count()
    );
    app.stop().await;
}

/// Cancel with the real engine and the default 15 s lease: a job of about
/// two seconds (the UR10 grid, 11,911 poses) asked to stop at once ends
/// `cancelled` with no calibration. Before, the flag reached the engine
/// only with the heartbeat every lease/3 = 5 s and the physics analysis
/// never looked at it: such a job always ended `succeeded`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_running_engine_job_cancels_within_the_lease() {
    let app = TestApp::spawn_with(
        "cancel-engine",
        Options {
            max_upload_bytes: 4 * 1024 * 1024,
            ..Options::default()
        },
    )
    .await;
    let ds = "real_ur10_ipa_grid";
    let (_, _, _, sid) = app.setup(ds, "UR10-CANCEL").await;
    app.upload_poses(sid, read(ds, "poses.csv")).await;
    let job = enqueue(&app, sid).await;
    let c = ok_json(
        app.post_raw(&format!("/jobs/{job}/cancel"), None, "").await,
        202,
    )
    .await;
    assert_eq!(c["cancel_requested"], true);
    let j = app.wait_job(job, Duration::from_secs(60)).await;
    assert_eq!(j["state"], "cancelled", "{j}");
    assert_eq!(j["calibration_id"], serde_json::Value::Null);
    let cals = ok_json(app.get("/calibrations").await, 200).await;
    assert_eq!(cals["total"], 0, "{cals}");
    app.stop().await;
}

/// A cancel that reaches the engine only as it finishes still wins, and the
/// job says why its progress reads 100 % yet no calibration came of it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cancel_as_the_job_finishes_stores_nothing_and_says_so() {
    // An engine that sees the cancel flag, then returns its result anyway
    // (as one does when the flag comes after its last look).
    let job_fn: drawcal::jobs::JobFn = Arc::new(|input, progress| {
        progress.update("finishing", 1.0);
        while !progress.cancelled() {
            std::thread::sleep(Duration::from_millis(10));
        }
        drawcal::pipeline::calibrate(
            &input.robot,
            &input.rig,
            &input.data,
            &input.options,
            &drawcal::identify::NoProgress,
        )
    });
    let app = TestApp::spawn_with(
        "cancel-at-end",
        Options {
            job_fn,
            lease: Duration::from_millis(600),
            ..Options::default()
        },
    )
    .await;
    let sid = session_with_poses(&app, "JOB-END").await;
    let job = enqueue(&app, sid).await;
    wait_state(&app, job, "running").await;
    ok_json(
        app.post_raw(&format!("/jobs/{job}/cancel"), None, "").await,
        202,
    )
    .await;
    let j = wait_state(&app, job, "cancelled").await;
    assert_eq!(j["calibration_id"], serde_json::Value::Null, "{j}");
    assert_eq!(j["error"], drawcal::jobs::CANCELLED_AS_IT_FINISHED, "{j}");
    let cals = ok_json(app.get("/calibrations").await, 200).await;
    assert_eq!(cals["total"], 0, "{cals}");
    app.stop().await;
}

/// Job options reach the engine: a parameter held by request is held, and
/// `undetermined_z: 0` keeps the wrist pair these data do not determine.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn held_parameters_reach_the_calibration() {
    let app = TestApp::spawn("hold").await;
    let (_, _, _, sid) = app.setup(DS, "HOLD").await;
    let options = json!({"hold": ["j2.a"], "undetermined_z": 0.0, "physics": false});
    let j = app
        .identify_session_with(sid, read(DS, "poses.csv"), &options)
        .await;
    let cal = ok_json(
        app.get(&format!("/calibrations/{}", j["calibration_id"]))
            .await,
        200,
    )
    .await;
    let fixed = cal["report"]["identifiability"]["fixed"]
        .as_array()
        .unwrap();
    let reason = |name: &str| {
        fixed
            .iter()
            .find(|f| f["name"] == name)
            .map(|f| f["reason"].clone())
    };
    assert_eq!(reason("j2.a"), Some(json!("requested")), "{fixed:?}");
    assert!(
        fixed.iter().all(|f| f["reason"] != "undetermined"),
        "{fixed:?}"
    );
    app.stop().await;
}

/// `free_set` reaches the calibration: the joint offsets alone, as asked.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_requested_free_set_reaches_the_calibration() {
    let app = TestApp::spawn("free-set").await;
    let (_, _, _, sid) = app.setup(DS, "FREE").await;
    let options = json!({"free_set": "offsets", "physics": false});
    let j = app
        .identify_session_with(sid, read(DS, "poses.csv"), &options)
        .await;
    let cal = ok_json(
        app.get(&format!("/calibrations/{}", j["calibration_id"]))
            .await,
        200,
    )
    .await;
    let f = &cal["report"]["free_set"];
    assert_eq!(
        (&f["chosen"], &f["how"]),
        (&json!("offsets"), &json!("requested")),
        "{f}"
    );
    let fixed = cal["report"]["identifiability"]["fixed"]
        .as_array()
        .unwrap();
    assert!(
        fixed
            .iter()
            .any(|p| p["name"] == "j2.a" && p["reason"] == "free_set"),
        "{fixed:?}"
    );
    app.stop().await;
}

/// A calibration with nothing held out (a `holdout_fraction` that rounds
/// to no pose, on a file
/// without a split column) has no held-out figures: null in the
/// calibration and out of an accuracy filter. Before, the empty set's 0.0
/// was stored and it ranked as the fleet's most accurate calibration.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_held_out_poses_no_held_out_accuracy() {
    let app = TestApp::spawn("no-holdout").await;
    let (_, _, _, sid) = app.setup(DS, "NO-HOLDOUT").await;
    // The file without its split column.
    let csv = read(DS, "poses.csv");
    let no_split: String = csv
        .lines()
        .map(|l| l.rsplit_once(',').unwrap().0)
        .collect::<Vec<_>>()
        .join("\n");
    assert!(!no_split.lines().next().unwrap().contains("split"));
    app.upload_poses(sid, no_split).await;
    let job = ok_json(
        app.post_raw(
            &format!("/sessions/{sid}/jobs"),
            Some("application/json"),
            // 0.001 of 50 poses rounds to none held out.
            json!({"holdout_fraction": 0.001}).to_string(),
        )
        .await,
        202,
    )
    .await;
    let j = app
        .wait_job(job["id"].as_i64().unwrap(), Duration::from_secs(120))
        .await;
    assert_eq!(j["state"], "succeeded", "{j}");
    let cal = ok_json(
        app.get(&format!("/calibrations/{}", j["calibration_id"]))
            .await,
        200,
    )
    .await;
    let c = &cal["calibration"];
    assert_eq!(c["n_test"], 0, "{c}");
    assert!(c["test_rms_after_mm"].is_null(), "{c}");
    assert!(c["test_rms_before_mm"].is_null(), "{c}");
    // The report itself has no held-out figures either, rather than zeros.
    let test = &cal["report"]["stats"]["test"];
    assert_eq!(test["n"], 0, "{test}");
    for model in ["before", "after"] {
        assert!(test[model]["rms_mm"].is_null(), "{test}");
        assert!(test[model]["x"]["max_abs_mm"].is_null(), "{test}");
    }
    let best = ok_json(app.get("/calibrations?max_test_rms_mm=0.001").await, 200).await;
    assert_eq!(best["total"], 0, "{best}");
    app.stop().await;
}

/// Poses whose joint angles all look like radians: the job fails with the
/// reason and how to insist, and no calibration is stored; with
/// `"force": true` it calibrates, the warning in the report.
#[tokio::test]
async fn a_session_in_radians_fails_unless_forced() {
    let app = TestApp::spawn("radians").await;
    let ds = "er3a_paper_like";
    let (_, _, _, session) = app.setup(ds, "ER3A-RAD").await;
    let rad = crate::common::q_columns_in_radians(&read(ds, "poses.csv"), None);
    ok_json(
        app.post_raw(&format!("/sessions/{session}/poses"), Some("text/csv"), rad)
            .await,
        200,
    )
    .await;
    let run = |body: &'static str| {
        let app = &app;
        async move {
            let job = ok_json(
                app.post_raw(
                    &format!("/sessions/{session}/jobs"),
                    Some("application/json"),
                    body,
                )
                .await,
                202,
            )
            .await;
            app.wait_job(job["id"].as_i64().unwrap(), Duration::from_secs(120))
                .await
        }
    };
    let refused = run("{}").await;
    assert_eq!(refused["state"], "failed", "{refused}");
    let why = refused["error"].as_str().unwrap();
    assert!(
        why.contains("not calibrated: the joint angles look like radians")
            && why.contains("\"force\": true"),
        "{why}"
    );
    assert!(refused["calibration_id"].is_null(), "{refused}");
    let forced = run(r#"{"force": true}"#).await;
    assert_eq!(forced["state"], "succeeded", "{forced}");
    let cal = forced["calibration_id"].as_i64().unwrap();
    let rep = ok_json(app.get(&format!("/calibrations/{cal}")).await, 200).await;
    assert!(
        rep["report"]["warnings"][0]
            .as_str()
            .unwrap()
            .starts_with("the joint angles look like radians"),
        "{}",
        rep["report"]["warnings"]
    );
}
