//! compensated.csv: the answer to targets.csv, one row per target in the
//! same order (DATA_FORMAT.md). The row type lives here, beside the file it
//! is written to, so that the format sits with the other file formats and
//! below the compensation that fills it in (`crate::compensate` re-exports
//! it).

use serde::{Deserialize, Serialize};

/// Outcome of one target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CompensationStatus {
    /// Compensated joints found within the limits.
    Ok,
    /// No joints put T on the target.
    Unreachable,
    /// The joints that reach the target violate a joint limit.
    JointLimit,
    /// The joints that reach the target are further from the taught ones
    /// than the bound allows (a joint target only): never sent silently.
    JointChange,
}

impl CompensationStatus {
    /// The compensated.csv spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            CompensationStatus::Ok => "ok",
            CompensationStatus::Unreachable => "unreachable",
            CompensationStatus::JointLimit => "joint_limit",
            CompensationStatus::JointChange => "joint_change",
        }
    }
}

/// One compensated target (a row of compensated.csv).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Compensated {
    /// Target id.
    pub target: String,
    /// Joint angles to send (deg); `None` unless `status` is ok.
    pub q_deg: Option<Vec<f64>>,
    /// Distance from the calibrated model's T to the target (mm).
    pub residual_mm: Option<f64>,
    /// Solver iterations.
    pub iterations: usize,
    /// Outcome.
    pub status: CompensationStatus,
    /// Why, when not ok.
    pub message: Option<String>,
}

/// Write compensated.csv rows.
pub fn write_csv<W: std::io::Write>(
    out: W,
    dof: usize,
    rows: &[Compensated],
) -> std::io::Result<()> {
    let mut w = csv::Writer::from_writer(out);
    let mut header = vec!["target".to_string()];
    header.extend((1..=dof).map(|j| format!("q{j}_deg")));
    header.extend(["residual_mm", "iterations", "status", "message"].map(String::from));
    w.write_record(&header)?;
    for r in rows {
        let mut rec = vec![r.target.clone()];
        match &r.q_deg {
            Some(q) => rec.extend(q.iter().map(|v| format!("{v:.6}"))),
            None => rec.extend(std::iter::repeat_n(String::new(), dof)),
        }
        rec.push(r.residual_mm.map(|v| format!("{v:.6}")).unwrap_or_default());
        rec.push(r.iterations.to_string());
        rec.push(r.status.as_str().to_string());
        rec.push(r.message.clone().unwrap_or_default());
        w.write_record(&rec)?;
    }
    w.flush()
}
