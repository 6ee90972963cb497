//! "Is my result good?": one word (green, amber, red) and the reason, in
//! terms a non-expert follows, from the figures a report already holds.

use std::fmt;

use serde::{Deserialize, Serialize};

use super::effect::Kind;
use super::{FixedReason, Report};

/// Held-out RMS up to this multiple of what the noise allows is as good as
/// these data can show (the expected figure itself has a spread of a few
/// tens of percent over held-out sets of 10-20 poses).
const GREEN_RATIO: f64 = 1.3;
/// Beyond this multiple, most of the held-out error is not noise.
const RED_RATIO: f64 = 2.0;

/// How a calibration's result reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    /// - warnings on the input, outliers, parameters these poses leave
    ///   undetermined (with the extra poses that would determine them), a
    ///   free set that cross-validation made smaller, or structure left
    ///   that no effect of the catalogue explains: at least amber;
    /// - what no pose of this rig would separate, what compensation does
    ///   with the physics found, and how many deviations are within noise
    ///   of nominal: said, green.
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
            // Parameters held at nominal for want of data are an error the
            // exact-model figure does not count: say so where it may be why.
            let held = r.extra_poses.as_ref().is_some_and(|x| !x.poses.is_empty());
            let why = if level > Level::Green && held {
                " (the parameters these poses leave at nominal, below, may be why)"
            } else {
                ""
            };
            checks.push((
                level,
                format!(
                    "held out {after:.4} mm RMS is {ratio:.2}x {what} ({allowed:.4} mm): \
                     {words}{why}"
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
        checks.extend(outliers(r));
        checks.extend(undetermined(r));
        checks.extend(smaller_free_set(r));
        checks.extend(compensation(r));
        checks.extend(not_significant(r));
        // Stable: within a level, the order the checks were made in.
        checks.sort_by_key(|c| std::cmp::Reverse(c.0));
        let level = checks.first().map_or(Level::Green, |c| c.0);
        let reasons = checks.into_iter().map(|(_, s)| s).collect();
        Verdict { level, reasons }
    }

    /// The report's own verdict, or for a report written before reports
    /// carried one, the verdict computed now.
    pub fn read(r: &Report) -> Verdict {
        r.verdict.clone().unwrap_or_else(|| Verdict::of(r))
    }
}

/// Poses the robust fit set apart.
fn outliers(r: &Report) -> Option<(Level, String)> {
    let n = r.outliers.len();
    (n > 0).then(|| {
        let ids: Vec<&str> = r.outliers.iter().take(5).map(|o| o.pose.as_str()).collect();
        (
            Level::Amber,
            format!(
                "{n} pose{} fit much worse than the rest ({}{}): check them (a string caught or \
                 slack, a wrong angle, a pose recorded while moving)",
                if n == 1 { "" } else { "s" },
                ids.join(", "),
                if n > 5 { ", ..." } else { "" }
            ),
        )
    })
}

/// Parameters held at nominal for want of data: what would determine them
/// (amber), or that no pose of this rig would (said, green: their effect
/// on T is carried by the parameters they move it like).
fn undetermined(r: &Report) -> Vec<(Level, String)> {
    let mut out = Vec::new();
    let Some(x) = &r.extra_poses else {
        let held: Vec<&str> = r
            .identifiability
            .fixed
            .iter()
            .filter(|f| f.reason == FixedReason::Undetermined)
            .map(|f| f.name.as_str())
            .collect();
        if !held.is_empty() {
            out.push((
                Level::Amber,
                format!(
                    "these poses leave {} undetermined (held at nominal); `drawcal plan` \
                     proposes poses that determine what this rig can",
                    held.join(", ")
                ),
            ));
        }
        return out;
    };
    if !x.poses.is_empty() {
        let names: Vec<String> = x
            .parameters
            .iter()
            .map(|p| match p.sigma_with_extra {
                Some(s) => format!("{} (1-sigma to {s:.3} {})", p.name, p.unit),
                None => p.name.clone(),
            })
            .collect();
        let n = x.poses.len();
        out.push((
            Level::Amber,
            format!(
                "these poses leave parameters undetermined (held at nominal): {n} extra \
                 pose{} (extra_poses in the report; `drawcal export REPORT --format \
                 extra-targets`) would determine {}",
                if n == 1 { "" } else { "s" },
                names.join(", ")
            ),
        ));
    }
    if !x.inseparable.is_empty() {
        let items: Vec<String> = x
            .inseparable
            .iter()
            .map(|f| format!("{} (like {})", f.name, f.aliased_with.join(", ")))
            .collect();
        out.push((
            Level::Green,
            format!(
                "no pose of this rig would separate {}: held at nominal, their effect on the \
                 tool point is carried by the parameters named",
                items.join("; ")
            ),
        ));
    }
    out
}

/// A free set smaller than every identifiable parameter, chosen by
/// cross-validation: the best these poses give, but what it holds at
/// nominal more poses would determine.
fn smaller_free_set(r: &Report) -> Option<(Level, String)> {
    let f = r.free_set.as_ref()?;
    if f.how != "cross_validation" || f.chosen == "all" {
        return None;
    }
    let held: Vec<&str> = r
        .identifiability
        .fixed
        .iter()
        .filter(|p| p.reason == FixedReason::FreeSet)
        .map(|p| p.name.as_str())
        .collect();
    Some((
        Level::Amber,
        format!(
            "with {} train poses a smaller model predicts better, so only the {} were freed \
             and {} stay at nominal: more well-spread poses (`drawcal plan`) let every \
             parameter be freed",
            r.stats.train.n,
            match f.chosen.as_str() {
                "offsets" => "joint offsets",
                "lengths" => "joint offsets and link lengths",
                other => other,
            },
            if held.is_empty() {
                "the rest".to_string()
            } else {
                held.join(", ")
            }
        ),
    ))
}

/// What compensation does with the effects found: which it applies (and
/// what each needs sent with a target), which describe this recording only.
fn compensation(r: &Report) -> Option<(Level, String)> {
    let (mut applied, mut session) = (Vec::new(), Vec::new());
    for f in &r.findings {
        let Some(model) = f.effect_model() else {
            continue;
        };
        let name = match (f.joint, f.sensor) {
            (Some(j), _) => format!("{} j{j}", f.effect),
            (None, Some(s)) => format!("{} s{s}", f.effect),
            _ => f.effect.clone(),
        };
        let needs = match &model.kind {
            Kind::ThermalExpansion { .. } => Some("temp_c"),
            Kind::Backlash { .. } => Some("the approach direction"),
            // Whatever a payload loads (the effect says which it is).
            _ if model.payload_matters(r.nominal_robot.dof()) => Some("payload_kg"),
            _ => None,
        };
        let used = match &model.kind {
            // A correction of what T is (not of what the strings read) by
            // a driver a future target carries.
            k @ Kind::DataDriven { driver, .. } => {
                driver.usable_for_compensation() && k.robot_side()
            }
            k => k.robot_side() && k.change_time_s().is_none() && *k != Kind::RigDrift,
        };
        match (used, needs) {
            (true, Some(n)) => applied.push(format!("{name} (send {n})")),
            (true, None) => applied.push(name),
            (false, _) => session.push(name),
        }
    }
    if applied.is_empty() && session.is_empty() {
        return None;
    }
    let mut parts = Vec::new();
    if !applied.is_empty() {
        parts.push(format!("compensation applies {}", applied.join(", ")));
    }
    if !session.is_empty() {
        parts.push(format!(
            "{} describe{} this recording (the rig, the sensors or the session's clock), not \
             the robot, and {} not applied",
            session.join(", "),
            if session.len() == 1 { "s" } else { "" },
            if session.len() == 1 { "is" } else { "are" }
        ));
    }
    Some((Level::Green, parts.join("; ")))
}

/// How many identified joint deviations are within two sigma of nominal:
/// not a fault (the robot is close to nominal there), but worth knowing.
fn not_significant(r: &Report) -> Option<(Level, String)> {
    let joint = |name: &str| name.starts_with('j');
    let n = r.parameters.iter().filter(|p| joint(&p.name)).count();
    let small = r
        .parameters
        .iter()
        .filter(|p| joint(&p.name) && p.sigma > 0.0 && p.deviation.abs() < 2.0 * p.sigma)
        .count();
    (n > 0 && small > 0).then(|| {
        (
            Level::Green,
            format!(
                "{small} of the {n} identified joint parameters {} within two sigma of nominal \
                 (no significant deviation there)",
                if small == 1 { "is" } else { "are" }
            ),
        )
    })
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
