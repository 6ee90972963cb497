//! A tool (adapter, quick changer) that tilts about the flange under its
//! payload's gravity moment (`tool_compliance`), concealed in simulated
//! recordings whose payload changes in blocks, and analysed blind. It is
//! close to the wrist joints' compliance (each wrist joint also deflects
//! under the payload's moment); the two differ in that the tool turns
//! about the whole moment vector at the flange, each joint about its own
//! axis with its own lever. Each must be named as itself, with its size;
//! nothing may be named on payload sessions without an effect; and
//! compensation must apply the droop at the payload the robot carries.

use drawcal::physics::simulate;

fn simulate(seed: u64, effect: Option<serde_json::Value>) -> simulate::Simulated {
    let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
        "robot": "er3a", "n_poses": 150, "seed": seed,
        "session": {"payload_kg": [0.0, 1.5, 3.0, 0.0, 1.5, 3.0]},
        "effects": effect.into_iter().collect::<Vec<_>>()
    }))
    .unwrap();
    simulate::generate(&spec).unwrap()
}

#[test]
fn a_compliant_tool_and_the_wrist_joints_compliance_are_each_named_as_themselves() {
    for seed in [1, 2] {
        let tool = simulate(
            seed,
            Some(serde_json::json!({"effect": "tool_compliance", "size_x_noise": 4})),
        );
        let r = crate::common::identify_default_sim(&tool);
        assert_eq!(
            crate::common::named(&r),
            [("tool_compliance".to_string(), None)],
            "seed {seed}"
        );
        crate::common::assert_size_within_3_sigma(&tool, &r.findings[0], &format!("seed {seed}"));
        for joint in [4, 5] {
            let wrist = simulate(
                seed,
                Some(serde_json::json!({
                    "effect": "joint_compliance", "joint": joint, "size_x_noise": 4
                })),
            );
            assert_eq!(
                crate::common::named(&crate::common::identify_default_sim(&wrist)),
                [("joint_compliance".to_string(), Some(joint))],
                "seed {seed}, joint {joint}"
            );
        }
    }
}

#[test]
fn payload_sessions_without_an_effect_name_nothing() {
    for seed in [11, 12, 13] {
        let r = crate::common::identify_default_sim(&simulate(seed, None));
        assert!(
            r.findings.is_empty(),
            "seed {seed}: {:?}",
            crate::common::named(&r)
        );
    }
}

#[test]
fn compensation_applies_the_tools_droop_at_the_payload_carried() {
    let sim = simulate(
        5,
        Some(serde_json::json!({"effect": "tool_compliance", "size_x_noise": 6})),
    );
    let report = crate::common::identify_default_sim(&sim);
    assert_eq!(
        crate::common::named(&report),
        [("tool_compliance".to_string(), None)]
    );
    // The calibrated pose's shift of T against the true one the
    // simulator put in the recording, each pose at its payload.
    let (with_rms, without_rms) = crate::common::load_shift_followed(&sim, &report);
    eprintln!(
        "droop left: {with_rms:.4} mm with the tool's compliance, {without_rms:.4} mm without"
    );
    assert!(
        with_rms < 0.25 * without_rms,
        "the compensator's droop is {with_rms:.4} mm RMS from the truth, {without_rms:.4} mm without it"
    );
}
