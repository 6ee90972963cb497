//! Structure in time or temperature that no named effect explains: a
//! joint's zero that jumps, a rig knocked that springs back, a string frame
//! that grows with the temperature or tilts with it, a probe that grows
//! with the process's heat. Each is located in time (at the joint, for the joint's zero) and
//! modelled without a name; the rig moves or the arm's expansion a forward
//! selection first fits to it are not reported.

use crate::common;
use drawcal::physics::effects::{CorrectionDriver, CorrectionTarget};

#[test]
fn a_joint_zero_that_jumps_is_located_at_that_joint_in_time_and_not_named_a_rig_move() {
    let (report, robot, _) = common::unnamed_near_the_twin(
        "xcheck4_joint_zero_step_std4",
        |p| p.driver == "time" && p.joint == Some(2),
        1.2,
    );
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
}

#[test]
fn a_knock_that_springs_back_is_located_in_time_and_not_named_rig_steps() {
    let (report, _, data) = common::unnamed_near_the_twin(
        "xcheck4_knock_recover_std4",
        |p| p.driver == "time" && p.joint.is_none(),
        1.5,
    );
    // The correction jumps where the steps were taken out: two knots
    // straddle the knock (1127.6 s) with no pose between them.
    let knots = match common::data_driven_correction(&report) {
        drawcal::physics::effects::Kind::DataDriven {
            driver: CorrectionDriver::Time,
            knots,
            ..
        } => knots,
        other => panic!("not a correction in time: {other:?}"),
    };
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
}

#[test]
fn a_string_frame_growing_with_the_temperature_is_not_the_arm_expanding() {
    let (report, _, _) = common::unnamed_near_the_twin(
        "xcheck4_rig_thermal_s5np",
        |p| p.driver == "temperature",
        1.2,
    );
    let (target, _, _, _) = common::correction_slot(&report);
    assert_eq!(target, CorrectionTarget::InstrumentScale);
}

/// Sensors sharing one reference that drifts read every length off in
/// proportion: every string's scale by the clock, not the arm growing (a
/// thermal expansion by the clock, which the strings' agreement first
/// suggests) nor the anchors spreading about their centroid.
#[test]
fn strings_sharing_a_drifting_reference_are_one_reading_scale_in_time() {
    let (report, _, _) =
        common::unnamed_near_the_twin("xcheck6_shared_reference_s5np", |p| p.driver == "time", 1.1);
    assert_eq!(
        common::correction_slot(&report),
        (
            CorrectionTarget::ReadingScale,
            None,
            CorrectionDriver::Time,
            None
        )
    );
}

#[test]
fn a_probe_growing_with_the_process_heat_is_a_tool_point_correction_in_time() {
    let (report, robot, _) = common::unnamed_near_the_twin(
        "xcheck6_tool_thermal_std4",
        |p| p.driver == "time" && p.joint.is_none(),
        1.6,
    );
    // The tool point in the flange frame by the clock, not T relative to
    // the rig (which does not turn with the flange) nor a joint's zero.
    assert_eq!(
        common::correction_slot(&report),
        (
            CorrectionTarget::ToolPoint,
            None,
            CorrectionDriver::Time,
            None
        )
    );
    let f = report
        .findings
        .iter()
        .find(|f| f.effect == "data_driven")
        .unwrap();
    assert!(
        f.evidence
            .contains("the tool point changed with this session's clock"),
        "{}",
        f.evidence
    );
    // It describes this session: compensation leaves it out.
    assert!(drawcal::physics::JointEffects::new(&report.findings, &robot).is_none());
}

#[test]
fn a_probe_growing_in_time_is_located_along_the_flange_axis_on_three_strings() {
    let (report, _, _) = common::unnamed_near_the_twin(
        "xcheck6_tool_thermal_s3tilt",
        |p| p.driver == "time" && p.joint.is_none(),
        1.5,
    );
    // The clock's test along the flange's z axis (the probe's), where the
    // raw residuals of neighbours in time agree less.
    assert!(
        report
            .findings
            .iter()
            .any(|f| f.effect == "unexplained" && f.evidence.contains("along the flange's z axis")),
        "{:#?}",
        report.findings
    );
    assert_eq!(
        common::correction_slot(&report).0,
        CorrectionTarget::ToolPoint
    );
}

/// A string frame that tilts about its feet as the cell warms moves its
/// anchors unequally: the frame's shape by the temperature is kept beside
/// T's move in time, and says so; nothing is named.
#[test]
fn a_frame_tilting_with_the_temperature_is_a_rig_shape_correction() {
    let (report, _, _) = common::unnamed_near_the_twin(
        "xcheck6_rig_thermal_tilt_std4",
        |p| p.driver == "time" || p.driver == "temperature",
        1.3,
    );
    let shape = common::correction_finding(
        &report,
        CorrectionTarget::RigShape,
        CorrectionDriver::Temperature,
    );
    assert!(
        shape
            .evidence
            .contains("the string frame changed shape during the session with its temperature"),
        "{}",
        shape.evidence
    );
}

/// A stereo camera whose mount creeps in yaw reads T off by an amount
/// that grows with the depth and changes in time: neither neighbours in
/// time nor in the workspace agree, poses close in both do. It is located
/// in time and modelled as the instrument's frame changing in time
/// (nothing was found before).
#[test]
fn a_camera_creeping_in_time_by_depth_is_located_and_corrected() {
    let (report, d) = common::corrected_unnamed(
        "xcheck10_stereo_camera_creep",
        |p| p.driver == "time" && p.joint.is_none() && p.sensor.is_none(),
        (
            CorrectionTarget::RigShape,
            None,
            CorrectionDriver::Time,
            None,
        ),
        0.92,
    );
    let place = common::place_where(&report, |p| p.driver == "time");
    assert_eq!(place.side, "point", "{place:?}");
    assert!(
        d.evidence
            .contains("the instrument's frame changed during the session"),
        "{}",
        d.evidence
    );
    assert!(
        d.explanation.contains("the measuring instrument's frame"),
        "{}",
        d.explanation
    );
    // Plotted as T's displacement: there are no strings to plot.
    assert!(d.evidence_plot.is_some(), "no evidence plot");
}
