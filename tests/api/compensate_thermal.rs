//! `POST /compensate` with a calibration that accepted thermal expansion
//! driven by the temperature: `temp_c` (JSON body, or the query string for
//! targets.csv) changes the joints and is reported back in `temp_c_used`
//! (`X-Temp-C-Used` on compensated.csv); a temperature out of range is
//! refused naming the field; without a thermal effect `temp_c_used` is null.

use serde_json::{Value, json};

use crate::helpers::{TestApp, err_json, q_at};
use crate::openapi::validate_response;

/// A robot with an active calibration of a simulated er3a session with
/// thermal expansion: (robot, calibration, reference temperature).
async fn thermal_calibration(app: &TestApp) -> (i64, i64, f64) {
    let spec = json!({
        "robot": "er3a",
        "n_poses": 120,
        "seed": 777,
        "effects": [{"effect": "thermal_expansion", "size_x_noise": 10}]
    });
    let (robot, cal, sim) = app.calibrate_simulated(spec, "THERMAL-1").await;
    (robot, cal, sim.dataset.poses[0].temp_c.unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn temp_c_moves_a_thermal_calibration_and_is_reported() {
    let app = TestApp::spawn("compthermal").await;
    let (robot, cal, t_ref) = thermal_calibration(&app).await;
    let target = json!({"target": "t1", "q_deg": [10, -20, 30, 0, 40, 0]});
    let ask = |body: Value| {
        let app = &app;
        async move { crate::openapi::compensate(app, &body).await }
    };

    // No temperature: the reference, and it says so.
    let at_ref = ask(json!({"robot_id": robot, "target": target})).await;
    assert_eq!(at_ref["calibration_id"], cal);
    assert_eq!(at_ref["results"][0]["status"], "ok", "{at_ref}");
    assert_eq!(at_ref["temp_c_used"].as_f64(), Some(t_ref), "{at_ref}");

    // 30 K warmer: other joints, and the temperature reported back.
    // Two decimals: the same number through JSON and the query string.
    let warm_t = ((t_ref + 30.0) * 100.0).round() / 100.0;
    let warm = ask(json!({"robot_id": robot, "target": target, "temp_c": warm_t})).await;
    assert_eq!(warm["results"][0]["status"], "ok", "{warm}");
    assert_eq!(warm["temp_c_used"].as_f64(), Some(warm_t));
    let moved = q_at(&warm, 0)
        .iter()
        .zip(q_at(&at_ref, 0))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        moved > 1e-3,
        "the temperature changes the joints ({moved} deg)"
    );
    // The reference temperature given explicitly: the same as none.
    let same = ask(json!({"robot_id": robot, "target": target, "temp_c": t_ref})).await;
    assert_eq!(q_at(&same, 0), q_at(&at_ref, 0));
    // The cache still holds the reference: asking again without one.
    let again = ask(json!({"robot_id": robot, "target": target})).await;
    assert_eq!(q_at(&again, 0), q_at(&at_ref, 0));

    // A batch big enough for the compute threads uses the temperature too.
    let batch: Vec<Value> = (0..8)
        .map(|i| json!({"target": format!("b{i}"), "q_deg": [10, -20, 30, 0, 40, 0]}))
        .collect();
    let warm_batch = ask(json!({"robot_id": robot, "targets": batch, "temp_c": warm_t})).await;
    assert_eq!(
        warm_batch["results"][7]["q_deg"],
        warm["results"][0]["q_deg"]
    );

    // targets.csv with temp_c in the query string; compensated.csv answer
    // carries it in X-Temp-C-Used.
    let csv = "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\nt1,10,-20,30,0,40,0\n";
    let r = app
        .client
        .post(app.url(&format!("/compensate?robot_id={robot}&temp_c={warm_t}")))
        .header("content-type", "text/csv")
        .body(csv)
        .send()
        .await
        .unwrap();
    let csv_json = validate_response("post", "/compensate", r).await;
    assert_eq!(csv_json, warm);
    let r = app
        .client
        .post(app.url(&format!("/compensate?robot_id={robot}&temp_c={warm_t}")))
        .header("content-type", "text/csv")
        .header("accept", "text/csv")
        .body(csv)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(
        r.headers()["x-temp-c-used"]
            .to_str()
            .unwrap()
            .parse::<f64>()
            .unwrap(),
        warm_t
    );

    // Bad temperatures: 422 naming temp_c, in the body and in the query.
    for bad in [500.0, -60.0] {
        let e = err_json(
            app.post_json(
                "/compensate",
                &json!({"robot_id": robot, "target": target, "temp_c": bad}),
            )
            .await,
            422,
            "invalid_input",
        )
        .await;
        assert_eq!(e["field"], "temp_c", "{e}");
    }
    for bad in ["NaN", "inf", "1e9"] {
        let r = app
            .client
            .post(app.url(&format!("/compensate?robot_id={robot}&temp_c={bad}")))
            .header("content-type", "text/csv")
            .body(csv)
            .send()
            .await
            .unwrap();
        let e = err_json(r, 422, "invalid_input").await;
        assert_eq!(e["field"], "temp_c", "{bad}: {e}");
    }
    // Not a number at all: a 4xx that names it.
    let r = app
        .client
        .post(app.url("/compensate"))
        .header("content-type", "application/json")
        .body(format!(
            r#"{{"robot_id": {robot}, "target": {target}, "temp_c": "warm"}}"#
        ))
        .send()
        .await
        .unwrap();
    let status = r.status().as_u16();
    let text = r.text().await.unwrap();
    assert!((400..500).contains(&status), "{status} {text}");
    assert!(text.contains("temp_c"), "{text}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn temp_c_used_is_null_without_a_thermal_effect() {
    let app = TestApp::spawn("compnothermal").await;
    let ds = "er3a_paper_like";
    let (_, robot, _, session) = app.setup(ds, "NOTHERMAL-1").await;
    let done = app
        .identify_session(session, crate::helpers::read(ds, "poses.csv"))
        .await;
    let cal = done["calibration_id"].as_i64().unwrap();
    let target = json!({"target": "t1", "q_deg": [10, -20, 30, 0, 40, 0]});
    let plain = validate_response(
        "post",
        "/compensate",
        app.post_json(
            "/compensate",
            &json!({"robot_id": robot, "calibration_id": cal, "target": target}),
        )
        .await,
    )
    .await;
    assert!(plain["temp_c_used"].is_null(), "{plain}");
    let with = validate_response(
        "post",
        "/compensate",
        app.post_json(
            "/compensate",
            &json!({"robot_id": robot, "calibration_id": cal, "target": target, "temp_c": 45.0}),
        )
        .await,
    )
    .await;
    assert!(with["temp_c_used"].is_null(), "{with}");
    assert_eq!(with["results"], plain["results"]);
    // ... and the answer says the temperature went unused, as the CLI does.
    assert_eq!(plain["notes"], serde_json::json!([]), "{plain}");
    let notes = with["notes"].as_array().unwrap();
    assert!(
        notes.len() == 1
            && notes[0]
                .as_str()
                .unwrap()
                .starts_with("temp_c is not used: the calibration has no thermal expansion"),
        "{with}"
    );
    app.stop().await;
}
