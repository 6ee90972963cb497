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
//!
//! One file per step: `candidates` (what a round may add), `normals`
//! (the linearised problem and its subset solves), `fixed` (the model
//! linearised once, candidates fitted against it), `scoring` (each
//! candidate's chi-square drop), `proposals` (singles and pairs, ranked;
//! a scanned change point refined), `trial` (the proposals tried in rank
//! order), `gates` (cross-validation, the held-out paired test, the
//! magnitude, a pair's members), `findings` (what a kept proposal
//! reports), `refit` (the nonlinear refit and its covariance),
//! `magnitude` (an effect's reported size), `finish` (earlier
//! findings restated, cancelling terms, the unexplained remainder);
//! beyond the catalogue, `data_driven` (the corrections without a name),
//! `compensation_use` (whether compensation can use one, in words) and
//! `naming` (named effects re-examined beside a correction).

mod candidates;
mod compensation_use;
mod data_driven;
mod findings;
mod finish;
mod fixed;
mod gates;
mod magnitude;
mod naming;
mod normals;
mod proposals;
mod refit;
mod scoring;
mod trial;

use nalgebra::Vector3;

use super::effects::{Context, CorrectionTarget, EffectModel, Kind, PoseInput};
use super::problem::EffectProblem;
use super::unexplained::robot_side_share;
use crate::error::Result;
use crate::identify::{Geometric, Observations, Progress};
use crate::kinematics::Params;
use crate::measure;
use crate::model::Measurement;
use crate::report::Finding;
use crate::rng::Rng;

pub use refit::FitInfo;

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
/// A kept effect's magnitude is at least this many sigma from zero.
pub const MAGNITUDE_Z: f64 = 2.0;
/// Highest harmonic of a joint's periodic error tried: once per
/// revolution (eccentricity), twice (an elliptic bearing or encoder disc)
/// and three times (a three-lobed gear or an encoder read by three heads).
pub const MAX_HARMONIC: u32 = 3;
/// At most this many effects are modelled.
const MAX_EFFECTS: usize = 6;

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

/// What every round reads and none changes: the session, its effect
/// context, the geometric selection and the cross-validation folds.
struct Inputs<'a> {
    obs: &'a Observations<'a>,
    ctx: Context,
    /// Free geometric parameters (the geometric selection's).
    free: Vec<usize>,
    /// Cross-validation fold of each train pose (position in `obs.train`).
    fold_of: Vec<usize>,
}

impl<'a> Inputs<'a> {
    /// The folds are shuffled with a fixed seed so that a session gives the
    /// same analysis every time.
    fn new(obs: &'a Observations<'a>, geo: &Geometric) -> Self {
        let ctx = effect_context(obs, &geo.after);
        let mut fold_of: Vec<usize> = (0..obs.train.len()).map(|i| i % normals::FOLDS).collect();
        Rng::new(7).shuffle(&mut fold_of);
        Inputs {
            obs,
            ctx,
            free: geo.selection.free.clone(),
            fold_of,
        }
    }

    /// The geometry's columns (positions in `free`) a linearised fit with
    /// `effects` holds where it is: the tool point's, when a correction of
    /// the tool point is among them. The correction's constant part is the
    /// tool point; with both free, the knots but one sum to nearly the tool
    /// point's columns, and a fit cancels the two in large opposite amounts
    /// that the geometry, moving on, no longer cancels.
    fn held_columns<'k>(&self, effects: impl IntoIterator<Item = &'k Kind>) -> Vec<usize> {
        let tool_point = effects.into_iter().any(|k| {
            matches!(
                k,
                Kind::DataDriven {
                    target: CorrectionTarget::ToolPoint,
                    ..
                }
            )
        });
        if !tool_point {
            return Vec::new();
        }
        let t = self.obs.chain.layout.tool();
        (0..self.free.len())
            .filter(|&c| (t..t + 3).contains(&self.free[c]))
            .collect()
    }
}

/// What one round hands the next: the model so far, what it reported, and
/// the effects turned down (not proposed again).
#[derive(Clone)]
struct State {
    /// Geometric parameters of the current fit.
    p: Vec<f64>,
    /// Effects kept so far, as the latest refit has them.
    accepted: Vec<EffectModel>,
    findings: Vec<Finding>,
    notes: Vec<String>,
    /// Kinds rejected alone (their slot is not proposed again).
    rejected: Vec<Kind>,
    /// Covariance of the latest refit (none until an effect is kept).
    final_fit: Option<FitInfo>,
    /// Instants (the clock's units) where a named step was taken out of
    /// the model: a data-driven correction in time may jump there.
    jumps_s: Vec<f64>,
    /// Joints whose compliance was fitted against the gravity load and
    /// still predicted the held-out readings better (0-based), with the
    /// paired z of that gain: where to look when the neighbour tests
    /// locate nothing.
    wrong_way: Vec<(usize, f64)>,
}

/// Run the analysis after `geometric()`.
pub fn analyse(obs: &Observations, geo: &Geometric, progress: &dyn Progress) -> Result<Analysis> {
    let inputs = Inputs::new(obs, geo);
    let mut state = State {
        p: geo.after.values.clone(),
        accepted: Vec::new(),
        findings: Vec::new(),
        notes: Vec::new(),
        rejected: Vec::new(),
        final_fit: None,
        jumps_s: Vec::new(),
        wrong_way: Vec::new(),
    };
    // Where the residual lives: robot side versus sensor side.
    let share = robot_side_share(obs, &state.p);
    if let (Some(s), Some(s0)) = share {
        state.notes.push(share_note(s, s0));
    }
    for round in 0..MAX_EFFECTS + 2 {
        if state.accepted.len() >= MAX_EFFECTS {
            break;
        }
        progress.update("physics analysis", round as f64 / (MAX_EFFECTS + 2) as f64);
        // A round refits the whole model: the place to honour a cancel.
        if progress.cancelled() {
            return Err(crate::Error::Cancelled);
        }
        let Some(scores) = scoring::score(&inputs, &state) else {
            break;
        };
        let proposals = proposals::propose(&scores);
        if !trial::keep_one(&inputs, &scores, &proposals, &mut state) {
            break;
        }
    }
    Ok(finish::finish(inputs, state, share, progress))
}

/// The summary line on where the geometric fit's string residual lives,
/// beside what noise alone would give.
fn share_note(s: f64, s0: f64) -> String {
    format!(
        "string residuals after the geometric fit: {:.0}% is a common displacement of T (robot side), {:.0}% disagreement between strings (sensor side); noise alone would give {:.0}% / {:.0}%",
        100.0 * s,
        100.0 * (1.0 - s),
        100.0 * s0,
        100.0 * (1.0 - s0)
    )
}

/// Build the effect context of a session: T at each pose is the located
/// point with strings (what each string's geometry is), and the model's T
/// (`p` at the commanded angles) with point data, whose measured point is
/// the reading itself: a correction driven by where T is must not read the
/// error it corrects.
pub fn effect_context(obs: &Observations, p: &Params) -> Context {
    let (rb, _) = p.base_rt();
    let points = obs.anchors.is_empty();
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
            point_rig: if points {
                obs.chain
                    .point(
                        &p.values,
                        &pose.q_rad,
                        crate::kinematics::chain::OutputFrame::Rig,
                    )
                    .1
            } else {
                *m
            },
        })
        .collect();
    Context::new(obs.robot, obs.anchors.clone(), obs.rig.r_mm, &rb, &inputs).with_flange_of(|i| {
        obs.chain
            .point(
                &p.values,
                &obs.data.poses[i].q_rad,
                crate::kinematics::chain::OutputFrame::Rig,
            )
            .0
            .r
    })
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

/// The robot base's rotation in the rig frame, as the geometric
/// parameters `p` have it.
fn p_base_rotation(obs: &Observations, p: &[f64]) -> nalgebra::Matrix3<f64> {
    let b = obs.chain.layout.base();
    crate::kinematics::rpy_matrix(p[b + 3], p[b + 4], p[b + 5])
}

/// RMS of 3-D errors (NaN without any: no held-out poses, nothing to say).
pub(super) use crate::stats::rms_norm as rms;

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
    problem.residuals(&problem.x0(), |pos, r| {
        out[pos].0 += r * r;
        out[pos].1 += 1;
    });
    out
}
