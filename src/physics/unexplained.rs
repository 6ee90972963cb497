//! What the catalogue leaves: residual structure after the accepted
//! effects, located and reported as an `unexplained` finding rather than
//! forced onto a wrong name. Four tests, each saying where the mismatch
//! lives: neighbouring poses (by a joint angle, also along the direction
//! that joint moves T; by time, temperature, the joint configuration) that
//! agree more than noise allows; with four or more strings, a robot-side
//! residual above the strings' own noise; and a mismatch confined to a
//! stretch of one joint's range that the held-out poses confirm.

use nalgebra::Vector3;

use super::analyse::{errors_with_effects, reading_errors, rms};
use super::effects::{Context, CorrectionDriver, EffectModel};
use super::periodogram;
use super::problem::EffectProblem;
use crate::identify::Observations;
use crate::report::{Finding, FindingModel, Place, UnexplainedLocation};
use crate::stats::{f_quantile_upper, normal_quantile, normal_upper_tail};

/// The part of one pose's string residuals `r` (one per anchor, mm) that a
/// displacement of T explains: least squares through the anchors' unit
/// vectors at `t` (rig frame). The displacement (mm) and the residual
/// energy it takes (`rᵀG(GᵀG)⁻¹Gᵀr`, mm²); `None` when the anchors do not
/// fix a point.
fn common_displacement(
    anchors: &[Vector3<f64>],
    t: &Vector3<f64>,
    r: &[f64],
) -> Option<(Vector3<f64>, f64)> {
    let mut gtg = nalgebra::Matrix3::zeros();
    let mut gtr = Vector3::zeros();
    for (a, &rk) in anchors.iter().zip(r) {
        let u = (t - a).normalize();
        gtg += u * u.transpose();
        gtr += u * rk;
    }
    let d = gtg.try_inverse()? * gtr;
    Some((d, gtr.dot(&d)))
}

/// Share of the train string residual energy that a displacement of T per
/// pose explains, and the share noise alone would give (3/m).
pub(super) fn robot_side_share(obs: &Observations, p: &[f64]) -> (Option<f64>, Option<f64>) {
    let m = obs.anchors.len();
    if m <= 3 {
        return (None, None);
    }
    let problem = obs.problem(p.to_vec(), vec![]);
    let mut r = Vec::new();
    let (mut robot, mut total) = (0.0, 0.0);
    for &i in &obs.train {
        let pose = &obs.data.poses[i];
        problem.pose_residuals(p, pose, &mut r);
        let (_, t) = obs
            .chain
            .point(p, &pose.q_rad, crate::kinematics::chain::OutputFrame::Rig);
        if let Some((_, energy)) = common_displacement(&obs.anchors, &t, &r) {
            robot += energy;
        }
        total += r.iter().map(|v| v * v).sum::<f64>();
    }
    if total <= 0.0 {
        return (None, None);
    }
    (Some(robot / total), Some(3.0 / m as f64))
}

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
    let confined = {
        let train: Vec<f64> = res
            .chunks(rpp)
            .map(|c| (c.iter().map(|v| v * v).sum::<f64>() / rpp as f64).sqrt())
            .collect();
        let test: Vec<f64> = reading_errors(obs, ctx, p, effects)
            .iter()
            .map(|&(ss, n)| (ss / n.max(1) as f64).sqrt())
            .collect();
        concentrated(obs, ctx, &train, &test, 1e-3)
    };
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
    // The evidence plot knows the plain orderings up to the configuration.
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
        winner.min(plot_len - 1),
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
                "joint {j}'s last move: backlash (a fixed amount by the side the joint itself arrived from) was tried; the error follows the way the joint last moved in another form: graded with the move's size (friction or elastic wind-up in the drive), by the side a drive turning two joints last turned (a parallelogram's rod or belt, a coupled wrist), or by the change of its gravity load over the move (a drive that creeps or winds up under load: a harmonic drive's flexspline relaxing during the dwell)"
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

/// The orderings whose neighbours are compared, each a name and its pairs
/// of train poses (positions in `obs.train`): by each joint angle, by time,
/// by temperature when every pose has one, and last each pose with its
/// nearest neighbour in joint space (the layout [`unexplained_plot`]
/// reads).
///
/// [`unexplained_plot`]: super::evidence::unexplained_plot
fn orderings(obs: &Observations, ctx: &Context) -> Vec<(String, Vec<(usize, usize)>)> {
    let n = ctx.n_joints;
    let mut keys: Vec<(String, Vec<f64>)> = (0..n)
        .map(|j| {
            (
                format!("joint {} angle", j + 1),
                obs.train.iter().map(|&i| ctx.poses[i].q_rad[j]).collect(),
            )
        })
        .collect();
    keys.push((
        "time (visiting order)".into(),
        obs.train.iter().map(|&i| ctx.poses[i].time_s).collect(),
    ));
    if has_temperature(obs) {
        keys.push((
            "temperature".into(),
            obs.train
                .iter()
                .map(|&i| obs.data.poses[i].temp_c.unwrap_or(0.0))
                .collect(),
        ));
    }
    // Neighbour pairs per ordering: sorted by one key, and each pose with
    // its nearest neighbour in joint space (the workspace). Poses close in
    // time are usually close in the workspace too (a tour, a raster), so
    // time only wins where it beats the configuration itself.
    let mut pairings: Vec<(String, Vec<(usize, usize)>)> = keys
        .iter()
        .map(|(name, key)| {
            let mut order: Vec<usize> = (0..key.len()).collect();
            order.sort_by(|a, b| key[*a].total_cmp(&key[*b]));
            // Each pose with the next two: a smooth function of the key
            // agrees over both, and the products of pairs that share a
            // pose are still uncorrelated under independent noise.
            let pairs = order
                .windows(2)
                .map(|w| (w[0], w[1]))
                .chain(order.windows(3).map(|w| (w[0], w[2])))
                .collect();
            (name.clone(), pairs)
        })
        .collect();
    pairings.push((
        "the joint configuration (nearest pose in joint space)".into(),
        nearest_in_joint_space(ctx, &obs.train),
    ));
    // Last, T's position: a field over the workspace (a distortion of the
    // measuring device, a compliance of the stand) follows where T is,
    // whatever the joints do to put it there.
    pairings.push((
        "T's position (nearest pose in the workspace)".into(),
        nearest_in_workspace(ctx, &obs.train),
    ));
    pairings
}

/// What the plain ordering `pk` of [`orderings`] follows, as a place's
/// driver and joint (1-based). The layout: one per joint, time,
/// temperature when recorded (`with_temp`), the configuration, T's
/// position.
fn driver_of(pk: usize, n: usize, with_temp: bool) -> (&'static str, Option<usize>) {
    let t = usize::from(with_temp);
    match pk {
        j if j < n => ("joint", Some(j + 1)),
        j if j == n => ("time", None),
        j if with_temp && j == n + 1 => ("temperature", None),
        j if j == n + 1 + t => ("configuration", None),
        _ => ("workspace", None),
    }
}

/// A neighbour test on one number per train pose rather than the whole
/// residual: the sensor-side part of one string's residual, along its
/// length, its direction or the clock; or, with point data, the residual
/// along the instrument's line of sight.
struct ScalarTest {
    name: String,
    /// The string (1-based) whose part it tests, if a string's.
    sensor: Option<usize>,
    /// The joint (1-based) whose part it tests, if a joint's, and what an
    /// agreement there would mean.
    joint: Option<(usize, &'static str)>,
    driver: &'static str,
    /// The side the place is on: "sensor" (the string's own part),
    /// "strings" (three strings: either side), "point" (point data) or
    /// "robot" (a joint's part).
    side: &'static str,
    test: ScalarTestKind,
    values: Vec<f64>,
}

/// How a [`ScalarTest`] looks for structure.
enum ScalarTestKind {
    /// Do the values of these neighbouring train poses agree?
    Neighbours(Vec<(usize, usize)>),
    /// Is there a sinusoid in the values as a function of the driver (see
    /// [`periodogram::strongest_period`])? Its z, computed once.
    Periodic(Option<f64>),
}

/// Per string, with the train poses ordered by the string's length and
/// by time: with four or more strings, the part of its residual no
/// displacement of T explains (its sensor side); with three, its whole
/// residual (three strings fix the point and nothing is left to tell a
/// string's error from T's displacement along it, so the place is the
/// string's, its side undecided). A string that reads wrong by a function
/// of its length (a drum's pitch, a worn spool) or of the clock shows here,
/// not in the robot-side tests.
fn string_tests(obs: &Observations, ctx: &Context, res: &[f64], rpp: usize) -> Vec<ScalarTest> {
    let m = obs.anchors.len();
    if m < 3 || rpp != m {
        return vec![];
    }
    let redundant = m > 3;
    let mut own = vec![Vec::with_capacity(obs.train.len()); m];
    for (pos, &i) in obs.train.iter().enumerate() {
        let r = &res[pos * rpp..(pos + 1) * rpp];
        let t = &ctx.poses[i].point_rig;
        let d = if redundant {
            common_displacement(&obs.anchors, t, r).map_or(Vector3::zeros(), |(d, _)| d)
        } else {
            Vector3::zeros()
        };
        for (k, a) in obs.anchors.iter().enumerate() {
            own[k].push(r[k] - (t - a).normalize().dot(&d));
        }
    }
    let (part, side) = if redundant {
        ("its own part of the residual", "sensor")
    } else {
        ("its residual", "strings")
    };
    let sorted_pairs = |key: &dyn Fn(usize) -> f64| -> Vec<(usize, usize)> {
        let mut order: Vec<usize> = (0..obs.train.len()).collect();
        order.sort_by(|a, b| key(*a).total_cmp(&key(*b)));
        order.windows(2).map(|w| (w[0], w[1])).collect()
    };
    let by_time = sorted_pairs(&|a| ctx.poses[obs.train[a]].time_s);
    let mut out = Vec::new();
    for (k, values) in own.into_iter().enumerate() {
        let sensor = Some(k + 1);
        let length = |a: usize| (ctx.poses[obs.train[a]].point_rig - obs.anchors[k]).norm();
        out.push(ScalarTest {
            name: format!("string {}'s length ({part})", k + 1),
            sensor,
            joint: None,
            driver: "string",
            side,
            test: ScalarTestKind::Neighbours(sorted_pairs(&length)),
            values: values.clone(),
        });
        // A periodic error of short cycles in the length, which neighbours
        // in the length miss (see `periodogram`).
        let lengths: Vec<f64> = (0..obs.train.len()).map(length).collect();
        if let Some((period, p)) = periodogram::strongest_period(&lengths, &values) {
            out.push(ScalarTest {
                name: format!(
                    "string {}'s length, periodically (period near {period:.1} mm; {part})",
                    k + 1
                ),
                sensor,
                joint: None,
                driver: "string",
                side,
                test: ScalarTestKind::Periodic(Some(-normal_quantile(p.clamp(1e-300, 0.5)))),
                values: values.clone(),
            });
        }
        // By the string's direction (where T is as seen from its anchor):
        // a string whose exit, eyelet or pulley adds friction or wrap as
        // the string swings.
        let dir = |a: usize| (ctx.poses[obs.train[a]].point_rig - obs.anchors[k]).normalize();
        out.push(ScalarTest {
            name: format!("string {}'s direction ({part})", k + 1),
            sensor,
            joint: None,
            driver: "workspace",
            side,
            test: ScalarTestKind::Neighbours(nearest_pairs(
                obs.train.len(),
                3,
                |a, c| dir(a)[c],
                |a, b| (dir(a) - dir(b)).norm_squared(),
            )),
            values: values.clone(),
        });
        // By its last change of length, signed: a string that reads
        // differently pulled out than retracted (friction in its drum,
        // stretch of its cable).
        let change = |a: usize| {
            ctx.driver_value(
                &ctx.poses[obs.train[a]],
                CorrectionDriver::StringMove,
                Some(k),
                None,
            )
        };
        out.push(ScalarTest {
            name: format!("string {}'s last change of length ({part})", k + 1),
            sensor,
            joint: None,
            driver: "motion",
            side,
            test: ScalarTestKind::Neighbours(sorted_pairs(&change)),
            values: values.clone(),
        });
        out.push(ScalarTest {
            name: format!("time (string {}'s {})", k + 1, &part[4..]),
            sensor,
            joint: None,
            driver: "time",
            side,
            test: ScalarTestKind::Neighbours(by_time.clone()),
            values,
        });
    }
    out
}

/// Point data: each train pose's residual along the instrument's line of
/// sight (its range error), with the poses paired by the line of sight's
/// direction in the flange frame (nearest pose): a target read off its
/// centre by an amount that turns with the target (a reflector's vertex
/// off its sphere's centre, a photogrammetric target's centroid shifting
/// with the angle it is seen at) makes the range error a function of that
/// direction, which neither the joint angles' nor T's neighbours share.
fn line_of_sight_test(
    obs: &Observations,
    ctx: &Context,
    res: &[f64],
    rpp: usize,
) -> Option<ScalarTest> {
    if !obs.anchors.is_empty() || rpp != 3 {
        return None;
    }
    // The correction's own driver, so that the test and the correction
    // see the same direction.
    let sight = |a: usize| {
        let pc = &ctx.poses[obs.train[a]];
        Vector3::from_fn(|c, _| ctx.driver_value(pc, CorrectionDriver::LineOfSight, Some(c), None))
    };
    let values = (0..obs.train.len())
        .map(|a| {
            let r = Vector3::new(res[a * 3], res[a * 3 + 1], res[a * 3 + 2]);
            r.dot(&ctx.poses[obs.train[a]].point_rig.normalize())
        })
        .collect();
    Some(ScalarTest {
        name: "the line of sight in the flange frame (nearest pose; the residual along it)".into(),
        sensor: None,
        joint: None,
        driver: "configuration",
        side: "point",
        test: ScalarTestKind::Neighbours(nearest_pairs(
            obs.train.len(),
            3,
            |a, c| sight(a)[c],
            |a, b| (sight(a) - sight(b)).norm_squared(),
        )),
        values,
    })
}

/// Per pair of neighbouring joints and each of the two: that joint's
/// component of the residual (along the direction it moves T), with the
/// train poses ordered round the direction of the two joints' last move
/// (the angle of `(Δq_i, Δq_(i+1))`, neighbours round the circle). A drive
/// that turns both joints (a parallelogram's rod or belt driving the elbow
/// from the turret, a coupled wrist) leaves its play or friction by the
/// side its motor last turned: the sign of a combination of the two moves,
/// the same for poses whose moves point alike, whatever the joints' own
/// signs say. A joint's own backlash, which the catalogue names first, is
/// such a function too; what stays after it is not.
fn drive_tests(obs: &Observations, ctx: &Context, along: Option<&[Vec<f64>]>) -> Vec<ScalarTest> {
    let Some(along) = along else {
        return vec![];
    };
    let n = ctx.n_joints;
    let mut out = Vec::new();
    for i in 0..n.saturating_sub(1) {
        let order = train_order(obs, ctx, CorrectionDriver::MoveDirection, i);
        let mut pairs: Vec<(usize, usize)> = order.windows(2).map(|w| (w[0], w[1])).collect();
        // Round the circle: the last joins the first (with three or more).
        if order.len() > 2 {
            pairs.push((order[order.len() - 1], order[0]));
        }
        for j in [i, i + 1] {
            out.push(ScalarTest {
                name: format!(
                    "the direction of the last move of joints {} and {}",
                    i + 1,
                    i + 2
                ),
                sensor: None,
                joint: Some((j + 1, DRIVE_PLAY)),
                driver: "motion",
                side: "robot",
                test: ScalarTestKind::Neighbours(pairs.clone()),
                values: along[j].clone(),
            });
        }
    }
    out
}

/// With link masses, per joint: its component of the residual with the
/// train poses ordered by the change of its gravity torque over the last
/// move. A drive that creeps or winds up under load (a harmonic drive's
/// flexspline relaxing during the dwell, friction holding part of an
/// elastic deflection) lags that change, where a compliance, which the
/// catalogue names first, follows the load itself.
fn load_change_tests(
    obs: &Observations,
    ctx: &Context,
    along: Option<&[Vec<f64>]>,
) -> Vec<ScalarTest> {
    let Some(along) = along.filter(|_| ctx.has_masses) else {
        return vec![];
    };
    (0..ctx.n_joints)
        .map(|j| {
            let order = train_order(obs, ctx, CorrectionDriver::GravityTorqueChange, j);
            ScalarTest {
                name: format!(
                    "the change of joint {}'s gravity torque over the last move",
                    j + 1
                ),
                sensor: None,
                joint: Some((j + 1, LOAD_LAG)),
                driver: "motion",
                side: "robot",
                test: ScalarTestKind::Neighbours(order.windows(2).map(|w| (w[0], w[1])).collect()),
                values: along[j].clone(),
            }
        })
        .collect()
}

/// What a joint's agreement by its and a neighbour's move direction means.
const DRIVE_PLAY: &str = "follows the way it and its neighbour last moved, not only the side it arrived from (a drive turning both joints with play or friction: a parallelogram's rod or belt, a coupled wrist)";
/// What a joint's agreement by the change of its load means.
const LOAD_LAG: &str = "follows the change of its gravity load over the last move, where a compliance follows the load itself (a drive that creeps or winds up under load: a harmonic drive's flexspline relaxing during the dwell)";

/// The train poses (positions in `obs.train`) sorted by the value of a
/// correction's `driver` (with `index`), as the correction sees it.
fn train_order(
    obs: &Observations,
    ctx: &Context,
    driver: CorrectionDriver,
    index: usize,
) -> Vec<usize> {
    let v: Vec<f64> = obs
        .train
        .iter()
        .map(|&k| ctx.driver_value(&ctx.poses[k], driver, Some(index), None))
        .collect();
    let mut order: Vec<usize> = (0..v.len()).collect();
    order.sort_by(|a, b| v[*a].total_cmp(&v[*b]));
    order
}

impl ScalarTest {
    /// Where it located the remainder, in words: the test `name`, its `z`
    /// and the threshold `zcrit`.
    fn sentence(&self, name: &str, z: f64, zcrit: f64) -> String {
        let three = self.side == "strings";
        if let Some((j, means)) = self.joint {
            return format!(
                "joint {j}'s part of the residual (along the direction it moves T) agrees between poses neighbouring by {name} more than independent noise allows (z = {z:.1}, threshold {zcrit:.1}): joint {j}'s angle is off by an amount that {means}, in a form no catalogue effect has"
            );
        }
        let (whose, reads) = if self.sensor.is_none() {
            (
                "the residual along the instrument's line of sight",
                "the range is read wrong, or T is displaced along the line of sight,",
            )
        } else if three {
            (
                "one string's residuals",
                "that string reads wrong, or T is displaced along it,",
            )
        } else {
            (
                "the part of the string residuals no displacement of T explains",
                "that string reads wrong",
            )
        };
        let (agree, varies) = match (&self.test, three) {
            (ScalarTestKind::Neighbours(_), true) => (
                "agree between neighbouring poses by",
                "varies smoothly with it",
            ),
            (ScalarTestKind::Neighbours(_), false) => (
                "agrees between neighbouring poses by",
                "varies smoothly with it",
            ),
            (ScalarTestKind::Periodic(_), true) => (
                "follow a sinusoid in",
                "is periodic in its length (a drum's winding pitch or a spool's eccentricity would look so)",
            ),
            (ScalarTestKind::Periodic(_), false) => (
                "follows a sinusoid in",
                "is periodic in its length (a drum's winding pitch or a spool's eccentricity would look so)",
            ),
        };
        let apart = if three {
            " (three strings cannot tell the two apart)"
        } else {
            ""
        };
        format!(
            "{whose} {agree} {name} more than independent noise allows (z = {z:.1}, threshold {zcrit:.1}): {reads} by an amount that {varies}, in a form no catalogue effect has{apart}"
        )
    }
}

impl Concentrated {
    /// Where the mismatch is confined, in words.
    fn sentence(&self) -> String {
        format!(
            "the train poses far off the rest ({ids}: misfit over {FAR_OFF_MEDIANS} times the median) lie with joint {j} between {lo:.0} and {hi:.0} deg, and the {m} held-out poses there confirm it (misfit RMS {a:.3} mm per reading, against {b:.3} elsewhere; Wilcoxon rank-sum p = {p:.1e}, threshold {t:.1e}): the mismatch is confined to that stretch of joint {j}'s range, in a form no catalogue effect has",
            ids = self.train_poses.join(", "),
            j = self.joint + 1,
            lo = self.lo_rad.to_degrees(),
            hi = self.hi_rad.to_degrees(),
            m = self.n_test_in,
            a = self.test_rms_in,
            b = self.test_rms_out,
            p = self.p,
            t = self.alpha,
        )
    }
}

/// What a neighbour test of an ordering compared between neighbours.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Along {
    /// The residuals themselves.
    Raw,
    /// For a joint's ordering, their components along the direction that
    /// joint moves T: an error of its own angle.
    Own,
    /// For a joint's ordering, their components along the directions every
    /// other joint moves T: another joint's angle error driven by this
    /// joint's angle (a cable or harness pulling, coupled drives).
    Others,
    /// For the clock's ordering, their components along the direction
    /// joint `.0` (0-based) moves T: that joint's zero changing during the
    /// session (a re-homing, a lost encoder count, a drive warming), whose
    /// displacement of T turns with the pose, so raw residuals of poses
    /// neighbouring in time need not agree while these components do.
    JointInTime(usize),
    /// For the clock's ordering, their components along the flange's axis
    /// `.0` (0 = x, 1 = y, 2 = z): the tool point changing during the
    /// session, whose displacement of T turns with the flange.
    FlangeInTime(usize),
}

/// What the neighbour test found over every ordering (see [`neighbours`]).
struct Neighbours {
    /// The z the agreement of neighbours must pass (Bonferroni over the
    /// orderings tested).
    zcrit: f64,
    /// The strongest agreement past `zcrit`: its z and what it ran along.
    best: Option<(f64, String)>,
    /// Per ordering of the pairings (the plot's layout), the larger of the
    /// raw and the along-the-joint z for the joints (NaN: none).
    zs: Vec<f64>,
    /// The winning test: an ordering of the pairings and what it ran on,
    /// or (index at or past the pairings) a string's own test,
    /// `pairings.len() + k` for `extra[k]`.
    winner_at: Option<(usize, Along)>,
    /// Every test past `zcrit`, strongest first.
    places: Vec<Place>,
}

/// Do neighbours agree more than independent noise allows? Per ordering,
/// the z of the summed products of neighbouring residuals `res` (`rpp`
/// per pose), and for the first `n` orderings (the joints) also of their
/// components `along` the direction the joint moves T; then each string's
/// own test of `extra`. Every z is kept for the plot; every one past the
/// threshold is a place, and the largest locates the mismatch.
fn neighbours(
    n: usize,
    with_temp: bool,
    point_data: bool,
    pairings: &[(String, Vec<(usize, usize)>)],
    along: Option<&[Vec<f64>]>,
    flange: Option<&[Vec<f64>]>,
    extra: &[ScalarTest],
    res: &[f64],
    rpp: usize,
) -> Neighbours {
    let n_plain = pairings.len();
    // Two statistics per test, Bonferroni over both: the products' sum
    // over its own scale, and their signs. The sum is the stronger where
    // the mismatch spreads over every pose; a few poses far off carry it
    // and its scale alike, so where the mismatch lives in a few (a field
    // growing towards the workspace's edge) the signs are stronger. Both
    // are sums of terms uncorrelated under independent symmetric noise,
    // also where pairs share a pose.
    let n_tests = 2
        * (n_plain
            + along.as_ref().map_or(0, |_| 3 * n)
            + flange.as_ref().map_or(0, |f| f.len())
            + extra.len());
    let alpha = 1e-3 / n_tests as f64;
    let zcrit = normal_quantile(1.0 - alpha);
    let mut best: Option<(f64, String)> = None;
    let mut zs = vec![f64::NAN; n_plain];
    let mut winner_at: Option<(usize, Along)> = None;
    let mut places: Vec<Place> = Vec::new();
    let place = |driver: &str, joint, sensor, side: &str, z| Place {
        driver: driver.into(),
        joint,
        sensor,
        side: side.into(),
        z,
        threshold: zcrit,
        range: None,
    };
    let whole = if point_data { "point" } else { "strings" };
    for (pk, (name, pairs)) in pairings.iter().enumerate() {
        let tries = ordering_tries(pk, n, pairs, along, flange, res, rpp);
        let (driver, joint) = driver_of(pk, n, with_temp);
        let mut strongest: Option<Place> = None;
        for (z, on) in tries {
            let Some(z) = z else { continue };
            // (NaN, not yet set, is replaced.)
            if zs[pk].is_nan() || z > zs[pk] {
                zs[pk] = z;
            }
            if z > zcrit {
                let side = if on == Along::Raw { whole } else { "robot" };
                let joint = match on {
                    Along::JointInTime(b) => Some(b + 1),
                    _ => joint,
                };
                if strongest.as_ref().is_none_or(|p| z > p.z) {
                    strongest = Some(place(driver, joint, None, side, z));
                }
            }
            if z > zcrit && best.as_ref().is_none_or(|b| z > b.0) {
                best = Some((z, on.label(name, pk)));
                winner_at = Some((pk, on));
            }
        }
        places.extend(strongest);
    }
    for (k, t) in extra.iter().enumerate() {
        let v = &t.values;
        let z = match &t.test {
            ScalarTestKind::Neighbours(pairs) => agreement_z(pairs, &|i, j| v[i] * v[j]),
            ScalarTestKind::Periodic(z) => *z,
        };
        let Some(z) = z else {
            continue;
        };
        if z > zcrit {
            // One place per string or joint (or none) and driver: its
            // strongest test.
            match places.iter_mut().find(|p| {
                p.driver == t.driver && p.sensor == t.sensor && p.joint == t.joint.map(|j| j.0)
            }) {
                Some(p) => p.z = p.z.max(z),
                None => places.push(place(t.driver, t.joint.map(|j| j.0), t.sensor, t.side, z)),
            }
            if best.as_ref().is_none_or(|b| z > b.0) {
                best = Some((z, t.name.clone()));
                winner_at = Some((n_plain + k, Along::Raw));
            }
        }
    }
    places.sort_by(|a, b| b.z.total_cmp(&a.z));
    Neighbours {
        zcrit,
        best,
        zs,
        winner_at,
        places,
    }
}

/// How much more neighbours agree than independent noise allows: per pair
/// the product `d` of their residuals, summed over its own scale, or
/// their signs counted, whichever is the larger z.
fn agreement_z(pairs: &[(usize, usize)], d: &dyn Fn(usize, usize) -> f64) -> Option<f64> {
    let (mut s, mut v, mut signs, mut n) = (0.0, 0.0, 0.0, 0usize);
    for &(i, k) in pairs {
        let x = d(i, k);
        s += x;
        v += x * x;
        if x != 0.0 {
            signs += x.signum();
            n += 1;
        }
    }
    (v > 0.0).then(|| (s / v.sqrt()).max(signs / (n as f64).sqrt()))
}

/// The z of each way ordering `pk`'s neighbour `pairs` are compared: the
/// raw residuals; for a joint's ordering (`pk < n`) their components along
/// that joint's and along the other joints' directions (`along`); for the
/// clock's (`pk == n`) along each joint's direction and the flange's axes.
fn ordering_tries(
    pk: usize,
    n: usize,
    pairs: &[(usize, usize)],
    along: Option<&[Vec<f64>]>,
    flange: Option<&[Vec<f64>]>,
    res: &[f64],
    rpp: usize,
) -> Vec<(Option<f64>, Along)> {
    let raw = |i: usize, k: usize| (0..rpp).map(|c| res[i * rpp + c] * res[k * rpp + c]).sum();
    let mut tries = vec![(agreement_z(pairs, &raw), Along::Raw)];
    if let (Some(a), true) = (along, pk < n) {
        let own = |i: usize, k: usize| a[pk][i] * a[pk][k];
        tries.push((agreement_z(pairs, &own), Along::Own));
        let others =
            |i: usize, k: usize| (0..n).filter(|&b| b != pk).map(|b| a[b][i] * a[b][k]).sum();
        tries.push((agreement_z(pairs, &others), Along::Others));
    }
    if let (Some(a), true) = (along, pk == n) {
        for (b, ab) in a.iter().enumerate() {
            let by_joint = |i: usize, k: usize| ab[i] * ab[k];
            tries.push((agreement_z(pairs, &by_joint), Along::JointInTime(b)));
        }
    }
    if let (Some(f), true) = (flange, pk == n) {
        for (c, fc) in f.iter().enumerate() {
            let by_axis = |i: usize, k: usize| fc[i] * fc[k];
            tries.push((agreement_z(pairs, &by_axis), Along::FlangeInTime(c)));
        }
    }
    tries
}

impl Along {
    /// The test in words: the ordering's `name` (ordering `pk`) and what
    /// was compared along it.
    fn label(self, name: &str, pk: usize) -> String {
        match self {
            Along::Raw => name.to_string(),
            Along::Own => format!("{name}, along the direction joint {} moves T", pk + 1),
            Along::Others => format!("{name}, along the directions the other joints move T"),
            Along::JointInTime(b) => {
                format!("{name}, along the direction joint {} moves T", b + 1)
            }
            Along::FlangeInTime(c) => format!("{name}, along the flange's {} axis", AXES[c]),
        }
    }
}

/// Which test located the remainder, first that holds of: neighbours that
/// agree (raw, then along a joint's motion), a confined mismatch, a
/// robot-side excess; the ordering its plot runs along and the sentence
/// saying where it lives. `None`: no structure is left.
fn located(
    nb: &Neighbours,
    excess: Option<Excess>,
    confined: Option<&Concentrated>,
    motion: Option<&Motion>,
    pairings: &[(String, Vec<(usize, usize)>)],
    extra: &[ScalarTest],
) -> Option<(usize, String)> {
    // The ordering that comes nearest, for the plot of a structure no
    // ordering placed.
    let nearest = || {
        nb.zs
            .iter()
            .enumerate()
            .filter(|(_, z)| z.is_finite())
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map_or((0, f64::NAN), |(w, z)| (w, *z))
    };
    let zcrit = nb.zcrit;
    Some(match (&nb.best, excess, nb.winner_at) {
        // A confined mismatch is the most specific place: the poses far
        // off the rest also pull the geometry, and what that leaves
        // elsewhere can agree between neighbours.
        _ if confined.is_some() => {
            let c = confined.expect("checked");
            (c.joint, c.sentence())
        }
        (Some((z, name)), _, Some((pk, Along::Raw))) if pk >= pairings.len() => {
            (pk, extra[pk - pairings.len()].sentence(name, *z, zcrit))
        }
        (Some((z, name)), _, Some((pk, Along::Raw))) => (
            pk,
            format!(
                "residuals of neighbouring poses by {name} agree more than independent noise allows (z = {z:.1}, threshold {zcrit:.1}): the mismatch varies smoothly with {name}"
            ),
        ),
        (Some((z, _)), _, Some((pk, Along::Own))) => (
            pk,
            format!(
                "along the direction joint {j} moves T, the residuals of poses neighbouring in joint {j}'s angle agree more than independent noise allows (z = {z:.1}, threshold {zcrit:.1}): the mismatch behaves like an error of joint {j}'s own angle that varies smoothly with the angle, in a form no catalogue effect has",
                j = pk + 1
            ),
        ),
        (Some((z, _)), _, Some((pk, Along::JointInTime(b)))) => (
            pk,
            format!(
                "along the direction joint {j} moves T, the residuals of poses neighbouring in time agree more than independent noise allows (z = {z:.1}, threshold {zcrit:.1}): the mismatch behaves like an error of joint {j}'s angle that changes during the session (its zero re-set, an encoder count lost, a drive warming), in a form no catalogue effect has",
                j = b + 1
            ),
        ),
        (Some((z, _)), _, Some((pk, Along::FlangeInTime(c)))) => (
            pk,
            format!(
                "along the flange's {} axis, the residuals of poses neighbouring in time agree more than independent noise allows (z = {z:.1}, threshold {zcrit:.1}): the mismatch behaves like the tool point moving in the flange frame during the session (a probe warming with the process, a tool slipping in its holder or re-seated), in a form no catalogue effect has",
                AXES[c]
            ),
        ),
        (Some((z, _)), _, Some((pk, Along::Others))) => (
            pk,
            format!(
                "along the directions the other joints move T, the residuals of poses neighbouring in joint {j}'s angle agree more than independent noise allows (z = {z:.1}, threshold {zcrit:.1}): the mismatch behaves like an error of another joint's angle driven by joint {j}'s (a cable or harness pulling, coupled drives), in a form no catalogue effect has",
                j = pk + 1
            ),
        ),
        (None, _, _) if motion.is_some() => {
            let m = motion.expect("checked");
            let (w, _) = nearest();
            (
                w,
                format!(
                    "the residual of each pose follows the move that led to it: T is off along that move by {:.2} % of its length (z = {:.1}, threshold {:.1}): the mismatch depends on the motion, not on where the pose is, in a form no catalogue effect has",
                    100.0 * m.fraction,
                    m.z,
                    m.threshold
                ),
            )
        }
        (None, Some(x), _) if x.f > x.threshold => {
            let (w, z) = nearest();
            (
                w,
                format!(
                    "the robot-side part of the string residuals is {:.1} times the variance the strings' own disagreement (their noise) explains (F = {:.1} on {} and {} degrees of freedom, threshold {:.1}), though it follows no driver of the catalogue and varies too fast for neighbouring poses to agree (nearest: {}, z = {z:.1})",
                    x.f, x.f, x.d1, x.d2, x.threshold, pairings[w].0
                ),
            )
        }
        _ => return None,
    })
}

/// A mismatch confined to a few poses, found by [`concentrated`].
#[derive(Debug, Clone)]
struct Concentrated {
    /// Joint (0-based) whose angle gathers them.
    joint: usize,
    /// The stretch of its range (rad) the held-out poses were tested in.
    lo_rad: f64,
    hi_rad: f64,
    /// Train poses far off the rest that lie in the stretch, by pose id.
    train_poses: Vec<String>,
    /// Held-out poses in the stretch, and the held-out misfit (RMS per
    /// reading, mm) inside and outside it.
    n_test_in: usize,
    test_rms_in: f64,
    test_rms_out: f64,
    /// Chance of held-out poses inside ranking this high without a
    /// mismatch there (permutation test), and what it had to beat.
    p: f64,
    alpha: f64,
}

/// A train pose is "far off" when its misfit passes this multiple of the
/// train poses' median misfit: about six standard deviations of noise for
/// three Gaussian readings, so noise alone hardly ever gives one.
const FAR_OFF_MEDIANS: f64 = 4.0;

/// An error confined to a stretch of one joint's range (a damaged or
/// eccentric stretch of gear, a cable or dress pack pulling in one
/// posture, a local collision with the rig) that only a few poses reach:
/// too few for any smooth model or neighbour test, and with a tracker no
/// string redundancy gives the noise to compare against. The few train
/// poses far off the rest (`misfit_train` above [`FAR_OFF_MEDIANS`] times
/// its median, at most a quarter of them) form, for each joint, a stretch
/// of its angle: the narrowest holding two thirds of them (skipped when
/// wider than a quarter of the joint's range over the train poses), padded
/// by the larger of half its width and a twentieth of that range. That is a
/// hypothesis made on the train poses alone; the held-out poses test it:
/// their misfits inside the stretch must rank above those outside
/// (Wilcoxon rank sum, [`rank_sum_upper_p`]) at `alpha` shared among the
/// joints. Misfits are per reading
/// (string residuals, or point coordinates), whose noise is the same at
/// every pose, not 3-D errors, whose noise grows where the rig's geometry
/// is poor.
fn concentrated(
    obs: &Observations,
    ctx: &Context,
    misfit_train: &[f64],
    misfit_test: &[f64],
    alpha: f64,
) -> Option<Concentrated> {
    let (n_tr, n_te) = (misfit_train.len(), misfit_test.len());
    if n_tr < 8 || n_te < 4 {
        return None;
    }
    let median = crate::stats::median(misfit_train);
    let far: Vec<usize> = (0..n_tr)
        .filter(|&k| misfit_train[k] > FAR_OFF_MEDIANS * median)
        .collect();
    if far.is_empty() || 4 * far.len() > n_tr {
        return None;
    }
    // Held-out ranks (1 = smallest misfit), ties in pose order.
    let mut by_misfit: Vec<usize> = (0..n_te).collect();
    by_misfit.sort_by(|a, b| misfit_test[*a].total_cmp(&misfit_test[*b]));
    let mut rank = vec![0usize; n_te];
    for (r, &k) in by_misfit.iter().enumerate() {
        rank[k] = r + 1;
    }
    let alpha_joint = alpha / ctx.n_joints.max(1) as f64;
    let mut best: Option<Concentrated> = None;
    for j in 0..ctx.n_joints {
        let q = |i: usize| ctx.poses[i].q_rad[j];
        let (lo_all, hi_all) = obs
            .train
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &i| {
                (a.min(q(i)), b.max(q(i)))
            });
        let range = hi_all - lo_all;
        if range.to_degrees() < 5.0 {
            continue;
        }
        let mut qf: Vec<(f64, usize)> = far.iter().map(|&k| (q(obs.train[k]), k)).collect();
        qf.sort_by(|a, b| a.0.total_cmp(&b.0));
        let need = if qf.len() <= 2 {
            qf.len()
        } else {
            (2 * qf.len()).div_ceil(3)
        };
        let (width, start) = (0..=qf.len() - need)
            .map(|s| (qf[s + need - 1].0 - qf[s].0, s))
            .min_by(|a, b| a.0.total_cmp(&b.0))?;
        if width > range / 4.0 {
            continue; // spread over the range: not confined to a stretch
        }
        let pad = (width / 2.0).max(range / 20.0);
        let (lo, hi) = (qf[start].0 - pad, qf[start + need - 1].0 + pad);
        let inside: Vec<bool> = obs
            .test
            .iter()
            .map(|&i| (lo..=hi).contains(&q(i)))
            .collect();
        let m = inside.iter().filter(|b| **b).count();
        if m == 0 || m == n_te {
            continue;
        }
        let observed: usize = (0..n_te).filter(|&k| inside[k]).map(|k| rank[k]).sum();
        let p = rank_sum_upper_p(n_te, m, observed);
        if p < alpha_joint && best.as_ref().is_none_or(|b| p < b.p) {
            // RMS of the held-out misfits inside (or outside) the stretch.
            let rms_where = |inner: bool| {
                let (ss, c) = (0..n_te)
                    .filter(|&k| inside[k] == inner)
                    .fold((0.0, 0usize), |(ss, c), k| {
                        (ss + misfit_test[k] * misfit_test[k], c + 1)
                    });
                (ss / c.max(1) as f64).sqrt()
            };
            best = Some(Concentrated {
                joint: j,
                lo_rad: lo,
                hi_rad: hi,
                train_poses: qf
                    .iter()
                    .filter(|(a, _)| (lo..=hi).contains(a))
                    .map(|&(_, k)| obs.data.poses[obs.train[k]].id.clone())
                    .collect(),
                n_test_in: m,
                test_rms_in: rms_where(true),
                test_rms_out: rms_where(false),
                p,
                alpha: alpha_joint,
            });
        }
    }
    best
}

/// Largest work (held-out poses x poses inside x their possible rank sums)
/// for which [`rank_sum_upper_p`] counts exactly.
const EXACT_RANK_SUM_WORK: usize = 10_000_000;

/// Chance that `m` of `n` ranks (1..=n) drawn at random sum to `observed`
/// or more: the one-sided Wilcoxon rank-sum p-value. Counted exactly
/// (subset sums by dynamic programming over the smaller side) while that
/// is cheap; beyond, the normal approximation with continuity correction,
/// which for these sizes (tens of poses on each side) errs on the large
/// side in the far tail (the rank sum is bounded, its tails lighter).
fn rank_sum_upper_p(n: usize, m: usize, observed: usize) -> f64 {
    if m == 0 || m >= n {
        return 1.0;
    }
    let total = n * (n + 1) / 2;
    // The other side's sum is fixed by this one's: count the smaller side.
    let (k, at_least) = if 2 * m <= n {
        (m, Some(observed))
    } else {
        (n - m, None) // the outside's sum must be at most total - observed
    };
    let bound = total.saturating_sub(observed);
    let max_sum = k * n;
    if n.saturating_mul(k).saturating_mul(max_sum) > EXACT_RANK_SUM_WORK {
        let (nf, mf) = (n as f64, m as f64);
        let mean = mf * (nf + 1.0) / 2.0;
        let sd = (mf * (nf - mf) * (nf + 1.0) / 12.0).sqrt();
        let z = (observed as f64 - 0.5 - mean) / sd;
        return normal_upper_tail(z);
    }
    // ways[j][s]: subsets of j of the ranks seen so far summing to s.
    let mut ways = vec![vec![0.0f64; max_sum + 1]; k + 1];
    ways[0][0] = 1.0;
    for r in 1..=n {
        for j in (1..=k.min(r)).rev() {
            let (lower, upper) = ways.split_at_mut(j);
            for s in (r..=max_sum).rev() {
                upper[0][s] += lower[j - 1][s - r];
            }
        }
    }
    let all: f64 = ways[k].iter().sum();
    let tail: f64 = match at_least {
        Some(o) => ways[k].iter().skip(o).sum(),
        None => ways[k].iter().take(bound + 1).sum(),
    };
    (tail / all).clamp(0.0, 1.0)
}

/// Robot-side residual variance against the strings' noise (see
/// [`robot_side_excess`]).
#[derive(Debug, Clone, Copy)]
struct Excess {
    /// Ratio of the two variances.
    f: f64,
    /// What it must exceed to count.
    threshold: f64,
    d1: usize,
    d2: usize,
}

/// The residual regressed on the move that led to each pose.
#[derive(Debug, Clone)]
struct Motion {
    /// T's displacement along the move, as a fraction of the move.
    fraction: f64,
    /// Its significance (two-sided normal z) and what it had to pass.
    z: f64,
    threshold: f64,
}

/// Does each train pose's residual follow the move that led to it (from
/// the pose recorded before it, train or test)? Each residual as a
/// displacement of T in the rig frame (a point's error, or the string
/// residuals' common displacement through the anchors) is regressed on the
/// move `T_k - T_(k-1)` (located points): one coefficient, its z against
/// the scatter left. An arm not settled at the dwell or a servo's following
/// error puts T off along or against its last move; no effect of the
/// catalogue depends on it. `zcrit` is the neighbour tests' threshold
/// (the same family-wise rate; one more test is a negligible change).
fn motion_test(
    obs: &Observations,
    ctx: &Context,
    res: &[f64],
    rpp: usize,
    zcrit: f64,
) -> Option<Motion> {
    let points = obs.anchors.is_empty();
    let (mut sdd, mut sdr) = (0.0, 0.0);
    let mut pairs = Vec::with_capacity(obs.train.len());
    for (pos, &i) in obs.train.iter().enumerate() {
        if i == 0 {
            continue;
        }
        let r = &res[pos * rpp..(pos + 1) * rpp];
        let here = ctx.poses[i].point_rig;
        let d = if points {
            nalgebra::Vector3::new(r[0], r[1], r[2])
        } else {
            // A pose whose anchors do not fix a point tells nothing here.
            let Some((d, _)) = common_displacement(&obs.anchors, &here, r) else {
                continue;
            };
            d
        };
        let mv = ctx.poses[i].move_rig;
        sdd += mv.norm_squared();
        sdr += mv.dot(&d);
        pairs.push((d, mv));
    }
    if pairs.len() < 20 || sdd <= 0.0 {
        return None;
    }
    let c = sdr / sdd;
    let scatter: f64 = pairs
        .iter()
        .map(|(d, mv)| (d - c * mv).norm_squared())
        .sum();
    let s2 = scatter / (3 * pairs.len() - 1) as f64;
    let z = c.abs() / (s2 / sdd).sqrt();
    Some(Motion {
        fraction: c,
        z,
        threshold: zcrit,
    })
}

/// False-alarm rate of the robot-side excess test (strict: it names no
/// cause, and a cross-check on 130 effect-free string sessions of other
/// rigs and arms saw one chance excess at 1e-3).
const EXCESS_ALPHA: f64 = 1e-4;
/// Smallest robot-side variance ratio reported, whatever its significance
/// (a robot-side residual RMS 1.4 times the noise): strings of unequal
/// noise split their variance between the two parts a little unevenly,
/// and a large session makes that significant.
const EXCESS_MIN_RATIO: f64 = 2.0;

/// With more than three strings, each pose's string residuals `res` (train
/// poses, `rpp` per pose) split into a common displacement of T (3 degrees
/// of freedom: robot side) and the strings' disagreement with any single
/// point (`m - 3`: sensor side, which only the strings' noise and
/// sensor-side effects feed). Without anything left out, both are noise:
/// their variances per degree of freedom (the robot side less the `n_params`
/// fitted) have an F distribution.
fn robot_side_excess(
    obs: &Observations,
    ctx: &Context,
    res: &[f64],
    rpp: usize,
    n_params: usize,
) -> Option<Excess> {
    let m = obs.anchors.len();
    if m <= 3 || rpp != m {
        return None;
    }
    let (mut robot, mut total, mut n) = (0.0, 0.0, 0usize);
    for (pos, &i) in obs.train.iter().enumerate() {
        let r = &res[pos * rpp..(pos + 1) * rpp];
        // A pose whose anchors do not fix a point tells nothing here.
        let Some((_, energy)) = common_displacement(&obs.anchors, &ctx.poses[i].point_rig, r)
        else {
            continue;
        };
        robot += energy;
        total += r.iter().map(|v| v * v).sum::<f64>();
        n += 1;
    }
    let d1 = (3 * n).checked_sub(n_params)?;
    let d2 = (m - 3) * n;
    let sensor = total - robot;
    if d1 < 10 || d2 < 10 || sensor <= 0.0 {
        return None;
    }
    Some(Excess {
        f: (robot / d1 as f64) / (sensor / d2 as f64),
        threshold: f_quantile_upper(EXCESS_ALPHA, d1, d2).max(EXCESS_MIN_RATIO),
        d1,
        d2,
    })
}

/// Per joint and train pose (position in `session.train`), the component of
/// the pose's residual, as a displacement of T in the rig frame, along the
/// direction a turn of that joint moves T (mm). A point residual is the
/// displacement; string residuals give it by least squares through the
/// anchors' unit vectors (their robot-side part). `None` with fewer than
/// three strings.
fn joint_components(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    res: &[f64],
    rpp: usize,
) -> Option<Vec<Vec<f64>>> {
    let disps = displacements(obs, ctx, res, rpp)?;
    let n = ctx.n_joints;
    let l = obs.chain.layout;
    let mut jac = obs.chain.new_jacobian();
    let mut out = vec![Vec::with_capacity(obs.train.len()); n];
    for (&i, disp) in obs.train.iter().zip(&disps) {
        obs.chain.point_jacobian(
            p,
            &ctx.poses[i].q_rad,
            crate::kinematics::chain::OutputFrame::Rig,
            &mut jac,
        );
        for (j, o) in out.iter_mut().enumerate() {
            let w = jac.d_params[l.joint(j, crate::kinematics::JointParam::Theta)];
            let norm = w.norm();
            o.push(if norm > 1e-9 {
                disp.dot(&w) / norm
            } else {
                0.0
            });
        }
    }
    Some(out)
}

/// Names of the flange's axes, for a sentence.
const AXES: [&str; 3] = ["x", "y", "z"];

/// Per train pose (position in `obs.train`), its residual as a
/// displacement of T in the rig frame (mm): a point residual is one;
/// string residuals give it by least squares through the anchors' unit
/// vectors (their robot-side part). `None` with fewer than three strings.
fn displacements(
    obs: &Observations,
    ctx: &Context,
    res: &[f64],
    rpp: usize,
) -> Option<Vec<Vector3<f64>>> {
    let m = obs.anchors.len();
    if m > 0 && (m < 3 || rpp != m) {
        return None;
    }
    Some(
        obs.train
            .iter()
            .enumerate()
            .map(|(pos, &i)| {
                let r = &res[pos * rpp..(pos + 1) * rpp];
                if m == 0 {
                    Vector3::new(r[0], r[1], r[2])
                } else {
                    common_displacement(&obs.anchors, &ctx.poses[i].point_rig, r)
                        .map_or(Vector3::zeros(), |(d, _)| d)
                }
            })
            .collect(),
    )
}

/// Per axis of the flange (x, y, z) and train pose, the component of the
/// pose's residual, as a displacement of T ([`displacements`]), along
/// that axis in the rig frame (mm).
fn flange_components(
    obs: &Observations,
    ctx: &Context,
    res: &[f64],
    rpp: usize,
) -> Option<Vec<Vec<f64>>> {
    let disps = displacements(obs, ctx, res, rpp)?;
    Some(
        (0..3)
            .map(|c| {
                obs.train
                    .iter()
                    .zip(&disps)
                    .map(|(&i, d)| d.dot(&ctx.poses[i].flange_axes_rig[c]))
                    .collect()
            })
            .collect(),
    )
}

/// Each train pose (position in `train`) paired with its nearest other
/// train pose in joint space, each pair once (mutual neighbours would
/// otherwise count twice and inflate the agreement statistic). Above
/// 12,000 poses a deterministic stride subsample bounds the search.
fn nearest_in_joint_space(ctx: &Context, train: &[usize]) -> Vec<(usize, usize)> {
    let q = |a: usize| &ctx.poses[train[a]].q_rad;
    let n = ctx.n_joints;
    nearest_pairs(
        train.len(),
        n,
        |a, c| q(a)[c],
        |a, b| q(a).iter().zip(q(b)).map(|(x, y)| (x - y).powi(2)).sum(),
    )
}

/// Each train pose paired with its nearest other train pose by T's
/// position (rig frame), each pair once; subsampled like
/// [`nearest_in_joint_space`].
fn nearest_in_workspace(ctx: &Context, train: &[usize]) -> Vec<(usize, usize)> {
    let t = |a: usize| ctx.poses[train[a]].point_rig;
    nearest_pairs(
        train.len(),
        3,
        |a, c| t(a)[c],
        |a, b| (t(a) - t(b)).norm_squared(),
    )
}

/// Each of `n` items (every `stride`-th above 12,000) paired with its
/// nearest other by `dist` (a sum of squared differences of the `dim`
/// coordinates `coord`; among equals the first in order), each pair once.
/// The same pairs as comparing every two items (a quadratic search took
/// seconds on the 11,911-pose grid), found in a k-d tree: a subtree is
/// passed over only when the squared distance to its splitting plane alone
/// exceeds the nearest distance so far (a sum of non-negative terms is
/// never below one of them, also in floating point), so ties are still
/// seen and broken by order.
fn nearest_pairs(
    n: usize,
    dim: usize,
    coord: impl Fn(usize, usize) -> f64,
    dist: impl Fn(usize, usize) -> f64,
) -> Vec<(usize, usize)> {
    let stride = n.div_ceil(12_000).max(1);
    let pick: Vec<usize> = (0..n).step_by(stride).collect();
    let finite = pick
        .iter()
        .all(|&a| (0..dim).all(|c| coord(a, c).is_finite()));
    let nearest: Vec<Option<usize>> = if finite && dim > 0 {
        let tree = KdTree::build(pick.clone(), dim, &coord);
        pick.iter()
            .map(|&a| {
                let mut best = None;
                tree.nearest(0, a, &coord, &dist, &mut best);
                best.map(|(_, b)| b)
            })
            .collect()
    } else {
        pick.iter()
            .map(|&a| {
                pick.iter()
                    .filter(|&&b| b != a)
                    .map(|&b| (dist(a, b), b))
                    .min_by(|x, y| x.0.total_cmp(&y.0))
                    .map(|(_, b)| b)
            })
            .collect()
    };
    pick.iter()
        .zip(nearest)
        .filter_map(|(&a, b)| b.map(|b| (a.min(b), a.max(b))))
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect()
}

/// A k-d tree over items (see [`nearest_pairs`]).
struct KdTree {
    /// The items, each node's a contiguous range.
    items: Vec<usize>,
    nodes: Vec<KdNode>,
}

/// A leaf (a range of `KdTree::items`) or a split: items of `left` have
/// coordinate `axis` at most `value`, those of `right` at least `value`.
enum KdNode {
    Leaf(usize, usize),
    Split {
        axis: usize,
        value: f64,
        left: usize,
        right: usize,
    },
}

impl KdTree {
    /// Leaves of at most this many items.
    const LEAF: usize = 8;

    fn build(items: Vec<usize>, dim: usize, coord: &impl Fn(usize, usize) -> f64) -> Self {
        let mut tree = KdTree {
            items,
            nodes: Vec::new(),
        };
        let len = tree.items.len();
        tree.node(0, len, dim, coord);
        tree
    }

    /// The node over `items[lo..hi]`, split at the median of the
    /// coordinate that spreads most; its index.
    fn node(
        &mut self,
        lo: usize,
        hi: usize,
        dim: usize,
        coord: &impl Fn(usize, usize) -> f64,
    ) -> usize {
        let at = self.nodes.len();
        self.nodes.push(KdNode::Leaf(lo, hi));
        if hi - lo <= Self::LEAF {
            return at;
        }
        let spread = |c: usize| {
            let v = self.items[lo..hi].iter().map(|&a| coord(a, c));
            v.clone().fold(f64::NEG_INFINITY, f64::max) - v.fold(f64::INFINITY, f64::min)
        };
        let axis = (0..dim)
            .max_by(|&x, &y| spread(x).total_cmp(&spread(y)))
            .unwrap_or(0);
        self.items[lo..hi].sort_by(|&x, &y| coord(x, axis).total_cmp(&coord(y, axis)));
        let mid = (lo + hi) / 2;
        let value = coord(self.items[mid], axis);
        let left = self.node(lo, mid, dim, coord);
        let right = self.node(mid, hi, dim, coord);
        self.nodes[at] = KdNode::Split {
            axis,
            value,
            left,
            right,
        };
        at
    }

    /// Search node `at` for the nearest item to `a` other than itself,
    /// updating `best` (distance, item; among equals the smaller item).
    fn nearest(
        &self,
        at: usize,
        a: usize,
        coord: &impl Fn(usize, usize) -> f64,
        dist: &impl Fn(usize, usize) -> f64,
        best: &mut Option<(f64, usize)>,
    ) {
        match self.nodes[at] {
            KdNode::Leaf(lo, hi) => {
                for &b in &self.items[lo..hi] {
                    if b == a {
                        continue;
                    }
                    let d = dist(a, b);
                    let better = match best {
                        None => true,
                        Some((bd, bb)) => d.total_cmp(bd).then(b.cmp(bb)).is_lt(),
                    };
                    if better {
                        *best = Some((d, b));
                    }
                }
            }
            KdNode::Split {
                axis,
                value,
                left,
                right,
            } => {
                let x = coord(a, axis);
                let (near, far) = if x <= value {
                    (left, right)
                } else {
                    (right, left)
                };
                self.nearest(near, a, coord, dist, best);
                let plane = (x - value).powi(2);
                if best.is_none_or(|(bd, _)| plane <= bd) {
                    self.nearest(far, a, coord, dist, best);
                }
            }
        }
    }
}

#[cfg(test)]
mod nearest_tests {
    use super::nearest_pairs;

    /// The pruned search finds the same pairs as comparing every two
    /// points, ties included (repeated points, a coarse grid).
    #[test]
    fn pruned_nearest_pairs_equal_the_quadratic_search() {
        let mut rng = crate::rng::Rng::new(11);
        for (n, dim, grid) in [
            (300, 6, false),
            (500, 3, true),
            (2, 2, false),
            (1, 3, false),
        ] {
            let pts: Vec<Vec<f64>> = (0..n)
                .map(|_| {
                    (0..dim)
                        .map(|_| {
                            let v = rng.uniform() * 4.0 - 2.0;
                            if grid { v.round() } else { v }
                        })
                        .collect()
                })
                .collect();
            let dist = |a: usize, b: usize| -> f64 {
                pts[a]
                    .iter()
                    .zip(&pts[b])
                    .map(|(x, y)| (x - y).powi(2))
                    .sum()
            };
            let got = nearest_pairs(n, dim, |a, c| pts[a][c], dist);
            let want: Vec<(usize, usize)> = (0..n)
                .filter_map(|a| {
                    (0..n)
                        .filter(|&b| b != a)
                        .map(|b| (dist(a, b), b))
                        .min_by(|x, y| x.0.total_cmp(&y.0))
                        .map(|(_, b)| (a.min(b), a.max(b)))
                })
                .collect::<std::collections::BTreeSet<_>>()
                .into_iter()
                .collect();
            assert_eq!(got, want, "n = {n}, dim = {dim}, grid = {grid}");
        }
    }
}

/// Where in the workspace the residual is largest: the quarter of one
/// joint's range (over the train poses) with the highest residual RMS,
/// when it stands out (1.3 times the overall RMS or more).
fn worst_region(ctx: &Context, train: &[usize], res: &[f64], rpp: usize) -> String {
    let n_t = train.len();
    if n_t < 40 {
        return String::new();
    }
    let sq = |a: usize| (0..rpp).map(|c| res[a * rpp + c].powi(2)).sum::<f64>();
    let all = ((0..n_t).map(sq).sum::<f64>() / n_t as f64).sqrt();
    let mut best: Option<(f64, String)> = None;
    for j in 0..ctx.n_joints {
        let mut order: Vec<usize> = (0..n_t).collect();
        order.sort_by(|a, b| {
            ctx.poses[train[*a]].q_rad[j].total_cmp(&ctx.poses[train[*b]].q_rad[j])
        });
        let lo = ctx.poses[train[order[0]]].q_rad[j];
        let hi = ctx.poses[train[order[n_t - 1]]].q_rad[j];
        if (hi - lo).to_degrees() < 5.0 {
            continue;
        }
        for quarter in order.chunks(n_t.div_ceil(4)) {
            let r = (quarter.iter().map(|&a| sq(a)).sum::<f64>() / quarter.len() as f64).sqrt();
            let (a, b) = (
                ctx.poses[train[quarter[0]]].q_rad[j].to_degrees(),
                ctx.poses[train[quarter[quarter.len() - 1]]].q_rad[j].to_degrees(),
            );
            if best.as_ref().is_none_or(|x| r > x.0) {
                best = Some((r, format!("joint {} between {a:.0} and {b:.0} deg", j + 1)));
            }
        }
    }
    match best {
        Some((r, where_)) if r >= 1.3 * all => format!(
            "; largest where {where_} (residual RMS {:.3} mm per reading there, {:.3} overall)",
            r / (rpp as f64).sqrt(),
            all / (rpp as f64).sqrt()
        ),
        _ => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::rank_sum_upper_p;

    /// Every subset of `m` of the ranks 1..=n, by brute force.
    fn brute_force(n: usize, m: usize, observed: usize) -> f64 {
        let (mut hit, mut all) = (0u64, 0u64);
        for mask in 0u32..(1 << n) {
            if mask.count_ones() as usize != m {
                continue;
            }
            let sum: usize = (0..n).filter(|b| mask & (1 << b) != 0).map(|b| b + 1).sum();
            all += 1;
            hit += (sum >= observed) as u64;
        }
        hit as f64 / all as f64
    }

    #[test]
    fn rank_sum_tail_is_exact_on_both_sides() {
        for (n, m) in [(10, 3), (9, 6), (12, 1), (12, 11), (8, 4)] {
            let total = n * (n + 1) / 2;
            for observed in 0..=total + 1 {
                let (a, b) = (
                    rank_sum_upper_p(n, m, observed),
                    brute_force(n, m, observed),
                );
                assert!(
                    (a - b).abs() < 1e-12,
                    "n {n} m {m} sum {observed}: {a} vs {b}"
                );
            }
        }
        // The three highest of 63 held-out ranks: one subset in C(63, 3).
        let p = rank_sum_upper_p(63, 3, 61 + 62 + 63);
        assert!((p * 39_711.0 - 1.0).abs() < 1e-9, "{p}");
    }

    #[test]
    fn rank_sum_tail_of_large_sessions_is_normal() {
        // Beyond the exact count: the mean has half the mass above it, and
        // the tail shrinks with the sum.
        let (n, m) = (3000, 400);
        let mean = m * (n + 1) / 2;
        assert!((rank_sum_upper_p(n, m, mean) - 0.5).abs() < 0.01);
        let sd = ((m * (n - m) * (n + 1)) as f64 / 12.0).sqrt();
        let p = rank_sum_upper_p(n, m, mean + (3.0 * sd) as usize);
        assert!((p / 1.35e-3 - 1.0).abs() < 0.05, "{p}");
    }
}
