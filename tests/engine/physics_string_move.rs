//! A string that reads differently pulled out than retracted (friction in
//! its drum, stretch of its cable): located at that string's last change
//! of length and corrected there, not named.

use crate::common;
use drawcal::physics::effects::{CorrectionDriver, CorrectionTarget};

#[test]
fn a_string_reading_by_its_direction_of_travel_is_located_at_its_last_change() {
    let (robot, rig, data) = common::load("xcheck4_string_hysteresis_std4");
    let report = common::identify_default(&robot, &rig, &data);
    common::nothing_named(&report);
    common::place_where(&report, |p| p.driver == "motion" && p.sensor == Some(2));
    assert_eq!(
        common::correction_slot(&report),
        (
            CorrectionTarget::StringReading,
            Some(1),
            CorrectionDriver::StringMove,
            Some(1)
        )
    );
    let (robot, rig, twin) = common::load("xcheck4_string_hysteresis_std4/twin");
    common::near_the_twin(&report, &common::identify_default(&robot, &rig, &twin), 1.2);
}
