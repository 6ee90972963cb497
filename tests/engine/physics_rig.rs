//! A rig that moved: simulated recordings with a concealed `rig_step` or
//! `rig_drift`, analysed blind, on string readings and on the same poses
//! turned into tracker-style point data. The effect is named, its change
//! point lands where it was put, the held-out error drops, and compensation
//! ignores it (the robot did not change, the rig did).

use crate::common;

use drawcal::identify::{IdentifyOptions, Observations};
use drawcal::model::{Dataset, Rig};
use drawcal::physics::{self, simulate};

fn spec(robot: &str, effect: &str, seed: u64) -> simulate::Spec {
    serde_json::from_value(serde_json::json!({
        "robot": robot,
        "n_poses": 100,
        "seed": seed,
        "effects": [{"effect": effect, "size_x_noise": 5, "at_fraction": 0.55}]
    }))
    .unwrap()
}

fn analyse(sim: &simulate::Simulated, rig: &Rig, data: &Dataset) -> physics::Analysis {
    common::analyse_blind(&sim.robot, rig, data).0
}

fn named(a: &physics::Analysis) -> Vec<&str> {
    a.findings
        .iter()
        .filter(|f| f.effect != "unexplained")
        .map(|f| f.effect.as_str())
        .collect()
}

/// The simulated recording as a tracker would give it: every pose's point
/// multilaterated from its (noisy) strings, in the rig frame.
fn as_point_data(sim: &simulate::Simulated) -> (Rig, Dataset) {
    let s = Observations::new(
        &sim.robot,
        &sim.rig,
        &sim.dataset,
        &IdentifyOptions::default(),
    )
    .unwrap();
    let base = sim.rig.base_in_rig.as_ref().unwrap();
    let n = sim.robot.dof();
    let m = sim.rig.anchors_mm.len();
    let mut lines = sim.poses_csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let mut out = Vec::new();
    let mut head: Vec<&str> = header[..=n].to_vec();
    head.extend(["x_mm", "y_mm", "z_mm"]);
    head.extend(&header[1 + n + m..]);
    out.push(head.join(","));
    for (line, p) in lines.zip(&s.measured) {
        let cells: Vec<&str> = line.split(',').collect();
        let mut row: Vec<String> = cells[..=n].iter().map(|c| c.to_string()).collect();
        row.extend([p.x, p.y, p.z].map(|v| format!("{v:.4}")));
        row.extend(cells[1 + n + m..].iter().map(|c| c.to_string()));
        out.push(row.join(","));
    }
    let rig = Rig::from_json(
        &serde_json::json!({
            "anchors_mm": [],
            "r_mm": 0.0,
            "base_in_rig": base,
            "instrument": "tracker (simulated)"
        })
        .to_string(),
    )
    .unwrap();
    let data = Dataset::from_csv(out.join("\n").as_bytes(), &sim.robot, &rig).unwrap();
    (rig, data)
}

#[test]
fn a_rig_step_is_named_with_its_time_on_strings_and_on_points() {
    let sim = simulate::generate(&spec("er3a", "rig_step", 31)).unwrap();
    let t_true = sim.effects[0].kind.change_time_s().unwrap();
    let last = sim.dataset.poses.last().unwrap().time_s.unwrap();
    let (point_rig, point_data) = as_point_data(&sim);
    for (what, a) in [
        ("strings", analyse(&sim, &sim.rig, &sim.dataset)),
        ("points", analyse(&sim, &point_rig, &point_data)),
    ] {
        assert_eq!(named(&a), vec!["rig_step"], "{what}: {:#?}", a.findings);
        let f = &a.findings[0];
        let effect = physics::effects_of(std::slice::from_ref(f));
        let t0 = effect[0].kind.change_time_s().unwrap();
        // Within a few poses of the true move (the session is ~`last` s).
        assert!(
            (t0 - t_true).abs() < 0.05 * last,
            "{what}: change at {t0} s, truth {t_true} s"
        );
        assert!(
            f.test_rms_after_mm < 0.6 * f.test_rms_before_mm,
            "{what}: {} -> {}",
            f.test_rms_before_mm,
            f.test_rms_after_mm
        );
        // The same quantity as the simulator's truth states (RMS
        // displacement of T after the move), within 10 % (train poses only
        // here, every pose there).
        let m_true = sim.truth["effects"][0]["magnitude"].as_f64().unwrap();
        assert!(
            (f.magnitude / m_true - 1.0).abs() < 0.1,
            "{what}: {} vs truth {m_true}",
            f.magnitude
        );
        // The robot is unchanged: no joint offsets for compensation.
        let q = vec![0.2; sim.robot.dof()];
        assert!(
            physics::joint_offsets_rad(&a.findings, &sim.robot, &q)
                .iter()
                .all(|v| *v == 0.0)
        );
    }
}

#[test]
fn a_rig_drift_is_named_on_another_arm() {
    let sim = simulate::generate(&spec("ur5", "rig_drift", 32)).unwrap();
    let a = analyse(&sim, &sim.rig, &sim.dataset);
    assert_eq!(named(&a), vec!["rig_drift"], "{:#?}", a.findings);
    let f = &a.findings[0];
    assert!(f.test_rms_after_mm < 0.6 * f.test_rms_before_mm);
    // The fitted translation rate points the way the true one does.
    let fitted = &physics::effects_of(std::slice::from_ref(f))[0].coef;
    let truth = &sim.effects[0].coef;
    let dot: f64 = (0..3).map(|i| fitted[i] * truth[i]).sum();
    let norm = |v: &[f64]| v[..3].iter().map(|x| x * x).sum::<f64>().sqrt();
    assert!(
        dot / (norm(fitted) * norm(truth)) > 0.9,
        "{fitted:?} vs {truth:?}"
    );
}

#[test]
fn the_rig_step_sign_follows_the_rig_not_the_model() {
    // Independent of the effect's own basis: an effect-free recording whose
    // tracker was moved by +v after t0 (so every point after it reads v
    // less in the rig frame). The fitted translation must be +v: the
    // coefficients are the rig's own motion.
    let mut s = spec("er3a", "rig_step", 33);
    s.effects.clear();
    let sim = simulate::generate(&s).unwrap();
    let (rig, mut data) = as_point_data(&sim);
    let last = data.poses.last().unwrap().time_s.unwrap();
    let t0 = 0.5 * last;
    let v = nalgebra::Vector3::new(0.3, -0.2, 0.25);
    for p in data.poses.iter_mut().filter(|p| p.time_s.unwrap() > t0) {
        if let drawcal::model::Measurement::Point(x) = &mut p.measurement {
            *x -= v;
        }
    }
    let a = analyse(&sim, &rig, &data);
    assert_eq!(named(&a), vec!["rig_step"], "{:#?}", a.findings);
    let e = &physics::effects_of(std::slice::from_ref(&a.findings[0]))[0];
    for c in 0..3 {
        assert!((e.coef[c] - v[c]).abs() < 0.05, "{:?} vs {v:?}", e.coef);
    }
    // No rotation was put in (mrad).
    assert!(e.coef[3..].iter().all(|w| w.abs() < 0.1), "{:?}", e.coef);
}

#[test]
fn without_a_clock_a_rig_step_is_placed_in_the_row_order() {
    // The same kind of recording with no time_s (nor temp_c): the rig's
    // move is still one rig_step, not an anchor_step on every string, and
    // it is placed by row, not in seconds.
    let sim = simulate::generate(&spec("er3a", "rig_step", 34)).unwrap();
    let t_true = sim.effects[0].kind.change_time_s().unwrap();
    let row_true = sim
        .dataset
        .poses
        .iter()
        .position(|p| p.time_s.unwrap() > t_true)
        .unwrap();
    let mut data = sim.dataset.clone();
    for p in &mut data.poses {
        p.time_s = None;
        p.temp_c = None;
    }
    let a = analyse(&sim, &sim.rig, &data);
    assert_eq!(named(&a), vec!["rig_step"], "{:#?}", a.findings);
    let f = &a.findings[0];
    assert!(f.explanation.contains("around row"), "{}", f.explanation);
    assert!(!f.explanation.contains(" s,"), "{}", f.explanation);
    // The change point is a row index: within a few rows of the true one.
    let t0 = physics::effects_of(std::slice::from_ref(f))[0]
        .kind
        .change_time_s()
        .unwrap();
    assert!(
        (t0 - row_true as f64).abs() < 5.0,
        "change at row index {t0}, truth {row_true}"
    );
    assert!(f.test_rms_after_mm < 0.6 * f.test_rms_before_mm);
}
