//! The service's bound on a joint target's compensation
//! (`--max-joint-change-deg`, `ServiceConfig::max_joint_change_deg`): a
//! target whose compensation moves a joint further is answered
//! `joint_change` with the joint, how far and the bound, never with joints
//! to send; the rest of the batch is compensated.

use serde_json::json;

use crate::helpers::{Options, TestApp};
use crate::openapi::validate_response;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_change_beyond_the_services_bound_is_refused_per_target() {
    let app = TestApp::spawn_with(
        "compbound",
        Options {
            // The ER3A's calibration moves these targets' joints by 1.10 to
            // 1.50 deg (their largest change, `drawcal compensate` on the
            // same calibration): a bound of 1.3 deg refuses some and not
            // others.
            max_joint_change_deg: 1.3,
            ..Options::default()
        },
    )
    .await;
    let ds = "er3a_paper_like";
    let (_, robot, _, session) = app.setup(ds, "BOUND-1").await;
    let done = app
        .identify_session(session, crate::helpers::read(ds, "poses.csv"))
        .await;
    let cal = done["calibration_id"].as_i64().unwrap();
    let targets: Vec<_> = (0..12)
        .map(|i| {
            let k = i as f64;
            json!({"target": format!("t{i}"), "q_deg": [10.0 * k - 60.0, -20.0 + k, 30.0, 5.0 * k, 40.0, 0.0]})
        })
        .collect();
    let answer = validate_response(
        "post",
        "/compensate",
        app.post_json(
            "/compensate",
            &json!({"robot_id": robot, "calibration_id": cal, "targets": targets}),
        )
        .await,
    )
    .await;
    let results = answer["results"].as_array().unwrap();
    let refused: Vec<_> = results
        .iter()
        .filter(|r| r["status"] == "joint_change")
        .collect();
    assert!(!refused.is_empty(), "{answer}");
    for r in &refused {
        assert!(r["q_deg"].is_null(), "{r}");
        let m = r["message"].as_str().unwrap();
        assert!(
            m.starts_with("joint ") && m.contains("would move") && m.contains("1.3 deg bound"),
            "{m}"
        );
    }
    // The rest is compensated, each joint within the bound.
    let ok: Vec<_> = results.iter().filter(|r| r["status"] == "ok").collect();
    assert!(!ok.is_empty(), "{answer}");
    assert_eq!(ok.len() + refused.len(), results.len(), "{answer}");
    for (r, t) in results.iter().zip(&targets) {
        if r["status"] == "ok" {
            let moved = crate::helpers::q_at(&json!({"results": [r]}), 0)
                .iter()
                .zip(t["q_deg"].as_array().unwrap())
                .map(|(a, b)| (a - b.as_f64().unwrap()).abs())
                .fold(0.0, f64::max);
            assert!(moved <= 1.3, "{r}");
        }
    }
    app.stop().await;
}
