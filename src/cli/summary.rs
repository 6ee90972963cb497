//! The human-readable summary `drawcal identify` prints: the held-out
//! accuracy before and after and the verdict first, then the paper's
//! Tables 3 and 4 (train and test, before and after) and what was found,
//! one line each. No line is wider than [`WIDTH`] columns; the detail
//! (every candidate the physics analysis did not keep, each finding's
//! explanation and evidence, the paper's closed form against least
//! squares, which parameter is aliased with which) is printed with
//! `--verbose`.

use std::fmt::Write;

use crate::model::Robot;
use crate::report::verdict::Verdict;
use crate::report::{ClosedFormComparison, ErrorStats, FixedReason, Report};

/// The widest line of the summary (columns).
pub const WIDTH: usize = 100;

/// What the summary says of the input beside the report.
pub struct Input<'a> {
    /// The nominal robot.
    pub robot: &'a Robot,
    /// Poses read.
    pub n_poses: usize,
    /// Strings per pose (0: measured points).
    pub n_strings: usize,
    /// Columns of poses.csv that were not read.
    pub ignored_columns: &'a [String],
}

/// Render the summary of a report; `verbose` adds the detail.
pub fn render(r: &Report, input: &Input, verbose: bool) -> String {
    let mut s = String::new();
    header(&mut s, r, input);
    accuracy(&mut s, r);
    method(&mut s, r, verbose);
    free_set(&mut s, r, verbose);
    rig(&mut s, r, verbose);
    precision(&mut s, r, verbose);
    error_table(&mut s, r);
    outliers(&mut s, r);
    physics(&mut s, r, verbose);
    s
}

/// Append `text` wrapped at [`WIDTH`] between words: its leading spaces
/// kept, the following lines indented by `indent` spaces. A word longer
/// than a line stays whole.
fn line(s: &mut String, text: &str, indent: usize) {
    let lead = text.len() - text.trim_start_matches(' ').len();
    s.push_str(&text[..lead]);
    let mut col = lead;
    let mut fresh = true;
    for word in text[lead..].split(' ').filter(|w| !w.is_empty()) {
        let len = word.chars().count();
        if !fresh && col + 1 + len > WIDTH {
            s.push('\n');
            s.extend(std::iter::repeat_n(' ', indent));
            col = indent;
            fresh = true;
        }
        if !fresh {
            s.push(' ');
            col += 1;
        }
        s.push_str(word);
        col += len;
        fresh = false;
    }
    s.push('\n');
}

/// The first line (robot, poses, what measured them), the warnings, the
/// ignored columns and the split.
fn header(s: &mut String, r: &Report, input: &Input) {
    let source = if input.n_strings > 0 {
        format!("{} strings", input.n_strings)
    } else {
        "measured points".to_string()
    };
    line(
        s,
        &format!(
            "drawcal identify: {} ({} joints), {} poses from {}",
            input.robot.name,
            input.robot.dof(),
            input.n_poses,
            source
        ),
        2,
    );
    for w in &r.warnings {
        line(s, &format!("WARNING: {w}"), 2);
    }
    if !input.ignored_columns.is_empty() {
        line(
            s,
            &format!(
                "poses.csv columns not read: {}",
                input.ignored_columns.join(", ")
            ),
            2,
        );
    }
    line(
        s,
        &format!(
            "split: {} train, {} test ({})",
            r.stats.train.n, r.stats.test.n, r.split_source
        ),
        2,
    );
}

/// Held out before -> after (and the geometric model's figure when physics
/// was modelled), then the verdict.
fn accuracy(s: &mut String, r: &Report) {
    let test = &r.stats.test;
    if test.n > 0 {
        let mut text = format!(
            "held out: {:.4} -> {:.4} mm RMS (nominal -> calibrated)",
            test.before.rms_mm, test.after.rms_mm
        );
        // The findings in the order they were kept: the first one's "before"
        // is the geometric model's (an `unexplained` finding leads when the
        // remainder was corrected without a name).
        let modelled = r.findings.iter().any(|f| f.effect != "unexplained");
        if let Some(first) = r.findings.first().filter(|_| modelled) {
            let _ = write!(
                text,
                "; {:.4} mm with the geometric model alone",
                first.test_rms_before_mm
            );
        }
        line(s, &text, 2);
    }
    let v = Verdict::read(r);
    line(
        s,
        &format!(
            "verdict: {}: {}",
            v.level.to_string().to_uppercase(),
            v.reasons.join("; ")
        ),
        2,
    );
}

/// The method line (the solver's figures, or the paper's one step) and the
/// parameters held at nominal, one line per reason (with what each is
/// aliased with when `verbose`).
fn method(s: &mut String, r: &Report, verbose: bool) {
    let id = &r.identifiability;
    if r.method == "paper" {
        // The solver figures in the report are those of the base-and-tool
        // fit the paper's step starts from, not of the step.
        line(
            s,
            &format!(
                "method paper: one pseudo-inverse step of the linearised error model on the \
                 located points, {} joint parameters, from the nominal joints with base and \
                 tool fitted",
                id.n_identified
            ),
            2,
        );
    } else {
        line(
            s,
            &format!(
                "method {}: {} iterations ({}), {} of {} parameters identified, condition \
                 number {:.0}",
                r.method,
                r.convergence.iterations,
                r.convergence.termination,
                id.n_identified,
                id.n_candidates,
                id.condition_number
            ),
            2,
        );
    }
    for reason in [
        FixedReason::Aliased,
        FixedReason::Undetermined,
        FixedReason::FreeSet,
        FixedReason::Requested,
    ] {
        let group: Vec<_> = id.fixed.iter().filter(|f| f.reason == reason).collect();
        if group.is_empty() {
            continue;
        }
        if verbose {
            line(s, &format!("{}:", reason.heading()), 2);
            for f in group {
                match f.aliased_with.as_slice() {
                    [] => line(s, &format!("  {}", f.name), 4),
                    with => line(
                        s,
                        &format!("  {} aliased with {}", f.name, with.join(", ")),
                        4,
                    ),
                }
            }
        } else {
            let names: Vec<&str> = group.iter().map(|f| f.name.as_str()).collect();
            let why = match reason {
                FixedReason::Aliased => "aliased",
                FixedReason::Undetermined => "undetermined",
                FixedReason::Requested => "as asked",
                FixedReason::FreeSet => "by the free-set choice",
            };
            line(
                s,
                &format!(
                    "held at nominal, {why} ({}): {}",
                    names.len(),
                    names.join(" ")
                ),
                4,
            );
        }
    }
}

/// Which identifiable parameters were freed (one line; none for reports
/// written before the choice): the cross-validation's scores when it ran,
/// with `verbose` its reason too.
fn free_set(s: &mut String, r: &Report, verbose: bool) {
    let Some(f) = &r.free_set else {
        return;
    };
    let text = match f.how.as_str() {
        "cross_validation" => {
            let scores: Vec<String> = f
                .candidates
                .iter()
                .map(|c| format!("{} ({}) {:.4}", c.name, c.n_free, c.cv_rms_mm))
                .collect();
            format!(
                "free set: {}, chosen by {}-fold cross-validation on the train poses (RMS of \
                 the left-out readings: {} mm){}",
                f.chosen,
                f.folds,
                scores.join(", "),
                if verbose {
                    format!("; {}", f.reason)
                } else {
                    String::new()
                }
            )
        }
        "requested" => format!("free set: {} as asked", f.chosen),
        _ => format!("free set: {} ({})", f.chosen, f.reason),
    };
    line(s, &text, 4);
}

/// The rig's anchors, when identified (`--rig-anchors`): one line, the
/// largest correction and the largest sigma; with `verbose`, every
/// anchor's correction.
fn rig(s: &mut String, r: &Report, verbose: bool) {
    let Some(ra) = &r.rig_anchors else {
        return;
    };
    let Some((big, norm)) = ra.largest() else {
        return;
    };
    let worst = ra
        .anchors
        .iter()
        .flat_map(|a| a.correction_mm_sigma)
        .fold(0.0, f64::max);
    let mut text = format!(
        "rig anchors identified ({} of {} shape modes): largest correction {norm:.3} mm ({}), \
         1-sigma <= {worst:.3} mm",
        ra.n_identified, ra.n_modes, big.anchor
    );
    let weak: Vec<&str> = ra
        .anchors
        .iter()
        .filter(|a| !a.identified)
        .map(|a| a.anchor.as_str())
        .collect();
    if !weak.is_empty() {
        let _ = write!(text, "; not determined: {}", weak.join(" "));
    }
    line(s, &text, 2);
    if verbose {
        for a in &ra.anchors {
            let c = a.correction_mm;
            let sd = a.correction_mm_sigma;
            line(
                s,
                &format!(
                    "  {}: dx {:.3} ± {:.3}, dy {:.3} ± {:.3}, dz {:.3} ± {:.3} mm; \
                     identifiability {:.3}",
                    a.anchor, c[0], sd[0], c[1], sd[1], c[2], sd[2], a.identifiability
                ),
                4,
            );
        }
        line(s, &format!("  (gauge: {})", ra.gauge), 4);
    }
}

/// What the data allow: string noise, the noise floor and the held-out RMS
/// an exact model would show; with `verbose`, the flange orientation's
/// sigma and the paper's closed form against least squares.
fn precision(s: &mut String, r: &Report, verbose: bool) {
    if let Some(sig) = r.string_sigma_mm {
        let mut text = format!("string noise {sig:.4} mm (1 sigma)");
        if let Some(f) = r.noise_floor_mm {
            let _ = write!(text, "; held-out noise floor {f:.4} mm");
        }
        if let Some(e) = r.expected_test_rms_mm {
            let _ = write!(text, "; an exact model would show about {e:.4} mm held out");
        }
        line(s, &text, 2);
    }
    if !verbose {
        return;
    }
    if r.expected_test_rms_mm.is_some() {
        line(
            s,
            &format!(
                "(the exact model's figure is the noise floor plus the spread of parameters \
                 identified from {} train poses)",
                r.stats.train.n
            ),
            2,
        );
    }
    if let Some(o) = r.flange_orientation_sigma_deg {
        line(
            s,
            &format!(
                "these data determine the flange orientation to {o:.3} deg (RMS rotation angle, \
                 1 sigma, robot base frame, before undetermined parameters are held; parameters \
                 held at nominal, among them those position data never see, taken as exact)"
            ),
            2,
        );
    }
    if let Some(c) = &r.closed_form_vs_lsq {
        line(
            s,
            &format!(
                "paper closed form vs least-squares points: RMS {:.4} mm, max {:.4} mm over {} \
                 poses{}: {}",
                c.rms_mm,
                c.max_mm,
                c.n,
                c.mirrored_note(),
                ClosedFormComparison::WHY
            ),
            2,
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
        let _ = writeln!(s);
        line(
            s,
            &format!(
                "outlier poses{}: {}",
                if r.robust { " (down-weighted)" } else { "" },
                ids.join(", ")
            ),
            2,
        );
    }
}

/// The physics analysis: its notes (the candidates it did not keep
/// counted, listed with `verbose`), then what it found, one line each
/// (with each finding's explanation and evidence when `verbose`).
fn physics(s: &mut String, r: &Report, verbose: bool) {
    let _ = writeln!(s);
    let (not_kept, notes): (Vec<&String>, Vec<&String>) = r
        .physics_notes
        .iter()
        .partition(|n| n.ends_with("not kept"));
    for note in notes {
        line(s, &format!("physics: {note}"), 2);
    }
    if verbose {
        for note in &not_kept {
            line(s, &format!("physics: {note}"), 2);
        }
    } else if !not_kept.is_empty() {
        line(
            s,
            &format!(
                "physics: {} candidate effect{} not kept (--verbose lists why)",
                not_kept.len(),
                if not_kept.len() == 1 { "" } else { "s" }
            ),
            2,
        );
    }
    if r.findings.is_empty() {
        if r.physics.ran() {
            line(s, "physics: nothing found beyond the geometric model", 2);
        }
        return;
    }
    line(
        s,
        "physics found beyond the geometric model (held-out RMS before -> after):",
        2,
    );
    for f in &r.findings {
        let place = match (f.joint, f.sensor) {
            (Some(j), _) => format!(" joint {j}"),
            (_, Some(k)) => format!(" sensor {k}"),
            _ => String::new(),
        };
        line(
            s,
            &format!(
                "- {}{}: {} {}; {:.4} -> {:.4} mm",
                f.effect,
                place,
                value_and_sigma(f.magnitude, f.sigma),
                f.unit,
                f.test_rms_before_mm,
                f.test_rms_after_mm
            ),
            4,
        );
        if verbose {
            line(s, &format!("  {}", f.explanation), 4);
            line(s, &format!("  evidence: {}", f.evidence), 4);
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
    use super::{WIDTH, line, value_and_sigma};

    #[test]
    fn lines_wrap_between_words_at_the_width() {
        let words = "word ".repeat(60);
        let mut s = String::new();
        line(&mut s, &format!("  {words}"), 4);
        let lines: Vec<&str> = s.lines().collect();
        assert!(lines.len() == 4, "{s}");
        assert!(lines.iter().all(|l| l.chars().count() <= WIDTH), "{s}");
        assert!(lines[0].starts_with("  word") && lines[1].starts_with("    word"));
        assert_eq!(s.matches("word").count(), 60);
        // A word longer than the width stays whole, on its own line.
        let mut s = String::new();
        line(&mut s, &format!("a {}", "x".repeat(120)), 2);
        assert_eq!(s, format!("a\n  {}\n", "x".repeat(120)));
    }

    #[test]
    fn values_are_shown_to_their_sigma() {
        assert_eq!(value_and_sigma(0.0025017, 5.11e-5), "0.002502 ± 0.000051");
        assert_eq!(value_and_sigma(0.0369, 0.0025), "0.0369 ± 0.0025");
        assert_eq!(value_and_sigma(-18686.3, 512.0), "-18686 ± 512");
        assert_eq!(value_and_sigma(1.5, f64::NAN), "1.5000");
    }
}
