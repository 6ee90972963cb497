//! The rules a calibration must pass to be activated
//! (`report::activation`): each broken rule named, with its bound and by
//! how much.

use crate::common;

use drawcal::report::activation::{ActivationBounds, refusals};

#[test]
fn a_sound_calibration_passes_and_each_broken_rule_is_named() {
    let (robot, rig, data) = common::load("er3a_paper_like");
    let r = common::identify_default(&robot, &rig, &data);
    let why = refusals(&r, &ActivationBounds::default());
    assert!(why.is_empty(), "{why:?}");
    let mut bad = r.clone();
    bad.calibrated_robot.joints[1].theta_offset_deg =
        bad.nominal_robot.joints[1].theta_offset_deg + 2.5;
    bad.calibrated_robot.tool_point_mm = bad.nominal_robot.tool_point_mm;
    bad.calibrated_robot.tool_point_mm[2] += 30.0;
    let why = refusals(&bad, &ActivationBounds::default());
    assert_eq!(why.len(), 2, "{why:?}");
    assert!(
        why[0].starts_with("j2.theta is corrected by +2.5"),
        "{why:?}"
    );
    assert!(
        why[0].contains("beyond the 2 deg bound (--max-angle-correction-deg"),
        "{why:?}"
    );
    assert!(
        why[1].starts_with("the tool point is corrected by +30.000 mm, 5.000 mm beyond"),
        "{why:?}"
    );
    let mut worse = r.clone();
    worse.stats.test.after.rms_mm = worse.stats.test.before.rms_mm * 1.5;
    let why = refusals(&worse, &ActivationBounds::default());
    assert!(
        why[0].contains("is not below the nominal model's"),
        "{why:?}"
    );
    let mut none = r;
    none.stats.test.n = 0;
    let why = refusals(&none, &ActivationBounds::default());
    assert!(why[0].contains("no held-out poses"), "{why:?}");
}
