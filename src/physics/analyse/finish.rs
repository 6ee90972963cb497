//! Finishing the analysis once no round keeps anything more: the earlier
//! findings restated as the final refit has their effects, a doubt on
//! terms of one joint that cancel each other, and the remainder no effect
//! explains.

use super::magnitude::magnitude;
use super::refit::FitInfo;
use super::{Analysis, Inputs, State, errors_with_effects};
use super::{data_driven, naming};
use crate::identify::{Observations, Progress};
use crate::kinematics::Params;
use crate::physics::effects::{Basis, Context, EffectModel};
use crate::physics::evidence::evidence_plot;
use crate::physics::unexplained::unexplained;
use crate::report::{Finding, FindingModel};

/// The effects of one joint cancel each other when the largest one's
/// spread of angle change over the train poses is this many times their
/// sum's.
const CANCEL_RATIO: f64 = 3.0;

/// The analysis as the last round left it. `share` is the robot-side share
/// of the geometric fit's residual and the share noise alone gives.
pub(super) fn finish(
    inputs: Inputs,
    mut state: State,
    share: (Option<f64>, Option<f64>),
    progress: &dyn Progress,
) -> Analysis {
    restated_and_shape_tested(&inputs, &mut state);
    condemn_unexplaining_names(&inputs, &mut state);
    drop_backlash_beside_motion(&inputs, &mut state);
    progress.update("physics analysis", 1.0);
    let Inputs { obs, ctx, .. } = inputs;
    let test_errors = errors_with_effects(obs, &ctx, &state.p, &state.accepted, &obs.test);
    Analysis {
        findings: state.findings,
        final_params: Params {
            layout: obs.chain.layout,
            values: state.p,
        },
        effects: state.accepted,
        context: ctx,
        test_errors,
        robot_side_share: share.0,
        robot_side_share_noise: share.1,
        notes: state.notes,
        final_sigmas: state.final_fit.map(|f| f.sigma_free),
    }
}

/// Every finding restated from the final model, terms of one joint that
/// cancel doubted, and the shape tests of named effects (thermal expansion
/// even over the lengths, backlash not graded, a compliance in proportion
/// to the load, an anchor step not a steady function of direction): an
/// effect that fails its own shape is replaced by the physics it shows.
fn restated_and_shape_tested(inputs: &Inputs, state: &mut State) {
    if let Some(fit) = &state.final_fit {
        restate(
            inputs.obs,
            &inputs.ctx,
            &state.p,
            &state.accepted,
            fit,
            &mut state.findings,
        );
    }
    doubt_cancelling_terms(
        inputs.obs,
        &inputs.ctx,
        &state.accepted,
        &mut state.findings,
    );
    // The catalogue's thermal expansion grows every length in proportion;
    // one link growing alone is another physics.
    if naming::uneven_thermal(inputs, state) {
        pruned_and_restated(inputs, state);
    }
    // Backlash is a fixed amount by the side a joint arrived from; an
    // error graded with the move's size is another physics.
    if naming::graded_backlash(inputs, state) {
        pruned_and_restated(inputs, state);
    }
    // A compliance is in proportion to the gravity load; an error that
    // follows the load otherwise is another physics.
    if naming::uneven_load(inputs, state) {
        pruned_and_restated(inputs, state);
    }
    // An anchor step is one move at one instant; an error that follows
    // where the string points is another physics.
    if naming::steady_anchor(inputs, state) {
        pruned_and_restated(inputs, state);
    }
}

/// Named terms whose shape is no one physical effect (a series of terms
/// of one joint, several moves of the rig or of one anchor) are taken out
/// and the structure they fitted is located and modelled without a name,
/// unless they predict the held-out poses clearly better; so are named
/// effects after which the remainder still follows the driver they act
/// through. Without such terms, the remainder is located (and corrected)
/// all the same.
fn condemn_unexplaining_names(inputs: &Inputs, state: &mut State) {
    let mut series = naming::series(state);
    let mut located = None;
    if series.is_empty() {
        let mut with_remainder = state.clone();
        locate_and_correct(inputs, &mut with_remainder);
        series = naming::left_in_their_driver(state, &with_remainder);
        located = Some(with_remainder);
    }
    if !series.is_empty() {
        let named = state.clone();
        naming::take_out(inputs, state, &series);
        let before = state.findings.len();
        let corrected = locate_and_correct(inputs, state);
        // Without a correction, the remainder located without them (a new
        // `unexplained` finding, not an earlier shape test's).
        let placed = !corrected && state.findings.len() > before;
        // Against what stays otherwise: the named model, with its
        // remainder's correction when that is what stays.
        let stays = located.as_ref().unwrap_or(&named);
        let z = naming::held_out_gain_z(
            inputs,
            (&stays.p, &stays.accepted),
            (&state.p, &state.accepted),
        );
        // A series is condemned by its shape: what replaced it need only
        // not be clearly worse. Where nothing took their place but the
        // structure is located without them, the same rule says they stay
        // only if they predict the held-out readings clearly better (the
        // named model's gain is -z).
        if corrected && z > -super::HELD_OUT_Z {
            naming::say_why(state, &series, z);
        } else if placed && z > -super::HELD_OUT_Z {
            naming::say_why_unnamed(state, &series, -z);
        } else {
            *state = located.unwrap_or_else(|| {
                let mut s = named;
                locate_and_correct(inputs, &mut s);
                s
            });
        }
    } else if let Some(with_remainder) = located {
        *state = with_remainder;
    }
}

/// Backlash kept beside a remainder that follows the move that led to each
/// pose fitted part of a motion-driven error: it is dropped, the remainder
/// located again, and every `unexplained` finding says why.
fn drop_backlash_beside_motion(inputs: &Inputs, state: &mut State) {
    let dropped = naming::drop_backlash_beside_motion(inputs, state);
    if !dropped.is_empty() {
        locate_and_correct(inputs, state);
        let why = format!(
            "{} {} kept, but the remainder still followed the move that led to each pose, of which backlash sees only the side each joint arrived from: {} fitted part of a motion-driven error, not a dead band, so {} not reported as physics",
            dropped.join(", "),
            if dropped.len() > 1 { "were" } else { "was" },
            if dropped.len() > 1 { "they" } else { "it" },
            if dropped.len() > 1 {
                "they are"
            } else {
                "it is"
            },
        );
        naming::tell(state, why);
    }
}

/// Anything left that varies smoothly? Say where (an `unexplained`
/// finding), and model it there without a name where that predicts the
/// held-out poses better (then the named terms it makes redundant are
/// dropped, and every finding restated from the refit). True when a
/// data-driven correction was kept. Where one was, what it leaves is
/// located and modelled again, up to [`ROUNDS`] rounds: a correction in
/// one driver (a string's last change) can leave the part that follows
/// another (its length), which the first round's places did not name.
fn locate_and_correct(inputs: &Inputs, state: &mut State) -> bool {
    let corrected = locate_and_correct_once(inputs, state);
    for _ in 1..ROUNDS {
        if !corrected || !locate_and_correct_once(inputs, state) {
            break;
        }
    }
    corrected
}

/// Rounds of locating and correcting what the last round left. A second
/// round lowered the ratio to the twin on nine of the cross-checks' halves
/// (EVAL.md, stop 43); a third lowered only tune9's and tune10's a little
/// more and doubled the analysis time again on the real UR10 recordings
/// (every later fit carries every earlier correction's knots).
const ROUNDS: usize = 2;

/// One round of [`locate_and_correct`]: locate, report, correct.
fn locate_and_correct_once(inputs: &Inputs, state: &mut State) -> bool {
    let located = unexplained(
        inputs.obs,
        &inputs.ctx,
        &state.p,
        &state.accepted,
        inputs.free.len(),
    );
    let Some(f) = located.or_else(|| {
        // A wrong-way compliance's joint is said once: a later round
        // would repeat it with the same z.
        let f = wrong_way_place(inputs, state)?;
        state.wrong_way.remove(0);
        Some(f)
    }) else {
        return false;
    };
    let places = f
        .unexplained()
        .map(|u| u.places.clone())
        .unwrap_or_default();
    state.findings.push(f);
    let at = state.findings.len() - 1;
    let n_before = state.accepted.len();
    data_driven::correct(inputs, state, &places);
    if state.accepted.len() == n_before {
        return false;
    }
    let kept: Vec<_> = state.accepted[n_before..]
        .iter()
        .map(|e| e.kind.clone())
        .collect();
    placed_by_correction(&mut state.findings[at], &kept, inputs.ctx.anchors.len());
    pruned_and_restated(inputs, state);
    true
}

/// Where the neighbour tests locate nothing but a joint's compliance was
/// fitted against its gravity load and still predicted the held-out
/// readings better (`State::wrong_way`): structure at that joint which
/// the catalogue's shape does not explain, reported `unexplained` at the
/// first such joint.
fn wrong_way_place(inputs: &Inputs, state: &State) -> Option<Finding> {
    let &(j, z) = state.wrong_way.first()?;
    let place = crate::report::Place {
        driver: "joint".into(),
        joint: Some(j + 1),
        sensor: None,
        side: "robot".into(),
        z,
        threshold: super::HELD_OUT_Z,
        range: None,
    };
    let why = format!(
        "joint_compliance on joint {} fitted negative (the joint moving against its gravity load, which an elastic joint never does) yet predicted the held-out readings better: a structure of another shape follows that joint's load or angle (a counterbalance, a play gravity takes up)",
        j + 1
    );
    Some(crate::physics::unexplained::unexplained_at(
        inputs.obs,
        &inputs.ctx,
        (&state.p, &state.accepted),
        place,
        format!(
            "no neighbour test located it, but a compliance of joint {} fitted the wrong way round predicted the held-out readings better (paired z = {z:.1})",
            j + 1
        ),
        vec![why],
    ))
}

/// A kept correction that says where the structure lives moves the
/// `unexplained` finding's place there, and its evidence says why: one
/// joint's angle by the clock (the time place takes the joint), one
/// string's reading over the workspace or its zero and scale by its
/// direction (the workspace place takes the string), one string's reading
/// by its last change (the move's place takes the string; `n_strings`
/// says whether the rig can tell its side).
fn placed_by_correction(
    finding: &mut Finding,
    kept: &[crate::physics::effects::Kind],
    n_strings: usize,
) {
    use crate::physics::effects::{CorrectionDriver, CorrectionTarget};
    let Some(FindingModel::Unexplained(u)) = &mut finding.parameters else {
        return;
    };
    // One string's reading as a field over the workspace says whose: the
    // workspace place takes the string.
    if let Some(s) = kept_index(
        kept,
        CorrectionTarget::StringReading,
        CorrectionDriver::Workspace,
    ) {
        for p in u
            .places
            .iter_mut()
            .filter(|p| p.driver == "workspace" && p.sensor.is_none())
        {
            p.sensor = Some(s + 1);
        }
    }
    // One string's reading by its last change of length says whose
    // motion: the move's place takes the string.
    if let Some(s) = kept_index(
        kept,
        CorrectionTarget::StringReading,
        CorrectionDriver::StringMove,
    ) {
        let mut moved = false;
        for p in u
            .places
            .iter_mut()
            .filter(|p| p.driver == "motion" && p.joint.is_none() && p.sensor.is_none())
        {
            p.sensor = Some(s + 1);
            // Three strings cannot tell a string's error from T's.
            p.side = if n_strings > 3 { "sensor" } else { "strings" }.into();
            moved = true;
        }
        // One place per string and driver: the strongest (they are
        // strongest first), where the string's own test placed it too.
        let mut seen = Vec::new();
        u.places.retain(|p| {
            let key = (p.driver.clone(), p.joint, p.sensor);
            let first = !seen.contains(&key);
            seen.push(key);
            first
        });
        if moved {
            finding.evidence = format!(
                "{}; it is string {}'s: a correction of that string's reading by its last change of length predicted the train poses best (cross-validated against T moved along its move and every other string's)",
                finding.evidence,
                s + 1
            );
        }
    }
    // One string's zero and scale by where it points says whose, whichever
    // string the place's own test pointed at (one string's error moves
    // the located point, so every string's residual follows it).
    if let Some(s) = kept_index(
        kept,
        CorrectionTarget::StringZeroScale,
        CorrectionDriver::StringDirection,
    ) {
        let mut moved = false;
        for p in u
            .places
            .iter_mut()
            .filter(|p| p.driver == "workspace" && p.sensor != Some(s + 1))
        {
            moved |= p.sensor.is_some();
            p.sensor = Some(s + 1);
        }
        if moved {
            finding.evidence = format!(
                "{}; it is string {}'s: a correction of that string's zero and scale by its direction predicted the train poses best (cross-validated against every other string's)",
                finding.evidence,
                s + 1
            );
        }
    }
    // The first such correction kept says where (one joint per place).
    let Some(t) = kept_index(kept, CorrectionTarget::JointAngle, CorrectionDriver::Time) else {
        return;
    };
    let mut placed = false;
    for p in u
        .places
        .iter_mut()
        .filter(|p| p.driver == "time" && p.sensor.is_none())
    {
        p.joint = Some(t + 1);
        placed = true;
    }
    if placed {
        finding.evidence = format!(
            "{}; in time it lives in joint {}'s angle: a correction of that joint's angle by the clock predicted the train poses best (cross-validated against T moved, each string's reading and every other joint's angle)",
            finding.evidence,
            t + 1
        );
    }
}

/// The target index (a joint or a string, 0-based) of the first kept
/// correction of `target` by `driver`.
fn kept_index(
    kept: &[crate::physics::effects::Kind],
    target: crate::physics::effects::CorrectionTarget,
    driver: crate::physics::effects::CorrectionDriver,
) -> Option<usize> {
    kept.iter().find_map(|k| match k {
        crate::physics::effects::Kind::DataDriven {
            target: t,
            target_index: Some(i),
            driver: d,
            ..
        } if *t == target && *d == driver => Some(*i),
        _ => None,
    })
}

/// Once a data-driven correction is in: the named effects it makes
/// redundant dropped ([`naming::prune`]), the whole model refit and every
/// finding restated from the refit.
fn pruned_and_restated(inputs: &Inputs, state: &mut State) {
    naming::prune(inputs, state);
    if let Some((p, accepted, fit)) = data_driven::linear_refit(inputs, state) {
        state.p = p;
        state.accepted = accepted;
        state.final_fit = Some(fit);
    }
    if let Some(fit) = &state.final_fit {
        restate(
            inputs.obs,
            &inputs.ctx,
            &state.p,
            &state.accepted,
            fit,
            &mut state.findings,
        );
    }
}

/// Later rounds refit the earlier effects: every finding reports its
/// effect as the final model (`p`, `accepted`, `fit`) has it (coefficients
/// for compensation, magnitude and sigma, evidence plot), not as the round
/// that kept it.
fn restate(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    accepted: &[EffectModel],
    fit: &FitInfo,
    findings: &mut [Finding],
) {
    for f in findings.iter_mut() {
        let Some(k) = f
            .effect_model()
            .and_then(|em| accepted.iter().position(|e| e.kind == em.kind))
        else {
            continue;
        };
        let e = &accepted[k];
        let at: usize = accepted[..k].iter().map(|e| e.kind.n_coef()).sum();
        let (mag, sig, _) = magnitude(ctx, obs, e, &fit.block(at, e.kind.n_coef()));
        f.magnitude = mag;
        f.sigma = sig;
        if let Some(FindingModel::Effect(fp)) = &mut f.parameters {
            fp.model.coef = e.coef.clone();
        }
        f.evidence_plot = evidence_plot(obs, ctx, p, accepted, k);
    }
}

/// Terms of one joint that cancel each other are a series fitted to an
/// angle error of another shape, not separate physics: say so in each of
/// that joint's findings.
fn doubt_cancelling_terms(
    obs: &Observations,
    ctx: &Context,
    accepted: &[EffectModel],
    findings: &mut [Finding],
) {
    for (j, largest_deg, net_deg, k) in cancelling_terms(obs, ctx, accepted) {
        let doubt = format!(
            "doubt: the {k} effects kept on joint {} largely cancel each other (each spreads the angle by up to {largest_deg:.4} deg over the train poses, together by {net_deg:.4} deg): together they describe an error of joint {}'s angle that none of them is alone; read them as one angle error of that joint, not as separate physics",
            j + 1,
            j + 1
        );
        // The terms of the joint's angle (not a link bending from it).
        for f in findings
            .iter_mut()
            .filter(|f| f.joint == Some(j + 1) && f.effect != "link_bending")
        {
            f.evidence = format!("{}; {doubt}", f.evidence);
        }
    }
}

/// Joints whose accepted effects (two or more) largely cancel each other
/// over the train poses: `(joint, largest effect's spread of dq, their
/// sum's spread (standard deviations, deg), number of effects)`.
fn cancelling_terms(
    obs: &Observations,
    ctx: &Context,
    accepted: &[EffectModel],
) -> Vec<(usize, f64, f64, usize)> {
    let n = ctx.n_joints;
    let mut buf = Basis::default();
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
