//! A joint target's compensation stays with the taught pose: a change of
//! any joint beyond the bound (default
//! `compensate::DEFAULT_MAX_JOINT_CHANGE_DEG`) is refused for that target,
//! saying which joint, how far and why, never sent to the robot silently.
//! Found on the UR10 of real_ur10_ipa_random: its first recorded pose,
//! taught upright and stretched (-180, -90, 0, -90, 0, 0), came back with
//! joint 1 turned 18.5 deg to make up for a correction of 15.45 mm, nearly
//! all of it the tool point's difference from robot.json's.

use crate::common;

use drawcal::compensate::{CompensationStatus, Compensator, DEFAULT_MAX_JOINT_CHANGE_DEG};
use drawcal::model::{Target, TargetKind};

fn joints(name: &str, q_deg: &[f64]) -> Target {
    Target {
        target: name.into(),
        kind: TargetKind::Joints {
            q_deg: q_deg.to_vec(),
        },
    }
}

#[test]
fn a_compensation_that_would_swing_the_arm_is_refused_by_name() {
    let (robot, rig, data) = common::load("real_ur10_ipa_random");
    let report = common::identify_default(&robot, &rig, &data);
    let mut comp = Compensator::from_report(&report).unwrap();
    assert_eq!(comp.max_joint_change_deg, DEFAULT_MAX_JOINT_CHANGE_DEG);
    let taught = [-180.0, -90.0, 0.0, -90.0, 0.0, 0.0];
    let upright = joints("upright", &taught);
    // The correction asked is 15.6-15.7 mm (with the analysis's
    // corrections), nearly all of it the tool point
    // (the T-Mac, identified 15.8-15.9 mm from robot.json's 109 mm along the
    // flange axis), which points along the stretched arm: the branch
    // through the taught joints cannot reach it, the solutions that do
    // swing joint 1, and the refusal says all that.
    let c = comp.compensate(&upright, false);
    assert_eq!(c.status, CompensationStatus::JointChange, "{c:?}");
    assert!(c.q_deg.is_none(), "no joints to send: {c:?}");
    let m = c.message.unwrap();
    assert!(
        m.starts_with("joint 1 would move")
            && m.contains("the taught pose is singular")
            && m.contains("5 deg bound")
            && m.contains("the correction asked is 15.")
            && m.contains("the calibrated tool point is 15."),
        "{m}"
    );
    // An ordinary taught pose compensates with the nearest joints: none
    // swings, each moves at most about two degrees for its 15 mm (joint 3
    // the most: 1.9-2.0 deg, as the analysis's corrections change).
    let ordinary = [-150.0, -80.0, 60.0, -70.0, 40.0, 10.0];
    let c = comp.compensate(&joints("ordinary", &ordinary), false);
    assert_eq!(c.status, CompensationStatus::Ok, "{c:?}");
    let moved = c
        .q_deg
        .unwrap()
        .iter()
        .zip(ordinary)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(moved < 2.5, "{moved}");
    // With the flange orientation held it is unreachable, and the answer
    // says how near it came, in position and orientation.
    let c = comp.compensate(&upright, true);
    assert_eq!(c.status, CompensationStatus::Unreachable, "{c:?}");
    let m = c.message.unwrap();
    assert!(
        m.contains("the nearest the calibrated model came is")
            && m.contains("deg from the orientation asked"),
        "{m}"
    );
    // The bound is the caller's: with none to speak of, the far solution
    // is what the solver finds (which is why the bound exists).
    comp.max_joint_change_deg = 360.0;
    let c = comp.compensate(&upright, false);
    assert_eq!(c.status, CompensationStatus::Ok, "{c:?}");
    let q1 = c.q_deg.unwrap()[0];
    assert!((q1 + 180.0).abs() > 10.0, "joint 1 at {q1}");
}
