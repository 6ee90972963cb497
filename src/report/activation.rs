//! Whether a calibration is fit to drive a robot: the rules the service
//! applies before it activates one (`POST /robots/{id}/activate`).
//!
//! A calibration is refused when it does not predict the held-out poses
//! better than the nominal model (or has no held-out poses to show it), or
//! when a correction it makes is larger than a calibration should make: a
//! joint angle parameter (alpha, theta offset, beta) beyond
//! [`ActivationBounds::angle_deg`], a length (a, d) beyond
//! [`ActivationBounds::length_mm`], the tool point beyond
//! [`ActivationBounds::tool_mm`]. Such a correction is what tampered or
//! mislabelled poses give (joint 2 recorded 1.5 degrees off, a session of
//! another robot), and a calibration with it would move the robot by that
//! much. The base pose in the rig frame is not bounded: compensation does
//! not use it.

use super::Report;

/// The largest corrections an activated calibration may make.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActivationBounds {
    /// Alpha, theta offset or beta of any joint (deg).
    pub angle_deg: f64,
    /// a or d of any joint (mm).
    pub length_mm: f64,
    /// The tool point (mm, the distance between robot.json's and the
    /// calibrated one).
    pub tool_mm: f64,
}

impl Default for ActivationBounds {
    /// A small arm's calibration corrects a degree at most (the paper's
    /// ER3A: 1.24 deg on joint 3's offset) and a few millimetres; a tool point measured by hand may be a centimetre or
    /// two off (the UR10's T-Mac: 15.8 mm).
    fn default() -> Self {
        ActivationBounds {
            angle_deg: 2.0,
            length_mm: 10.0,
            tool_mm: 25.0,
        }
    }
}

/// Why `report` may not be activated under `bounds`, if it may not: every
/// rule it breaks, each saying which bound and by how much.
pub fn refusals(report: &Report, bounds: &ActivationBounds) -> Vec<String> {
    let mut why = Vec::new();
    let test = &report.stats.test;
    if test.n == 0 {
        why.push(
            "it has no held-out poses, so nothing shows it predicts better than the nominal model; \
             identify it again with some poses held out"
                .to_string(),
        );
    } else if !(test.after.rms_mm < test.before.rms_mm) {
        why.push(format!(
            "its held-out RMS ({:.4} mm over {} poses) is not below the nominal model's ({:.4} mm)",
            test.after.rms_mm, test.n, test.before.rms_mm
        ));
    }
    let pairs = report
        .nominal_robot
        .joints
        .iter()
        .zip(&report.calibrated_robot.joints)
        .enumerate();
    for (j, (n, c)) in pairs {
        let lengths = [("a", n.a_mm, c.a_mm), ("d", n.d_mm, c.d_mm)];
        for (name, nominal, calibrated) in lengths {
            check(
                &mut why,
                &format!("j{}.{name}", j + 1),
                calibrated - nominal,
                bounds.length_mm,
                "mm",
                "--max-length-correction-mm",
            );
        }
        let angles = [
            ("alpha", n.alpha_deg, c.alpha_deg),
            ("theta", n.theta_offset_deg, c.theta_offset_deg),
            ("beta", n.beta_deg, c.beta_deg),
        ];
        for (name, nominal, calibrated) in angles {
            check(
                &mut why,
                &format!("j{}.{name}", j + 1),
                calibrated - nominal,
                bounds.angle_deg,
                "deg",
                "--max-angle-correction-deg",
            );
        }
    }
    let tool: f64 = report
        .nominal_robot
        .tool_point_mm
        .iter()
        .zip(&report.calibrated_robot.tool_point_mm)
        .map(|(n, c)| (c - n).powi(2))
        .sum::<f64>()
        .sqrt();
    check(
        &mut why,
        "the tool point",
        tool,
        bounds.tool_mm,
        "mm",
        "--max-tool-correction-mm",
    );
    why
}

/// One correction against its bound.
fn check(why: &mut Vec<String>, what: &str, change: f64, bound: f64, unit: &str, flag: &str) {
    if change.abs() > bound || !change.is_finite() {
        why.push(format!(
            "{what} is corrected by {change:+.3} {unit}, {:.3} {unit} beyond the {bound} {unit} \
             bound ({flag} of drawcal serve)",
            change.abs() - bound
        ));
    }
}
