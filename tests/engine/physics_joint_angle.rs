//! Errors of a joint's own angle, concealed in simulated recordings and
//! analysed blind: a scale error (`joint_scale`: a gear-ratio or
//! encoder-scale error) and a third harmonic, each named alone on the
//! right joint. Before they were in the catalogue both were reported
//! `unexplained` or approximated by the first two harmonics of the joint.
//! And one joint's angle driven by another's, which no catalogue effect
//! is: located at the driving joint and corrected without a name.

use crate::common;

use drawcal::physics::effects::{CorrectionDriver, CorrectionTarget};
use drawcal::physics::{self, simulate};

/// Simulate one effect and analyse the recording blind: the recording, the
/// analysis, its final held-out 3-D RMS (mm).
fn run(
    robot: &str,
    seed: u64,
    n_poses: usize,
    effect: serde_json::Value,
) -> (simulate::Simulated, physics::Analysis, f64) {
    let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
        "robot": robot, "n_poses": n_poses, "seed": seed, "effects": [effect]
    }))
    .unwrap();
    let sim = simulate::generate(&spec).unwrap();
    let (a, rms) = common::analyse_blind(&sim.robot, &sim.rig, &sim.dataset);
    (sim, a, rms)
}

fn named(a: &physics::Analysis) -> Vec<(&str, Option<usize>)> {
    a.findings
        .iter()
        .map(|f| (f.effect.as_str(), f.joint))
        .collect()
}

#[test]
fn a_joint_scale_error_is_named_alone_with_its_size() {
    for (robot, joint, seed) in [("er3a", 1, 11), ("ur5", 3, 12), ("arm4_mdh", 2, 13)] {
        let effect =
            serde_json::json!({"effect": "joint_scale", "joint": joint, "size_x_noise": 5});
        let (sim, a, final_rms) = run(robot, seed, 100, effect);
        assert_eq!(
            named(&a),
            [("joint_scale", Some(joint))],
            "{robot}: {:#?}",
            a.findings
        );
        let f = &a.findings[0];
        let (truth, unit) = simulate::report_magnitude(&sim.effects[0], &a.context);
        assert_eq!(f.unit, unit);
        assert!(
            (f.magnitude - truth).abs() < 3.0 * f.sigma,
            "{robot}: {} ± {} {unit}, truth {truth}",
            f.magnitude,
            f.sigma
        );
        assert!(
            final_rms < 0.7 * f.test_rms_before_mm,
            "{robot}: held-out {} -> {final_rms}",
            f.test_rms_before_mm
        );
        assert!(
            final_rms < 1.3 * sim.point_noise_mm,
            "{robot}: held-out {final_rms} vs point noise {}",
            sim.point_noise_mm
        );
    }
}

/// A third harmonic of joint 1 (a three-lobed gear): one finding, harmonic
/// 3, no `unexplained` left.
#[test]
fn a_third_harmonic_is_named_with_its_harmonic() {
    let effect = serde_json::json!({"effect": "joint_periodic", "joint": 1, "harmonic": 3, "size_x_noise": 8});
    let (_, a, _) = run("er3a", 41, 120, effect);
    assert_eq!(
        named(&a),
        [("joint_periodic", Some(1))],
        "{:#?}",
        a.findings
    );
    assert_eq!(
        common::params(&a.findings[0])["harmonic"],
        3,
        "{:#?}",
        a.findings
    );
}

/// Over joint 2's range a scale error is nearly a once- plus a
/// twice-per-revolution error. Ranked each on its own residual variance,
/// that pair (four coefficients, fitting some noise too) outranked the one
/// coefficient that is the truth on this dataset (held-out 0.0421 mm
/// against 0.0404); ranked on one scale it must explain more than its
/// extra coefficients charge, and does not.
#[test]
fn one_effect_beats_two_that_approximate_it() {
    let effect = serde_json::json!({"effect": "joint_scale", "joint": 2, "size_x_noise": 5});
    let (_, a, _) = run("er3a", 195668, 80, effect);
    assert_eq!(named(&a), [("joint_scale", Some(2))], "{:#?}", a.findings);
}

/// One joint's angle driven by another's (from the third cross-check,
/// `tests/data/xcheck3_coupling_points`): joint 3 off by a sinusoid of
/// joint 2's angle, on a UR5 whose joints 2 and 3 are parallel, seen by a
/// tracker. A `joint_periodic` of joint 2 takes most of it; what it leaves
/// turns with joint 1, so neighbours in joint 2's angle agree only along
/// the directions the other joints move T. Before that test (and pairs of
/// each pose with its next two neighbours) `joint_periodic` of joint 2 was
/// named and the held-out RMS stayed 3.2 times the twin's. The analysis
/// must name nothing, locate it at joint 2, correct joint 3's angle as a
/// function of joint 2's and come near the twin.
#[test]
fn one_joint_driven_by_another_is_located_and_corrected() {
    let (robot, rig, data) = common::load("xcheck3_coupling_points");
    let report = common::identify_default(&robot, &rig, &data);
    common::nothing_named(&report);
    common::place_where(&report, |p| {
        p.driver == "joint" && p.joint == Some(2) && p.z > p.threshold
    });
    assert_eq!(
        common::correction_slot(&report),
        (
            CorrectionTarget::JointAngle,
            Some(2),
            CorrectionDriver::JointAngle,
            Some(1)
        )
    );
    let (robot, rig, twin) = common::load("xcheck3_coupling_points/twin");
    common::near_the_twin(
        &report,
        &common::identify_default(&robot, &rig, &twin),
        1.15,
    );
}

/// A play that gravity takes up follows the sign of the joint's gravity
/// torque, not its size: the compliance a forward selection first names
/// (an angle in proportion to the torque) loses to a function of the
/// torque jumping where it changes sign, and is not reported.
#[test]
fn a_play_gravity_takes_up_is_not_a_compliance() {
    let (report, _, _) = common::unnamed_near_the_twin(
        "xcheck5_gravity_play_s3tilt",
        |p| p.driver == "joint" && p.joint == Some(3),
        1.3,
    );
    assert_eq!(
        common::correction_slot(&report),
        (
            CorrectionTarget::JointAngle,
            Some(2),
            CorrectionDriver::GravityTorque,
            Some(2)
        )
    );
}

/// A counterbalance spring's torque is a function of joint 2's angle of no
/// catalogue shape: two periodic terms of the joint together fit it, which
/// is no one physical effect, so they are not named; the data-driven
/// correction of the joint's angle by its angle replaces them, fitted beside
/// the compliance the recording also holds (the simulator took the spring's
/// projection onto the gravity torque out), which stays.
#[test]
fn a_counterbalance_spring_is_no_series_of_periodic_terms() {
    let (robot, rig, data) = common::load("xcheck6_counterbalance_mdh_std4");
    let report = common::identify_default(&robot, &rig, &data);
    let named: Vec<(&str, Option<usize>)> = report
        .findings
        .iter()
        .filter(|f| !matches!(f.effect.as_str(), "unexplained" | "data_driven"))
        .map(|f| (f.effect.as_str(), f.joint))
        .collect();
    assert_eq!(
        named,
        [("joint_compliance", Some(2))],
        "{:#?}",
        report.findings
    );
    common::place_where(&report, |p| p.driver == "joint" && p.joint == Some(2));
    assert_eq!(
        common::correction_slot(&report),
        (
            CorrectionTarget::JointAngle,
            Some(1),
            CorrectionDriver::JointAngle,
            Some(1)
        )
    );
    let (robot, rig, twin) = common::load("xcheck6_counterbalance_mdh_std4/twin");
    common::near_the_twin(&report, &common::identify_default(&robot, &rig, &twin), 1.1);
}

/// A compliance fitted against the gravity load is not named, but when it
/// predicted the held-out readings better it says where structure is:
/// with nothing located by the neighbour tests after a first correction of
/// joint 2 by its angle, the joint is reported `unexplained`, and why, and
/// corrected there by its gravity load. Nothing is named (a one-per-
/// revolution harmonic of joint 2 was, before the second round of
/// corrections).
#[test]
fn a_compliance_fitted_the_wrong_way_still_places_the_joint() {
    let (robot, rig, data) = common::load("xcheck6_counterbalance_points");
    let report = common::identify_default(&robot, &rig, &data);
    common::nothing_named(&report);
    let place = common::place_where(&report, |p| p.driver == "joint" && p.joint == Some(2));
    assert!(place.z >= 2.0, "{place:?}");
    assert!(
        report
            .findings
            .iter()
            .any(|f| f.effect == "unexplained" && f.evidence.contains("fitted the wrong way round")),
        "{:#?}",
        report.findings
    );
    // Corrected there by the joint's gravity load, which its angle alone
    // does not give, and the held-out error falls by more than half.
    let d = common::correction_finding(
        &report,
        CorrectionTarget::JointAngle,
        CorrectionDriver::GravityTorque,
    );
    assert_eq!(d.joint, Some(2));
    assert!(
        d.test_rms_after_mm < 0.5 * d.test_rms_before_mm,
        "{} -> {}",
        d.test_rms_before_mm,
        d.test_rms_after_mm
    );
}

/// A string picking up a joint motor's interference (an offset by the
/// joint's load) moves the located point as the joint is loaded: a
/// compliance of joint 2 once fitted it, and stayed beside an `unexplained`
/// finding at joint 2. It is not named; the remainder is placed at joint 2,
/// and the string's reading as a function of joint 2's gravity torque is
/// the correction, which compensation does not need (it is the string's).
#[test]
fn a_string_reading_by_a_joints_load_is_no_compliance() {
    use drawcal::physics::effects::{CorrectionDriver, CorrectionTarget};
    let (_, d) = common::corrected_unnamed(
        "xcheck7_servo_interference_std4",
        |p| p.driver == "joint" && p.joint == Some(2),
        (
            CorrectionTarget::StringReading,
            Some(1),
            CorrectionDriver::GravityTorque,
            Some(1),
        ),
        0.5,
    );
    assert!(
        d.evidence.contains("compensation does not need it"),
        "{}",
        d.evidence
    );
}

/// Where only the robot side's excess placed the remainder, a correction
/// of any joint's angle by any joint's is tried: here (a dress pack pulling
/// joint 1 back near the ends of its travel) it takes the place of three
/// shape terms of joint 1 that together fitted one error of its angle, and
/// predicts the held-out readings far better; nothing is named.
#[test]
fn a_correction_where_only_the_robot_side_placed_the_remainder_replaces_forced_names() {
    use drawcal::physics::effects::{CorrectionDriver, CorrectionTarget};
    common::corrected_unnamed(
        "xcheck4_harness_windup_std4",
        |p| p.driver == "robot",
        (
            CorrectionTarget::JointAngle,
            Some(0),
            CorrectionDriver::JointAngle,
            Some(0),
        ),
        0.5,
    );
}

/// A reducer stiffer against one sense of torque than the other deflects
/// by the torque's size as well as by the torque: a harmonic of the joint's
/// angle resembles that (the load turns over with the angle) and is what a
/// forward selection first names, but a function of the joint's gravity
/// torque predicts the held-out readings clearly better, so the harmonic is
/// dropped rather than named and the remainder is corrected by the load.
#[test]
fn a_reducer_stiffer_one_way_is_not_a_harmonic() {
    let (report, d) = common::corrected_unnamed(
        "xcheck9_asymmetric_stiffness_std4",
        |p| p.driver == "joint" && p.joint == Some(2),
        (
            CorrectionTarget::JointAngle,
            Some(1),
            CorrectionDriver::GravityTorque,
            Some(1),
        ),
        0.5,
    );
    let u = report
        .findings
        .iter()
        .find(|f| f.effect == "unexplained")
        .expect("an unexplained finding");
    assert!(
        u.evidence.contains("joint_periodic") && u.evidence.contains("gravity torque"),
        "{}",
        u.evidence
    );
    assert!(d.evidence.contains("compensation"), "{}", d.evidence);
}
