//! What the catalogue leaves: residual structure after the accepted
//! effects, located and reported as an `unexplained` finding rather than
//! forced onto a wrong name. The tests, each saying where the mismatch
//! lives: neighbouring poses (by a joint angle, also along the direction
//! that joint moves T; by time, temperature, the joint configuration; by a
//! string's length, direction or last move) that agree more than noise
//! allows ([`neighbours`](mod@neighbours), [`scalar`]); with four or more strings, a
//! robot-side residual above the strings' own noise, and a residual that
//! follows the move into each pose ([`robot_side`]); and a mismatch
//! confined to a stretch of one joint's range that the held-out poses
//! confirm ([`confined`]). [`located`](mod@located) says which of them holds.
//!
//! The layout: this file builds the finding; [`orderings`](mod@orderings) says which
//! poses neighbour which; [`nearest`] finds nearest poses.

mod confined;
mod located;
mod nearest;
mod neighbours;
mod orderings;
mod robot_side;
mod scalar;

pub(in crate::physics) use robot_side::robot_side_share;

use confined::{Concentrated, concentrated};
use located::{located, worst_region};
use neighbours::{Along, neighbours};
use orderings::{orderings, time_and_workspace_at};
use robot_side::{
    Excess, Motion, flange_components, joint_components, motion_test, robot_side_excess,
};
use scalar::{
    drive_tests, line_of_sight_test, load_change_tests, play_in_time_tests, string_tests,
};

use super::analyse::{errors_with_effects, reading_errors, rms};
use super::effects::{Context, EffectModel};
use super::problem::EffectProblem;
use crate::identify::Observations;
use crate::report::{Finding, FindingModel, Place, UnexplainedLocation};
use crate::stats::normal_quantile;

/// Residual structure left after the accepted effects: neighbouring poses
/// (sorted by each joint angle, by time, by temperature) whose residuals
/// agree more than independent noise allows; or, with more than three
/// strings, a robot-side residual larger than the strings' own noise
/// explains, whatever it follows (an error that flips direction between
/// neighbours, e.g. a joint error seen from both sides of its axis, defeats
/// the neighbour test but not this one); or, failing the neighbour test, a
/// mismatch confined to a few poses in one stretch of a joint's range
/// ([`concentrated`]). `n_free` is the number of geometric parameters
/// fitted.
pub(super) fn unexplained(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    effects: &[EffectModel],
    n_free: usize,
) -> Option<Finding> {
    let (res, rpp) = train_residuals(obs, ctx, p, effects);
    let pairings = orderings(obs, ctx);
    // The same joint orderings once more, on the part of each residual
    // along the direction that joint moves T: an error of the joint's own
    // angle, smooth in the angle (a harmonic the catalogue lacks, a gear
    // ratio, a local bump), moves T in opposite directions on the two sides
    // of the axis, so raw residuals of neighbours in that angle need not
    // agree while these components do.
    let along = joint_components(obs, ctx, p, &res, rpp);
    // And in time along the flange's axes: the tool point changing during
    // the session (a probe warming, a tool slipping in its holder) moves T
    // as the flange turns.
    let flange = flange_components(obs, ctx, &res, rpp);
    let with_temp = has_temperature(obs);
    let mut extra = string_tests(obs, ctx, &res, rpp);
    extra.extend(line_of_sight_test(obs, ctx, &res, rpp));
    extra.extend(drive_tests(obs, ctx, along.as_deref()));
    extra.extend(load_change_tests(obs, ctx, along.as_deref()));
    extra.extend(play_in_time_tests(obs, ctx, along.as_deref()));
    let nb = neighbours(
        ctx.n_joints,
        with_temp,
        obs.anchors.is_empty(),
        &pairings,
        along.as_deref(),
        flange.as_deref(),
        &extra,
        &res,
        rpp,
    );
    let n_params = n_free + effects.iter().map(|e| e.kind.n_coef()).sum::<usize>();
    let excess = robot_side_excess(obs, ctx, &res, rpp, n_params);
    let motion = motion_test(obs, ctx, &res, rpp, nb.zcrit).filter(|m| m.z > m.threshold);
    let confined = confined_stretch(obs, ctx, (p, effects), &res, rpp);
    let (winner, located) = located(
        &nb,
        excess,
        confined.as_ref(),
        motion.as_ref(),
        &pairings,
        &extra,
    )?;
    // A confined mismatch already says where it lives.
    let region = if confined.is_some() {
        String::new()
    } else {
        worst_region(ctx, &obs.train, &res, rpp)
    };
    let places = places(
        obs,
        ctx,
        &nb.places,
        confined.as_ref(),
        excess.as_ref(),
        motion.as_ref(),
    );
    // The evidence plot knows the plain orderings up to the configuration
    // (time and T's position together: the clock's).
    let plot_len = ctx.n_joints + 2 + usize::from(with_temp);
    let (ordering, z) = match winner {
        w if w < pairings.len() => (pairings[w].0.clone(), nb.zs[w]),
        w => (
            extra[w - pairings.len()].name.clone(),
            nb.best.as_ref().map_or(f64::NAN, |b| b.0),
        ),
    };
    let resembles = resemblances(&places);
    let parameters = UnexplainedLocation {
        ordering,
        along_joint_motion: nb.winner_at.is_some_and(|(_, on)| on == Along::Own),
        z,
        confined_joint: confined.as_ref().map(|c| c.joint + 1),
        confined_deg: confined
            .as_ref()
            .map(|c| [c.lo_rad.to_degrees(), c.hi_rad.to_degrees()]),
        confined_train_poses: confined.as_ref().map(|c| c.train_poses.clone()),
        confined_p: confined.as_ref().map(|c| c.p),
        robot_side_variance_ratio: excess.as_ref().map(|x| x.f),
        variance_ratio_threshold: excess.as_ref().map(|x| x.threshold),
        places,
        resembles,
    };
    let plot = super::evidence::unexplained_plot(
        obs,
        ctx,
        p,
        effects,
        if winner == time_and_workspace_at(ctx.n_joints, with_temp) {
            ctx.n_joints
        } else {
            winner.min(plot_len - 1)
        },
        &nb.zs[..plot_len],
    );
    let rms_res = (res.iter().map(|r| r * r).sum::<f64>() / res.len().max(1) as f64).sqrt();
    Some(finding(
        obs,
        ctx,
        (p, effects),
        rms_res,
        parameters,
        format!("{located}{region}"),
        plot,
    ))
}

/// A mismatch confined to a stretch of one joint's range
/// ([`concentrated`]), from each train pose's residual RMS (`res`, `rpp`
/// per pose) and each held-out pose's under the model `(p, effects)`.
fn confined_stretch(
    obs: &Observations,
    ctx: &Context,
    (p, effects): (&[f64], &[EffectModel]),
    res: &[f64],
    rpp: usize,
) -> Option<Concentrated> {
    let train: Vec<f64> = res
        .chunks(rpp)
        .map(|c| (c.iter().map(|v| v * v).sum::<f64>() / rpp as f64).sqrt())
        .collect();
    let test: Vec<f64> = reading_errors(obs, ctx, p, effects)
        .iter()
        .map(|&(ss, n)| (ss / n.max(1) as f64).sqrt())
        .collect();
    concentrated(obs, ctx, &train, &test, 1e-3)
}

/// An `unexplained` finding at one `place` that a shape test located
/// (not the neighbour tests): `evidence` says how, `resembles` which
/// catalogue effect was set aside and why. Its plot orders the poses by
/// the place's driver (time, temperature or a joint's angle).
pub(super) fn unexplained_at(
    obs: &Observations,
    ctx: &Context,
    (p, effects): (&[f64], &[EffectModel]),
    place: Place,
    evidence: String,
    resembles: Vec<String>,
) -> Finding {
    let (res, _) = train_residuals(obs, ctx, p, effects);
    let rms_res = (res.iter().map(|r| r * r).sum::<f64>() / res.len().max(1) as f64).sqrt();
    let nj = ctx.n_joints;
    let with_temp = has_temperature(obs);
    let winner = match (place.driver.as_str(), place.joint) {
        ("temperature", _) if with_temp => nj + 1,
        ("joint", Some(j)) if j >= 1 && j <= nj => j - 1,
        _ => nj,
    };
    let plot_z = vec![f64::NAN; nj + 2 + usize::from(with_temp)];
    let plot = super::evidence::unexplained_plot(obs, ctx, p, effects, winner, &plot_z);
    let parameters = UnexplainedLocation {
        ordering: place.driver.clone(),
        along_joint_motion: false,
        z: place.z,
        confined_joint: None,
        confined_deg: None,
        confined_train_poses: None,
        confined_p: None,
        robot_side_variance_ratio: None,
        variance_ratio_threshold: None,
        places: vec![place],
        resembles,
    };
    finding(obs, ctx, (p, effects), rms_res, parameters, evidence, plot)
}

/// The `unexplained` finding of the model `(p, effects)`: `rms_res` its
/// train residual RMS per reading, `parameters` where it lives.
fn finding(
    obs: &Observations,
    ctx: &Context,
    (p, effects): (&[f64], &[EffectModel]),
    rms_res: f64,
    parameters: UnexplainedLocation,
    evidence: String,
    evidence_plot: Option<crate::report::EvidencePlot>,
) -> Finding {
    let test = rms(&errors_with_effects(obs, ctx, p, effects, &obs.test));
    Finding {
        effect: "unexplained".into(),
        joint: None,
        sensor: None,
        magnitude: rms_res,
        sigma: f64::NAN, // no fitted parameter: no uncertainty (null)
        unit: "mm (train residual RMS per reading)".into(),
        explanation: "structure remains that no effect of the catalogue explains; it is reported rather than forced onto a wrong name".into(),
        evidence,
        test_rms_before_mm: test,
        test_rms_after_mm: test,
        parameters: Some(FindingModel::Unexplained(parameters)),
        evidence_plot,
    }
}

/// Every place the structure was located: a confined stretch of a joint's
/// range, the neighbour tests' places, the move that led to each pose,
/// and, when nothing else placed it, the robot-side excess.
fn places(
    obs: &Observations,
    ctx: &Context,
    located: &[Place],
    confined: Option<&Concentrated>,
    excess: Option<&Excess>,
    motion: Option<&Motion>,
) -> Vec<Place> {
    let mut places = located.to_vec();
    if let Some(m) = motion {
        places.push(Place {
            driver: "motion".into(),
            joint: None,
            sensor: None,
            side: if obs.anchors.is_empty() {
                "point"
            } else {
                "robot"
            }
            .into(),
            z: m.z,
            threshold: m.threshold,
            range: None,
        });
    }
    // A confined stretch first: the winner of `located` whenever it holds.
    if let Some(c) = confined {
        places.insert(
            0,
            Place {
                driver: "joint".into(),
                joint: Some(c.joint + 1),
                sensor: None,
                side: if obs.anchors.is_empty() {
                    "point"
                } else {
                    "strings"
                }
                .into(),
                z: normal_quantile(1.0 - c.p),
                threshold: normal_quantile(1.0 - c.alpha / ctx.n_joints.max(1) as f64),
                range: Some([c.lo_rad.to_degrees(), c.hi_rad.to_degrees()]),
            },
        );
    }
    if let Some(x) = excess.filter(|x| x.f > x.threshold && places.is_empty()) {
        places.push(Place {
            driver: "robot".into(),
            joint: None,
            sensor: None,
            side: "robot".into(),
            z: x.f,
            threshold: x.threshold,
            range: None,
        });
    }
    places
}

/// True when every pose recorded a temperature (then it is an ordering).
fn has_temperature(obs: &Observations) -> bool {
    obs.data.poses.iter().all(|p| p.temp_c.is_some())
}

/// The catalogue effects that act where the structure was located, and
/// why they do not explain it: the analysis tried each of them in its
/// rounds, and none passed its gates or, kept, left this structure.
fn resemblances(places: &[Place]) -> Vec<String> {
    let mut out = Vec::new();
    let mut say = |s: String| {
        if !out.contains(&s) {
            out.push(s);
        }
    };
    for p in places {
        match (p.driver.as_str(), p.joint, p.sensor) {
            ("joint", Some(j), _) => say(format!(
                "joint {j}: joint_periodic (1, 2 or 3 per revolution), joint_scale, joint_compliance and backlash act on its angle; each was tried and none explains this shape (a stretch, a harmonic the catalogue lacks, or an error driven by another joint)"
            )),
            ("time", _, Some(s)) => say(format!(
                "string {s} over time: sensor_drift (linear creep) and anchor_step (one move) were tried; the structure is neither"
            )),
            ("string", _, Some(s)) => say(format!(
                "string {s} by its length: sensor_scale (proportional) and sensor_offset (constant) were tried; the structure is neither"
            )),
            ("time", Some(j), None) => say(format!(
                "joint {j} over time: no catalogue effect changes a joint's zero during the session; rig_step and rig_drift (the rig moving) were tried and move T alike at every pose, where a joint's zero moves it as the pose turns that joint's axis"
            )),
            ("time", _, None) => say(
                "time: rig_step (one move), rig_drift (linear creep) and thermal_expansion (warm-up) were tried; the structure is none of them".into(),
            ),
            ("temperature", _, _) => say(
                "temperature: thermal_expansion (every length in proportion) was tried; the structure is not a uniform growth".into(),
            ),
            ("motion", _, Some(s)) => say(format!(
                "string {s}'s last change of length: no catalogue effect depends on the way a string last moved; friction in its drum or stretch of its cable (reading differently pulled out than retracted) would"
            )),
            ("motion", Some(j), _) => say(format!(
                "joint {j}'s last move: backlash (a fixed amount by the side the joint itself arrived from) was tried; the error follows the way the joint last moved in another form: graded with the move's size (friction or elastic wind-up in the drive), by the side a drive turning two joints last turned (a parallelogram's rod or belt, a coupled wrist), or by the change of its gravity load over the move (a drive that creeps or winds up under load: a harmonic drive's flexspline relaxing during the dwell), or by the side it arrived from with a play that changes during the session (grease thinning as the drive warms, wear)"
            )),
            ("motion", _, _) => say(
                "the move that led to each pose: no catalogue effect depends on it (backlash depends only on the side a joint arrived from); an arm not settled at the dwell (overshoot or lag), a servo's following error or a tool still swinging would".into(),
            ),
            ("workspace", _, Some(s)) => say(format!(
                "string {s} by its direction: cable_sag (a function of the string's horizontal span) and sensor_scale were tried; no catalogue effect depends on the angle at which a string leaves its anchor, which friction or wrap at its exit, eyelet or pulley would"
            )),
            ("workspace", _, _) => say(
                "the workspace: no catalogue effect is a field over the workspace; a distortion of the measuring device or a compliance of the stand or base would be".into(),
            ),
            ("configuration", _, _) => say(
                "the configuration: no catalogue effect is a function of the whole pose (where T is and how the flange faces the instrument); a distortion of the measuring device, a compliance of the stand or base, or a target read off its centre by an amount that turns with it would be".into(),
            ),
            _ => {}
        }
    }
    out
}

/// The train poses' residuals with the accepted effects, pose after pose,
/// and the rows per pose (one per string, or a point's three coordinates):
/// every test of [`unexplained`] reads them a pose at a time.
fn train_residuals(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    effects: &[EffectModel],
) -> (Vec<f64>, usize) {
    let problem =
        EffectProblem::of_observations(obs, ctx, obs.train.clone(), p, vec![], effects.to_vec());
    let x = problem.x0();
    let rpp = problem.rows_per_pose();
    let mut res = vec![0.0; obs.train.len() * rpp];
    let mut at = 0;
    problem.residuals(&x, |_, r| {
        res[at] = r;
        at += 1;
    });
    (res, rpp)
}
