//! Pose plans (`POST /plans`): `drawcal plan` as a background job, its
//! answer in the CLI's form (poses, report, targets.csv), strict options,
//! roles and sites.

use std::time::Duration;

use serde_json::{Value, json};

use crate::helpers::{TestApp, client_with_key, err_json, ok_json, read};
use crate::openapi::validate_response;

const DS: &str = "er3a_paper_like";

/// Small enough to plan in a moment in a test build, and enough poses to
/// determine every parameter of the er3a on its rig.
fn small(extra: Value) -> Value {
    let mut body = json!({"n_poses": 12, "n_check": 3, "candidates": 400, "seed": 3});
    for (k, v) in extra.as_object().unwrap() {
        body[k] = v.clone();
    }
    body
}

/// Poll a plan until it ends.
async fn wait_plan(app: &TestApp, id: i64) -> Value {
    for _ in 0..600 {
        let p = ok_json(app.get(&format!("/plans/{id}")).await, 200).await;
        if ["succeeded", "failed"].contains(&p["state"].as_str().unwrap()) {
            return p;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("plan {id} did not end in time");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plan_from_a_stored_model_and_rig_in_the_clis_form() {
    let app = TestApp::spawn("plans").await;
    let (model, robot, rig, _) = app.setup(DS, "PLAN-1").await;
    let r = app
        .post_json("/plans", &small(json!({"model_id": model, "rig_id": rig})))
        .await;
    assert_eq!(r.headers()["location"], "/plans/1");
    let queued = validate_response("post", "/plans", r).await;
    assert!(
        ["queued", "running"].contains(&queued["state"].as_str().unwrap()),
        "{queued}"
    );
    assert_eq!(queued["options"]["candidates"], 400, "{queued}");
    assert_eq!(queued["created_by"], "test-admin");
    assert!(queued["poses"].is_null() && queued["targets_csv"].is_null());
    let id = queued["id"].as_i64().unwrap();

    let done = wait_plan(&app, id).await;
    assert_eq!(done["state"], "succeeded", "{done}");
    let done =
        validate_response("get", "/plans/{id}", app.get(&format!("/plans/{id}")).await).await;
    let report = &done["report"];
    assert_eq!(report["format"], "drawcal plan v1", "{report}");
    assert_eq!(
        (report["n_poses"].as_u64(), report["n_check"].as_u64()),
        (Some(12), Some(3))
    );
    assert!(report["predicted"]["holdout_rms_mm"].as_f64().unwrap() > 0.0);
    let poses = done["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 15);
    assert!(
        poses
            .iter()
            .all(|p| p["q_deg"].as_array().unwrap().len() == 6)
    );

    // targets.csv: n_poses train rows and the check rows, in the poses' order,
    // the same as the answer's copy.
    let r = app.get(&format!("/plans/{id}/targets.csv")).await;
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-type"], "text/csv");
    let csv = r.text().await.unwrap();
    assert_eq!(csv, done["targets_csv"].as_str().unwrap());
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,split")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 15, "{csv}");
    let split = |s: &str| rows.iter().filter(|r| r[7] == s).count();
    assert_eq!((split("train"), split("test")), (12, 3), "{csv}");
    for (row, pose) in rows.iter().zip(poses) {
        assert_eq!(row[0], pose["id"].as_str().unwrap());
    }

    // A robot's model is its model: the same request by robot gives the
    // same plan (the seed fixes it).
    let by_robot = ok_json(
        app.post_json("/plans", &small(json!({"robot_id": robot, "rig_id": rig})))
            .await,
        202,
    )
    .await;
    assert_eq!(by_robot["model_id"], model);
    let again = wait_plan(&app, by_robot["id"].as_i64().unwrap()).await;
    assert_eq!(again["targets_csv"], done["targets_csv"]);

    // Recorded in the audit log under the key's name.
    let audit = ok_json(app.get("/audit").await, 200).await;
    assert!(
        audit["items"]
            .as_array()
            .unwrap()
            .iter()
            .any(|a| a["action"] == "create_plan" && a["target"] == format!("plan {id}")),
        "{audit}"
    );
    app.stop().await;
}

/// Too few poses to determine the model: the plan still succeeds, its
/// predictions for N are `null` (not a number the rounding made of a
/// singular inverse, and not a 500 when the stored plan is read back) and a
/// note says which N of the curve does determine it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plan_too_small_to_determine_the_model_says_so() {
    let app = TestApp::spawn("plans-undetermined").await;
    let (model, _, rig, _) = app.setup(DS, "PLAN-U").await;
    let body = small(json!({"model_id": model, "rig_id": rig, "n_poses": 8}));
    let queued = ok_json(app.post_json("/plans", &body).await, 202).await;
    let id = queued["id"].as_i64().unwrap();
    assert_eq!(wait_plan(&app, id).await["state"], "succeeded");
    let done =
        validate_response("get", "/plans/{id}", app.get(&format!("/plans/{id}")).await).await;
    let report = &done["report"];
    assert!(report["predicted"]["holdout_rms_mm"].is_null(), "{report}");
    assert!(report["predicted"]["model_rms_mm"].is_null(), "{report}");
    let notes: Vec<&str> = report["notes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    let note = notes
        .iter()
        .find(|n| n.starts_with("8 poses do not determine every parameter"))
        .unwrap_or_else(|| panic!("{notes:?}"));
    // The N it names is one of the curve's, with a finite prediction.
    let enough: u64 = note
        .rsplit("; ")
        .next()
        .and_then(|t| t.strip_suffix(" poses do"))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{note}"));
    assert!(
        report["by_n"]
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p["n_poses"] == enough && p["model_rms_mm"].as_f64().is_some()),
        "{report}"
    );
    app.stop().await;
}

/// A payload planned for a compliance: the poses carry it in the answer
/// and targets.csv gains `payload_kg` before `split`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plan_with_a_payload_carries_it_per_pose() {
    let app = TestApp::spawn("plans-payload").await;
    let (model, _, rig, _) = app.setup(DS, "PLAN-4").await;
    let body = small(json!({"model_id": model, "rig_id": rig,
        "effects": ["joint_compliance"], "payload_kg": 8.0}));
    let queued = ok_json(app.post_json("/plans", &body).await, 202).await;
    let id = queued["id"].as_i64().unwrap();
    assert_eq!(wait_plan(&app, id).await["state"], "succeeded");
    let done =
        validate_response("get", "/plans/{id}", app.get(&format!("/plans/{id}")).await).await;
    let csv = done["targets_csv"].as_str().unwrap();
    assert!(
        csv.starts_with("target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,payload_kg,split\n"),
        "{csv}"
    );
    let loads: Vec<f64> = done["poses"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["payload_kg"].as_f64().unwrap())
        .collect();
    assert!(loads.iter().all(|&p| p == 0.0 || p == 8.0), "{loads:?}");
    assert_eq!(
        done["report"]["payload"]["payload_kg"], 8.0,
        "{}",
        done["report"]
    );
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_plans_are_refused_naming_the_field_and_store_nothing() {
    let app = TestApp::spawn("plans-bad").await;
    let (model, robot, rig, _) = app.setup(DS, "PLAN-2").await;
    let base = json!({"model_id": model, "rig_id": rig, "n_poses": 30});
    let with = |k: &str, v: Value| {
        let mut b = base.clone();
        b[k] = v;
        b
    };
    let cases: Vec<(Value, &str)> = vec![
        (with("n_poses", json!(2)), "n_poses"),
        (with("n_poses", json!(-3)), "n_poses"),
        (with("n", json!(30)), "n"),
        (with("candidates", json!(100)), "candidates"),
        (with("candidates", json!(1_000_000)), "candidates"),
        (with("n_check", json!(31)), "n_check"),
        (with("noise_mm", json!(0)), "noise_mm"),
        (with("effects", json!(["temperature"])), "effects"),
        (with("effects", json!(["backlash", "backlash"])), "effects"),
        (with("home_deg", json!([0, 0, 0])), "home_deg"),
        (with("payload_kg", json!(0)), "payload_kg"),
        (with("payload_kg", json!(6000)), "payload_kg"),
        (with("payload_kg", json!(10)), "payload_kg"),
        (
            with(
                "workspace",
                json!({"keep_out": [{"min_mm": [1, 0, 0], "max_mm": [0, 1, 1]}]}),
            ),
            "workspace.keep_out[0]",
        ),
        (
            with("workspace", json!({"min_string_mm": -1})),
            "workspace.min_string_mm",
        ),
        (with("workspace", json!({"floor": 0})), "workspace.floor"),
        (with("rig_id", json!(999)), "rig_id"),
        (with("model_id", json!(999)), "model_id"),
        (with("robot_id", json!(robot)), "robot_id"),
        (json!({"rig_id": rig, "n_poses": 30}), "model_id"),
        (json!({"model_id": model, "n_poses": 30}), "rig_id"),
        (
            json!({"robot_id": 999, "rig_id": rig, "n_poses": 30}),
            "robot_id",
        ),
    ];
    for (body, field) in cases {
        let e = err_json(app.post_json("/plans", &body).await, 422, "invalid_input").await;
        assert_eq!(e["field"], field, "{body}: {e}");
    }
    // A string rig must say where the robot stands.
    let mut loose: Value = serde_json::from_str(&read(DS, "rig.json")).unwrap();
    loose.as_object_mut().unwrap().remove("base_in_rig");
    let loose = ok_json(app.post_json("/rigs", &loose).await, 201).await;
    let e = err_json(
        app.post_json("/plans", &with("rig_id", loose["id"].clone()))
            .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "rig_id", "{e}");
    assert!(
        e["message"].as_str().unwrap().contains("base_in_rig"),
        "{e}"
    );
    // Nothing was queued.
    err_json(app.get("/plans/1").await, 404, "not_found").await;
    err_json(app.get("/plans/1/targets.csv").await, 404, "not_found").await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn plans_need_an_engineer_and_keep_to_the_keys_sites() {
    let app = TestApp::spawn("plans-roles").await;
    let (model, here, rig, _) = app.setup(DS, "PLAN-3").await;
    let there = ok_json(
        app.post_json(
            "/robots",
            &json!({"serial_number": "PLAN-4", "model_id": model, "site": "plant-2"}),
        )
        .await,
        201,
    )
    .await["id"]
        .as_i64()
        .unwrap();
    let key = |name: &str, role: &str, sites: Value| {
        let body = json!({"name": name, "role": role, "sites": sites});
        let app = &app;
        async move {
            let made = ok_json(app.post_json("/keys", &body).await, 201).await;
            client_with_key(made["secret"].as_str().unwrap())
        }
    };
    let reader = key("plan-reader", "reader", json!([])).await;
    let operator = key("plan-operator", "operator", json!([])).await;
    let local = key("plant-1-eng", "engineer", json!(["plant-1"])).await;
    let body = small(json!({"model_id": model, "rig_id": rig}));

    // No key: 401; a reader or an operator: 403.
    let anon = reqwest::Client::new();
    err_json(
        anon.post(app.url("/plans"))
            .json(&body)
            .send()
            .await
            .unwrap(),
        401,
        "unauthorized",
    )
    .await;
    for c in [&reader, &operator] {
        let e = err_json(
            c.post(app.url("/plans")).json(&body).send().await.unwrap(),
            403,
            "forbidden",
        )
        .await;
        assert!(
            e["message"].as_str().unwrap().contains("needs engineer"),
            "{e}"
        );
    }
    // A plan for a robot at another site is refused to a key limited to
    // sites; one at its site, or for a model, is planned.
    let at = |robot: i64| small(json!({"robot_id": robot, "rig_id": rig}));
    err_json(
        local
            .post(app.url("/plans"))
            .json(&at(there))
            .send()
            .await
            .unwrap(),
        403,
        "forbidden",
    )
    .await;
    let mine = ok_json(
        local
            .post(app.url("/plans"))
            .json(&at(here))
            .send()
            .await
            .unwrap(),
        202,
    )
    .await;
    let theirs = ok_json(app.post_json("/plans", &at(there)).await, 202).await;
    let (mine, theirs) = (mine["id"].as_i64().unwrap(), theirs["id"].as_i64().unwrap());
    wait_plan(&app, mine).await;
    // Readers read plans; the limited key not another site's.
    let r = reader
        .get(app.url(&format!("/plans/{mine}")))
        .send()
        .await
        .unwrap();
    assert_eq!(ok_json(r, 200).await["robot_id"], here);
    let r = local
        .get(app.url(&format!("/plans/{theirs}")))
        .send()
        .await
        .unwrap();
    err_json(r, 403, "forbidden").await;
    let r = local
        .get(app.url(&format!("/plans/{theirs}/targets.csv")))
        .send()
        .await
        .unwrap();
    err_json(r, 403, "forbidden").await;
    wait_plan(&app, theirs).await;
    app.stop().await;
}

/// The per-key job rate covers plans too.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn plans_count_against_the_keys_job_rate() {
    let app = TestApp::spawn_with(
        "plans-rate",
        crate::helpers::Options {
            limits: drawcal::http::limits::LimitConfig {
                jobs_per_minute: 1,
                ..Default::default()
            },
            ..Default::default()
        },
    )
    .await;
    let (model, _, rig, _) = app.setup(DS, "PLAN-5").await;
    let body = small(json!({"model_id": model, "rig_id": rig}));
    let first = ok_json(app.post_json("/plans", &body).await, 202).await;
    let r = app.post_json("/plans", &body).await;
    assert!(r.headers().contains_key("retry-after"));
    err_json(r, 429, "too_many_requests").await;
    // Not done yet or done: targets.csv only once it has succeeded.
    let id = first["id"].as_i64().unwrap();
    let r = app.get(&format!("/plans/{id}/targets.csv")).await;
    if r.status() == 409 {
        err_json(r, 409, "conflict").await;
    }
    assert_eq!(wait_plan(&app, id).await["state"], "succeeded");
    app.stop().await;
}
