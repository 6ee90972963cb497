//! The naming gate once a data-driven correction is in the model: every
//! named effect kept must still improve the held-out readings on its own.
//! Catalogue terms kept in earlier rounds to mop up structure of another
//! shape (three harmonics and a scale error on a joint with a local bump)
//! stop doing so once a correction of the right shape is there; they are
//! then dropped, not reported as physics, and the `unexplained` finding
//! says which catalogue effects the structure resembled and why they were
//! not kept.

pub(super) use super::gates::held_out_gain_z;
use super::normals::{normals, solve_subset};
use super::{Inputs, State};
use crate::physics::effects::EffectModel;
use crate::physics::problem::EffectProblem;
use crate::report::FindingModel;

/// The paired z a named effect's own held-out gain must reach beside a
/// kept data-driven correction: the gate a new proposal passes
/// ([`HELD_OUT_Z`](super::HELD_OUT_Z)). It was admitted against a model
/// that lacked the structure's true shape, which it may have been fitting
/// in part, so its admission is re-examined as if it were proposed now.
const KEEP_BESIDE_CORRECTION_Z: f64 = super::HELD_OUT_Z;

/// Drop, weakest first, every named effect without which the model (refit
/// by one linearised step) predicts the held-out readings about as well:
/// its paired z of gain below [`KEEP_BESIDE_CORRECTION_Z`]. Each drop is
/// said in the `unexplained` finding's `resembles` and in the notes.
pub(super) fn prune(inputs: &Inputs, state: &mut State) {
    prune_overlapping(inputs, state);
    loop {
        let mut weakest: Option<(usize, f64, Vec<f64>, Vec<EffectModel>)> = None;
        for k in 0..state.accepted.len() {
            if state.accepted[k].kind.is_data_driven() {
                continue;
            }
            let Some((p, eff)) = without(inputs, state, k) else {
                continue;
            };
            let z = held_out_gain_z(inputs, (&p, &eff), (&state.p, &state.accepted));
            if z < KEEP_BESIDE_CORRECTION_Z && weakest.as_ref().is_none_or(|w| z < w.1) {
                weakest = Some((k, z, p, eff));
            }
        }
        let Some((k, z, p, eff)) = weakest else {
            return;
        };
        let gone = state.accepted[k].kind.clone();
        let why = format!(
            "{} was kept in an earlier round, but beside the data-driven correction it no longer improves the held-out readings on its own as a new effect must (paired z = {z:.1}, needs {KEEP_BESIDE_CORRECTION_Z}): it was absorbing part of a structure of another shape, so it is dropped rather than named",
            described(&gone)
        );
        drop_kinds(state, &[gone], &why);
        state.p = p;
        state.accepted = eff;
    }
}

/// The named effects that act where a kept correction acts, through the
/// same driver: on the corrected joint (its compliance, backlash,
/// harmonics, scale) for a correction of a joint's angle, on the corrected
/// string for a string's, every effect of the session's clock (rig moves,
/// drifts, a warm-up) for a correction of T in time. The correction can
/// take every shape they have.
fn overlapping(state: &State) -> Vec<usize> {
    use crate::physics::effects::{CorrectionDriver, CorrectionTarget, Kind, ThermalDriver};
    let mut out = Vec::new();
    for c in state.accepted.iter().filter(|e| e.kind.is_data_driven()) {
        let Kind::DataDriven {
            target,
            target_index,
            driver,
            ..
        } = &c.kind
        else {
            continue;
        };
        for (k, e) in state.accepted.iter().enumerate() {
            let hit = match (target, driver, &e.kind) {
                (_, _, other) if other.is_data_driven() => false,
                (
                    CorrectionTarget::JointAngle,
                    CorrectionDriver::Time | CorrectionDriver::Temperature,
                    _,
                ) => false,
                (CorrectionTarget::JointAngle, _, other) => other.joint() == *target_index,
                // A play in time can be the one constant play too.
                (CorrectionTarget::JointPlay, _, Kind::Backlash { joint_index }) => {
                    Some(*joint_index) == *target_index
                }
                (CorrectionTarget::StringReading | CorrectionTarget::StringZeroScale, _, other) => {
                    other.sensor() == *target_index
                }
                (CorrectionTarget::Point, CorrectionDriver::Time, other) => matches!(
                    other,
                    Kind::RigStep { .. }
                        | Kind::RigDrift
                        | Kind::ThermalExpansion {
                            driver: ThermalDriver::Time | ThermalDriver::Order,
                            ..
                        }
                ),
                // The frame's shape moves anchors, singly or together (or,
                // with point data, turns the instrument's space as a rig
                // move does).
                (CorrectionTarget::RigShape, _, other) => matches!(
                    other,
                    Kind::AnchorStep { .. }
                        | Kind::SensorDrift { .. }
                        | Kind::RigStep { .. }
                        | Kind::RigDrift
                ),
                (CorrectionTarget::Point, CorrectionDriver::Temperature, other) => matches!(
                    other,
                    Kind::ThermalExpansion {
                        driver: ThermalDriver::Temperature,
                        ..
                    }
                ),
                _ => false,
            };
            if hit && !out.contains(&k) {
                out.push(k);
            }
        }
    }
    out
}

/// The named effects [`overlapping`] a correction are dropped together
/// unless, together, they still improve the held-out readings
/// significantly beside it (the gate a new proposal passes).
fn prune_overlapping(inputs: &Inputs, state: &mut State) {
    let group = overlapping(state);
    if group.is_empty() {
        return;
    }
    let Some((p, eff)) = without_all(inputs, state, &group) else {
        return;
    };
    let z = held_out_gain_z(inputs, (&p, &eff), (&state.p, &state.accepted));
    if z >= super::HELD_OUT_Z {
        return;
    }
    let gone: Vec<_> = group
        .iter()
        .map(|&k| state.accepted[k].kind.clone())
        .collect();
    let names: Vec<String> = gone.iter().map(|k| described(k)).collect();
    let why = format!(
        "{} kept in earlier rounds acted where the data-driven correction acts; beside it they no longer improve the held-out readings significantly (paired z = {z:.1}, a new effect needs {}): they were absorbing a structure of another shape, so they are dropped rather than named",
        names.join(", "),
        super::HELD_OUT_Z
    );
    drop_kinds(state, &gone, &why);
    state.p = p;
    state.accepted = eff;
}

/// `kind` with where it acts, for a sentence.
fn described(gone: &crate::physics::effects::Kind) -> String {
    match (gone.acting_joint(), gone.sensor()) {
        (Some(j), _) if gone.joint().is_none() => {
            format!("{} from joint {}", gone.name(), j + 1)
        }
        (Some(j), _) => format!("{} on joint {}", gone.name(), j + 1),
        (_, Some(s)) => format!("{} on string {}", gone.name(), s + 1),
        _ => gone.name().to_string(),
    }
}

/// Remove the findings of `gone`, and say `why` in the `unexplained`
/// finding and the notes.
fn drop_kinds(state: &mut State, gone: &[crate::physics::effects::Kind], why: &str) {
    state
        .findings
        .retain(|f| f.effect_model().is_none_or(|m| !gone.contains(&m.kind)));
    tell(state, why.to_string());
}

/// The model without effect `k`, refit by one linearised step of the
/// geometry and the other effects from where they are.
fn without(inputs: &Inputs, state: &State, k: usize) -> Option<(Vec<f64>, Vec<EffectModel>)> {
    without_all(inputs, state, &[k])
}

/// The model without the effects `ks`, refit likewise.
fn without_all(
    inputs: &Inputs,
    state: &State,
    ks: &[usize],
) -> Option<(Vec<f64>, Vec<EffectModel>)> {
    let Inputs {
        obs,
        ctx,
        free,
        fold_of,
    } = inputs;
    let effects: Vec<EffectModel> = state
        .accepted
        .iter()
        .enumerate()
        .filter(|(i, _)| !ks.contains(i))
        .map(|(_, e)| e.clone())
        .collect();
    let problem = EffectProblem::of_observations(
        obs,
        ctx,
        obs.train.clone(),
        &state.p,
        free.clone(),
        effects,
    );
    let x0 = problem.x0();
    let nm = normals(&problem, &x0, fold_of);
    let (a, b, _) = nm.total();
    let held = inputs.held_columns(problem.effects.iter().map(|e| &e.kind));
    let cols: Vec<usize> = (0..x0.len()).filter(|c| !held.contains(c)).collect();
    let (_, delta) = solve_subset(&a, &b, &cols)?;
    let mut x = x0;
    for (&c, d) in cols.iter().zip(&delta) {
        x[c] += d;
    }
    Some(problem.unpack(&x))
}

/// Thermal expansion grows every length in proportion to it. When one
/// length's growth alone (a data-driven correction of that length in the
/// same driver) predicts the held-out readings clearly better (paired z
/// of at least [`HELD_OUT_Z`](super::HELD_OUT_Z)), the lengths did not
/// grow in proportion and the catalogue's effect is not the physics: it
/// is dropped, an `unexplained` finding at the thermal driver says so and
/// the length's growth is kept as the correction. True when done.
pub(super) fn uneven_thermal(inputs: &Inputs, state: &mut State) -> bool {
    use crate::physics::effects::{CorrectionDriver, Kind, ThermalDriver};
    let Some(k) = state
        .accepted
        .iter()
        .position(|e| matches!(e.kind, Kind::ThermalExpansion { .. }))
    else {
        return false;
    };
    let (driver, place_driver) = match inputs.ctx.thermal_driver {
        ThermalDriver::Temperature => (CorrectionDriver::Temperature, "temperature"),
        ThermalDriver::Time | ThermalDriver::Order => (CorrectionDriver::Time, "time"),
    };
    let families = super::data_driven::length_families(inputs, driver);
    replace_by_correction(
        inputs,
        state,
        k,
        (place_driver, None, None),
        super::HELD_OUT_Z,
        &families,
        |kind, z| {
            let Kind::DataDriven { target_index, .. } = kind else {
                return None;
            };
            let length = crate::physics::effects::length_name(*target_index);
            Some(Replacement {
                joint: target_index.map(|i| i / 5 + 1),
                located: format!(
                    "a growth with the {place_driver} located in one length, {length}, by the test of thermal expansion's shape (every length in proportion against each length alone)"
                ),
                why: format!(
                    "thermal_expansion (every a and d growing in proportion with the {place_driver}) was kept, but {length} growing alone predicts the held-out readings better (paired z = {z:.1}, needs {}): the lengths did not grow in proportion, so it is not the catalogue's expansion of the arm",
                    super::HELD_OUT_Z
                ),
            })
        },
    )
}

/// Backlash stops a joint short by a fixed amount by the side it arrived
/// from. When a correction of that joint's angle by the size of its last
/// move (signed) predicts the held-out readings clearly better (paired z
/// of at least [`HELD_OUT_Z`](super::HELD_OUT_Z)), the error is graded
/// with the move, which a dead band is not (friction or elastic wind-up in
/// the drive is): the backlash is dropped, an `unexplained` finding at the
/// joint's last move says so and the graded correction is kept; not when T
/// off along its move (an arm not settled) fits better still, which the
/// locator places later. Each backlash kept is tried; true when any was
/// replaced.
pub(super) fn graded_backlash(inputs: &Inputs, state: &mut State) -> bool {
    use crate::physics::effects::{CorrectionDriver, Kind};
    let mut any = false;
    let joints: Vec<usize> = state
        .accepted
        .iter()
        .filter_map(|e| match e.kind {
            Kind::Backlash { joint_index } => Some(joint_index),
            _ => None,
        })
        .collect();
    for j in joints {
        let Some(k) = state
            .accepted
            .iter()
            .position(|e| e.kind == Kind::Backlash { joint_index: j })
        else {
            continue;
        };
        let families = super::data_driven::move_families(inputs, j);
        any |= replace_by_correction(
            inputs,
            state,
            k,
            ("motion", Some(j + 1), None),
            super::HELD_OUT_Z,
            &families,
            |kind, z| {
                // T off along its move is the arm not settled, which the
                // locator places at the motion without this test.
                let Kind::DataDriven {
                    driver: CorrectionDriver::JointMove,
                    ..
                } = kind
                else {
                    return None;
                };
                Some(Replacement {
                    joint: Some(j + 1),
                    located: format!(
                        "an error of joint {}'s angle graded with the size of its last move, located by the test of backlash's shape (a fixed amount by the side the joint arrived from, against a smooth function of the signed move)",
                        j + 1
                    ),
                    why: format!(
                        "backlash of joint {} (a fixed amount by the side it arrived from) was kept, but a smooth function of the joint's signed last move predicts the held-out readings better (paired z = {z:.1}, needs {}): the error grows with the move, which a dead band does not; friction or elastic wind-up in the drive would",
                        j + 1,
                        super::HELD_OUT_Z
                    ),
                })
            },
        );
    }
    any
}

/// An anchor step moves one anchor once: that string's reading changes at
/// one instant by the anchor's displacement along it. When the string's
/// reading as a smooth function of its direction from the anchor (a post
/// that bends with the string's pull, wrap or friction at its exit)
/// predicts the held-out readings clearly better (paired z of at least
/// [`HELD_OUT_Z`](super::HELD_OUT_Z)), the step was fitting a structure
/// of the string's geometry that the tour's order mixed with time: the
/// step is dropped, an `unexplained` finding at the string's direction
/// says so and the correction is kept. Each anchor step kept is tried;
/// true when any was replaced.
pub(super) fn steady_anchor(inputs: &Inputs, state: &mut State) -> bool {
    use crate::physics::effects::Kind;
    let mut any = false;
    let steps: Vec<Kind> = state
        .accepted
        .iter()
        .filter(|e| matches!(e.kind, Kind::AnchorStep { .. }))
        .map(|e| e.kind.clone())
        .collect();
    for step in steps {
        let Kind::AnchorStep { sensor_index, .. } = step else {
            continue;
        };
        let Some(k) = state.accepted.iter().position(|e| e.kind == step) else {
            continue;
        };
        let families = super::data_driven::direction_families(inputs, sensor_index);
        let s = sensor_index + 1;
        any |= replace_by_correction(
            inputs,
            state,
            k,
            ("workspace", None, Some(s)),
            super::HELD_OUT_Z,
            &families,
            |_, z| {
                Some(Replacement {
                    joint: None,
                    located: format!(
                        "an error of string {s}'s reading that follows its direction from its anchor, located by the test of anchor_step's shape (one move of the anchor at one instant, against a smooth function of the string's direction)"
                    ),
                    why: format!(
                        "anchor_step on string {s} (its anchor moved once) was kept, but the string's reading as a smooth function of its direction from the anchor predicts the held-out readings better (paired z = {z:.1}, needs {}): the error follows where the string points, which the tour's order had mixed with the clock; a post bending with the string's pull, or wrap or friction at its exit, would",
                        super::HELD_OUT_Z
                    ),
                })
            },
        );
    }
    any
}

/// The paired z a function of a joint's gravity torque must beat its
/// compliance by: more than a new effect's [`HELD_OUT_Z`](super::HELD_OUT_Z),
/// as the function (smooth or jumping where the torque changes sign, up to
/// eight knots) contains the compliance and can take part of what another
/// effect of that joint leaves (measured: at z >= 2, 2 of 31 simulated
/// compliances at 3x the noise were replaced).
const LOAD_SHAPE_Z: f64 = 3.0;

/// A compliance turns a joint in proportion to its gravity torque; a
/// harmonic follows its angle. When a smooth function of that torque (or
/// one jumping where it changes sign) predicts the held-out readings
/// clearly better (paired z of at least [`LOAD_SHAPE_Z`]), the joint's
/// error follows its load in a form neither has (a reducer stiffer one way
/// than the other, play that gravity takes up, a stiffness that changes
/// with the load; a harmonic of the angle only resembled it, as the load
/// turns over with the angle): the named effect is dropped, an
/// `unexplained` finding at the joint's angle says so and the correction
/// is kept. Each compliance and each harmonic with link masses is tried;
/// true when any was replaced.
pub(super) fn uneven_load(inputs: &Inputs, state: &mut State) -> bool {
    use crate::physics::effects::Kind;
    let mut any = false;
    let tried: Vec<Kind> = state
        .accepted
        .iter()
        .filter(|e| match &e.kind {
            Kind::JointCompliance { regressors, .. } => regressors.is_empty(),
            Kind::JointPeriodic { .. } => true,
            _ => false,
        })
        .map(|e| e.kind.clone())
        .collect();
    for kind in tried {
        let Some(j) = kind.joint() else { continue };
        // Gone already (with an earlier replacement's pruning).
        let Some(k) = state.accepted.iter().position(|e| e.kind == kind) else {
            continue;
        };
        let families = super::data_driven::load_families(inputs, j);
        if families.is_empty() {
            continue;
        }
        let (shape, physics) = match kind {
            Kind::JointPeriodic { .. } => (
                "a harmonic of its angle",
                "the error follows the load, not the angle (the load turns over with the angle, so a harmonic resembled it); a reducer stiffer one way than the other, play that gravity takes up, or a stiffness that changes with the load would do this",
            ),
            _ => (
                "an angle in proportion to its gravity torque",
                "the joint is not elastic; play that gravity takes up as the load changes sign, or a stiffness that changes with the load, would do this",
            ),
        };
        let name = described(&kind);
        any |= replace_by_correction(
            inputs,
            state,
            k,
            ("joint", Some(j + 1), None),
            LOAD_SHAPE_Z,
            &families,
            |_, z| {
                Some(Replacement {
                    joint: Some(j + 1),
                    located: format!(
                        "an error of joint {}'s angle that follows its gravity load out of proportion, located by the test of {name}'s shape ({shape}, against a smooth function of the gravity torque)",
                        j + 1
                    ),
                    why: format!(
                        "{name} ({shape}) was kept, but a smooth function of joint {}'s gravity torque predicts the held-out readings better (paired z = {z:.1}, needs {LOAD_SHAPE_Z}): {physics}",
                        j + 1
                    ),
                })
            },
        );
    }
    any
}

/// What a catalogue effect replaced by a data-driven correction is
/// reported as: the joint of the place, how it was located, why the name
/// was dropped.
struct Replacement {
    joint: Option<usize>,
    located: String,
    why: String,
}

/// Replace the accepted named effect `k` by the best data-driven
/// correction of `families` at the place `(driver, joint, sensor)` when
/// the model with it predicts the held-out readings clearly better than
/// with the named effect (paired z of at least `needs_z`).
/// `describe` words the replacement from the correction kept and z. The
/// named effect's finding gives way to an `unexplained` finding at the
/// place; true when done.
fn replace_by_correction(
    inputs: &Inputs,
    state: &mut State,
    k: usize,
    (driver, joint, sensor): (&str, Option<usize>, Option<usize>),
    needs_z: f64,
    families: &[Vec<crate::physics::effects::Kind>],
    describe: impl Fn(&crate::physics::effects::Kind, f64) -> Option<Replacement>,
) -> bool {
    let Some((p, eff)) = without(inputs, state, k) else {
        return false;
    };
    let gone = state.accepted[k].kind.clone();
    let mut alt = state.clone();
    alt.findings
        .retain(|f| f.effect_model().is_none_or(|m| m.kind != gone));
    alt.p = p;
    alt.accepted = eff;
    let bare = (alt.p.clone(), alt.accepted.clone());
    let at = alt.findings.len();
    let mut place = crate::report::Place {
        driver: driver.into(),
        joint,
        sensor,
        side: if sensor.is_some() { "sensor" } else { "robot" }.into(),
        z: f64::NAN,
        threshold: super::HELD_OUT_Z,
        range: None,
    };
    if !super::data_driven::try_place(inputs, &mut alt, families, &place) {
        return false;
    }
    let z = held_out_gain_z(inputs, (&state.p, &state.accepted), (&alt.p, &alt.accepted));
    if z < needs_z {
        return false;
    }
    let Some(r) = alt.accepted.last().and_then(|e| describe(&e.kind, z)) else {
        return false;
    };
    place.joint = r.joint;
    place.z = z;
    let finding = crate::physics::unexplained::unexplained_at(
        inputs.obs,
        &inputs.ctx,
        (&bare.0, &bare.1),
        place,
        r.located,
        vec![r.why.clone()],
    );
    alt.findings.insert(at, finding);
    alt.notes.push(r.why);
    *state = alt;
    true
}

/// A set of named effects whose shape is no one physical effect.
pub(super) struct Series {
    /// Their positions in the accepted effects.
    members: Vec<usize>,
    /// Their names and places, for the sentence.
    names: Vec<String>,
    /// What makes the shape unphysical.
    why: &'static str,
}

/// The named effects of `state` whose shape is no one physical effect:
/// three or more terms of one joint (a bending link's counts at its root
/// joint, [`Kind::acting_joint`](crate::physics::effects::Kind::acting_joint)), or two
/// shape terms (harmonics, a scale error) of one joint; two or more moves
/// or drifts of the rig; two or more steps or creeps of one string.
pub(super) fn series(state: &State) -> Vec<Series> {
    use crate::physics::effects::Kind;
    let acc = &state.accepted;
    let mut out = Vec::new();
    let n_joints = acc
        .iter()
        .filter_map(|e| e.kind.acting_joint())
        .max()
        .map_or(0, |j| j + 1);
    for j in 0..n_joints {
        let terms: Vec<usize> = (0..acc.len())
            .filter(|&k| !acc[k].kind.is_data_driven() && acc[k].kind.acting_joint() == Some(j))
            .collect();
        let is_shape = |k: &usize| {
            matches!(
                acc[*k].kind,
                Kind::JointPeriodic { .. } | Kind::JointScale { .. }
            )
        };
        let shapes: Vec<usize> = terms.iter().copied().filter(is_shape).collect();
        // Two shape terms are the series on their own: a compliance or a
        // backlash beside them stays, fitted with what replaces them.
        let members = if shapes.len() >= 2 {
            shapes
        } else if terms.len() >= 3 {
            terms
        } else {
            continue;
        };
        out.push(Series {
            why: if !members.iter().all(is_shape) {
                "three or more terms of one joint together fit one error of its angle, which is no one physical effect"
            } else {
                "several shape terms of one joint together fit one error of its angle, which is no one physical effect"
            },
            names: members.iter().map(|&k| described(&acc[k].kind)).collect(),
            members,
        });
    }
    let rig: Vec<usize> = (0..acc.len())
        .filter(|&k| matches!(acc[k].kind, Kind::RigStep { .. } | Kind::RigDrift))
        .collect();
    if rig.len() >= 2 {
        out.push(Series {
            names: rig.iter().map(|&k| described(&acc[k].kind)).collect(),
            members: rig,
            why: "several moves of the rig in one session fit one motion of another shape, which is no one physical effect",
        });
    }
    let strings = acc
        .iter()
        .filter_map(|e| e.kind.sensor())
        .max()
        .map_or(0, |s| s + 1);
    for s in 0..strings {
        let members: Vec<usize> = (0..acc.len())
            .filter(|&k| {
                matches!(
                    acc[k].kind,
                    Kind::AnchorStep { .. } | Kind::SensorDrift { .. }
                ) && acc[k].kind.sensor() == Some(s)
            })
            .collect();
        if members.len() >= 2 {
            out.push(Series {
                names: members.iter().map(|&k| described(&acc[k].kind)).collect(),
                members,
                why: "several steps or creeps of one string in one session fit one change of another shape, which is no one physical effect",
                });
        }
    }
    out
}

/// The named effects of `state` after which the remainder, as `located`
/// (the same model with its remainder located) places it, still follows
/// the driver they act through: the clock for a step or a creep of the rig
/// or of one string (and a thermal expansion driven by the clock), the
/// temperature for a thermal expansion driven by it, a string's length
/// for that string's scale or offset, a joint's angle for that joint's
/// compliance, periodic term or scale error (and the root joint's for a
/// bending link). They did not explain the structure
/// they were found on (a knock that springs back, a joint's zero that
/// jumped, a frame that grows with the temperature, a drum that winds
/// unevenly), so they are condemned like a series.
pub(super) fn left_in_their_driver(state: &State, located: &State) -> Vec<Series> {
    use crate::physics::effects::{Kind, ThermalDriver};
    // Only the remainder located now (earlier shape tests' findings said
    // where what they replaced lived, not what is left).
    let places: Vec<&crate::report::Place> = located
        .findings
        .iter()
        .skip(state.findings.len())
        .filter_map(|f| f.unexplained())
        .flat_map(|u| u.places.iter())
        .collect();
    // The rig's effects by a place of the whole residual (no string), a
    // string's by that string's own.
    let at = |driver: &str, sensor: Option<usize>| {
        places.iter().any(|p| {
            p.driver == driver
                && match sensor {
                    None => p.sensor.is_none(),
                    Some(s) => p.sensor == Some(s + 1),
                }
        })
    };
    let acc = &state.accepted;
    let members: Vec<usize> = (0..acc.len())
        .filter(|&k| match acc[k].kind {
            Kind::RigStep { .. }
            | Kind::RigDrift
            | Kind::ThermalExpansion {
                driver: ThermalDriver::Time | ThermalDriver::Order,
                ..
            } => at("time", None),
            Kind::ThermalExpansion {
                driver: ThermalDriver::Temperature,
                ..
            } => at("temperature", None),
            Kind::AnchorStep { sensor_index, .. } | Kind::SensorDrift { sensor_index } => {
                at("time", Some(sensor_index))
            }
            Kind::SensorScale { sensor_index } | Kind::SensorOffset { sensor_index } => places
                .iter()
                .any(|p| p.driver == "string" && p.sensor == Some(sensor_index + 1)),
            // A joint's angle error by its angle or its load, where the
            // remainder still follows that joint's angle.
            Kind::JointCompliance { joint_index, .. }
            | Kind::JointPeriodic { joint_index, .. }
            | Kind::JointScale { joint_index }
            | Kind::LinkBending {
                link_index: joint_index,
            } => places
                .iter()
                .any(|p| p.driver == "joint" && p.joint == Some(joint_index + 1)),
            _ => false,
        })
        .collect();
    if members.is_empty() {
        return Vec::new();
    }
    vec![Series {
        names: members.iter().map(|&k| described(&acc[k].kind)).collect(),
        members,
        why: "the remainder still followed the driver they act through after them, so they did not explain the structure they were found on",
    }]
}

/// Take every series' effects out of the model (findings and effects),
/// the rest refit by one linearised step.
pub(super) fn take_out(inputs: &Inputs, state: &mut State, series: &[Series]) {
    let ks: Vec<usize> = series.iter().flat_map(|s| s.members.clone()).collect();
    let Some((p, eff)) = without_all(inputs, state, &ks) else {
        return;
    };
    let gone: Vec<_> = ks.iter().map(|&k| state.accepted[k].kind.clone()).collect();
    state
        .findings
        .retain(|f| f.effect_model().is_none_or(|m| !gone.contains(&m.kind)));
    state
        .jumps_s
        .extend(gone.iter().filter_map(|k| k.change_time_s()));
    state.p = p;
    state.accepted = eff;
}

/// Say in the `unexplained` finding (and the notes) which named terms the
/// structure was first fitted with and why they are not reported.
pub(super) fn say_why(state: &mut State, series: &[Series], z: f64) {
    for s in series {
        let why = format!(
            "{} {} first fitted to this structure, but {}; the data-driven correction predicts the held-out readings {} (paired z = {z:.1}), so {} not reported as physics",
            s.names.join(", "),
            if s.names.len() > 1 { "were" } else { "was" },
            s.why,
            if z >= 0.0 { "better" } else { "about as well" },
            if s.names.len() > 1 {
                "they are"
            } else {
                "it is"
            }
        );
        tell(state, why);
    }
}

/// Why named terms are not reported: in every `unexplained` finding
/// (what it resembles and why that does not explain it) and in the notes.
pub(super) fn tell(state: &mut State, why: String) {
    for f in state.findings.iter_mut() {
        if let Some(FindingModel::Unexplained(u)) = &mut f.parameters {
            u.resembles.push(why.clone());
        }
    }
    state.notes.push(why);
}

/// Say in the `unexplained` finding (and the notes) which named terms the
/// structure was first fitted with, and that without them, no correction
/// in their place, the held-out readings are predicted about as well or
/// better (paired z of the named model's gain `z`, below [`HELD_OUT_Z`]).
///
/// [`HELD_OUT_Z`]: super::HELD_OUT_Z
pub(super) fn say_why_unnamed(state: &mut State, series: &[Series], z: f64) {
    for s in series {
        let why = format!(
            "{} {} first fitted to this structure, but {}; without {} the held-out readings are predicted {} (the named model's gain: paired z = {z:.1}, needs {}), so {} not reported as physics",
            s.names.join(", "),
            if s.names.len() > 1 { "were" } else { "was" },
            s.why,
            if s.names.len() > 1 { "them" } else { "it" },
            if z > 0.0 {
                "about as well"
            } else {
                "as well or better"
            },
            super::HELD_OUT_Z,
            if s.names.len() > 1 {
                "they are"
            } else {
                "it is"
            }
        );
        tell(state, why);
    }
}

/// Backlash depends on the motion only through the side each joint
/// arrived from. When the remainder still follows the move that led to
/// each pose (an `unexplained` finding placed at `motion`), the backlash
/// terms kept were fitting part of that motion-driven error, not a dead
/// band: they are taken out (their findings too, and the `unexplained`
/// finding, to be located again), the rest refit by one linearised step.
/// The names dropped, for a sentence; empty when nothing was done.
pub(super) fn drop_backlash_beside_motion(inputs: &Inputs, state: &mut State) -> Vec<String> {
    use crate::physics::effects::Kind;
    // T's motion, not one string's last change (a sensor's own) nor one
    // joint's (its drive's own way of moving or being loaded, which says
    // nothing of the other joints' dead bands).
    let motion = state.findings.iter().any(|f| {
        f.unexplained().is_some_and(|u| {
            u.places
                .iter()
                .any(|p| p.driver == "motion" && p.sensor.is_none() && p.joint.is_none())
        })
    });
    let ks: Vec<usize> = (0..state.accepted.len())
        .filter(|&k| matches!(state.accepted[k].kind, Kind::Backlash { .. }))
        .collect();
    if !motion || ks.is_empty() {
        return Vec::new();
    }
    let Some((p, eff)) = without_all(inputs, state, &ks) else {
        return Vec::new();
    };
    let gone: Vec<_> = ks.iter().map(|&k| state.accepted[k].kind.clone()).collect();
    state.findings.retain(|f| {
        f.unexplained().is_none() && f.effect_model().is_none_or(|m| !gone.contains(&m.kind))
    });
    state.p = p;
    state.accepted = eff;
    gone.iter().map(described).collect()
}
