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
