//! A tool (adapter, quick changer) that tilts about the flange under its
//! payload's gravity moment (`tool_compliance`), concealed in simulated
//! recordings whose payload changes in blocks, and analysed blind. It is
//! close to the wrist joints' compliance (each wrist joint also deflects
//! under the payload's moment); the two differ in that the tool turns
//! about the whole moment vector at the flange, each joint about its own
//! axis with its own lever. Each must be named as itself, with its size;
//! nothing may be named on payload sessions without an effect; and
//! compensation must apply the droop at the payload the robot carries.

use drawcal::compensate::Compensator;
use drawcal::model::Split;
use drawcal::physics::simulate;
use drawcal::report::Report;

fn simulate(seed: u64, effect: Option<serde_json::Value>) -> simulate::Simulated {
    let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
        "robot": "er3a", "n_poses": 150, "seed": seed,
        "session": {"payload_kg": [0.0, 1.5, 3.0, 0.0, 1.5, 3.0]},
        "effects": effect.into_iter().collect::<Vec<_>>()
    }))
    .unwrap();
    simulate::generate(&spec).unwrap()
}

fn calibrate(sim: &simulate::Simulated) -> Report {
    drawcal::pipeline::calibrate(
        &sim.robot,
        &sim.rig,
        &sim.dataset,
        &Default::default(),
        &drawcal::identify::NoProgress,
    )
    .unwrap()
}

fn named(r: &Report) -> Vec<(String, Option<usize>)> {
    r.findings
        .iter()
        .map(|f| (f.effect.clone(), f.joint))
        .collect()
}

#[test]
fn a_compliant_tool_and_the_wrist_joints_compliance_are_each_named_as_themselves() {
    for seed in [1, 2] {
        let tool = simulate(
            seed,
            Some(serde_json::json!({"effect": "tool_compliance", "size_x_noise": 4})),
        );
        let r = calibrate(&tool);
        assert_eq!(
            named(&r),
            [("tool_compliance".to_string(), None)],
            "seed {seed}"
        );
        let f = &r.findings[0];
        let ctx = drawcal::physics::analyse::effect_context(
            &drawcal::identify::Observations::new(
                &tool.robot,
                &tool.rig,
                &tool.dataset,
                &Default::default(),
            )
            .unwrap(),
            &drawcal::kinematics::Params::of_robot(&tool.robot),
        );
        let (truth, unit) = simulate::report_magnitude(&tool.effects[0], &ctx);
        assert_eq!(f.unit, unit);
        assert!(
            (f.magnitude - truth).abs() < 3.0 * f.sigma,
            "seed {seed}: {} ± {} {unit}, truth {truth}",
            f.magnitude,
            f.sigma
        );
        for joint in [4, 5] {
            let wrist = simulate(
                seed,
                Some(serde_json::json!({
                    "effect": "joint_compliance", "joint": joint, "size_x_noise": 4
                })),
            );
            assert_eq!(
                named(&calibrate(&wrist)),
                [("joint_compliance".to_string(), Some(joint))],
                "seed {seed}, joint {joint}"
            );
        }
    }
}

#[test]
fn payload_sessions_without_an_effect_name_nothing() {
    for seed in [11, 12, 13] {
        let r = calibrate(&simulate(seed, None));
        assert!(r.findings.is_empty(), "seed {seed}: {:?}", named(&r));
    }
}

#[test]
fn compensation_applies_the_tools_droop_at_the_payload_carried() {
    let sim = simulate(
        5,
        Some(serde_json::json!({"effect": "tool_compliance", "size_x_noise": 6})),
    );
    let report = calibrate(&sim);
    assert_eq!(named(&report), [("tool_compliance".to_string(), None)]);
    let comp = Compensator::from_report(&report).unwrap();
    let mut without = report.clone();
    without.findings.clear();
    let comp_without = Compensator::from_report(&without).unwrap();
    // The calibrated pose with the droop at each test pose's payload
    // against the true droop the simulator put in the recording: the
    // model's T shift must follow the truth's, the model without it not.
    let nominal = drawcal::kinematics::Params::of_robot(&sim.robot);
    let ctx = drawcal::physics::analyse::effect_context(
        &drawcal::identify::Observations::new(
            &sim.robot,
            &sim.rig,
            &sim.dataset,
            &Default::default(),
        )
        .unwrap(),
        &nominal,
    );
    // The context's frame: the nominal base's rotation in the rig.
    let rig_to_base = nominal.base_rt().0.transpose();
    let mut buf = drawcal::physics::effects::Basis::default();
    let (mut with_sq, mut without_sq, mut n) = (0.0, 0.0, 0.0);
    for (i, pose) in sim.dataset.poses.iter().enumerate() {
        if pose.split != Some(Split::Test) {
            continue;
        }
        let kg = pose.payload_kg.unwrap_or(0.0);
        // The true droop, turned from the context's rig frame into the
        // robot base frame the compensator works in.
        let truth = rig_to_base * ctx.apply(&sim.effects, i, &mut buf).dp;
        let at = comp.with_payload_kg(kg);
        let shift = at.calibrated_pose(&pose.q_rad).0 - comp_without.calibrated_pose(&pose.q_rad).0;
        with_sq += (shift - truth).norm_squared();
        without_sq += truth.norm_squared();
        n += 1.0;
    }
    let (with_rms, without_rms) = ((with_sq / n).sqrt(), (without_sq / n).sqrt());
    eprintln!(
        "droop left: {with_rms:.4} mm with the tool's compliance, {without_rms:.4} mm without"
    );
    assert!(
        with_rms < 0.25 * without_rms,
        "the compensator's droop is {with_rms:.4} mm RMS from the truth, {without_rms:.4} mm without it"
    );
}
