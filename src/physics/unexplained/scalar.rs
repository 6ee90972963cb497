//! Neighbour tests on one number per train pose: a string's own part of
//! the residual (by its length, direction, last move and the clock), the
//! residual along an instrument's line of sight, and a joint's component
//! by the direction of a two-joint drive's last move or by the change of
//! its load.

use nalgebra::Vector3;

use super::nearest::nearest_pairs;
use super::orderings::train_order;
use super::robot_side::common_displacement;
use crate::identify::Observations;
use crate::physics::effects::{Context, CorrectionDriver};
use crate::physics::periodogram;
use crate::stats::normal_quantile;

/// A neighbour test on one number per train pose rather than the whole
/// residual: the sensor-side part of one string's residual, along its
/// length, its direction or the clock; or, with point data, the residual
/// along the instrument's line of sight.
pub(super) struct ScalarTest {
    pub(super) name: String,
    /// The string (1-based) whose part it tests, if a string's.
    pub(super) sensor: Option<usize>,
    /// The joint (1-based) whose part it tests, if a joint's, and what an
    /// agreement there would mean.
    pub(super) joint: Option<(usize, &'static str)>,
    pub(super) driver: &'static str,
    /// The side the place is on: "sensor" (the string's own part),
    /// "strings" (three strings: either side), "point" (point data) or
    /// "robot" (a joint's part).
    pub(super) side: &'static str,
    pub(super) test: ScalarTestKind,
    pub(super) values: Vec<f64>,
}

/// How a [`ScalarTest`] looks for structure.
pub(super) enum ScalarTestKind {
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
pub(super) fn string_tests(
    obs: &Observations,
    ctx: &Context,
    res: &[f64],
    rpp: usize,
) -> Vec<ScalarTest> {
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
pub(super) fn line_of_sight_test(
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
pub(super) fn drive_tests(
    obs: &Observations,
    ctx: &Context,
    along: Option<&[Vec<f64>]>,
) -> Vec<ScalarTest> {
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
pub(super) fn load_change_tests(
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

/// Per joint: its component of the residual times the side it arrived
/// from (+1, -1; nothing where the recording does not say), with the train
/// poses in time. A play that changes during the session (grease thinning
/// as the drive warms, wear) leaves, after the catalogue's one constant
/// play, an error whose sign follows the approach and whose size follows
/// the clock: these products agree between poses neighbouring in time,
/// where a joint's zero changing in time (the component itself agreeing)
/// makes them flip with every change of approach.
pub(super) fn play_in_time_tests(
    obs: &Observations,
    ctx: &Context,
    along: Option<&[Vec<f64>]>,
) -> Vec<ScalarTest> {
    let Some(along) = along else {
        return vec![];
    };
    let by_time = train_order(obs, ctx, CorrectionDriver::Time, 0);
    let pairs: Vec<(usize, usize)> = by_time.windows(2).map(|w| (w[0], w[1])).collect();
    (0..ctx.n_joints)
        .map(|j| ScalarTest {
            name: format!("time, joint {}'s part by the side it arrived from", j + 1),
            sensor: None,
            joint: Some((j + 1, PLAY_IN_TIME)),
            driver: "motion",
            side: "robot",
            test: ScalarTestKind::Neighbours(pairs.clone()),
            values: obs
                .train
                .iter()
                .zip(&along[j])
                .map(|(&i, v)| v * ctx.poses[i].direction[j])
                .collect(),
        })
        .collect()
}

/// What a joint's agreement by its and a neighbour's move direction means.
pub(super) const DRIVE_PLAY: &str = "follows the way it and its neighbour last moved, not only the side it arrived from (a drive turning both joints with play or friction: a parallelogram's rod or belt, a coupled wrist)";
/// What a joint's agreement by the side it arrived from, in time, means.
const PLAY_IN_TIME: &str = "takes the sign of the side it arrived from and changes in size during the session, where backlash is one constant play (a play that changes as the drive warms or wears)";
/// What a joint's agreement by the change of its load means.
pub(super) const LOAD_LAG: &str = "follows the change of its gravity load over the last move, where a compliance follows the load itself (a drive that creeps or winds up under load: a harmonic drive's flexspline relaxing during the dwell)";

impl ScalarTest {
    /// Where it located the remainder, in words: the test `name`, its `z`
    /// and the threshold `zcrit`.
    pub(super) fn sentence(&self, name: &str, z: f64, zcrit: f64) -> String {
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
