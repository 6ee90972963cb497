//! The simulator writes the shared datasets' files, readable by the
//! engine, with readings that agree with truth.json's true points.

use drawcal::cli::simulate::write;
use drawcal::model::{Dataset, Rig, Robot};
use drawcal::physics::simulate::{Spec, generate};

#[test]
fn writes_consistent_files() {
    let spec: Spec = serde_json::from_str(
        r#"{"robot": "ur5", "n_poses": 40, "seed": 11,
            "effects": [{"effect": "backlash", "joint": 3, "magnitude": 0.02}]}"#,
    )
    .unwrap();
    let sim = generate(&spec).unwrap();
    let dir = std::env::temp_dir().join(format!("drawcal_sim_{}", std::process::id()));
    write(&sim, &dir).unwrap();
    let robot =
        Robot::from_json(&std::fs::read_to_string(dir.join("robot.json")).unwrap()).unwrap();
    let rig = Rig::from_json(&std::fs::read_to_string(dir.join("rig.json")).unwrap()).unwrap();
    let data = Dataset::from_csv(
        std::fs::File::open(dir.join("poses.csv")).unwrap(),
        &robot,
        &rig,
    )
    .unwrap();
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    assert_eq!(data.poses.len(), 40);
    let pts = truth["true_points_mm"].as_array().unwrap();
    let r = rig.r_mm;
    let bound = 5.0 * 0.02 + 0.024;
    for (pose, t) in data.poses.iter().zip(pts) {
        assert!(pose.time_s.is_some() && pose.temp_c.is_some());
        for (j, q) in pose.q_rad.iter().enumerate() {
            let d = q.to_degrees();
            assert!(d >= robot.joints[j].q_min_deg && d <= robot.joints[j].q_max_deg);
        }
        let t = nalgebra::Vector3::new(
            t[0].as_f64().unwrap(),
            t[1].as_f64().unwrap(),
            t[2].as_f64().unwrap(),
        );
        if let drawcal::model::Measurement::Strings(l) = &pose.measurement {
            for (k, v) in l.iter().enumerate() {
                let exact = (t - rig.anchor(k)).norm() - r;
                assert!(
                    (v - exact).abs() < bound,
                    "pose {} string {k}: {v} vs {exact}",
                    pose.id
                );
            }
        } else {
            panic!("string data expected");
        }
    }
    // Time increases along the tour.
    assert!(data.poses.windows(2).all(|w| w[1].time_s > w[0].time_s));
    assert_eq!(truth["effects"][0]["effect"], "backlash");
    assert!((truth["effects"][0]["magnitude"].as_f64().unwrap() - 0.02).abs() < 1e-12);
    std::fs::remove_dir_all(&dir).ok();
}
