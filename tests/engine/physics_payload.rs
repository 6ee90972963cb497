//! A payload recorded per pose (`payload_kg`, weights swapped part-way
//! through the session) loads the compliant joint: the analysis must use
//! it, with link masses (one compliance) and without (unit-mass
//! regressors), and compensation assumes the session's payload.

use crate::common;

use drawcal::model::Dataset;
use drawcal::physics::{self, simulate};

fn simulated(robot: &str, seed: u64) -> simulate::Simulated {
    let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
        "robot": robot,
        "n_poses": 120,
        "seed": seed,
        "session": {"payload_kg": [0.0, 12.0, 4.0]},
        "effects": [{"effect": "joint_compliance", "joint": 2, "size_x_noise": 6}]
    }))
    .unwrap();
    simulate::generate(&spec).unwrap()
}

/// The analysis, its findings and the final held-out RMS.
fn analyse(sim: &simulate::Simulated, data: &Dataset) -> (physics::Analysis, f64) {
    common::analyse_blind(&sim.robot, &sim.rig, data)
}

/// The same recording with the payload column removed.
fn without_payload(sim: &simulate::Simulated) -> Dataset {
    let csv = common::drop_columns(&sim.poses_csv, &["payload_kg"]);
    Dataset::from_csv(csv.as_bytes(), &sim.robot, &sim.rig).unwrap()
}

fn check(robot: &str, seed: u64) {
    let sim = simulated(robot, seed);
    assert!(sim.poses_csv.lines().next().unwrap().contains("payload_kg"));
    let (a, rms) = analyse(&sim, &sim.dataset);
    let named: Vec<_> = a
        .findings
        .iter()
        .filter(|f| f.effect != "unexplained")
        .collect();
    assert!(
        named
            .iter()
            .any(|f| f.effect == "joint_compliance" && f.joint == Some(2)),
        "{robot}: {:#?}",
        a.findings
    );
    assert!(
        rms < 1.25 * sim.point_noise_mm,
        "{robot}: held-out {rms} vs point noise {}",
        sim.point_noise_mm
    );
    let f = named
        .iter()
        .find(|f| f.effect == "joint_compliance")
        .unwrap();
    // The median of 0, 12 and 4 kg in equal blocks.
    assert_eq!(
        common::params(&f)["reference_payload_kg"].as_f64(),
        Some(4.0)
    );
    // A client must send the payload for this compliance.
    assert_eq!(common::params(&f)["payload_matters"], true, "{robot}");
    // Ignoring the recorded payload leaves the swaps unexplained.
    let (blind, rms_blind) = analyse(&sim, &without_payload(&sim));
    // Fitted without any payload, a compliance takes one only through link
    // masses: without them there is no lever to apply it to.
    let compliance: Vec<_> = blind
        .findings
        .iter()
        .filter(|f| f.effect == "joint_compliance")
        .collect();
    assert!(!compliance.is_empty(), "{robot}: {:#?}", blind.findings);
    for f in compliance {
        assert_eq!(
            common::params(&f)["payload_matters"],
            sim.robot.links.is_some(),
            "{robot}: {:?}",
            f.parameters
        );
    }
    assert!(
        rms_blind > 1.1 * rms,
        "{robot}: without the payload column {rms_blind} vs with {rms}"
    );
}

#[test]
fn compliance_with_link_masses_carries_the_recorded_payload() {
    check("er3a", 5);
}

#[test]
fn compliance_without_link_masses_carries_the_recorded_payload() {
    check("ur5", 6);
}
