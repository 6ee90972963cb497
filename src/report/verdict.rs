//! "Is my result good?": one word (green, amber, red) and the reason, in
//! terms a non-expert follows, from the figures a report already holds.

use std::fmt;

use super::Report;

/// Held-out RMS up to this multiple of what the noise allows is as good as
/// these data can show (the expected figure itself has a spread of a few
/// tens of percent over held-out sets of 10-20 poses).
const GREEN_RATIO: f64 = 1.3;
/// Beyond this multiple, most of the held-out error is not noise.
const RED_RATIO: f64 = 2.0;

/// How a calibration's result reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// As accurate as the noise allows; nothing asks for attention.
    Green,
    /// Usable, but something asks for attention (the reason says what).
    Amber,
    /// Not to be used as it is.
    Red,
}

impl fmt::Display for Level {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Level::Green => "green",
            Level::Amber => "amber",
            Level::Red => "red",
        })
    }
}

/// The verdict: the worst level any check gave, and every check's reason.
#[derive(Debug, Clone, PartialEq)]
pub struct Verdict {
    /// The worst level.
    pub level: Level,
    /// One sentence per check, worst first.
    pub reasons: Vec<String>,
}

impl Verdict {
    /// The verdict on `r`:
    ///
    /// - nothing held out: amber (the accuracy is unchecked);
    /// - the held-out RMS not better than the nominal model's: red;
    /// - the held-out RMS against what the noise allows (the report's
    ///   `expected_test_rms_mm`; for point data, which carry no noise
    ///   estimate, the train RMS widened for the parameters fitted): green
    ///   within 1.3x, red beyond 2x, amber between;
    /// - warnings on the input, or structure left that no effect of the
    ///   catalogue explains: at least amber.
    pub fn of(r: &Report) -> Verdict {
        let mut checks: Vec<(Level, String)> = Vec::new();
        let test = &r.stats.test;
        let (before, after) = (test.before.rms_mm, test.after.rms_mm);
        if test.n == 0 || !after.is_finite() {
            checks.push((
                Level::Amber,
                "no pose was held out, so the accuracy is unchecked (hold some out: --holdout)"
                    .into(),
            ));
        } else if after.partial_cmp(&before) != Some(std::cmp::Ordering::Less) {
            checks.push((
                Level::Red,
                format!(
                    "the calibration does not improve the held-out poses ({before:.4} -> \
                     {after:.4} mm RMS)"
                ),
            ));
        } else if let Some((allowed, what, noise_known)) = allowed_mm(r) {
            let ratio = after / allowed;
            let level = if ratio <= GREEN_RATIO {
                Level::Green
            } else if ratio <= RED_RATIO {
                Level::Amber
            } else {
                Level::Red
            };
            let words = match (level, noise_known) {
                (Level::Green, true) => "as good as the noise allows",
                (Level::Amber, true) => "some of the error is not noise",
                (Level::Red, true) => {
                    "most of the error is not noise: the model leaves something out"
                }
                // Point data: the train residual holds the noise and
                // whatever the model leaves out alike.
                (Level::Green, false) => {
                    "the held-out poses are fitted as well as the train ones (these data carry \
                     no noise estimate: how much of it is noise is not known)"
                }
                (_, false) => {
                    "the held-out poses are fitted worse than the train ones: too few poses \
                     for the parameters, or an error that varies over the workspace"
                }
            };
            checks.push((
                level,
                format!(
                    "held out {after:.4} mm RMS is {ratio:.2}x {what} ({allowed:.4} mm): {words}"
                ),
            ));
        }
        if !r.warnings.is_empty() {
            checks.push((
                Level::Amber,
                format!(
                    "{} warning{} on the input (above)",
                    r.warnings.len(),
                    if r.warnings.len() == 1 { "" } else { "s" }
                ),
            ));
        }
        let unexplained = r
            .findings
            .iter()
            .filter(|f| f.effect == "unexplained")
            .count();
        if unexplained > 0 {
            checks.push((
                Level::Amber,
                "structure is left that no effect of the catalogue explains (physics, below)"
                    .into(),
            ));
        }
        checks.sort_by_key(|c| std::cmp::Reverse(c.0));
        let level = checks.first().map_or(Level::Green, |c| c.0);
        let reasons = checks.into_iter().map(|(_, s)| s).collect();
        Verdict { level, reasons }
    }
}

/// What the held-out RMS is compared with, what that figure is, and
/// whether it is the noise's (string data) or the train residual's (point
/// data).
fn allowed_mm(r: &Report) -> Option<(f64, &'static str, bool)> {
    if let Some(e) = r.expected_test_rms_mm.filter(|e| e.is_finite() && *e > 0.0) {
        return Some((e, "what an exact model would show", true));
    }
    let (n, p) = (
        r.stats.train.n as f64,
        r.identifiability.n_identified as f64,
    );
    let train = r.stats.train.after.rms_mm;
    (n > p + 1.0 && train.is_finite() && train > 0.0).then(|| {
        (
            train * (n / (n - p)).sqrt(),
            "what the train residual predicts",
            false,
        )
    })
}
