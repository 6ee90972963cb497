//! The candidates of a round: every effect of the catalogue the session
//! can show (a backlash needs both approach directions, a thermal term a
//! driver that varies, a step a clock or a row order to place it) whose
//! slot no accepted effect holds, each with its look-elsewhere count.

use super::MAX_HARMONIC;
use crate::identify::Observations;
use crate::physics::effects::{Context, EffectModel, Kind, ThermalDriver};

/// Change-point grid of the anchor-step scan (coarse, then refined).
pub(super) const STEP_GRID: usize = 12;
/// Train poses a change point leaves on each side at least: a rig move
/// has six coefficients, and a segment of a pose or two would let it fit
/// those poses' noise (or an unrelated error) exactly.
pub(super) const MIN_SEGMENT_POSES: usize = 8;
/// Cap on the look-elsewhere count of one scanned change-point family.
const SCAN_EFFECTIVE_MAX: usize = 100;
/// Warm-up time constants tried for thermal expansion driven by time, as
/// fractions of the session's length (a linear growth is tried too).
const WARM_UP_TAU_FRACTIONS: [f64; 4] = [0.125, 0.25, 0.5, 1.0];

/// A candidate: the effect and how many positions were scanned to find it.
#[derive(Debug, Clone)]
pub(super) struct Candidate {
    pub(super) kind: Kind,
    pub(super) scanned: usize,
    pub(super) what: String,
}

/// The candidates being listed, so that each family's function can add
/// its own while a slot an accepted effect holds is left out in one place.
struct Listing<'a> {
    accepted: &'a [EffectModel],
    out: Vec<Candidate>,
}

impl Listing<'_> {
    /// Adds a candidate unless an accepted effect holds its slot.
    fn push(&mut self, kind: Kind, scanned: usize, what: String) {
        if !self.accepted.iter().any(|e| same_slot(&e.kind, &kind)) {
            self.out.push(Candidate {
                kind,
                scanned,
                what,
            });
        }
    }
}

/// Every candidate of a round, in a fixed order (joints, thermal, the rig,
/// the strings): the order breaks ties between equal scores.
pub(super) fn candidates(
    obs: &Observations,
    ctx: &Context,
    accepted: &[EffectModel],
) -> Vec<Candidate> {
    let train = &obs.train;
    let mut list = Listing {
        accepted,
        out: Vec::new(),
    };
    for j in 0..ctx.n_joints {
        joint_candidates(&mut list, ctx, train, j);
    }
    // The mount giving under the arm's moment: known only with masses.
    if ctx.has_masses {
        list.push(
            Kind::BaseTilt,
            1,
            "the gravity moment of the arm about the base".into(),
        );
    }
    // A long link bending under the weight it carries: known only with
    // masses.
    for j in 0..ctx.n_joints {
        if ctx.can_bend(j) {
            list.push(
                Kind::LinkBending { link_index: j },
                1,
                format!(
                    "the bending of the link from joint {} to joint {} under its load",
                    j + 1,
                    j + 2
                ),
            );
        }
    }
    // The tool giving under its payload: known only where poses carry one.
    if train.iter().any(|&i| ctx.poses[i].flange_moment_nm > 0.0) {
        list.push(
            Kind::ToolCompliance,
            1,
            "the gravity moment of the payload about the flange".into(),
        );
    }
    thermal_candidates(&mut list, ctx, train, accepted);
    // Change points at quantiles of the train times; each family scans
    // every change point of the session, so its look-elsewhere count is
    // spread over the grid.
    let times = sorted_train_times(obs, ctx);
    let change_points: Vec<f64> = if times.len() >= 2 * STEP_GRID {
        (1..STEP_GRID)
            .map(|g| g * times.len() / STEP_GRID)
            .filter(|&at| at >= MIN_SEGMENT_POSES && times.len() - at >= MIN_SEGMENT_POSES)
            .map(|at| 0.5 * (times[at - 1] + times[at]))
            .collect()
    } else {
        vec![]
    };
    // Look-elsewhere allowance of a change point scanned over the session:
    // every position counts while they are few; beyond SCAN_EFFECTIVE_MAX
    // the scan's statistics at neighbouring positions are so correlated
    // that more positions add almost no chance of a false alarm (for a
    // step scanned over a fixed fraction of the session the tail
    // probability tends to a constant times one test's: Siegmund's
    // approximation gives tens of effective tests at these thresholds).
    let scanned_per_point = times
        .len()
        .saturating_sub(1)
        .min(SCAN_EFFECTIVE_MAX)
        .div_ceil(STEP_GRID - 1);
    rig_candidates(
        &mut list,
        ctx,
        accepted,
        times.len(),
        &change_points,
        scanned_per_point,
    );
    if !ctx.anchors.is_empty() {
        string_candidates(&mut list, ctx, &change_points, scanned_per_point);
    }
    list.out
}

/// The train poses' distinct times, sorted: where change points may sit.
pub(super) fn sorted_train_times(obs: &Observations, ctx: &Context) -> Vec<f64> {
    let mut times: Vec<f64> = obs.train.iter().map(|&i| ctx.poses[i].time_s).collect();
    times.sort_by(|a, b| a.total_cmp(b));
    times.dedup();
    times
}

/// Joint `j`'s candidates: compliance where a gravity torque or lever is
/// known, backlash where the joint approached from both sides, a scale
/// error and each harmonic of a periodic error.
fn joint_candidates(list: &mut Listing, ctx: &Context, train: &[usize], j: usize) {
    let regressors = if ctx.has_masses {
        vec![]
    } else {
        ctx.compliance_regressors(j, train)
    };
    if ctx.has_masses || !regressors.is_empty() {
        list.push(
            Kind::JointCompliance {
                joint_index: j,
                regressors,
            },
            1,
            format!("gravity torque on joint {}", j + 1),
        );
    }
    let dirs: Vec<f64> = train.iter().map(|&i| ctx.poses[i].direction[j]).collect();
    if dirs.iter().any(|&d| d > 0.0) && dirs.iter().any(|&d| d < 0.0) {
        list.push(
            Kind::Backlash { joint_index: j },
            1,
            format!("the direction joint {} approached from", j + 1),
        );
    }
    list.push(
        Kind::JointScale { joint_index: j },
        1,
        format!("joint {} angle, in proportion (a scale error)", j + 1),
    );
    for h in 1..=MAX_HARMONIC {
        list.push(
            Kind::JointPeriodic {
                joint_index: j,
                harmonic: h,
            },
            1,
            format!("sin/cos of {h}x joint {} angle", j + 1),
        );
    }
}

/// Thermal expansion, while none is accepted and its driver varies over
/// the train poses.
fn thermal_candidates(
    list: &mut Listing,
    ctx: &Context,
    train: &[usize],
    accepted: &[EffectModel],
) {
    let th: Vec<f64> = train.iter().map(|&i| ctx.poses[i].thermal).collect();
    let (th_min, th_max) = th
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let thermal_taken = accepted
        .iter()
        .any(|e| matches!(e.kind, Kind::ThermalExpansion { .. }));
    // (Written so that a NaN range lists nothing, as a test of `>` does.)
    if !(th_max > th_min) || thermal_taken {
        return;
    }
    // Without a temperature the clock stands in for it, and a warm-up
    // settles rather than growing for ever: the time constant is
    // scanned (fractions of the session's length, and a linear growth),
    // each one a test of the look-elsewhere allowance.
    let taus: Vec<Option<f64>> = match ctx.thermal_driver {
        ThermalDriver::Time | ThermalDriver::Order => std::iter::once(None)
            .chain(WARM_UP_TAU_FRACTIONS.iter().map(|f| Some(f * th_max)))
            .collect(),
        ThermalDriver::Temperature => vec![None],
    };
    for &tau_h in &taus {
        list.push(
            Kind::ThermalExpansion {
                driver: ctx.thermal_driver,
                tau_h,
            },
            // The family's look-elsewhere count is one test per
            // time constant.
            1,
            match (ctx.thermal_driver, tau_h) {
                (ThermalDriver::Temperature, _) => "temperature".into(),
                (ThermalDriver::Time, None) => "time (no temperature)".into(),
                (ThermalDriver::Time, Some(t)) => format!(
                    "time (no temperature), as a warm-up settling with a time constant of {t:.2} h"
                ),
                (ThermalDriver::Order, None) => "row order (no time nor temperature)".into(),
                (ThermalDriver::Order, Some(t)) => format!(
                    "row order (no time nor temperature), as a warm-up settling over about {:.0} rows",
                    t * 1000.0
                ),
            },
        );
    }
}

/// The whole rig: a steady drift, and a move at each change point whose
/// grid bracket holds no kept one. `n_times` is the number of distinct
/// train times.
fn rig_candidates(
    list: &mut Listing,
    ctx: &Context,
    accepted: &[EffectModel],
    n_times: usize,
    change_points: &[f64],
    scanned_per_point: usize,
) {
    // A rig drift is six rates at once: it needs a recorded clock (a
    // string's drift, one rate, and a warm-up take the row order). A step
    // is a place in the session, which the row order gives too (else a rig
    // that moved is only seen as every anchor stepping at once).
    if ctx.timed && n_times > 2 {
        list.push(
            Kind::RigDrift,
            1,
            "a steady motion of the whole rig over the session".into(),
        );
    }
    for (g, &t0) in change_points.iter().enumerate() {
        // A kept step was refined within its grid neighbours: that bracket
        // is taken (another step elsewhere in the session is not).
        let lo = if g > 0 {
            change_points[g - 1]
        } else {
            f64::NEG_INFINITY
        };
        let hi = change_points.get(g + 1).copied().unwrap_or(f64::INFINITY);
        let kept_here = accepted
            .iter()
            .any(|e| matches!(e.kind, Kind::RigStep { t0_s } if t0_s > lo && t0_s < hi));
        if !kept_here {
            list.push(
                Kind::RigStep { t0_s: t0 },
                scanned_per_point,
                format!("a move of the whole rig {}", ctx.when(t0)),
            );
        }
    }
}

/// The strings: each one's scale, constant and creep, the sag of all, and
/// each one's step at every change point.
fn string_candidates(
    list: &mut Listing,
    ctx: &Context,
    change_points: &[f64],
    scanned_per_point: usize,
) {
    let m = ctx.anchors.len();
    let drift_clock = if ctx.timed {
        "time (a steady creep)"
    } else {
        "row order (a steady creep; no time_s)"
    };
    for k in 0..m {
        list.push(
            Kind::SensorScale { sensor_index: k },
            1,
            format!("length of string {}", k + 1),
        );
        list.push(
            Kind::SensorOffset { sensor_index: k },
            1,
            format!("a constant on string {}", k + 1),
        );
        list.push(
            Kind::SensorDrift { sensor_index: k },
            1,
            format!("{} on string {}", drift_clock, k + 1),
        );
    }
    list.push(Kind::CableSag, 1, "horizontal span of the strings".into());
    for &t0 in change_points {
        for k in 0..m {
            list.push(
                Kind::AnchorStep {
                    sensor_index: k,
                    t0_s: t0,
                },
                scanned_per_point,
                format!("a change {} on string {}", ctx.when(t0), k + 1),
            );
        }
    }
}

/// Same effect on the same joint/sensor (a second harmonic is another slot).
pub(super) fn same_slot(a: &Kind, b: &Kind) -> bool {
    match (a, b) {
        (
            Kind::AnchorStep {
                sensor_index: x, ..
            },
            Kind::AnchorStep {
                sensor_index: y, ..
            },
        ) => x == y,
        (Kind::RigStep { t0_s: x }, Kind::RigStep { t0_s: y }) => x == y,
        (
            Kind::JointCompliance { joint_index: x, .. },
            Kind::JointCompliance { joint_index: y, .. },
        ) => x == y,
        // A data-driven correction's slot is what it corrects and what
        // drives it, at any number of knots.
        (
            Kind::DataDriven {
                target: t1,
                target_index: i1,
                driver: d1,
                driver_index: k1,
                ..
            },
            Kind::DataDriven {
                target: t2,
                target_index: i2,
                driver: d2,
                driver_index: k2,
                ..
            },
        ) => t1 == t2 && i1 == i2 && d1 == d2 && k1 == k2,
        _ => a == b,
    }
}
