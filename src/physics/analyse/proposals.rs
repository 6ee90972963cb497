//! What a round proposes: every significant candidate alone, and for the
//! leading ones the best partner tested jointly (both significant given
//! the other), ranked on one scale; and, for a proposal tried, its scanned
//! change points refined between their grid neighbours.

use super::Inputs;
use super::State;
use super::candidates::{Candidate, MIN_SEGMENT_POSES, STEP_GRID, same_slot, sorted_train_times};
use super::fixed::FixedBase;
use super::normals::solve_subset;
use super::scoring::Scores;
use crate::physics::effects::{EffectModel, Kind};

/// Leading candidates for which a jointly tested partner is sought.
const PAIR_LEADS: usize = 4;

/// A proposal of one round: one candidate, or two tested jointly. Members
/// are (index into the scored list, chi-square given the other member).
#[derive(Debug, Clone)]
pub(super) struct Proposal {
    score: f64,
    pub(super) members: Vec<(usize, f64)>,
    /// Drop of the train SSE over the accepted model (mm²).
    drop: f64,
    /// Sum of the members' Bonferroni thresholds.
    threshold: f64,
    /// Residual variance per reading with the proposal fitted (mm²).
    s2: f64,
}

/// The round's proposals, best first. Two effects present at once mask
/// each other on the held-out poses; modelled together they do not.
pub(super) fn propose(s: &Scores) -> Vec<Proposal> {
    let scored = &s.scored;
    let sig: Vec<usize> = (0..scored.len())
        .filter(|&i| scored[i].chi2 > scored[i].threshold)
        .collect();
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
        if let Some(bp) = best_partner(s, w) {
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
    proposals
}

/// The partner of lead `w` (index into the scored list) that, fitted with
/// it, keeps both significant given the other and scores best; partners
/// of one lead are compared on the lead's variance (a partner fitting more
/// noise gains nothing by it).
fn best_partner(s: &Scores, w: usize) -> Option<Proposal> {
    let (scored, cands) = (&s.scored, &s.cands);
    let base_drop = s.base_drop;
    let mut cols_w = s.base.clone();
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
        let Some((d, _)) = solve_subset(&s.a, &s.b, &cols) else {
            continue;
        };
        let dof = (s.nm.rows as f64 - cols.len() as f64).max(1.0);
        let s2 = ((s.rr - d) / dof).max(1e-30);
        let chi_c = (d - d_w) / s2;
        let chi_w = (d - base_drop - scored[c].drop) / s2;
        if chi_c <= scored[c].threshold || chi_w <= scored[w].threshold {
            continue;
        }
        let threshold = scored[w].threshold + scored[c].threshold;
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
    best
}

/// Refine each scanned change point among `cs` (a proposal's members)
/// between its grid neighbours, with the partner (if any) fitted
/// alongside: the coarse grid places a step only roughly.
pub(super) fn refine_change_points(inputs: &Inputs, state: &State, cs: &mut [Candidate]) {
    let ctx = &inputs.ctx;
    for i in 0..cs.len() {
        if let Some(t0_s) = cs[i].kind.change_time_s() {
            let mut ctx_eff = state.accepted.clone();
            ctx_eff.extend(
                cs.iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, c)| EffectModel::zero(c.kind.clone())),
            );
            let t0 = refine_step(inputs, &state.p, ctx_eff, &cs[i].kind, t0_s);
            cs[i].kind = cs[i].kind.with_change_time(t0);
            cs[i].what = match cs[i].kind.sensor() {
                Some(k) => format!("a change {} on string {}", ctx.when(t0), k + 1),
                None => format!("a move of the whole rig {}", ctx.when(t0)),
            };
        }
    }
}

/// Scan the change point of an anchor step around `t0` over the train
/// pose times between its coarse-grid neighbours. Each position's step is
/// fitted against the model (`p` with `accepted`) linearised once.
fn refine_step(
    inputs: &Inputs,
    p: &[f64],
    accepted: Vec<EffectModel>,
    kind: &Kind,
    t0: f64,
) -> f64 {
    let Inputs { obs, ctx, .. } = inputs;
    let times = sorted_train_times(obs, ctx);
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
    let fixed = FixedBase::of(inputs, p, accepted, vec![0usize; obs.train.len()]);
    let base: Vec<usize> = (0..fixed.n_base).collect();
    let mut at = lo;
    while at <= hi {
        let t = 0.5 * (times[at - 1] + times[at]);
        let nm = fixed.with(inputs, &kind.with_change_time(t));
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
