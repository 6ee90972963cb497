//! `POST /compensate` with a calibration that accepted a backlash: where a
//! joint stops depends on the side it arrives from. `approach` (JSON body
//! or query string) says how the joints arrive: `positive` (default),
//! `negative`, or `in_order` (the targets are visited in request order);
//! the answer says which was used (`approach_used`, `X-Approach-Used`).

use serde_json::{Value, json};

use crate::helpers::{TestApp, err_json, q_at};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn approach_follows_a_backlash_calibration() {
    let app = TestApp::spawn("compbacklash").await;
    let spec = json!({
        "robot": "er3a",
        "n_poses": 150,
        "seed": 31,
        "effects": [{"effect": "backlash", "joint": 2, "size_x_noise": 10}]
    });
    let (robot, _, _) = app.calibrate_simulated(spec, "BACKLASH-1").await;
    let ask = |body: Value| {
        let app = &app;
        async move { crate::openapi::compensate(app, &body).await }
    };
    // Joint 2 goes down from the first target to the second.
    let targets = json!([
        {"target": "up", "q_deg": [10, -10, 30, 0, 40, 0]},
        {"target": "down", "q_deg": [10, -30, 30, 0, 40, 0]}
    ]);
    let default = ask(json!({"robot_id": robot, "targets": targets})).await;
    assert_eq!(default["approach_used"], "positive", "{default}");
    let negative =
        ask(json!({"robot_id": robot, "targets": targets, "approach": "negative"})).await;
    assert_eq!(negative["approach_used"], "negative");
    let moved = q_at(&negative, 0)
        .iter()
        .zip(q_at(&default, 0))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        moved > 1e-3,
        "the side joint 2 arrives from matters ({moved} deg)"
    );
    // In order: the first target arrives as the start (+q), the second
    // with joint 2 moving down, as the all-negative answer has it.
    let in_order =
        ask(json!({"robot_id": robot, "targets": targets, "approach": "in_order"})).await;
    assert_eq!(in_order["approach_used"], "in_order");
    assert_eq!(q_at(&in_order, 0), q_at(&default, 0));
    let d: f64 = q_at(&in_order, 1)
        .iter()
        .zip(q_at(&negative, 1))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(d < 1e-6, "{in_order} vs {negative}");

    // targets.csv with approach in the query string; the CSV answer says it.
    let csv = "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\nup,10,-10,30,0,40,0\ndown,10,-30,30,0,40,0\n";
    let r = app
        .client
        .post(app.url(&format!("/compensate?robot_id={robot}&approach=in_order")))
        .header("content-type", "text/csv")
        .header("accept", "text/csv")
        .body(csv)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["x-approach-used"], "in_order");
    // An approach that is not one: a 4xx naming it.
    let e = app
        .post_json(
            "/compensate",
            &json!({"robot_id": robot, "targets": targets, "approach": "sideways"}),
        )
        .await;
    let status = e.status().as_u16();
    let text = e.text().await.unwrap();
    assert!((400..500).contains(&status), "{status} {text}");
    assert!(text.contains("approach"), "{text}");
    let r = app
        .client
        .post(app.url(&format!("/compensate?robot_id={robot}&approach=sideways")))
        .header("content-type", "text/csv")
        .body(csv)
        .send()
        .await
        .unwrap();
    let e = err_json(r, 400, "bad_request").await;
    assert!(e.to_string().contains("approach"), "{e}");
    // With a JSON body the options go in the body; one in the query string
    // is refused naming it (not robot_id, which the body gives).
    let r = app
        .client
        .post(app.url("/compensate?approach=in_order"))
        .json(&json!({"robot_id": robot, "targets": targets}))
        .send()
        .await
        .unwrap();
    let e = err_json(r, 422, "invalid_input").await;
    assert_eq!(e["field"], "approach", "{e}");
    app.stop().await;
}
