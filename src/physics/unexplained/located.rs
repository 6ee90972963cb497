//! Which test located the remainder, in words, and where in the
//! workspace the residual is largest.

use super::confined::Concentrated;
use super::neighbours::{AXES, Along, Neighbours};
use super::robot_side::{Excess, Motion};
use super::scalar::ScalarTest;
use crate::physics::effects::Context;

/// Which test located the remainder, first that holds of: neighbours that
/// agree (raw, then along a joint's motion), a confined mismatch, a
/// robot-side excess; the ordering its plot runs along and the sentence
/// saying where it lives. `None`: no structure is left.
pub(super) fn located(
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
    // The bar the winning test passed.
    let zcrit = nb.winner_threshold;
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

/// Where in the workspace the residual is largest: the quarter of one
/// joint's range (over the train poses) with the highest residual RMS,
/// when it stands out (1.3 times the overall RMS or more).
pub(super) fn worst_region(ctx: &Context, train: &[usize], res: &[f64], rpp: usize) -> String {
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
