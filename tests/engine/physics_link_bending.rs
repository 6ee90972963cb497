//! A long link (the upper arm, the forearm) that bends as a cantilever
//! under the weight it carries (`link_bending`), concealed in simulated
//! recordings and analysed blind. Its shape is close to the compliance of
//! the joints at its ends (the load that bends it is, but for the lever,
//! the root joint's gravity torque); it differs in that the end both moves
//! and turns, by the Euler-Bernoulli tip deflections. Each must be named
//! as itself, with its size, and compensation must apply the bending.

use drawcal::physics::simulate;

fn simulate(robot: &str, seed: u64, effect: serde_json::Value) -> simulate::Simulated {
    let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
        "robot": robot, "n_poses": 150, "seed": seed, "effects": [effect]
    }))
    .unwrap();
    simulate::generate(&spec).unwrap()
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
            let r = crate::common::identify_default_sim(&sim);
            assert_eq!(
                crate::common::named(&r),
                [("link_bending".to_string(), Some(link))],
                "{robot} link {link}"
            );
            crate::common::assert_size_within_3_sigma(
                &sim,
                &r.findings[0],
                &format!("{robot} link {link}"),
            );
        }
        for joint in [2, 3] {
            let sim = simulate(
                robot,
                3,
                serde_json::json!({"effect": "joint_compliance", "joint": joint, "size_x_noise": 4}),
            );
            assert_eq!(
                crate::common::named(&crate::common::identify_default_sim(&sim)),
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
    let report = crate::common::identify_default_sim(&sim);
    assert_eq!(
        crate::common::named(&report),
        [("link_bending".to_string(), Some(2))]
    );
    // The calibrated pose's shift of T against the true one the
    // simulator put in the recording, each pose at its payload.
    let (with_rms, without_rms) = crate::common::load_shift_followed(&sim, &report);
    eprintln!(
        "bending left: {with_rms:.4} mm with the link's bending, {without_rms:.4} mm without"
    );
    assert!(
        with_rms < 0.25 * without_rms,
        "the compensator's bending is {with_rms:.4} mm RMS from the truth, {without_rms:.4} mm without it"
    );
}
