//! The analysis after a geometric identification: locate the mismatch, name
//! the missing physics, model it, prove it on held-out poses.
//!
//! Method (forward selection with statistical gates):
//! 1. Linearise the augmented problem at the current fit: columns are the
//!    free geometric parameters, the accepted effects' coefficients and the
//!    coefficients of every candidate effect (at zero). One pass over the
//!    train rows accumulates `JᵀJ`, `Jᵀr`, `rᵀr`, split into five folds.
//! 2. For each candidate, the chi-square drop of adding it (block
//!    elimination of the current columns, so geometry and accepted effects
//!    are refitted alongside), an alias check (a coefficient whose column
//!    is nearly a combination of the geometric ones is dropped: it is not
//!    counted twice), and a significance test against the residual variance
//!    with a Bonferroni allowance for every candidate and every scanned
//!    change point tested.
//! 3. The most significant candidate must also lower the 5-fold
//!    cross-validated error of the train poses; it is then refitted
//!    nonlinearly with everything else (Levenberg-Marquardt) and kept only
//!    if the held-out RMS drops.
//! 4. Repeat until nothing significant remains. Finally, test whether the
//!    residuals still vary smoothly along any joint angle, time or
//!    temperature, exceed the strings' own noise, or are confined to a
//!    stretch of one joint's range (confirmed on the held-out poses); if so
//!    report an `unexplained` finding saying where.

use nalgebra::{DMatrix, DVector, Vector3};

use super::effects::{Context, EffectModel, Kind, PoseInput, ThermalDriver};
use super::problem::{EffectProblem, accumulate};
use super::unexplained::{robot_side_share, unexplained};
use crate::error::Result;
use crate::identify::lm::{self, LeastSquares, LmSettings};
use crate::identify::{Geometric, Observations, Progress};
use crate::kinematics::Params;
use crate::measure;
use crate::model::Measurement;
use crate::report::{EffectParameters, Finding, FindingModel};
use crate::rng::Rng;
use crate::stats::chi2_quantile_upper;

/// Family-wise false-alarm rate of one selection round.
pub const ALPHA: f64 = 0.005;
/// A coefficient whose column keeps less than this fraction (sine of the
/// angle) outside the span of the geometric columns is aliased.
pub const ALIAS_SINE: f64 = 0.03;
/// The held-out gain must exceed this many standard errors (one-sided,
/// about 2.3% by chance), so noise alone does not buy an effect.
pub const HELD_OUT_Z: f64 = 2.0;
/// Each member of a pair kept together must improve the held-out readings
/// beyond the other alone by this paired z (positive evidence that it
/// adds something; the pair as a whole passes [`HELD_OUT_Z`]).
pub const PAIR_MEMBER_Z: f64 = 1.0;
/// Other candidates of this round on the same joint or sensor that explain
/// on their own at least [`TWIN_SHARE`] of what the kept effect `kind`
/// (scored as `kept`) explains, one per effect, described: a positioner
/// whose gravity torque is a pure sinusoid of the joint makes compliance
/// and a once-per-turn error the same model, and the name is then a choice
/// the finding must own up to. `members` are the kept proposal's.
fn indistinguishable(
    scored: &[Scored],
    cands: &[Candidate],
    members: &[(usize, f64)],
    kind: &Kind,
    kept: &Scored,
) -> Vec<String> {
    let mut out: Vec<&Candidate> = Vec::new();
    for o in scored {
        let c = &cands[o.idx];
        let k = &c.kind;
        let member = members.iter().any(|m| scored[m.0].idx == o.idx);
        let twin = !member
            && (k.joint().is_some() || k.sensor().is_some())
            && k.name() != kind.name()
            && k.joint() == kind.joint()
            && k.sensor() == kind.sensor()
            && o.drop >= TWIN_SHARE * kept.drop;
        // One per effect (a step scanned over the session would otherwise
        // be listed at every position).
        if twin && !out.iter().any(|x| x.kind.name() == k.name()) {
            out.push(c);
        }
    }
    out.iter()
        .map(|c| format!("{} ({})", c.kind.name(), c.what))
        .collect()
}

/// Two-sided false-alarm rate of [`MAGNITUDE_Z`] sigma, for magnitudes
/// that are a norm of several coefficients (tested as a block).
const MAGNITUDE_ALPHA: f64 = 0.0455;

/// Is a fitted effect's size distinguishable from none? A magnitude that
/// is one signed coefficient (a compliance with masses, a backlash, a
/// thermal, scale or offset coefficient, a sag) must be [`MAGNITUDE_Z`]
/// sigma from zero; one that is a norm of several (a periodic amplitude,
/// a step of an anchor or of the rig, the RMS of a lumped compliance) is
/// never negative, so its coefficients are tested together: the Wald
/// statistic `cᵀ C⁻¹ c` against chi-square with as many degrees of freedom.
fn distinguishable_from_zero(e: &EffectModel, info: &FitInfo, mag: f64, sig: f64) -> bool {
    let signed = match &e.kind {
        Kind::JointCompliance { regressors, .. } => regressors.is_empty(),
        Kind::JointPeriodic { .. }
        | Kind::AnchorStep { .. }
        | Kind::RigStep { .. }
        | Kind::RigDrift => false,
        _ => true,
    };
    if signed {
        return mag.abs() > MAGNITUDE_Z * sig;
    }
    let c = DVector::from_column_slice(&e.coef);
    let Ok(inv) = info.cov_last.clone().pseudo_inverse(1e-12) else {
        return true;
    };
    let wald = c.dot(&(&inv * &c));
    let rank = info.cov_last.rank(1e-12 * info.cov_last.norm()).max(1);
    wald > chi2_quantile_upper(MAGNITUDE_ALPHA, rank)
}

/// Another candidate explaining at least this share of a kept effect's
/// chi-square drop on its own is named beside it as indistinguishable.
const TWIN_SHARE: f64 = 0.98;
/// A kept effect's magnitude is at least this many sigma from zero.
pub const MAGNITUDE_Z: f64 = 2.0;
/// Cross-validation folds.
const FOLDS: usize = 5;
/// At most this many effects are modelled.
const MAX_EFFECTS: usize = 6;
/// Change-point grid of the anchor-step scan (coarse, then refined).
const STEP_GRID: usize = 12;
/// Train poses a change point leaves on each side at least: a rig move
/// has six coefficients, and a segment of a pose or two would let it fit
/// those poses' noise (or an unrelated error) exactly.
const MIN_SEGMENT_POSES: usize = 8;
/// Cap on the look-elsewhere count of one scanned change-point family.
const SCAN_EFFECTIVE_MAX: usize = 100;
/// Leading candidates for which a jointly tested partner is sought.
const PAIR_LEADS: usize = 4;
/// Highest harmonic of a joint's periodic error tried: once per
/// revolution (eccentricity), twice (an elliptic bearing or encoder disc)
/// and three times (a three-lobed gear or an encoder read by three heads).
pub const MAX_HARMONIC: u32 = 3;
/// Proposals (single effects or pairs) tried per round.
const TRIES: usize = 4;
/// Warm-up time constants tried for thermal expansion driven by time, as
/// fractions of the session's length (a linear growth is tried too).
const WARM_UP_TAU_FRACTIONS: [f64; 4] = [0.125, 0.25, 0.5, 1.0];

/// A proposal of one round: one candidate, or two tested jointly. Members
/// are (index into the scored list, chi-square given the other member).
#[derive(Debug, Clone)]
struct Proposal {
    score: f64,
    members: Vec<(usize, f64)>,
    /// Drop of the train SSE over the accepted model (mm²).
    drop: f64,
    /// Sum of the members' Bonferroni thresholds.
    threshold: f64,
    /// Residual variance per reading with the proposal fitted (mm²).
    s2: f64,
}

/// Held-out residuals in the space of what was measured (string readings
/// or point coordinates), per test pose: the sum of squares over the pose's
/// rows and their number.
pub(super) fn reading_errors(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    effects: &[EffectModel],
) -> Vec<(f64, usize)> {
    let problem =
        EffectProblem::of_observations(obs, ctx, obs.test.clone(), p, vec![], effects.to_vec());
    let mut out = vec![(0.0, 0usize); obs.test.len()];
    problem.rows(&problem.x0(), |pos, r, _| {
        out[pos].0 += r * r;
        out[pos].1 += 1;
    });
    out
}

fn rms_sums(e: &[(f64, usize)]) -> f64 {
    let (s, n) = e.iter().fold((0.0, 0), |acc, v| (acc.0 + v.0, acc.1 + v.1));
    (s / n.max(1) as f64).sqrt()
}

/// Wilcoxon signed-rank z of the per-pose drop of the summed squares.
fn paired_gain_z_sums(before: &[(f64, usize)], after: &[(f64, usize)]) -> f64 {
    let b: Vec<Vector3<f64>> = before
        .iter()
        .map(|v| Vector3::new(v.0.sqrt(), 0.0, 0.0))
        .collect();
    let a: Vec<Vector3<f64>> = after
        .iter()
        .map(|v| Vector3::new(v.0.sqrt(), 0.0, 0.0))
        .collect();
    paired_gain_z(&b, &a)
}

/// Result of the analysis.
#[derive(Debug, Clone)]
pub struct Analysis {
    /// Findings, in the order they were accepted, then any `unexplained`.
    pub findings: Vec<Finding>,
    /// Geometric parameters refitted with the accepted effects.
    pub final_params: Params,
    /// The accepted effect models (internal units).
    pub effects: Vec<EffectModel>,
    /// Effect context of every pose (for compensation and errors).
    pub context: Context,
    /// Held-out errors of the final model (base frame, mm), test poses in
    /// session order.
    pub test_errors: Vec<Vector3<f64>>,
    /// Share of the string residual energy that one displacement of T
    /// explains (robot side), after the geometric fit; `None` without a
    /// redundant string.
    pub robot_side_share: Option<f64>,
    /// The share expected from noise alone (3 / strings).
    pub robot_side_share_noise: Option<f64>,
    /// Lines for the CLI summary: where the residual lives.
    pub notes: Vec<String>,
    /// 1-sigma of the free geometric parameters from the final refit with
    /// the accepted effects (None when nothing was accepted: the geometric
    /// fit's own covariance stands).
    pub final_sigmas: Option<Vec<f64>>,
}

/// One-sided z that the held-out error dropped: Wilcoxon signed-rank test
/// (normal approximation) on `|e_before|² - |e_after|²` per held-out pose.
/// Rank-based because the squared errors of located points are
/// heavy-tailed (poses with a poor string geometry dominate a mean).
fn paired_gain_z(before: &[Vector3<f64>], after: &[Vector3<f64>]) -> f64 {
    let mut d: Vec<f64> = before
        .iter()
        .zip(after)
        .map(|(b, a)| b.norm_squared() - a.norm_squared())
        .filter(|v| *v != 0.0)
        .collect();
    let n = d.len() as f64;
    // Fewer than two poses changed: no evidence either way.
    if n < 2.0 {
        return 0.0;
    }
    d.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    let w_plus: f64 = d
        .iter()
        .enumerate()
        .filter(|(_, v)| **v > 0.0)
        .map(|(r, _)| (r + 1) as f64)
        .sum();
    let mean = n * (n + 1.0) / 4.0;
    let var = n * (n + 1.0) * (2.0 * n + 1.0) / 24.0;
    (w_plus - mean) / var.sqrt()
}

/// Build the effect context of a session (located or measured points).
pub fn effect_context(obs: &Observations, p: &Params) -> Context {
    let (rb, _) = p.base_rt();
    let inputs: Vec<PoseInput> = obs
        .data
        .poses
        .iter()
        .zip(&obs.measured)
        .map(|(pose, m)| PoseInput {
            q_rad: &pose.q_rad,
            time_s: pose.time_s,
            temp_c: pose.temp_c,
            payload_kg: pose.payload_kg,
            point_rig: *m,
        })
        .collect();
    Context::new(obs.robot, obs.anchors.clone(), obs.rig.r_mm, &rb, &inputs)
}

/// Errors (model minus measured T, robot base frame, mm) at poses `idx` of
/// the geometric parameters `p` with `effects` applied: robot-side effects
/// move the model's T, sensor-side effects correct the readings before the
/// point is located again. Without effects this equals `Session::errors`.
pub fn errors_with_effects(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    effects: &[EffectModel],
    idx: &[usize],
) -> Vec<Vector3<f64>> {
    let rb = p_base_rotation(obs, p);
    let sensor = effects.iter().any(|e| !e.kind.robot_side());
    idx.iter()
        .map(|&i| {
            let pose = &obs.data.poses[i];
            let (t, dl) = EffectProblem::model_point(&obs.chain, ctx, p, effects, i, &pose.q_rad);
            let measured = match (&pose.measurement, sensor) {
                (Measurement::Strings(l), true) => {
                    let dist: Vec<f64> = l
                        .iter()
                        .zip(&dl)
                        .map(|(v, d)| v - d + obs.rig.r_mm)
                        .collect();
                    measure::locate(&obs.anchors, &dist, Some(&obs.measured[i]))
                        .map(|x| x.point)
                        .unwrap_or(obs.measured[i])
                }
                _ => obs.measured[i],
            };
            rb.transpose() * (t - measured)
        })
        .collect()
}

fn p_base_rotation(obs: &Observations, p: &[f64]) -> nalgebra::Matrix3<f64> {
    let b = obs.chain.layout.base();
    crate::kinematics::rpy_matrix(p[b + 3], p[b + 4], p[b + 5])
}

pub(super) fn rms(e: &[Vector3<f64>]) -> f64 {
    if e.is_empty() {
        return f64::NAN;
    }
    (e.iter().map(|v| v.norm_squared()).sum::<f64>() / e.len() as f64).sqrt()
}

/// A candidate: the effect and how many positions were scanned to find it.
#[derive(Debug, Clone)]
struct Candidate {
    kind: Kind,
    scanned: usize,
    what: String,
}

fn candidates(obs: &Observations, ctx: &Context, accepted: &[EffectModel]) -> Vec<Candidate> {
    let n = ctx.n_joints;
    let m = ctx.anchors.len();
    let train = &obs.train;
    let mut out = Vec::new();
    let taken = |k: &Kind| accepted.iter().any(|e| same_slot(&e.kind, k));
    let mut push = |kind: Kind, scanned: usize, what: String| {
        if !taken(&kind) {
            out.push(Candidate {
                kind,
                scanned,
                what,
            });
        }
    };
    for j in 0..n {
        let regressors = if ctx.has_masses {
            vec![]
        } else {
            ctx.compliance_regressors(j, train)
        };
        if ctx.has_masses || !regressors.is_empty() {
            push(
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
            push(
                Kind::Backlash { joint_index: j },
                1,
                format!("the direction joint {} approached from", j + 1),
            );
        }
        push(
            Kind::JointScale { joint_index: j },
            1,
            format!("joint {} angle, in proportion (a scale error)", j + 1),
        );
        for h in 1..=MAX_HARMONIC {
            push(
                Kind::JointPeriodic {
                    joint_index: j,
                    harmonic: h,
                },
                1,
                format!("sin/cos of {h}x joint {} angle", j + 1),
            );
        }
    }
    let th: Vec<f64> = train.iter().map(|&i| ctx.poses[i].thermal).collect();
    let (th_min, th_max) = th
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let thermal_taken = accepted
        .iter()
        .any(|e| matches!(e.kind, Kind::ThermalExpansion { .. }));
    if th_max > th_min && !thermal_taken {
        use super::effects::ThermalDriver;
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
            push(
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
    // Change points at quantiles of the train times; each family scans
    // every change point of the session, so its look-elsewhere count is
    // spread over the grid.
    let mut times: Vec<f64> = train.iter().map(|&i| ctx.poses[i].time_s).collect();
    times.sort_by(|a, b| a.total_cmp(b));
    times.dedup();
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
    // A rig drift is six rates at once: it needs a recorded clock (a
    // string's drift, one rate, and a warm-up take the row order). A step
    // is a place in the session, which the row order gives too (else a rig
    // that moved is only seen as every anchor stepping at once).
    if ctx.timed && times.len() > 2 {
        push(
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
            push(
                Kind::RigStep { t0_s: t0 },
                scanned_per_point,
                format!("a move of the whole rig {}", ctx.when(t0)),
            );
        }
    }
    if m > 0 {
        let drift_clock = if ctx.timed {
            "time (a steady creep)"
        } else {
            "row order (a steady creep; no time_s)"
        };
        for k in 0..m {
            push(
                Kind::SensorScale { sensor_index: k },
                1,
                format!("length of string {}", k + 1),
            );
            push(
                Kind::SensorOffset { sensor_index: k },
                1,
                format!("a constant on string {}", k + 1),
            );
            push(
                Kind::SensorDrift { sensor_index: k },
                1,
                format!("{} on string {}", drift_clock, k + 1),
            );
        }
        push(Kind::CableSag, 1, "horizontal span of the strings".into());
        for &t0 in &change_points {
            for k in 0..m {
                push(
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
    out
}

/// Same effect on the same joint/sensor (a second harmonic is another slot).
fn same_slot(a: &Kind, b: &Kind) -> bool {
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
        _ => a == b,
    }
}

/// Normal equations of the train poses, linearised at `p` with the
/// accepted effects at their fitted values and `extra` effects appended at
/// zero (their columns are what a candidate would add).
fn train_normals(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    free: &[usize],
    accepted: &[EffectModel],
    extra: impl IntoIterator<Item = Kind>,
    fold_of: &[usize],
) -> Normals {
    let mut effects = accepted.to_vec();
    effects.extend(extra.into_iter().map(EffectModel::zero));
    let problem =
        EffectProblem::of_observations(obs, ctx, obs.train.clone(), p, free.to_vec(), effects);
    normals(&problem, &problem.x0(), fold_of)
}

/// Each member of a pair significant given the other (chi-square of its
/// columns over its threshold), linearised at the current parameters.
fn pair_holds(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    free: &[usize],
    accepted: &[EffectModel],
    pair: &[Candidate],
    thresholds: &[f64],
) -> bool {
    let nm = train_normals(
        obs,
        ctx,
        p,
        free,
        accepted,
        pair.iter().map(|c| c.kind.clone()),
        &vec![0; obs.train.len()],
    );
    let (a, b, rr) = nm.total();
    let n_acc: usize = accepted.iter().map(|e| e.kind.n_coef()).sum();
    let base: Vec<usize> = (0..free.len() + n_acc).collect();
    let mut off = base.len();
    let own: Vec<Vec<usize>> = pair
        .iter()
        .map(|c| {
            let nc = c.kind.n_coef();
            let cols = unaliased(&a, &base, &(off..off + nc).collect::<Vec<_>>());
            off += nc;
            cols
        })
        .collect();
    let mut full = base.clone();
    own.iter().for_each(|c| full.extend(c));
    let Some((d_full, _)) = solve_subset(&a, &b, &full) else {
        return false;
    };
    let dof = (nm.rows as f64 - full.len() as f64).max(1.0);
    let s2 = ((rr - d_full) / dof).max(1e-30);
    (0..pair.len()).all(|mi| {
        let mut without = base.clone();
        for (oi, c) in own.iter().enumerate() {
            if oi != mi {
                without.extend(c);
            }
        }
        solve_subset(&a, &b, &without).is_some_and(|(d, _)| (d_full - d) / s2 > thresholds[mi])
    })
}

/// Normal equations of a column set, split by fold.
struct Normals {
    n: usize,
    a: Vec<DMatrix<f64>>,
    b: Vec<Vec<f64>>,
    rr: Vec<f64>,
    rows: usize,
}

impl Normals {
    fn total(&self) -> (DMatrix<f64>, Vec<f64>, f64) {
        let mut a = DMatrix::zeros(self.n, self.n);
        let mut b = vec![0.0; self.n];
        let mut rr = 0.0;
        for f in 0..self.a.len() {
            a += &self.a[f];
            for i in 0..self.n {
                b[i] += self.b[f][i];
            }
            rr += self.rr[f];
        }
        (a, b, rr)
    }
}

fn normals(problem: &EffectProblem, x: &[f64], fold_of: &[usize]) -> Normals {
    let n = x.len();
    let mut up = vec![vec![0.0; n * n]; FOLDS];
    let mut g = vec![vec![0.0; n]; FOLDS];
    let mut rr = vec![0.0; FOLDS];
    let mut rows = 0;
    problem.rows(x, |pos, r, row| {
        let f = fold_of[pos];
        accumulate(&mut up[f], &mut g[f], n, row, r);
        rr[f] += r * r;
        rows += 1;
    });
    let a = up
        .iter()
        .map(|u| {
            DMatrix::from_fn(
                n,
                n,
                |i, j| if i <= j { u[i * n + j] } else { u[j * n + i] },
            )
        })
        .collect();
    Normals {
        n,
        a,
        b: g,
        rr,
        rows,
    }
}

/// `min |r + J δ|²` over the columns `cols`: the SSE drop `bᵀA⁻¹b` and `δ`.
/// A column no row supports (all zero, e.g. a backlash's unknown-approach
/// offset when cross-validation holds out the poses it covers) stays at 0.
fn solve_subset(a: &DMatrix<f64>, b: &[f64], cols: &[usize]) -> Option<(f64, Vec<f64>)> {
    if cols.iter().any(|&i| a[(i, i)] == 0.0) {
        let live: Vec<usize> = cols.iter().copied().filter(|&i| a[(i, i)] != 0.0).collect();
        let (drop, d) = solve_subset(a, b, &live)?;
        let mut it = d.into_iter();
        let full = cols
            .iter()
            .map(|&i| {
                if a[(i, i)] == 0.0 {
                    0.0
                } else {
                    it.next().unwrap_or(0.0)
                }
            })
            .collect();
        return Some((drop, full));
    }
    let k = cols.len();
    if k == 0 {
        return Some((0.0, vec![]));
    }
    let d: Vec<f64> = cols.iter().map(|&i| a[(i, i)].sqrt().max(1e-300)).collect();
    let mut s = DMatrix::from_fn(k, k, |i, j| a[(cols[i], cols[j])] / (d[i] * d[j]));
    for i in 0..k {
        s[(i, i)] += 1e-12;
    }
    let rhs = nalgebra::DVector::from_fn(k, |i, _| b[cols[i]] / d[i]);
    let ch = s.cholesky()?;
    let y = ch.solve(&rhs);
    let drop = rhs.dot(&y);
    Some((drop, (0..k).map(|i| -y[i] / d[i]).collect()))
}

/// Cross-validated SSE of the column set `cols` (linearised refits).
fn cv_sse(nm: &Normals, a: &DMatrix<f64>, b: &[f64], cols: &[usize]) -> f64 {
    let mut total = 0.0;
    for f in 0..nm.a.len() {
        let af = &nm.a[f];
        let bf = &nm.b[f];
        let a_tr = a - af;
        let b_tr: Vec<f64> = b.iter().zip(bf).map(|(x, y)| x - y).collect();
        let delta = match solve_subset(&a_tr, &b_tr, cols) {
            Some((_, d)) => d,
            None => return f64::INFINITY,
        };
        let mut sse = nm.rr[f];
        for (i, &ci) in cols.iter().enumerate() {
            sse += 2.0 * delta[i] * bf[ci];
            for (j, &cj) in cols.iter().enumerate() {
                sse += delta[i] * af[(ci, cj)] * delta[j];
            }
        }
        total += sse;
    }
    total
}

/// Columns of `cand` (absolute indices) that are not aliased with `base`.
fn unaliased(a: &DMatrix<f64>, base: &[usize], cand: &[usize]) -> Vec<usize> {
    let mut keep = Vec::new();
    for &c in cand {
        let aii = a[(c, c)];
        if aii <= 0.0 {
            continue;
        }
        let mut cols = base.to_vec();
        cols.extend(&keep);
        let bcol: Vec<f64> = (0..a.nrows()).map(|r| a[(r, c)]).collect();
        // Part of column c explained by the others: the "drop" of fitting
        // column c's own values with them.
        let explained = solve_subset(a, &bcol, &cols).map(|(d, _)| d).unwrap_or(aii);
        let sin2 = ((aii - explained) / aii).max(0.0);
        if sin2.sqrt() > ALIAS_SINE {
            keep.push(c);
        }
    }
    keep
}

/// Score of one candidate in one round.
#[derive(Debug, Clone)]
struct Scored {
    idx: usize,
    cols: Vec<usize>,
    drop: f64,
    chi2: f64,
    threshold: f64,
    /// Residual variance per reading with the candidate fitted (mm²).
    s2: f64,
}

/// Run the analysis after `geometric()`.
pub fn analyse(obs: &Observations, geo: &Geometric, progress: &dyn Progress) -> Result<Analysis> {
    let ctx = effect_context(obs, &geo.after);
    let free = geo.selection.free.clone();
    let mut p = geo.after.values.clone();
    let mut accepted: Vec<EffectModel> = Vec::new();
    let mut findings = Vec::new();
    let mut notes = Vec::new();
    let mut fold_of: Vec<usize> = (0..obs.train.len()).map(|i| i % FOLDS).collect();
    Rng::new(7).shuffle(&mut fold_of);

    // Where the residual lives: robot side versus sensor side.
    let (share, share_noise) = robot_side_share(obs, &p);
    if let (Some(s), Some(s0)) = (share, share_noise) {
        notes.push(format!(
            "string residuals after the geometric fit: {:.0}% is a common displacement of T (robot side), {:.0}% disagreement between strings (sensor side); noise alone would give {:.0}% / {:.0}%",
            100.0 * s,
            100.0 * (1.0 - s),
            100.0 * s0,
            100.0 * (1.0 - s0)
        ));
    }

    let mut rejected: Vec<Kind> = Vec::new();
    let mut final_sigmas = None;
    let mut final_fit: Option<FitInfo> = None;
    for round in 0..MAX_EFFECTS + 2 {
        if accepted.len() >= MAX_EFFECTS {
            break;
        }
        progress.update("physics analysis", round as f64 / (MAX_EFFECTS + 2) as f64);
        // A round refits the whole model: the place to honour a cancel.
        if progress.cancelled() {
            return Err(crate::Error::Cancelled);
        }
        let cands: Vec<Candidate> = candidates(obs, &ctx, &accepted)
            .into_iter()
            .filter(|c| !rejected.iter().any(|r| same_slot(r, &c.kind)))
            .collect();
        if cands.is_empty() {
            break;
        }
        let nm = train_normals(
            obs,
            &ctx,
            &p,
            &free,
            &accepted,
            cands.iter().map(|c| c.kind.clone()),
            &fold_of,
        );
        let (a, b, rr) = nm.total();
        let n_acc: usize = accepted.iter().map(|e| e.kind.n_coef()).sum();
        let base: Vec<usize> = (0..free.len() + n_acc).collect();
        let Some((base_drop, _)) = solve_subset(&a, &b, &base) else {
            break;
        };
        let sse0 = rr - base_drop;
        let n_tests: usize = cands.iter().map(|c| c.scanned).sum();
        let mut scored = Vec::new();
        let mut off = free.len() + n_acc;
        for (ci, c) in cands.iter().enumerate() {
            let nc = c.kind.n_coef();
            let own: Vec<usize> = (off..off + nc).collect();
            off += nc;
            let cols = unaliased(&a, &base, &own);
            if cols.is_empty() {
                continue;
            }
            let mut all_cols = base.clone();
            all_cols.extend(&cols);
            let Some((d, _)) = solve_subset(&a, &b, &all_cols) else {
                continue;
            };
            let drop = (d - base_drop).max(0.0);
            let dof = (nm.rows as f64 - all_cols.len() as f64).max(1.0);
            let s2 = ((sse0 - drop) / dof).max(1e-30);
            let chi2 = drop / s2;
            // Bonferroni over every test this round (scanned positions
            // count individually: the look-elsewhere allowance).
            let alpha = ALPHA / n_tests as f64;
            let threshold = chi2_quantile_upper(alpha, cols.len());
            scored.push(Scored {
                idx: ci,
                cols,
                drop,
                chi2,
                threshold,
                s2,
            });
        }
        // Rank by the chi-square in excess of its own Bonferroni threshold
        // (a penalised likelihood: every block of coefficients pays the
        // look-elsewhere price of its family), so a 3-coefficient scanned
        // change point must explain more than a 1-coefficient constant.
        scored.sort_by(|x, y| (y.chi2 - y.threshold).total_cmp(&(x.chi2 - x.threshold)));
        let sig: Vec<usize> = (0..scored.len())
            .filter(|&i| scored[i].chi2 > scored[i].threshold)
            .collect();
        // Proposals: every significant single candidate, and for the
        // leading ones the best partner tested jointly (both must stay
        // significant given the other). Two effects present at once mask
        // each other on the held-out poses; modelled together they do not.
        let mut proposals: Vec<Proposal> = sig
            .iter()
            .map(|&i| Proposal {
                // Scored on the round's common scale below.
                score: 0.0,
                members: vec![(i, scored[i].chi2)],
                drop: scored[i].drop,
                threshold: scored[i].threshold,
                s2: scored[i].s2,
            })
            .collect();
        for &w in sig.iter().take(PAIR_LEADS) {
            let mut cols_w = base.clone();
            cols_w.extend(&scored[w].cols);
            let d_w = base_drop + scored[w].drop;
            let mut best: Option<Proposal> = None;
            for c in 0..scored.len() {
                let (kc, kw) = (&cands[scored[c].idx].kind, &cands[scored[w].idx].kind);
                let both_thermal = matches!(kc, Kind::ThermalExpansion { .. })
                    && matches!(kw, Kind::ThermalExpansion { .. });
                if c == w || same_slot(kc, kw) || both_thermal {
                    continue;
                }
                let mut cols = cols_w.clone();
                cols.extend(&scored[c].cols);
                let Some((d, _)) = solve_subset(&a, &b, &cols) else {
                    continue;
                };
                let dof = (nm.rows as f64 - cols.len() as f64).max(1.0);
                let s2 = ((rr - d) / dof).max(1e-30);
                let chi_c = (d - d_w) / s2;
                let chi_w = (d - base_drop - scored[c].drop) / s2;
                if chi_c <= scored[c].threshold || chi_w <= scored[w].threshold {
                    continue;
                }
                let threshold = scored[w].threshold + scored[c].threshold;
                // Partners of one lead compared on the lead's variance
                // (a partner fitting more noise gains nothing by it).
                let score = (d - base_drop) / scored[w].s2 - threshold;
                if best.as_ref().is_none_or(|b| score > b.score) {
                    best = Some(Proposal {
                        score,
                        members: vec![(w, chi_w), (c, chi_c)],
                        drop: d - base_drop,
                        threshold,
                        s2,
                    });
                }
            }
            if let Some(bp) = best {
                let dup = proposals.iter().any(|q| {
                    q.members.len() == 2
                        && q.members
                            .iter()
                            .all(|m| bp.members.iter().any(|x| x.0 == m.0))
                });
                if !dup {
                    proposals.push(bp);
                }
            }
        }
        // Ranked on one scale: every proposal's drop over the smallest
        // residual variance of the round. With its own, a pair that fits
        // three more coefficients of noise divides a large drop by a
        // slightly smaller variance and outranks the one effect that is
        // the truth (two harmonics of a joint beating its scale error);
        // on one scale the extra coefficients must explain more than their
        // thresholds charge.
        let s2_ref = proposals.iter().map(|p| p.s2).fold(f64::INFINITY, f64::min);
        for p in &mut proposals {
            p.score = p.drop / s2_ref - p.threshold;
        }
        proposals.sort_by(|x, y| y.score.total_cmp(&x.score));
        let cv0 = cv_sse(&nm, &a, &b, &base);
        let e_before = errors_with_effects(obs, &ctx, &p, &accepted, &obs.test);
        let r_before = reading_errors(obs, &ctx, &p, &accepted);
        let test_before = rms(&e_before);
        let mut progressed = false;
        // At most TRIES proposals of each size: a pair turned down because
        // one member adds nothing does not use up a try of its lead alone.
        let mut tried = [0usize; 2];
        for prop in &proposals {
            let single = prop.members.len() == 1;
            let count = &mut tried[usize::from(!single)];
            if *count == TRIES {
                continue;
            }
            *count += 1;
            let mut cs: Vec<Candidate> = prop
                .members
                .iter()
                .map(|m| cands[scored[m.0].idx].clone())
                .collect();
            if cs
                .iter()
                .any(|c| rejected.iter().any(|r| same_slot(r, &c.kind)))
            {
                continue;
            }
            // Refine a scanned change point between its grid neighbours,
            // with the partner (if any) fitted alongside. A rejection is
            // recorded on the grid's kind, which is what comes back.
            let grid: Vec<Kind> = cs.iter().map(|c| c.kind.clone()).collect();
            for i in 0..cs.len() {
                if let Some(t0_s) = cs[i].kind.change_time_s() {
                    let mut ctx_eff = accepted.clone();
                    ctx_eff.extend(
                        cs.iter()
                            .enumerate()
                            .filter(|(j, _)| *j != i)
                            .map(|(_, c)| EffectModel::zero(c.kind.clone())),
                    );
                    let t0 = refine_step(obs, &ctx, &p, &free, &ctx_eff, &cs[i].kind, t0_s);
                    cs[i].kind = cs[i].kind.with_change_time(t0);
                    cs[i].what = match cs[i].kind.sensor() {
                        Some(k) => format!("a change {} on string {}", ctx.when(t0), k + 1),
                        None => format!("a move of the whole rig {}", ctx.when(t0)),
                    };
                }
            }
            // A pair chosen with a change point on the coarse grid may lean
            // on its partner to mop up the misplaced step; with the step
            // refined, each member must still be significant given the
            // other (the step alone is proposed separately).
            if !single && cs.iter().any(|c| c.kind.change_time_s().is_some()) {
                let thresholds: Vec<f64> =
                    prop.members.iter().map(|m| scored[m.0].threshold).collect();
                if !pair_holds(obs, &ctx, &p, &free, &accepted, &cs, &thresholds) {
                    continue;
                }
            }
            let mut cv_cols = base.clone();
            for m in &prop.members {
                cv_cols.extend(&scored[m.0].cols);
            }
            let cv1 = cv_sse(&nm, &a, &b, &cv_cols);
            if cv1 >= cv0 {
                if single {
                    rejected.push(grid[0].clone());
                }
                continue;
            }
            // Nonlinear refit of geometry, accepted effects and the new ones.
            let mut trial = accepted.clone();
            trial.extend(cs.iter().map(|c| EffectModel::zero(c.kind.clone())));
            let Ok((p_new, eff_new, fit)) = refit(obs, &ctx, &p, &free, &trial) else {
                if single {
                    rejected.push(grid[0].clone());
                }
                continue;
            };
            let e_after = errors_with_effects(obs, &ctx, &p_new, &eff_new, &obs.test);
            let test_after = rms(&e_after);
            // Held-out gate on what was measured (string readings or
            // points): noise there is homogeneous, unlike located points.
            let r_after = reading_errors(obs, &ctx, &p_new, &eff_new);
            let gain_z = paired_gain_z_sums(&r_before, &r_after);
            let (rb, ra) = (rms_sums(&r_before), rms_sums(&r_after));
            // The 3-D held-out errors the report shows must not get worse
            // beyond their noise (located points amplify the string noise
            // by the rig's geometry, three strings most: there the gain is
            // seen on the readings first).
            let gain_z_3d = paired_gain_z(&e_before, &e_after);
            let held_out_gain = ra < rb && gain_z > HELD_OUT_Z && gain_z_3d > -HELD_OUT_Z;
            if !obs.test.is_empty() && !held_out_gain {
                let names: Vec<String> = cs
                    .iter()
                    .map(|c| format!("{} ({})", c.kind.name(), c.what))
                    .collect();
                notes.push(format!(
                    "{} {} significant on the train poses but did not improve the held-out error by more than noise explains (held-out RMS per reading {:.4} -> {:.4} mm, paired z = {:.1}, threshold {HELD_OUT_Z}; 3-D {:.4} -> {:.4} mm, paired z = {:.1}, must stay above -{HELD_OUT_Z}): not kept",
                    names.join(" with "),
                    if single { "was" } else { "were, jointly," },
                    rb,
                    ra,
                    gain_z,
                    test_before,
                    test_after,
                    gain_z_3d
                ));
                if single {
                    rejected.push(grid[0].clone());
                }
                continue;
            }
            // A finding states a magnitude: one that cannot be told from
            // zero is no finding, whatever its nuisance coefficients (the
            // free offset of a backlash before the joint's first move)
            // absorbed.
            let n_acc_coef: usize = accepted.iter().map(|e| e.kind.n_coef()).sum();
            let weak = cs.iter().enumerate().find_map(|(mi, c)| {
                let e = &eff_new[accepted.len() + mi];
                let at = n_acc_coef + cs[..mi].iter().map(|c| c.kind.n_coef()).sum::<usize>();
                let info = fit.block(at, e.kind.n_coef());
                let (mag, sig, unit) = magnitude(&ctx, obs, e, &info);
                (!distinguishable_from_zero(e, &info, mag, sig))
                    .then(|| format!("{} ({}): {mag:.4} ± {sig:.4} {unit}", c.kind.name(), c.what))
            });
            if let Some(w) = weak {
                notes.push(format!(
                    "{w} improved the held-out error but its magnitude is within {MAGNITUDE_Z} sigma of zero: not kept"
                ));
                if single {
                    rejected.push(grid[0].clone());
                }
                continue;
            }
            // Each member of a pair alone, refitted: the pair must beat
            // both on the held-out readings, so that a partner that adds
            // nothing does not ride on the lead's held-out gain. The
            // held-out 3-D RMS of the singles is what the report shows
            // between the two steps.
            let mut stage_rms = vec![test_before];
            let mut order: Vec<usize> = (0..cs.len()).collect();
            let mut pair_note = None;
            if !single {
                let alone: Vec<Option<(f64, f64)>> = (0..2)
                    .map(|mi| {
                        let mut first = accepted.clone();
                        first.push(trial[accepted.len() + mi].clone());
                        refit(obs, &ctx, &p, &free, &first).ok().map(|(pm, em, _)| {
                            let r_alone = reading_errors(obs, &ctx, &pm, &em);
                            (
                                rms(&errors_with_effects(obs, &ctx, &pm, &em, &obs.test)),
                                paired_gain_z_sums(&r_alone, &r_after),
                            )
                        })
                    })
                    .collect();
                // A member that cannot be refitted alone shows nothing.
                let weakest = alone
                    .iter()
                    .map(|a| a.map_or(f64::NEG_INFINITY, |(_, z)| z))
                    .fold(f64::INFINITY, f64::min);
                if !obs.test.is_empty() && weakest <= PAIR_MEMBER_Z {
                    let names: Vec<String> = cs
                        .iter()
                        .map(|c| format!("{} ({})", c.kind.name(), c.what))
                        .collect();
                    notes.push(format!(
                        "{} improved the held-out error jointly, but one of them added nothing beyond the other alone (paired z = {weakest:.1}, threshold {PAIR_MEMBER_Z}): the pair was not kept",
                        names.join(" with ")
                    ));
                    continue;
                }
                let mid: Vec<f64> = alone
                    .iter()
                    .map(|a| a.map_or(f64::NAN, |(r, _)| r))
                    .collect();
                let both_drop = |m: f64| test_before > m && m > test_after;
                if !both_drop(mid[0]) && both_drop(mid[1]) {
                    order = vec![1, 0];
                }
                stage_rms.push(mid[order[0]]);
                pair_note = Some(weakest);
            }
            stage_rms.push(test_after);
            let (rs, _) = robot_side_share(obs, &p);
            for (stage, &mi) in order.iter().enumerate() {
                let c = &cs[mi];
                let e = eff_new[accepted.len() + mi].clone();
                let nc = e.kind.n_coef();
                let coef_at = n_acc_coef + cs[..mi].iter().map(|c| c.kind.n_coef()).sum::<usize>();
                let info = fit.block(coef_at, nc);
                let (mag, sig, unit) = magnitude(&ctx, obs, &e, &info);
                let side = match rs {
                    Some(v) if e.kind.robot_side() => format!(
                        "; the residual it explains is robot-side (all strings agree on one displacement of T: {:.0}% of the residual energy)",
                        100.0 * v
                    ),
                    Some(v) => format!(
                        "; the residual it explains is sensor-side (the strings disagree with any single point: {:.0}% of the residual energy)",
                        100.0 * (1.0 - v)
                    ),
                    None => String::new(),
                };
                let s = &scored[prop.members[mi].0];
                let joint = if single {
                    String::new()
                } else {
                    let other = &cs[1 - mi];
                    format!(
                        ", tested jointly with {} ({}): chi-square {:.1} given it; the pair beats either alone on the held-out readings (paired z >= {:.1})",
                        other.kind.name(),
                        other.what,
                        prop.members[mi].1,
                        pair_note.unwrap_or(f64::NAN)
                    )
                };
                let evidence = format!(
                    "residual correlates with {}: adding it drops chi-square by {:.1} on {} coefficient(s) (threshold {:.1}, {} candidate tests{}){}, explaining {:.0}% of the remaining train residual; 5-fold cross-validated SSE {:.4} -> {:.4} mm^2; held-out RMS per reading {:.4} -> {:.4} mm (paired z = {:.1}){}",
                    c.what,
                    s.chi2,
                    s.cols.len(),
                    s.threshold,
                    n_tests,
                    match &c.kind {
                        Kind::ThermalExpansion { tau_h: Some(_), .. } => {
                            ", time constant scanned"
                        }
                        k if k.change_time_s().is_some() => {
                            ", change point scanned; figures at the nearest grid point, before refinement"
                        }
                        _ => "",
                    },
                    joint,
                    100.0 * s.drop / rr.max(1e-30),
                    cv0,
                    cv1,
                    rb,
                    ra,
                    gain_z,
                    side
                );
                let evidence = match thermal_doubt(&ctx, &e) {
                    Some(doubt) => format!("{evidence}; {doubt}"),
                    None => evidence,
                };
                let twins = indistinguishable(&scored, &cands, &prop.members, &e.kind, s);
                let evidence = if twins.is_empty() {
                    evidence
                } else {
                    format!(
                        "{evidence}; indistinguishable on this data from {}: it explains as much of the train residual (the two models predict nearly the same errors at these poses), so the name is the better-scoring of equals",
                        twins.join(" or ")
                    )
                };
                let params = finding_parameters(&ctx, &e);
                findings.push(Finding {
                    effect: e.kind.name().into(),
                    joint: e.kind.joint().map(|j| j + 1),
                    sensor: e.kind.sensor().map(|k| k + 1),
                    magnitude: mag,
                    sigma: sig,
                    unit,
                    explanation: e.kind.explanation(&ctx),
                    evidence,
                    test_rms_before_mm: stage_rms[stage],
                    test_rms_after_mm: stage_rms[stage + 1],
                    parameters: Some(FindingModel::Effect(params)),
                    evidence_plot: super::evidence::evidence_plot(
                        obs,
                        &ctx,
                        &p_new,
                        &eff_new,
                        accepted.len() + mi,
                    ),
                });
            }
            p = p_new;
            accepted = eff_new;
            final_sigmas = Some(fit.sigma_free.clone());
            final_fit = Some(fit);
            progressed = true;
            break;
        }
        if !progressed {
            break;
        }
    }
    // Later rounds refit the earlier effects: every finding reports its
    // effect as the final model has it (coefficients for compensation,
    // magnitude and sigma, evidence plot), not as the round that kept it.
    if let Some(fit) = &final_fit {
        for f in findings.iter_mut() {
            let Some(k) = f
                .effect_model()
                .and_then(|em| accepted.iter().position(|e| e.kind == em.kind))
            else {
                continue;
            };
            let e = &accepted[k];
            let at: usize = accepted[..k].iter().map(|e| e.kind.n_coef()).sum();
            let (mag, sig, _) = magnitude(&ctx, obs, e, &fit.block(at, e.kind.n_coef()));
            f.magnitude = mag;
            f.sigma = sig;
            if let Some(FindingModel::Effect(fp)) = &mut f.parameters {
                fp.model.coef = e.coef.clone();
            }
            f.evidence_plot = super::evidence::evidence_plot(obs, &ctx, &p, &accepted, k);
        }
    }

    // Terms of one joint that cancel each other are a series fitted to an
    // angle error of another shape, not separate physics: say so.
    for (j, largest_deg, net_deg, k) in cancelling_terms(obs, &ctx, &accepted) {
        let doubt = format!(
            "doubt: the {k} effects kept on joint {} largely cancel each other (each spreads the angle by up to {largest_deg:.4} deg over the train poses, together by {net_deg:.4} deg): together they describe an error of joint {}'s angle that none of them is alone; read them as one angle error of that joint, not as separate physics",
            j + 1,
            j + 1
        );
        for f in findings.iter_mut().filter(|f| f.joint == Some(j + 1)) {
            f.evidence = format!("{}; {doubt}", f.evidence);
        }
    }
    // Anything left that varies smoothly?
    if let Some(f) = unexplained(obs, &ctx, &p, &accepted, free.len()) {
        findings.push(f);
    }
    progress.update("physics analysis", 1.0);
    let test_errors = errors_with_effects(obs, &ctx, &p, &accepted, &obs.test);
    Ok(Analysis {
        findings,
        final_params: Params {
            layout: obs.chain.layout,
            values: p,
        },
        effects: accepted,
        context: ctx,
        test_errors,
        robot_side_share: share,
        robot_side_share_noise: share_noise,
        notes,
        final_sigmas,
    })
}

type Fit = (Vec<f64>, Vec<EffectModel>, FitInfo);

/// What a named finding records of its effect: the model, and what
/// compensation needs beside it (the payload a compliance was fitted
/// around and whether a payload changes it, as compensation decides it;
/// the temperature a thermal expansion scales from).
fn finding_parameters(ctx: &Context, e: &EffectModel) -> EffectParameters {
    let mut p = EffectParameters::new(e.clone());
    if let Kind::JointCompliance { .. } = e.kind {
        p.reference_payload_kg = ctx.payload_ref_kg;
        p.payload_matters = Some(e.payload_matters(ctx.n_joints));
    }
    if let Kind::ThermalExpansion { driver, .. } = e.kind {
        p.reference = Some("driver zero at the first pose (temperature, time or row)".into());
        if driver == ThermalDriver::Temperature {
            p.reference_temp_c = ctx.temp_ref_c;
        }
    }
    p
}

/// Covariance information of a refit.
pub struct FitInfo {
    /// Covariance of the effect coefficients (all effects of the refit, or
    /// one effect's block), internal units.
    pub cov_last: DMatrix<f64>,
    /// 1-sigma of the free geometric parameters (in the order of the
    /// geometric selection's `free`), internal units, from the same fit.
    pub sigma_free: Vec<f64>,
}

impl FitInfo {
    /// The covariance block of `len` coefficients starting at `start`.
    fn block(&self, start: usize, len: usize) -> FitInfo {
        FitInfo {
            cov_last: DMatrix::from_fn(len, len, |i, j| {
                let (a, b) = (start + i, start + j);
                if a < self.cov_last.nrows() && b < self.cov_last.ncols() {
                    self.cov_last[(a, b)]
                } else {
                    0.0
                }
            }),
            sigma_free: vec![],
        }
    }
}

fn refit(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    free: &[usize],
    effects: &[EffectModel],
) -> Result<Fit> {
    let problem = EffectProblem::of_observations(
        obs,
        ctx,
        obs.train.clone(),
        p,
        free.to_vec(),
        effects.to_vec(),
    );
    let res = lm::minimize(&problem, &problem.x0(), &LmSettings::default(), |_, _| true)?;
    let (pn, en) = problem.unpack(&res.x);
    let n = res.x.len();
    let dof = (problem.n_residuals() as f64 - n as f64).max(1.0);
    let s2 = 2.0 * res.cost / dof;
    let nc = problem.n_coef();
    // A coefficient no train pose supports (a backlash's unknown-approach
    // offset whose poses are all held out) has a zero column: scale 1 keeps
    // NaN out of the SVD, which does not terminate on NaN.
    let d: Vec<f64> = (0..n)
        .map(|i| match res.jtj[(i, i)] {
            v if v > 0.0 && v.is_finite() => v.sqrt(),
            _ => 1.0,
        })
        .collect();
    let scaled = DMatrix::from_fn(n, n, |i, j| res.jtj[(i, j)] / (d[i] * d[j]));
    let inv = if scaled.iter().all(|v| v.is_finite()) {
        scaled
            .pseudo_inverse(1e-12)
            .unwrap_or_else(|_| DMatrix::zeros(n, n))
    } else {
        DMatrix::zeros(n, n)
    };
    let cov_last = DMatrix::from_fn(nc, nc, |i, j| {
        let (a, b) = (n - nc + i, n - nc + j);
        s2 * inv[(a, b)] / (d[a] * d[b])
    });
    let sigma_free = (0..n - nc)
        .map(|i| (s2 * inv[(i, i)]).max(0.0).sqrt() / d[i])
        .collect();
    Ok((
        pn,
        en,
        FitInfo {
            cov_last,
            sigma_free,
        },
    ))
}

/// Scan the change point of an anchor step around `t0` over the train
/// pose times between its coarse-grid neighbours.
fn refine_step(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    free: &[usize],
    accepted: &[EffectModel],
    kind: &Kind,
    t0: f64,
) -> f64 {
    let mut times: Vec<f64> = obs.train.iter().map(|&i| ctx.poses[i].time_s).collect();
    times.sort_by(|a, b| a.total_cmp(b));
    times.dedup();
    let n = times.len();
    let pos = times.iter().position(|&t| t > t0).unwrap_or(n - 1);
    let span = n / STEP_GRID + 1;
    let lo = pos.saturating_sub(span).max(MIN_SEGMENT_POSES);
    let hi = (pos + span).min(n.saturating_sub(MIN_SEGMENT_POSES));
    if lo > hi {
        return t0;
    }
    // At most 24 evaluations: a finer grid inside the bracket.
    let stride = ((hi - lo) / 24).max(1);
    let mut best = (f64::NEG_INFINITY, t0);
    let n_acc: usize = accepted.iter().map(|e| e.kind.n_coef()).sum();
    let base: Vec<usize> = (0..free.len() + n_acc).collect();
    let fold0 = vec![0usize; obs.train.len()];
    let mut at = lo;
    while at <= hi {
        let t = 0.5 * (times[at - 1] + times[at]);
        let nm = train_normals(
            obs,
            ctx,
            p,
            free,
            accepted,
            [kind.with_change_time(t)],
            &fold0,
        );
        let (a, b, _) = nm.total();
        let mut cols = base.clone();
        let nb = base.len();
        cols.extend(nb..nb + kind.n_coef());
        if let (Some((d1, _)), Some((d0, _))) =
            (solve_subset(&a, &b, &cols), solve_subset(&a, &b, &base))
        {
            if d1 - d0 > best.0 {
                best = (d1 - d0, t);
            }
        }
        at += stride;
    }
    best.1
}

/// Reported magnitude, 1-sigma and unit of an effect.
fn magnitude(
    ctx: &Context,
    obs: &Observations,
    e: &EffectModel,
    fit: &FitInfo,
) -> (f64, f64, String) {
    let deg = 180.0 / std::f64::consts::PI;
    let f: Box<dyn Fn(&[f64]) -> f64> = match &e.kind {
        Kind::JointCompliance {
            regressors,
            joint_index,
        } => {
            if regressors.is_empty() {
                Box::new(move |c: &[f64]| c[0] * deg)
            } else {
                // Lumped coefficients: report the RMS deflection.
                let j = *joint_index;
                let kind = e.kind.clone();
                let train = obs.train.clone();
                Box::new(move |c: &[f64]| {
                    let mut buf = super::effects::Basis::default();
                    let mut s = 0.0;
                    for &i in &train {
                        ctx.basis(&kind, i, &mut buf);
                        let n = ctx.n_joints;
                        let d: f64 = (0..c.len()).map(|k| c[k] * buf.dq[k * n + j]).sum();
                        s += d * d;
                    }
                    (s / train.len().max(1) as f64).sqrt() * deg
                })
            }
        }
        Kind::Backlash { .. } => Box::new(move |c: &[f64]| c[0] * deg),
        Kind::JointPeriodic { .. } => Box::new(move |c: &[f64]| c[0].hypot(c[1]) * deg),
        Kind::JointScale { .. } => Box::new(|c: &[f64]| c[0] * 1e6),
        // A settling warm-up: its initial rate per hour says little at a
        // glance; the growth it reached over the session does.
        Kind::ThermalExpansion {
            tau_h: Some(tau), ..
        } => {
            let growth = warm_up_growth(ctx, *tau);
            Box::new(move |c: &[f64]| c[0] * growth * 1e6)
        }
        Kind::ThermalExpansion { .. } => Box::new(|c: &[f64]| c[0] * 1e6),
        Kind::SensorScale { .. } => Box::new(|c: &[f64]| c[0] * 1e6),
        Kind::SensorOffset { .. } | Kind::SensorDrift { .. } | Kind::CableSag => {
            Box::new(|c: &[f64]| c[0])
        }
        Kind::AnchorStep { .. } => {
            Box::new(|c: &[f64]| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt())
        }
        Kind::RigStep { .. } | Kind::RigDrift => {
            let kind = e.kind.clone();
            let train = obs.train.clone();
            Box::new(move |c: &[f64]| ctx.rigid_rms_mm(&kind, c, &train))
        }
    };
    let unit = match &e.kind {
        Kind::ThermalExpansion {
            tau_h: Some(tau),
            driver,
        } => match driver {
            super::effects::ThermalDriver::Order => format!(
                "ppm (growth over the session, a warm-up settling over about {:.0} rows)",
                tau * 1000.0
            ),
            _ => format!(
                "ppm (growth over the session, a warm-up settling with a time constant of {tau:.2} h)"
            ),
        },
        Kind::SensorDrift { .. } if !ctx.timed => "mm per 1000 rows".into(),
        other => fixed_unit(other).into(),
    };
    let c = &e.coef;
    let v = f(c);
    // Delta method with a numerical gradient of the magnitude.
    let mut grad = vec![0.0; c.len()];
    for i in 0..c.len() {
        let h = 1e-6 * c.iter().map(|x| x.abs()).fold(0.0, f64::max).max(1e-12);
        let mut cp = c.clone();
        cp[i] += h;
        let mut cm = c.clone();
        cm[i] -= h;
        grad[i] = (f(&cp) - f(&cm)) / (2.0 * h);
    }
    let mut var = 0.0;
    for i in 0..c.len() {
        for j in 0..c.len() {
            if i < fit.cov_last.nrows() && j < fit.cov_last.ncols() {
                var += grad[i] * fit.cov_last[(i, j)] * grad[j];
            }
        }
    }
    (v, var.max(0.0).sqrt(), unit)
}

/// The effects of one joint cancel each other when the largest one's
/// spread of angle change over the train poses is this many times their
/// sum's.
const CANCEL_RATIO: f64 = 3.0;

/// Joints whose accepted effects (two or more) largely cancel each other
/// over the train poses: `(joint, largest effect's spread of dq, their
/// sum's spread (standard deviations, deg), number of effects)`.
fn cancelling_terms(
    obs: &Observations,
    ctx: &Context,
    accepted: &[EffectModel],
) -> Vec<(usize, f64, f64, usize)> {
    let n = ctx.n_joints;
    let mut buf = super::effects::Basis::default();
    let mut out = Vec::new();
    for j in 0..n {
        let on_j: Vec<&EffectModel> = accepted
            .iter()
            .filter(|e| e.kind.joint() == Some(j))
            .collect();
        if on_j.len() < 2 {
            continue;
        }
        // Per train pose, each effect's angle change and their sum; the
        // constant part of each is the joint's zero offset (the geometry
        // takes it), so spreads are compared about the mean.
        let rows: Vec<Vec<f64>> = obs
            .train
            .iter()
            .map(|&i| {
                on_j.iter()
                    .map(|e| {
                        ctx.basis(&e.kind, i, &mut buf);
                        e.coef
                            .iter()
                            .enumerate()
                            .map(|(c, v)| v * buf.dq[c * n + j])
                            .sum()
                    })
                    .collect()
            })
            .collect();
        let spread = |f: &dyn Fn(&[f64]) -> f64| {
            let v: Vec<f64> = rows.iter().map(|r| f(r)).collect();
            let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt()
        };
        let largest = (0..on_j.len())
            .map(|k| spread(&|r: &[f64]| r[k]))
            .fold(0.0, f64::max);
        let net = spread(&|r: &[f64]| r.iter().sum());
        if largest > CANCEL_RATIO * net {
            out.push((j, largest.to_degrees(), net.to_degrees(), on_j.len()));
        }
    }
    out
}

/// Largest growth of a metal arm's links over a session that thermal
/// expansion explains: about 20 K on aluminium (23 ppm/K) or 40 K on steel.
const MAX_THERMAL_GROWTH_PPM: f64 = 500.0;

/// A doubt to state with a thermal finding whose growth over the session
/// is beyond what a metal arm's thermal expansion gives: the fit holds, the
/// name may not (an instrument whose scale drifted as it warmed up looks
/// the same).
fn thermal_doubt(ctx: &Context, e: &EffectModel) -> Option<String> {
    let Kind::ThermalExpansion { tau_h, .. } = e.kind else {
        return None;
    };
    let (lo, hi) = ctx
        .poses
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.thermal), hi.max(p.thermal))
        });
    let span = match tau_h {
        Some(tau) => warm_up_growth(ctx, tau),
        None => hi - lo,
    };
    let growth_ppm = (e.coef.first()? * span * 1e6).abs();
    (growth_ppm > MAX_THERMAL_GROWTH_PPM).then(|| {
        format!(
            "doubt: a growth of {growth_ppm:.0} ppm over the session is more than a metal arm's thermal expansion gives (12-23 ppm/K; {MAX_THERMAL_GROWTH_PPM:.0} ppm is 20-40 K): check the temperature record, or an instrument whose scale drifted as it warmed up"
        )
    })
}

/// How far a warm-up with time constant `tau_h` settled over the session:
/// its driver at the last hour recorded (h).
fn warm_up_growth(ctx: &Context, tau_h: f64) -> f64 {
    let hours = ctx.poses.iter().map(|p| p.thermal).fold(0.0, f64::max);
    super::effects::warm_up(hours, tau_h)
}

/// Unit of an effect's magnitude (see [`magnitude`]).
fn fixed_unit(kind: &Kind) -> &'static str {
    match kind {
        Kind::JointCompliance { regressors, .. } if regressors.is_empty() => "deg/(N*m)",
        Kind::JointCompliance { .. } => "deg (RMS deflection)",
        Kind::Backlash { .. } => "deg (half dead band)",
        Kind::JointPeriodic { .. } => "deg (amplitude)",
        Kind::JointScale { .. } => "ppm (of the joint angle)",
        Kind::ThermalExpansion { driver, .. } => match driver {
            super::effects::ThermalDriver::Temperature => "ppm/K",
            super::effects::ThermalDriver::Time => "ppm/h",
            super::effects::ThermalDriver::Order => "ppm per 1000 rows",
        },
        Kind::SensorScale { .. } => "ppm",
        Kind::SensorOffset { .. } => "mm",
        Kind::SensorDrift { .. } => "mm/h",
        Kind::CableSag => "mm/m^3",
        Kind::AnchorStep { .. } => "mm",
        Kind::RigStep { .. } => "mm (RMS displacement of T after the move)",
        Kind::RigDrift => "mm (RMS displacement of T over the session)",
    }
}
