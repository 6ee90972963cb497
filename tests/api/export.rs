//! `GET /calibrations/{id}/export`: the stored calibration's model out as
//! `drawcal export` writes it, and the extra poses its verdict suggests.

use crate::helpers;

use std::time::Duration;

use drawcal::export::{self, ExportFormat};
use drawcal::physics::simulate::{self, GivenPose, Spec, SpecFiles};
use drawcal::plan::{Scene, Workspace};
use drawcal::report::Report;
use drawcal::rng::Rng;
use helpers::{TestApp, err_json, ok_json};

/// Calibrate `poses_csv` in a new session; the calibration id.
async fn calibrate(app: &TestApp, robot: &str, rig: &str, poses_csv: String, serial: &str) -> i64 {
    let (_, _, _, session) = app.setup_from(robot, rig, serial).await;
    ok_json(
        app.post_raw(
            &format!("/sessions/{session}/poses"),
            Some("text/csv"),
            poses_csv,
        )
        .await,
        200,
    )
    .await;
    let job = ok_json(
        app.post_raw(&format!("/sessions/{session}/jobs"), None, "")
            .await,
        202,
    )
    .await;
    let job = app
        .wait_job(job["id"].as_i64().unwrap(), Duration::from_secs(120))
        .await;
    assert_eq!(job["state"], "succeeded", "{job}");
    job["calibration_id"].as_i64().unwrap()
}

/// A simulated ER3A session of 30 poses in which joint 4 never turns (so
/// what only its turning shows is held at nominal), 10 random test poses.
fn joint_4_still() -> (String, String, String) {
    let (robot, rig, _) = simulate::preset("er3a").unwrap();
    let ws = Workspace::default();
    let scene = Scene::new(&robot, &rig, &ws).unwrap();
    let (c, _, _) = scene.sample(40, 4000, &mut Rng::new(7));
    let poses = c
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let mut q_deg = c.q_deg.clone();
            if i < 30 {
                q_deg[3] = 10.0;
            }
            GivenPose {
                id: format!("p{}", i + 1),
                q_deg,
                test: Some(i >= 30),
                payload_kg: None,
            }
        })
        .collect();
    let spec: Spec =
        serde_json::from_value(serde_json::json!({"robot": "er3a", "seed": 3})).unwrap();
    let sim = simulate::generate_with(
        &spec,
        SpecFiles {
            poses: Some(poses),
            ..Default::default()
        },
    )
    .unwrap();
    let dir = std::env::temp_dir().join(format!("drawcal-export-{}", std::process::id()));
    drawcal::cli::simulate::write(&sim, &dir).unwrap();
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap();
    let texts = (read("robot.json"), read("rig.json"), read("poses.csv"));
    let _ = std::fs::remove_dir_all(&dir);
    texts
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn exports_are_the_cli_texts_and_extra_targets_need_extra_poses() {
    let app = TestApp::spawn("export").await;
    err_json(
        app.get("/calibrations/999999/export?format=urdf").await,
        404,
        "not_found",
    )
    .await;
    let (robot, rig, poses) = joint_4_still();
    let cal = calibrate(&app, &robot, &rig, poses, "ER3A-EXPORT").await;
    let out = ok_json(app.get(&format!("/calibrations/{cal}")).await, 200).await;
    let report: Report = serde_json::from_value(out["report"].clone()).unwrap();
    assert!(
        report
            .extra_poses
            .as_ref()
            .is_some_and(|x| !x.poses.is_empty()),
        "the session suggests extra poses"
    );
    for (name, format, media) in [
        ("urdf", ExportFormat::Urdf, "application/xml"),
        ("robot-json", ExportFormat::RobotJson, "application/json"),
        ("csv", ExportFormat::Csv, "text/csv"),
        ("extra-targets", ExportFormat::ExtraTargets, "text/csv"),
    ] {
        let r = app
            .get(&format!("/calibrations/{cal}/export?format={name}"))
            .await;
        assert_eq!(r.status(), 200, "{name}");
        assert_eq!(r.headers()["content-type"], media, "{name}");
        let disposition = r.headers()["content-disposition"]
            .to_str()
            .unwrap()
            .to_string();
        assert!(
            disposition.starts_with("attachment; filename=\"calibration-"),
            "{disposition}"
        );
        let text = r.text().await.unwrap();
        assert_eq!(text, export::export(&report, format).unwrap(), "{name}");
    }
    // A calibration whose poses determine everything they can: nothing to
    // record next (the calibration's state refuses it, not the query).
    let ds = "er3a_paper_like";
    let full = calibrate(
        &app,
        &helpers::read(ds, "robot.json"),
        &helpers::read(ds, "rig.json"),
        helpers::read(ds, "poses.csv"),
        "ER3A-EXPORT-2",
    )
    .await;
    let e = err_json(
        app.get(&format!("/calibrations/{full}/export?format=extra-targets"))
            .await,
        409,
        "conflict",
    )
    .await;
    assert!(
        e["message"].as_str().unwrap().contains("no extra poses"),
        "{e}"
    );
    // An unknown format, or none, is refused before anything is read.
    for q in ["?format=step", "", "?format=urdf&x=1"] {
        let r = app.get(&format!("/calibrations/{cal}/export{q}")).await;
        assert!(
            r.status() == 400 || r.status() == 422,
            "{q}: {}",
            r.status()
        );
    }
    app.stop().await;
}
