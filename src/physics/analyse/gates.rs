//! The gates a proposal must pass, in the order they are tried: with a
//! refined change point, each member of a pair still significant given
//! the other; a lower 5-fold cross-validated error of the train poses;
//! after the nonlinear refit, a held-out gain beyond noise (paired test on
//! what was measured, and the 3-D errors not worse); magnitudes
//! distinguishable from zero; and each member of a pair adding something
//! beyond the other alone.

use nalgebra::{DVector, Vector3};

use super::candidates::Candidate;
use super::magnitude::magnitude;
use super::normals::{cv_sse, solve_subset, train_normals, unaliased};
use super::proposals::Proposal;
use super::refit::{FitInfo, refit};
use super::scoring::Scores;
use super::{
    HELD_OUT_Z, Inputs, MAGNITUDE_Z, PAIR_MEMBER_Z, State, errors_with_effects, reading_errors, rms,
};
use crate::identify::Observations;
use crate::physics::effects::{Context, EffectModel, Kind};
use crate::stats::chi2_quantile_upper;

/// Two-sided false-alarm rate of [`MAGNITUDE_Z`] sigma, for magnitudes
/// that are a norm of several coefficients (tested as a block).
const MAGNITUDE_ALPHA: f64 = 0.0455;

/// Why a proposal was turned down: the note the summary gets (if any),
/// and whether a single candidate's slot is closed for later rounds.
pub(super) struct Turned {
    pub(super) note: Option<String>,
    pub(super) reject: bool,
    /// Fitted the way its physics cannot go after it passed the held-out
    /// gate (structure at its driver that the catalogue's shape does not
    /// explain): the paired z of its held-out gain.
    pub(super) wrong_way: Option<f64>,
}

impl Turned {
    /// Turned down without a word, its slot left open (a pair that no
    /// longer holds together says nothing against either member).
    fn quietly() -> Self {
        Turned {
            note: None,
            reject: false,
            wrong_way: None,
        }
    }

    /// Turned down for good: a single candidate is not proposed again.
    fn rejected(note: Option<String>) -> Self {
        Turned {
            note,
            reject: true,
            wrong_way: None,
        }
    }
}

/// The current model's errors before a round's proposals: what every gate
/// of the round compares with.
pub(super) struct Before {
    /// 5-fold cross-validated SSE of the current columns (mm²).
    pub(super) cv0: f64,
    /// Held-out 3-D errors, and their RMS.
    e: Vec<Vector3<f64>>,
    pub(super) test_rms: f64,
    /// Held-out reading residuals per test pose.
    r: Vec<(f64, usize)>,
}

impl Before {
    /// Computed once per round: every proposal of the round is measured
    /// against the same current model.
    pub(super) fn of(inputs: &Inputs, s: &Scores, state: &State) -> Self {
        let Inputs { obs, ctx, .. } = inputs;
        let cv0 = cv_sse(&s.nm, &s.a, &s.b, &s.base);
        let e = errors_with_effects(obs, ctx, &state.p, &state.accepted, &obs.test);
        let r = reading_errors(obs, ctx, &state.p, &state.accepted);
        let test_rms = rms(&e);
        Before {
            cv0,
            e,
            test_rms,
            r,
        }
    }

    /// The current model's held-out errors alone, for a step that has no
    /// round's scores (its cross-validation is its own): `cv0` is NaN.
    pub(super) fn now(inputs: &Inputs, state: &State) -> Self {
        let Inputs { obs, ctx, .. } = inputs;
        let e = errors_with_effects(obs, ctx, &state.p, &state.accepted, &obs.test);
        let r = reading_errors(obs, ctx, &state.p, &state.accepted);
        let test_rms = rms(&e);
        Before {
            cv0: f64::NAN,
            e,
            test_rms,
            r,
        }
    }
}

/// What the held-out poses said of a refitted proposal.
pub(super) struct HeldOut {
    /// Held-out RMS per reading before and after (mm).
    pub(super) rb: f64,
    pub(super) ra: f64,
    /// Paired z of the readings' gain.
    pub(super) gain_z: f64,
    /// Held-out 3-D RMS after (mm).
    pub(super) test_after: f64,
    /// Held-out reading residuals after, per test pose.
    r_after: Vec<(f64, usize)>,
}

/// How a kept proposal's members are reported: in which order, with the
/// held-out 3-D RMS before, between and after them.
pub(super) struct Stages {
    pub(super) order: Vec<usize>,
    pub(super) rms: Vec<f64>,
    /// A pair's weakest member's paired z beyond the other alone.
    pub(super) pair_z: Option<f64>,
}

/// "name (what)" of each member, for notes.
fn names(cs: &[Candidate]) -> String {
    let names: Vec<String> = cs
        .iter()
        .map(|c| format!("{} ({})", c.kind.name(), c.what))
        .collect();
    names.join(" with ")
}

/// A pair chosen with a change point on the coarse grid may lean on its
/// partner to mop up the misplaced step; with the step refined, each
/// member must still be significant given the other (the step alone is
/// proposed separately).
pub(super) fn pair_still_holds(
    inputs: &Inputs,
    s: &Scores,
    state: &State,
    prop: &Proposal,
    cs: &[Candidate],
) -> Result<(), Turned> {
    if cs.len() == 1 || !cs.iter().any(|c| c.kind.change_time_s().is_some()) {
        return Ok(());
    }
    let thresholds: Vec<f64> = prop
        .members
        .iter()
        .map(|m| s.scored[m.0].threshold)
        .collect();
    let Inputs { obs, ctx, free, .. } = inputs;
    if pair_holds(obs, ctx, &state.p, free, &state.accepted, cs, &thresholds) {
        Ok(())
    } else {
        Err(Turned::quietly())
    }
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

/// The proposal's columns must lower the cross-validated SSE of the train
/// poses (linearised refits): its 5-fold SSE.
pub(super) fn cross_validated(s: &Scores, prop: &Proposal, cv0: f64) -> Result<f64, Turned> {
    let mut cv_cols = s.base.clone();
    for m in &prop.members {
        cv_cols.extend(&s.scored[m.0].cols);
    }
    let cv1 = cv_sse(&s.nm, &s.a, &s.b, &cv_cols);
    if cv1 >= cv0 {
        return Err(Turned::rejected(None));
    }
    Ok(cv1)
}

/// The nonlinear refit of geometry, accepted effects and the proposal's
/// members (`trial`); one that fails turns the proposal down.
pub(super) fn refitted(
    inputs: &Inputs,
    state: &State,
    trial: &[EffectModel],
) -> Result<(Vec<f64>, Vec<EffectModel>, FitInfo), Turned> {
    let Inputs { obs, ctx, free, .. } = inputs;
    refit(obs, ctx, &state.p, free, trial).map_err(|_| Turned::rejected(None))
}

/// The least fraction of the held-out 3-D RMS a named effect must take
/// away (see [`held_out`]).
const NAMED_MIN_GAIN: f64 = 0.01;

/// Held-out gate on what was measured (string readings or points): noise
/// there is homogeneous, unlike located points. The 3-D held-out errors
/// the report shows must not get worse beyond their noise (located points
/// amplify the string noise by the rig's geometry, three strings most:
/// there the gain is seen on the readings first).
pub(super) fn held_out(
    inputs: &Inputs,
    before: &Before,
    cs: &[Candidate],
    p_new: &[f64],
    eff_new: &[EffectModel],
) -> Result<HeldOut, Turned> {
    let Inputs { obs, ctx, .. } = inputs;
    let e_after = errors_with_effects(obs, ctx, p_new, eff_new, &obs.test);
    let test_after = rms(&e_after);
    let r_after = reading_errors(obs, ctx, p_new, eff_new);
    let gain_z = paired_gain_z_sums(&before.r, &r_after);
    let (rb, ra) = (rms_sums(&before.r), rms_sums(&r_after));
    let gain_z_3d = paired_gain_z(&before.e, &e_after);
    // A name sends an engineer to a part: a named effect must also move
    // the held-out tool points the report shows, not only the readings.
    let named = cs.iter().all(|c| !c.kind.is_data_driven());
    let moves_points = !named || test_after <= (1.0 - NAMED_MIN_GAIN) * before.test_rms;
    let held_out_gain = ra < rb && gain_z > HELD_OUT_Z && gain_z_3d > -HELD_OUT_Z;
    if !obs.test.is_empty() && held_out_gain && !moves_points {
        return Err(Turned::rejected(Some(format!(
            "{} improved the held-out readings (RMS per reading {rb:.4} -> {ra:.4} mm, paired z = {gain_z:.1}) but not the held-out tool points by {:.0} % (3-D {:.4} -> {:.4} mm), which a named effect must: not kept",
            names(cs),
            100.0 * NAMED_MIN_GAIN,
            before.test_rms,
            test_after,
        ))));
    }
    if !obs.test.is_empty() && !held_out_gain {
        return Err(Turned::rejected(Some(format!(
            "{} {} significant on the train poses but did not improve the held-out error by more than noise explains (held-out RMS per reading {:.4} -> {:.4} mm, paired z = {:.1}, threshold {HELD_OUT_Z}; 3-D {:.4} -> {:.4} mm, paired z = {:.1}, must stay above -{HELD_OUT_Z}): not kept",
            names(cs),
            if cs.len() == 1 {
                "was"
            } else {
                "were, jointly,"
            },
            rb,
            ra,
            gain_z,
            before.test_rms,
            test_after,
            gain_z_3d
        ))));
    }
    Ok(HeldOut {
        rb,
        ra,
        gain_z,
        test_after,
        r_after,
    })
}

/// A finding states a magnitude: one that cannot be told from zero is no
/// finding, whatever its nuisance coefficients (the free offset of a
/// backlash before the joint's first move) absorbed. Every member's
/// magnitude in the refit (`eff_new`, `fit`) must pass, and go the way
/// its physics can (refused otherwise with `gain_z`, the held-out gain's
/// paired z, as [`Turned::wrong_way`]).
pub(super) fn magnitudes(
    inputs: &Inputs,
    state: &State,
    cs: &[Candidate],
    eff_new: &[EffectModel],
    fit: &FitInfo,
    gain_z: f64,
) -> Result<(), Turned> {
    let Inputs { obs, ctx, .. } = inputs;
    let accepted = &state.accepted;
    let n_acc_coef: usize = accepted.iter().map(|e| e.kind.n_coef()).sum();
    let weak = cs.iter().enumerate().find_map(|(mi, c)| {
        let e = &eff_new[accepted.len() + mi];
        let at = n_acc_coef + cs[..mi].iter().map(|c| c.kind.n_coef()).sum::<usize>();
        let info = fit.block(at, e.kind.n_coef());
        let (mag, sig, unit) = magnitude(ctx, obs, e, &info);
        (!distinguishable_from_zero(e, &info, mag, sig))
            .then(|| format!("{} ({}): {mag:.4} ± {sig:.4} {unit}", c.kind.name(), c.what))
    });
    if let Some(w) = weak {
        return Err(Turned::rejected(Some(format!(
            "{w} improved the held-out error but its magnitude is within {MAGNITUDE_Z} sigma of zero: not kept"
        ))));
    }
    let wrong_way = cs.iter().enumerate().find_map(|(mi, c)| {
        let e = &eff_new[accepted.len() + mi];
        unphysical(e).map(|why| format!("{} ({}): {why}", c.kind.name(), c.what))
    });
    match wrong_way {
        Some(w) => Err(Turned {
            wrong_way: Some(gain_z),
            ..Turned::rejected(Some(format!(
                "{w}; it improved the held-out error by fitting a structure of another physics: not kept"
            )))
        }),
        None => Ok(()),
    }
}

/// Most negative thermal expansion coefficient of an arm's material
/// (per K): carbon-fibre composites reach about -1e-6, every metal is
/// positive.
const MIN_EXPANSION_PER_K: f64 = -5e-6;

/// Why the fitted effect `e` goes the way its physics cannot, if it does:
/// a string hangs longer than its chord, never shorter; a joint and a
/// robot's mount yield with their gravity load, not against it; an arm
/// does not shrink as it warms. (The catalogue's shapes fit part of many
/// other structures; fitted the wrong way round they are not that physics.)
fn unphysical(e: &EffectModel) -> Option<String> {
    use crate::physics::effects::ThermalDriver;
    let c = *e.coef.first()?;
    match &e.kind {
        Kind::CableSag if c < 0.0 => Some(
            "fitted negative, strings reading shorter than their chords, which a hanging string never does".into(),
        ),
        Kind::JointCompliance { regressors, .. } if regressors.is_empty() && c < 0.0 => Some(
            "fitted negative, the joint moving against its gravity load, which an elastic joint never does (a balancer that over-compensates, or a play that gravity takes up, would)".into(),
        ),
        Kind::BaseTilt if c < 0.0 => Some(
            "fitted negative, the mount tilting against the arm's gravity moment, which a yielding mount never does".into(),
        ),
        Kind::LinkBending { .. } if c < 0.0 => Some(
            "fitted negative, the link bending against the weight it carries, which an elastic link never does".into(),
        ),
        Kind::ToolCompliance if c < 0.0 => Some(
            "fitted negative, the tool tilting against its payload's gravity moment, which a yielding adapter never does".into(),
        ),
        Kind::ThermalExpansion {
            driver: ThermalDriver::Temperature,
            ..
        } if c < MIN_EXPANSION_PER_K => Some(format!(
            "fitted at {:.1} ppm/K, the arm shrinking as it warms, beyond any arm's material (at least {:.0} ppm/K)",
            c * 1e6,
            MIN_EXPANSION_PER_K * 1e6
        )),
        _ => None,
    }
}

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

/// Each member of a pair alone, refitted: the pair must beat both on the
/// held-out readings, so that a partner that adds nothing does not ride
/// on the lead's held-out gain. The held-out 3-D RMS of the singles is
/// what the report shows between the two steps (the member that gains
/// first reported first). A single passes as it is.
pub(super) fn pair_members(
    inputs: &Inputs,
    state: &State,
    before: &Before,
    cs: &[Candidate],
    trial: &[EffectModel],
    held: &HeldOut,
) -> Result<Stages, Turned> {
    let Inputs { obs, ctx, free, .. } = inputs;
    let (p, accepted) = (&state.p, &state.accepted);
    let (test_before, test_after) = (before.test_rms, held.test_after);
    let mut stage_rms = vec![test_before];
    let mut order: Vec<usize> = (0..cs.len()).collect();
    let mut pair_z = None;
    if cs.len() != 1 {
        let alone: Vec<Option<(f64, f64)>> = (0..2)
            .map(|mi| {
                let mut first = accepted.clone();
                first.push(trial[accepted.len() + mi].clone());
                refit(obs, ctx, p, free, &first).ok().map(|(pm, em, _)| {
                    let r_alone = reading_errors(obs, ctx, &pm, &em);
                    (
                        rms(&errors_with_effects(obs, ctx, &pm, &em, &obs.test)),
                        paired_gain_z_sums(&r_alone, &held.r_after),
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
            return Err(Turned {
                note: Some(format!(
                    "{} improved the held-out error jointly, but one of them added nothing beyond the other alone (paired z = {weakest:.1}, threshold {PAIR_MEMBER_Z}): the pair was not kept",
                    names(cs)
                )),
                reject: false,
                wrong_way: None,
            });
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
        pair_z = Some(weakest);
    }
    stage_rms.push(test_after);
    Ok(Stages {
        order,
        rms: stage_rms,
        pair_z,
    })
}

/// Paired z that the held-out readings of model `b` beat those of model
/// `a` (each its geometric parameters and effects): positive when `b`
/// predicts the held-out poses better.
pub(super) fn held_out_gain_z(
    inputs: &Inputs,
    a: (&[f64], &[EffectModel]),
    b: (&[f64], &[EffectModel]),
) -> f64 {
    let Inputs { obs, ctx, .. } = inputs;
    let ra = reading_errors(obs, ctx, a.0, a.1);
    let rb = reading_errors(obs, ctx, b.0, b.1);
    paired_gain_z_sums(&ra, &rb)
}

/// RMS per row of summed squares `(sum, rows)` per pose.
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
