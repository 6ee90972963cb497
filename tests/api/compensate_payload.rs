//! `POST /compensate` with a calibration that accepted a joint compliance:
//! `payload_kg` (JSON body, or the query string for targets.csv) changes
//! the joints and is reported back in `payload_kg_used`
//! (`X-Payload-Kg-Used` on compensated.csv); the default is the calibration
//! session's median payload; a payload out of range is refused naming the
//! field; without a compliance `payload_kg_used` is null and the payload
//! changes nothing.

use serde_json::{Value, json};

use crate::helpers::{TestApp, err_json, q_at};
use crate::openapi::validate_response;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn payload_kg_moves_a_compliant_calibration_and_is_reported() {
    let app = TestApp::spawn("comppayload").await;
    // Test weights of 0, 12 and 4 kg swapped part-way (median 4 kg).
    let spec = json!({
        "robot": "er3a",
        "n_poses": 120,
        "seed": 5,
        "session": {"payload_kg": [0.0, 12.0, 4.0]},
        "effects": [{"effect": "joint_compliance", "joint": 2, "size_x_noise": 10}]
    });
    let (robot, cal, _) = app.calibrate_simulated(spec, "PAYLOAD-1").await;
    let target = json!({"target": "t1", "q_deg": [10, -20, 30, 0, 40, 0]});
    let ask = |body: Value| {
        let app = &app;
        async move { crate::openapi::compensate(app, &body).await }
    };

    let default = ask(json!({"robot_id": robot, "target": target})).await;
    assert_eq!(default["calibration_id"], cal);
    assert_eq!(default["results"][0]["status"], "ok", "{default}");
    assert_eq!(default["payload_kg_used"].as_f64(), Some(4.0), "{default}");
    assert!(default["temp_c_used"].is_null(), "{default}");

    let heavy = ask(json!({"robot_id": robot, "target": target, "payload_kg": 12.0})).await;
    assert_eq!(heavy["payload_kg_used"].as_f64(), Some(12.0));
    let moved = q_at(&heavy, 0)
        .iter()
        .zip(q_at(&default, 0))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(moved > 1e-3, "8 kg more moves the joints ({moved} deg)");
    // The session's payload given explicitly: the same as none.
    let same = ask(json!({"robot_id": robot, "target": target, "payload_kg": 4.0})).await;
    assert_eq!(q_at(&same, 0), q_at(&default, 0));
    // A batch on the compute threads, with a temperature that does not
    // matter here, uses the payload too.
    let batch: Vec<Value> = (0..8)
        .map(|i| json!({"target": format!("b{i}"), "q_deg": [10, -20, 30, 0, 40, 0]}))
        .collect();
    let heavy_batch = ask(json!({
        "robot_id": robot, "targets": batch, "payload_kg": 12.0, "temp_c": 30.0
    }))
    .await;
    assert_eq!(
        heavy_batch["results"][7]["q_deg"],
        heavy["results"][0]["q_deg"]
    );
    assert!(heavy_batch["temp_c_used"].is_null());
    let notes: Vec<&str> = heavy_batch["notes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    assert!(
        notes.iter().any(|n| n.starts_with("temp_c is not used"))
            && notes.iter().any(|n| n.contains("payload of 12 kg")),
        "{notes:?}"
    );

    // targets.csv with payload_kg in the query string; compensated.csv
    // carries it in X-Payload-Kg-Used.
    let csv = "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\nt1,10,-20,30,0,40,0\n";
    let post_csv = |query: String, accept: Option<&'static str>| {
        let app = &app;
        async move {
            let mut r = app
                .client
                .post(app.url(&format!("/compensate?robot_id={robot}{query}")))
                .header("content-type", "text/csv");
            if let Some(a) = accept {
                r = r.header("accept", a);
            }
            r.body(csv).send().await.unwrap()
        }
    };
    let csv_json = validate_response(
        "post",
        "/compensate",
        post_csv("&payload_kg=12".into(), None).await,
    )
    .await;
    assert_eq!(csv_json, heavy);
    let r = post_csv("&payload_kg=12".into(), Some("text/csv")).await;
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["x-payload-kg-used"], "12");
    assert!(r.headers().get("x-temp-c-used").is_none());

    // Bad payloads: 422 naming payload_kg, in the body and in the query.
    for bad in [-1.0, 1e6] {
        let e = err_json(
            app.post_json(
                "/compensate",
                &json!({"robot_id": robot, "target": target, "payload_kg": bad}),
            )
            .await,
            422,
            "invalid_input",
        )
        .await;
        assert_eq!(e["field"], "payload_kg", "{e}");
    }
    for bad in ["NaN", "-inf", "6000"] {
        let e = err_json(
            post_csv(format!("&payload_kg={bad}"), None).await,
            422,
            "invalid_input",
        )
        .await;
        assert_eq!(e["field"], "payload_kg", "{bad}: {e}");
    }
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn payload_kg_used_is_null_without_a_compliance() {
    let app = TestApp::spawn("compnopayload").await;
    let ds = "er3a_paper_like";
    let (_, robot, _, session) = app.setup(ds, "NOPAYLOAD-1").await;
    let done = app
        .identify_session(session, crate::helpers::read(ds, "poses.csv"))
        .await;
    let cal = done["calibration_id"].as_i64().unwrap();
    let target = json!({"target": "t1", "q_deg": [10, -20, 30, 0, 40, 0]});
    let ask = |extra: Value| {
        let app = &app;
        let mut body = json!({"robot_id": robot, "calibration_id": cal, "target": target});
        body.as_object_mut()
            .unwrap()
            .extend(extra.as_object().unwrap().clone());
        async move { crate::openapi::compensate(app, &body).await }
    };
    let plain = ask(json!({})).await;
    assert!(plain["payload_kg_used"].is_null(), "{plain}");
    assert!(plain["approach_used"].is_null(), "no backlash: {plain}");
    let with = ask(json!({"payload_kg": 25.0})).await;
    assert!(with["payload_kg_used"].is_null(), "{with}");
    assert_eq!(with["results"], plain["results"]);
    app.stop().await;
}
