//! A string that reads differently pulled out than retracted (friction in
//! its drum, stretch of its cable): located at that string's last change
//! of length and corrected there, not named.

use crate::common;
use drawcal::physics::effects::{CorrectionDriver, CorrectionTarget};

#[test]
fn a_string_reading_by_its_direction_of_travel_is_located_at_its_last_change() {
    let (report, _, _) = common::unnamed_near_the_twin(
        "xcheck4_string_hysteresis_std4",
        |p| p.driver == "motion" && p.sensor == Some(2),
        1.2,
    );
    assert_eq!(
        common::correction_slot(&report),
        (
            CorrectionTarget::StringReading,
            Some(1),
            CorrectionDriver::StringMove,
            Some(1)
        )
    );
}

/// A string read through a slow filter lags its last change of length;
/// the located point, which every string's reading makes, follows the move,
/// so T's own move test locates it first. At that place the string's
/// reading by its last change is tried beside T moved along its move, and
/// kept, it moves the place to the string.
#[test]
fn a_lagging_string_found_by_ts_move_is_placed_at_the_string() {
    let (_, d) = common::corrected_unnamed(
        "xcheck9_string_filter_lag_std4",
        |p| p.driver == "motion" && p.sensor == Some(1) && p.joint.is_none(),
        (
            CorrectionTarget::StringReading,
            Some(0),
            CorrectionDriver::StringMove,
            Some(0),
        ),
        0.8,
    );
    assert!(d.evidence.contains("compensation"), "{}", d.evidence);
}

/// What one correction leaves is located again and corrected again: a
/// string whose drum winds loosely after a retraction reads long by an
/// amount set by its last change and its length. The first correction (by
/// its last change) takes part; the remainder is located once more and a
/// second correction of the same string's reading, by its length, takes
/// much of the rest, nothing named.
#[test]
fn what_a_first_correction_leaves_is_located_and_corrected_again() {
    let (report, _, _) = common::unnamed_near_the_twin(
        "xcheck8_string_retract_slack_std4",
        |p| p.driver == "motion" && p.sensor == Some(1),
        1.8,
    );
    let corrections: Vec<_> = report
        .findings
        .iter()
        .filter(|f| f.effect == "data_driven")
        .collect();
    let unexplained = report
        .findings
        .iter()
        .filter(|f| f.effect == "unexplained")
        .count();
    assert!(
        corrections.len() == 2 && unexplained == 2,
        "{:#?}",
        report.findings
    );
    let second = corrections[1];
    assert!(
        second.sensor == Some(1) && second.test_rms_after_mm < 0.8 * second.test_rms_before_mm,
        "{second:#?}"
    );
}
