//! The calibration inputs, typed and validated: the robot's nominal model
//! (robot.json), the measuring rig (rig.json), recorded poses (poses.csv) and
//! compensation targets (targets.csv). Formats: `DATA_FORMAT.md` v1.

pub mod dataset;
pub mod rig;
pub mod robot;
pub mod targets;

pub use dataset::{Dataset, Measurement, PoseRecord, Split};
pub use rig::{BasePose, Rig, SensorSpec};
pub use robot::{Convention, JointSpec, LinkMass, Robot};
pub use targets::{Target, TargetKind};

use crate::error::{Error, Result};

/// Reject NaN and infinities with an error naming the field.
pub(crate) fn finite(field: &str, v: f64) -> Result<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::field(
            field,
            format!("must be a finite number, got {v}"),
        ))
    }
}
