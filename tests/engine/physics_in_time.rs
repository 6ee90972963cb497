//! Structure in time or temperature that no named effect explains: a
//! joint's zero that jumps, a rig knocked that springs back, a string frame
//! that grows with the temperature. Each is located in time (at the joint,
//! for the joint's zero) and modelled without a name; the rig moves or the
//! arm's expansion a forward selection first fits to it are not reported.

use crate::common;
use drawcal::physics::effects::{CorrectionDriver, CorrectionTarget};

#[test]
fn a_joint_zero_that_jumps_is_located_at_that_joint_in_time_and_not_named_a_rig_move() {
    let (robot, rig, data) = common::load("xcheck4_joint_zero_step_std4");
    let report = common::identify_default(&robot, &rig, &data);
    common::nothing_named(&report);
    common::place_where(&report, |p| p.driver == "time" && p.joint == Some(2));
    assert_eq!(
        common::correction_slot(&report),
        (
            CorrectionTarget::JointAngle,
            Some(1),
            CorrectionDriver::Time,
            None
        )
    );
    // Located by the clock's test along joint 2's direction, not only
    // placed there by the correction.
    assert!(
        report.findings.iter().any(|f| f.effect == "unexplained"
            && f.evidence.contains("along the direction joint 2 moves T")),
        "{:#?}",
        report.findings
    );
    // The correction follows this session's clock: compensation leaves it
    // out (and there is no other joint effect to apply).
    assert!(drawcal::physics::JointEffects::new(&report.findings, &robot).is_none());
    let (robot, rig, twin) = common::load("xcheck4_joint_zero_step_std4/twin");
    common::near_the_twin(&report, &common::identify_default(&robot, &rig, &twin), 1.2);
}

#[test]
fn a_knock_that_springs_back_is_located_in_time_and_not_named_rig_steps() {
    let (robot, rig, data) = common::load("xcheck4_knock_recover_std4");
    let report = common::identify_default(&robot, &rig, &data);
    common::nothing_named(&report);
    common::place_where(&report, |p| p.driver == "time" && p.joint.is_none());
    // The correction jumps where the steps were taken out: two knots
    // straddle the knock (1127.6 s) with no pose between them.
    let knots = report
        .findings
        .iter()
        .find_map(|f| match f.effect_model().map(|m| &m.kind) {
            Some(drawcal::physics::effects::Kind::DataDriven {
                driver: CorrectionDriver::Time,
                knots,
                ..
            }) => Some(knots.clone()),
            _ => None,
        })
        .expect("a correction in time");
    let times: Vec<f64> = data.poses.iter().filter_map(|p| p.time_s).collect();
    assert!(
        knots.windows(2).any(|w| {
            w[0] < 1127.6 + 60.0
                && w[1] > 1127.6 - 60.0
                && !times.iter().any(|&t| t > w[0] && t < w[1])
                && w[1] - w[0] < 30.0
        }),
        "no jump near the knock: {knots:?}"
    );
    let (robot, rig, twin) = common::load("xcheck4_knock_recover_std4/twin");
    common::near_the_twin(&report, &common::identify_default(&robot, &rig, &twin), 1.5);
}

#[test]
fn a_string_frame_growing_with_the_temperature_is_not_the_arm_expanding() {
    let (robot, rig, data) = common::load("xcheck4_rig_thermal_s5np");
    let report = common::identify_default(&robot, &rig, &data);
    common::nothing_named(&report);
    common::place_where(&report, |p| p.driver == "temperature");
    let (target, _, _, _) = common::correction_slot(&report);
    assert_eq!(target, CorrectionTarget::InstrumentScale);
    let (robot, rig, twin) = common::load("xcheck4_rig_thermal_s5np/twin");
    common::near_the_twin(&report, &common::identify_default(&robot, &rig, &twin), 1.2);
}
