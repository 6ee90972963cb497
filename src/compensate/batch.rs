//! Batches: targets compensated independently (one bad target never fails
//! the others), or in the order the robot visits them when a backlash
//! makes each target's joints depend on the move that reaches it.

use crate::model::Target;

use super::{Compensated, Compensator};

/// Compensate a batch in order; one bad target never fails the others.
pub fn compensate_all(
    comp: &Compensator,
    targets: &[Target],
    orientation: bool,
) -> Vec<Compensated> {
    targets
        .iter()
        .map(|t| comp.compensate(t, orientation))
        .collect()
}

/// Compensate targets the robot visits in the given order: with an
/// accepted backlash each joint arrives from the direction it moves in from
/// the previous target's compensated joints (the first target, and a joint
/// that does not move, keep the direction before: +q at the start). A
/// target is solved with the directions carried over, and solved again
/// when its joints turn out to arrive from the other side. Without a
/// backlash, [`compensate_all`].
pub fn compensate_in_order(
    comp: &Compensator,
    targets: &[Target],
    orientation: bool,
) -> Vec<Compensated> {
    if !comp.has_backlash() {
        return compensate_all(comp, targets, orientation);
    }
    let mut direction = vec![1.0; comp.dof()];
    let mut previous: Option<Vec<f64>> = None;
    let mut out = Vec::with_capacity(targets.len());
    for t in targets {
        let arriving = |q_deg: &[f64], carried: &[f64]| -> Vec<f64> {
            match &previous {
                Some(p) => q_deg
                    .iter()
                    .zip(p)
                    .zip(carried)
                    .map(|((a, b), &d)| {
                        crate::physics::effects::step_direction(b.to_radians(), a.to_radians(), d)
                    })
                    .collect(),
                None => carried.to_vec(),
            }
        };
        let mut row = comp.with_approach(&direction).compensate(t, orientation);
        if let Some(q) = &row.q_deg {
            let d = arriving(q, &direction);
            if d != direction {
                let again = comp.with_approach(&d).compensate(t, orientation);
                // Keep the second answer when it is consistent with its own
                // approach (a move of a few micro-degrees could flip back).
                if again
                    .q_deg
                    .as_ref()
                    .is_some_and(|q2| arriving(q2, &direction) == d)
                {
                    row = again;
                }
            }
        }
        if let Some(q) = &row.q_deg {
            direction = arriving(q, &direction);
            previous = Some(q.clone());
        }
        out.push(row);
    }
    out
}
