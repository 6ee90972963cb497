//! A long link (the upper arm, the forearm) that bends as a cantilever
//! under the weight it carries (`link_bending`), concealed in simulated
//! recordings and analysed blind. Its shape is close to the compliance of
//! the joints at its ends (the load that bends it is, but for the lever,
//! the root joint's gravity torque); it differs in that the end both moves
//! and turns, by the Euler-Bernoulli tip deflections. Each must be named
//! as itself, with its size, and compensation must apply the bending.

use drawcal::compensate::Compensator;
use drawcal::model::Split;
use drawcal::physics::simulate;
use drawcal::report::Report;

fn simulate(robot: &str, seed: u64, effect: serde_json::Value) -> simulate::Simulated {
    let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
        "robot": robot, "n_poses": 150, "seed": seed, "effects": [effect]
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

/// Each finding's name with its joint (a bending link's: the joint at its
/// root, 1-based).
fn named(r: &Report) -> Vec<(String, Option<usize>)> {
    r.findings
        .iter()
        .map(|f| (f.effect.clone(), f.joint))
        .collect()
}

fn context(sim: &simulate::Simulated) -> drawcal::physics::Context {
    drawcal::physics::analyse::effect_context(
        &drawcal::identify::Observations::new(
            &sim.robot,
            &sim.rig,
            &sim.dataset,
            &Default::default(),
        )
        .unwrap(),
        &drawcal::kinematics::Params::of_robot(&sim.robot),
    )
}

#[test]
fn a_bending_link_and_the_compliance_of_its_joints_are_each_named_as_themselves() {
    // The upper arm (from joint 2) and the forearm (from joint 3 on the
    // UR5, whose elbow-to-wrist span is along a3; from joint 4 on the
    // ER3A, whose forearm runs along joint 4's axis).
    for (robot, links) in [("ur5", [2, 3]), ("er3a", [2, 4])] {
        for link in links {
            let sim = simulate(
                robot,
                3,
                serde_json::json!({"effect": "link_bending", "joint": link, "size_x_noise": 4}),
            );
            let r = calibrate(&sim);
            assert_eq!(
                named(&r),
                [("link_bending".to_string(), Some(link))],
                "{robot} link {link}"
            );
            let f = &r.findings[0];
            let (truth, unit) = simulate::report_magnitude(&sim.effects[0], &context(&sim));
            assert_eq!(f.unit, unit);
            assert!(
                (f.magnitude - truth).abs() < 3.0 * f.sigma,
                "{robot} link {link}: {} ± {} {unit}, truth {truth}",
                f.magnitude,
                f.sigma
            );
        }
        for joint in [2, 3] {
            let sim = simulate(
                robot,
                3,
                serde_json::json!({"effect": "joint_compliance", "joint": joint, "size_x_noise": 4}),
            );
            assert_eq!(
                named(&calibrate(&sim)),
                [("joint_compliance".to_string(), Some(joint))],
                "{robot} joint {joint}"
            );
        }
    }
}

#[test]
fn compensation_applies_a_bending_link() {
    let sim = simulate(
        "ur5",
        5,
        serde_json::json!({"effect": "link_bending", "joint": 2, "size_x_noise": 6}),
    );
    let report = calibrate(&sim);
    assert_eq!(named(&report), [("link_bending".to_string(), Some(2))]);
    let comp = Compensator::from_report(&report).unwrap();
    let mut without = report.clone();
    without.findings.clear();
    let comp_without = Compensator::from_report(&without).unwrap();
    // The calibrated pose's shift of T by the bending against the true
    // bending the simulator put in the recording.
    let ctx = context(&sim);
    let rig_to_base = drawcal::kinematics::Params::of_robot(&sim.robot)
        .base_rt()
        .0
        .transpose();
    let mut buf = drawcal::physics::effects::Basis::default();
    let (mut with_sq, mut without_sq, mut n) = (0.0, 0.0, 0.0);
    for (i, pose) in sim.dataset.poses.iter().enumerate() {
        if pose.split != Some(Split::Test) {
            continue;
        }
        let truth = rig_to_base * ctx.apply(&sim.effects, i, &mut buf).dp;
        let shift =
            comp.calibrated_pose(&pose.q_rad).0 - comp_without.calibrated_pose(&pose.q_rad).0;
        with_sq += (shift - truth).norm_squared();
        without_sq += truth.norm_squared();
        n += 1.0;
    }
    let (with_rms, without_rms) = ((with_sq / n).sqrt(), (without_sq / n).sqrt());
    eprintln!(
        "bending left: {with_rms:.4} mm with the link's bending, {without_rms:.4} mm without"
    );
    assert!(
        with_rms < 0.25 * without_rms,
        "the compensator's bending is {with_rms:.4} mm RMS from the truth, {without_rms:.4} mm without it"
    );
}
