//! The human-readable summary `drawcal identify` prints: the paper's Tables
//! 3 and 4 (train and test, before and after) and what was found.

use std::fmt::Write;

use crate::model::Robot;
use crate::report::{ErrorStats, FixedReason, Report};

/// Render the summary of a report. The report's warnings come right
/// after the first line, each as `WARNING: ...`.
pub fn render(r: &Report, robot: &Robot, n_poses: usize, n_strings: usize) -> String {
    let mut s = String::new();
    header(&mut s, r, robot, n_poses, n_strings);
    method(&mut s, r);
    fixed(&mut s, r);
    precision(&mut s, r);
    error_table(&mut s, r);
    outliers(&mut s, r);
    physics(&mut s, r);
    s
}

/// The first line (robot, poses, what measured them), the warnings, and
/// the split.
fn header(s: &mut String, r: &Report, robot: &Robot, n_poses: usize, n_strings: usize) {
    let source = if n_strings > 0 {
        format!("{n_strings} strings")
    } else {
        "measured points".to_string()
    };
    let _ = writeln!(
        s,
        "drawcal identify: {} ({} joints), {} poses from {}",
        robot.name,
        robot.dof(),
        n_poses,
        source
    );
    for w in &r.warnings {
        let _ = writeln!(s, "WARNING: {w}");
    }
    let _ = writeln!(
        s,
        "split: {} train, {} test ({})",
        r.stats.train.n, r.stats.test.n, r.split_source
    );
}

/// The method line: the solver's figures, or the paper's one step.
fn method(s: &mut String, r: &Report) {
    let id = &r.identifiability;
    if r.method == "paper" {
        // The solver figures in the report are those of the base-and-tool
        // fit the paper's step starts from, not of the step.
        let _ = writeln!(
            s,
            "method paper: one pseudo-inverse step of the linearised error model on the located points, {} joint parameters, from the nominal joints with base and tool fitted",
            id.n_identified
        );
    } else {
        let _ = writeln!(
            s,
            "method {}: {} iterations ({}), {} of {} parameters identified, condition number {:.0}",
            r.method,
            r.convergence.iterations,
            r.convergence.termination,
            id.n_identified,
            id.n_candidates,
            id.condition_number
        );
    }
}

/// The parameters held at nominal, grouped by why.
fn fixed(s: &mut String, r: &Report) {
    let id = &r.identifiability;
    for reason in [
        FixedReason::Aliased,
        FixedReason::Undetermined,
        FixedReason::Requested,
    ] {
        let group: Vec<_> = id.fixed.iter().filter(|f| f.reason == reason).collect();
        if group.is_empty() {
            continue;
        }
        let _ = writeln!(s, "{}:", reason.heading());
        for f in group {
            if f.aliased_with.is_empty() {
                let _ = writeln!(s, "  {}", f.name);
            } else {
                let _ = writeln!(
                    s,
                    "  {:<11} aliased with {}",
                    f.name,
                    f.aliased_with.join(", ")
                );
            }
        }
    }
}

/// What the data allow: string noise and the noise floor, the held-out RMS
/// an exact model would show, the flange orientation's sigma, and the
/// paper's closed form against least squares.
fn precision(s: &mut String, r: &Report) {
    if let Some(sig) = r.string_sigma_mm {
        let _ = writeln!(
            s,
            "string noise {:.4} mm (1 sigma); noise floor of the held-out 3-D RMS {}",
            sig,
            r.noise_floor_mm
                .map(|f| format!("{f:.4} mm"))
                .unwrap_or("-".into())
        );
    }
    if let Some(e) = r.expected_test_rms_mm {
        let _ = writeln!(
            s,
            "an exact model identified from these {} train poses would show about {e:.4} mm held out (the floor plus the parameters' spread)",
            r.stats.train.n
        );
    }
    if let Some(o) = r.flange_orientation_sigma_deg {
        let _ = writeln!(
            s,
            "these data determine the flange orientation to {o:.3} deg (RMS rotation angle, 1 sigma, robot base frame, before undetermined parameters are held; parameters held at nominal, among them those position data never see, taken as exact)"
        );
    }
    if let Some(c) = &r.closed_form_vs_lsq {
        let _ = writeln!(
            s,
            "paper closed form vs least-squares points: RMS {:.4} mm, max {:.4} mm over {} poses{}",
            c.rms_mm,
            c.max_mm,
            c.n,
            c.mirrored_note()
        );
    }
}

/// The paper's Tables 3 and 4 as one table: max, mean and RMS errors per
/// column (train and test, before and after, the paper's method on test).
fn error_table(s: &mut String, r: &Report) {
    let _ = writeln!(s);
    let cols: Vec<(&str, &ErrorStats)> = vec![
        ("train before", &r.stats.train.before),
        ("train after", &r.stats.train.after),
        ("test before", &r.stats.test.before),
        ("test after", &r.stats.test.after),
    ];
    let mut cols = cols;
    if let Some(p) = &r.paper_stats {
        cols.push(("paper test", &p.test.after));
    }
    let _ = write!(s, "{:<16}", "error (mm)");
    for (name, _) in &cols {
        let _ = write!(s, "{name:>13}");
    }
    let _ = writeln!(s);
    let rows: [(&str, fn(&ErrorStats) -> f64); 9] = [
        ("max |dx|", |e| e.x.max_abs_mm),
        ("max |dy|", |e| e.y.max_abs_mm),
        ("max |dz|", |e| e.z.max_abs_mm),
        ("max 3-D", |e| e.max_mm),
        ("mean |dx|", |e| e.x.mean_abs_mm),
        ("mean |dy|", |e| e.y.mean_abs_mm),
        ("mean |dz|", |e| e.z.mean_abs_mm),
        ("mean 3-D", |e| e.mean_mm),
        ("RMS 3-D", |e| e.rms_mm),
    ];
    for (label, f) in rows {
        let _ = write!(s, "{label:<16}");
        for (_, e) in &cols {
            // No poses in that column (nothing held out): no figure, not 0.
            match f(e) {
                v if v.is_finite() => write!(s, "{v:>13.4}"),
                _ => write!(s, "{:>13}", "-"),
            }
            .ok();
        }
        let _ = writeln!(s);
    }
}

/// The outlier poses, if any.
fn outliers(s: &mut String, r: &Report) {
    if !r.outliers.is_empty() {
        let ids: Vec<String> = r
            .outliers
            .iter()
            .map(|o| format!("{} ({:.2} mm)", o.pose, o.residual_mm))
            .collect();
        let _ = writeln!(
            s,
            "\noutlier poses{}: {}",
            if r.robust { " (down-weighted)" } else { "" },
            ids.join(", ")
        );
    }
}

/// The physics analysis: its notes, then what it found (or that it found
/// nothing).
fn physics(s: &mut String, r: &Report) {
    let _ = writeln!(s);
    for note in &r.physics_notes {
        let _ = writeln!(s, "physics: {note}");
    }
    if r.findings.is_empty() {
        if r.physics.ran() {
            let _ = writeln!(s, "physics: nothing found beyond the geometric model");
        }
    } else {
        let _ = writeln!(s, "physics found beyond the geometric model:");
        for f in &r.findings {
            let place = match (f.joint, f.sensor) {
                (Some(j), _) => format!(" joint {j}"),
                (_, Some(k)) => format!(" sensor {k}"),
                _ => String::new(),
            };
            let _ = writeln!(
                s,
                "- {}{}: {} {}",
                f.effect,
                place,
                value_and_sigma(f.magnitude, f.sigma),
                f.unit
            );
            let _ = writeln!(s, "  {}", f.explanation);
            let _ = writeln!(s, "  evidence: {}", f.evidence);
            let _ = writeln!(
                s,
                "  held-out RMS {:.4} -> {:.4} mm",
                f.test_rms_before_mm, f.test_rms_after_mm
            );
        }
    }
}

/// `value ± sigma` to two significant digits of the sigma, whatever the
/// unit's scale (0.002502 ± 0.000051 deg/(N*m), -18686 ± 512 ppm); the
/// value alone, to four decimals, when there is no sigma (`unexplained`).
fn value_and_sigma(value: f64, sigma: f64) -> String {
    if !(sigma.is_finite() && sigma > 0.0) {
        return format!("{value:.4}");
    }
    let decimals = (1.0 - sigma.log10().floor()).clamp(0.0, 12.0) as usize;
    format!("{value:.decimals$} ± {sigma:.decimals$}")
}

#[cfg(test)]
mod tests {
    use super::value_and_sigma;

    #[test]
    fn values_are_shown_to_their_sigma() {
        assert_eq!(value_and_sigma(0.0025017, 5.11e-5), "0.002502 ± 0.000051");
        assert_eq!(value_and_sigma(0.0369, 0.0025), "0.0369 ± 0.0025");
        assert_eq!(value_and_sigma(-18686.3, 512.0), "-18686 ± 512");
        assert_eq!(value_and_sigma(1.5, f64::NAN), "1.5000");
    }
}
