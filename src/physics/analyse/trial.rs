//! Trying a round's proposals in rank order: the first to pass every gate
//! is kept (its findings written, the model refitted with it), and a
//! single candidate turned down by the data is not proposed again.

use super::candidates::{Candidate, same_slot};
use super::gates::{self, Before, HeldOut, Stages, Turned};
use super::proposals::{self, Proposal};
use super::refit::FitInfo;
use super::scoring::Scores;
use super::{Inputs, State, findings};
use crate::physics::effects::{EffectModel, Kind};

/// Proposals (single effects or pairs) tried per round.
const TRIES: usize = 4;

/// A proposal that passed every gate: the refit with it, and what the
/// gates measured on the way (the findings quote it).
pub(super) struct Kept {
    pub(super) p_new: Vec<f64>,
    pub(super) eff_new: Vec<EffectModel>,
    pub(super) fit: FitInfo,
    /// 5-fold cross-validated SSE with the proposal (mm²).
    pub(super) cv1: f64,
    pub(super) held: HeldOut,
    pub(super) stages: Stages,
}

/// Try `proposals` (best first) until one is kept; false when none was
/// (the analysis then stops). At most [`TRIES`] proposals of each size: a
/// pair turned down because one member adds nothing does not use up a
/// try of its lead alone.
pub(super) fn keep_one(
    inputs: &Inputs,
    scores: &Scores,
    proposals: &[Proposal],
    state: &mut State,
) -> bool {
    let before = Before::of(inputs, scores, state);
    let mut tried = [0usize; 2];
    for prop in proposals {
        let single = prop.members.len() == 1;
        let count = &mut tried[usize::from(!single)];
        if *count == TRIES {
            continue;
        }
        *count += 1;
        if try_one(inputs, scores, &before, prop, state) {
            return true;
        }
    }
    false
}

/// One proposal through the gates: kept (findings written, `state` moved
/// to the refit) or turned down (its note and rejection recorded).
fn try_one(
    inputs: &Inputs,
    scores: &Scores,
    before: &Before,
    prop: &Proposal,
    state: &mut State,
) -> bool {
    let mut cs: Vec<Candidate> = prop
        .members
        .iter()
        .map(|m| scores.cands[scores.scored[m.0].idx].clone())
        .collect();
    if cs
        .iter()
        .any(|c| state.rejected.iter().any(|r| same_slot(r, &c.kind)))
    {
        return false;
    }
    // A rejection is recorded on the grid's kind, which is what comes
    // back.
    let grid = cs[0].kind.clone();
    proposals::refine_change_points(inputs, state, &mut cs);
    match through_gates(inputs, scores, before, prop, &cs, state) {
        Ok(kept) => {
            findings::write(inputs, scores, before, prop, &cs, &kept, state);
            state.p = kept.p_new;
            state.accepted = kept.eff_new;
            state.final_fit = Some(kept.fit);
            true
        }
        Err(Turned {
            note,
            reject,
            wrong_way,
        }) => {
            // A compliance fitted against the gravity load that predicted
            // the held-out readings better: structure at that joint.
            if let (Some(z), [c]) = (wrong_way, cs.as_slice())
                && let Kind::JointCompliance {
                    joint_index,
                    regressors,
                } = &c.kind
                && regressors.is_empty()
                && !state.wrong_way.iter().any(|w| w.0 == *joint_index)
            {
                state.wrong_way.push((*joint_index, z));
            }
            state.notes.extend(note);
            if reject && cs.len() == 1 {
                state.rejected.push(grid);
            }
            false
        }
    }
}

/// The gates of [`gates`] in order, the nonlinear refit between the
/// linearised ones and the held-out ones.
fn through_gates(
    inputs: &Inputs,
    scores: &Scores,
    before: &Before,
    prop: &Proposal,
    cs: &[Candidate],
    state: &State,
) -> Result<Kept, Turned> {
    gates::pair_still_holds(inputs, scores, state, prop, cs)?;
    let cv1 = gates::cross_validated(scores, prop, before.cv0)?;
    let mut trial = state.accepted.clone();
    trial.extend(cs.iter().map(|c| EffectModel::zero(c.kind.clone())));
    let (p_new, eff_new, fit) = gates::refitted(inputs, state, &trial)?;
    let held = gates::held_out(inputs, before, cs, &p_new, &eff_new)?;
    gates::magnitudes(inputs, state, cs, &eff_new, &fit, held.gain_z)?;
    let stages = gates::pair_members(inputs, state, before, cs, &trial, &held)?;
    Ok(Kept {
        p_new,
        eff_new,
        fit,
        cv1,
        held,
        stages,
    })
}
