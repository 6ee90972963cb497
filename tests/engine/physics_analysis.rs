//! The analysis on the shared datasets: the labelled compliance is found
//! on the right joint with the true magnitude inside 3 sigma, the
//! effect-free datasets give no finding, and compensation offsets follow.

use drawcal::identify::{IdentifyOptions, NoProgress, Observations, geometric};
use drawcal::model::{Dataset, Rig, Robot};
use drawcal::physics;

fn load(dir: &str) -> (Robot, Rig, Dataset, serde_json::Value) {
    let robot =
        Robot::from_json(&std::fs::read_to_string(format!("{dir}/robot.json")).unwrap()).unwrap();
    let rig = Rig::from_json(&std::fs::read_to_string(format!("{dir}/rig.json")).unwrap()).unwrap();
    let data = Dataset::from_csv(
        std::fs::File::open(format!("{dir}/poses.csv")).unwrap(),
        &robot,
        &rig,
    )
    .unwrap();
    let truth = std::fs::read_to_string(format!("{dir}/truth.json"))
        .map(|t| serde_json::from_str(&t).unwrap())
        .unwrap_or(serde_json::Value::Null);
    (robot, rig, data, truth)
}

fn analyse(dir: &str) -> (physics::Analysis, f64, serde_json::Value, Robot) {
    let (robot, rig, data, truth) = load(dir);
    let opts = IdentifyOptions::default();
    let s = Observations::new(&robot, &rig, &data, &opts).unwrap();
    let g = geometric(&s, &opts, &NoProgress).unwrap();
    let e = s.errors(&g.after.values, &s.test);
    let geo_rms = (e.iter().map(|v| v.norm_squared()).sum::<f64>() / e.len() as f64).sqrt();
    (
        physics::analyse(&s, &g, &NoProgress).unwrap(),
        geo_rms,
        truth,
        robot,
    )
}

#[test]
fn finds_the_labelled_compliance() {
    let (a, geo_rms, truth, robot) = analyse("tests/data/er3a_compliance_j2");
    let real: Vec<_> = a
        .findings
        .iter()
        .filter(|f| f.effect != "unexplained")
        .collect();
    assert_eq!(real.len(), 1, "{:#?}", a.findings);
    let f = real[0];
    let t = &truth["effects"][0];
    assert_eq!(f.effect, t["effect"].as_str().unwrap());
    assert_eq!(f.joint, t["joint"].as_u64().map(|j| j as usize));
    let m = t["magnitude"].as_f64().unwrap();
    assert!(
        (f.magnitude - m).abs() < 3.0 * f.sigma,
        "{} ± {} vs {m}",
        f.magnitude,
        f.sigma
    );
    assert!(f.test_rms_after_mm < 0.5 * f.test_rms_before_mm);
    let final_rms = (a.test_errors.iter().map(|v| v.norm_squared()).sum::<f64>()
        / a.test_errors.len() as f64)
        .sqrt();
    assert!(final_rms < 0.5 * geo_rms, "{final_rms} vs {geo_rms}");
    // Compensation: the deflection at a pose is c·τ on joint 2 only.
    let q = [0.3, 0.5, -0.2, 0.1, 0.7, 0.0];
    let off = physics::joint_offsets_rad(&a.findings, &robot, &q);
    assert!(off[1].abs() > 1e-6, "{off:?}");
    for (j, o) in off.iter().enumerate() {
        if j != 1 {
            assert_eq!(*o, 0.0);
        }
    }
    // The same model rebuilt from the report's parameters.
    let json = serde_json::to_string(&a.findings).unwrap();
    let back: Vec<drawcal::report::Finding> = serde_json::from_str(&json).unwrap();
    assert_eq!(physics::joint_offsets_rad(&back, &robot, &q), off);
}

#[test]
fn effect_free_datasets_give_no_finding() {
    for d in ["tests/data/er3a_paper_like", "tests/data/ur5_geometric"] {
        let (a, _, _, _) = analyse(d);
        assert!(a.findings.is_empty(), "{d}: {:#?}", a.findings);
    }
}
