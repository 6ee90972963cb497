//! The residual as a displacement of T: with four or more strings, its
//! robot-side part against the strings' own noise; its components along
//! the direction each joint moves T and along the flange's axes; and
//! whether it follows the move that led to each pose.

use nalgebra::Vector3;

use crate::identify::Observations;
use crate::physics::effects::Context;
use crate::stats::f_quantile_upper;

/// The part of one pose's string residuals `r` (one per anchor, mm) that a
/// displacement of T explains: least squares through the anchors' unit
/// vectors at `t` (rig frame). The displacement (mm) and the residual
/// energy it takes (`rᵀG(GᵀG)⁻¹Gᵀr`, mm²); `None` when the anchors do not
/// fix a point.
pub(super) fn common_displacement(
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
pub(in crate::physics) fn robot_side_share(
    obs: &Observations,
    p: &[f64],
) -> (Option<f64>, Option<f64>) {
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

/// Robot-side residual variance against the strings' noise (see
/// [`robot_side_excess`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Excess {
    /// Ratio of the two variances.
    pub(super) f: f64,
    /// What it must exceed to count.
    pub(super) threshold: f64,
    pub(super) d1: usize,
    pub(super) d2: usize,
}

/// The residual regressed on the move that led to each pose.
#[derive(Debug, Clone)]
pub(super) struct Motion {
    /// T's displacement along the move, as a fraction of the move.
    pub(super) fraction: f64,
    /// Its significance (two-sided normal z) and what it had to pass.
    pub(super) z: f64,
    pub(super) threshold: f64,
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
pub(super) fn motion_test(
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
pub(super) const EXCESS_ALPHA: f64 = 1e-4;
/// Smallest robot-side variance ratio reported, whatever its significance
/// (a robot-side residual RMS 1.4 times the noise): strings of unequal
/// noise split their variance between the two parts a little unevenly,
/// and a large session makes that significant.
pub(super) const EXCESS_MIN_RATIO: f64 = 2.0;

/// With more than three strings, each pose's string residuals `res` (train
/// poses, `rpp` per pose) split into a common displacement of T (3 degrees
/// of freedom: robot side) and the strings' disagreement with any single
/// point (`m - 3`: sensor side, which only the strings' noise and
/// sensor-side effects feed). Without anything left out, both are noise:
/// their variances per degree of freedom (the robot side less the `n_params`
/// fitted) have an F distribution.
pub(super) fn robot_side_excess(
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
pub(super) fn joint_components(
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

/// Per train pose (position in `obs.train`), its residual as a
/// displacement of T in the rig frame (mm): a point residual is one;
/// string residuals give it by least squares through the anchors' unit
/// vectors (their robot-side part). `None` with fewer than three strings.
pub(super) fn displacements(
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
pub(super) fn flange_components(
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
