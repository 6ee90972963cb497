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

/// A CSV reader that trims cells and tolerates ragged rows (so a short row
/// is reported by us with its row number), with its header.
pub(crate) fn csv_with_header<R: std::io::Read>(
    input: R,
) -> Result<(csv::Reader<R>, csv::StringRecord)> {
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(input);
    let headers = rdr
        .headers()
        .map_err(|e| Error::field("header", e.to_string()))?
        .clone();
    Ok((rdr, headers))
}

/// A finite number from a cell, or an error naming the row and column.
pub(crate) fn parse_cell(row: usize, col: &str, raw: &str) -> Result<f64> {
    let v: f64 = raw
        .trim()
        .parse()
        .map_err(|_| Error::cell(row, col, format!("'{raw}' is not a number")))?;
    if !v.is_finite() {
        return Err(Error::cell(
            row,
            col,
            format!("'{raw}' is not a finite number"),
        ));
    }
    Ok(v)
}
