//! A mismatch confined to a few poses in one stretch of a joint's range,
//! found on the train poses and confirmed by the held-out ones (a
//! Wilcoxon rank-sum test).

use crate::identify::Observations;
use crate::physics::effects::Context;
use crate::stats::normal_upper_tail;

/// A mismatch confined to a few poses, found by [`concentrated`].
#[derive(Debug, Clone)]
pub(super) struct Concentrated {
    /// Joint (0-based) whose angle gathers them.
    pub(super) joint: usize,
    /// The stretch of its range (rad) the held-out poses were tested in.
    pub(super) lo_rad: f64,
    pub(super) hi_rad: f64,
    /// Train poses far off the rest that lie in the stretch, by pose id.
    pub(super) train_poses: Vec<String>,
    /// Held-out poses in the stretch, and the held-out misfit (RMS per
    /// reading, mm) inside and outside it.
    pub(super) n_test_in: usize,
    pub(super) test_rms_in: f64,
    pub(super) test_rms_out: f64,
    /// Chance of held-out poses inside ranking this high without a
    /// mismatch there (permutation test), and what it had to beat.
    pub(super) p: f64,
    pub(super) alpha: f64,
}

impl Concentrated {
    /// Where the mismatch is confined, in words.
    pub(super) fn sentence(&self) -> String {
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

/// A train pose is "far off" when its misfit passes this multiple of the
/// train poses' median misfit: about six standard deviations of noise for
/// three Gaussian readings, so noise alone hardly ever gives one.
pub(super) const FAR_OFF_MEDIANS: f64 = 4.0;

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
pub(super) fn concentrated(
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
pub(super) const EXACT_RANK_SUM_WORK: usize = 10_000_000;

/// Chance that `m` of `n` ranks (1..=n) drawn at random sum to `observed`
/// or more: the one-sided Wilcoxon rank-sum p-value. Counted exactly
/// (subset sums by dynamic programming over the smaller side) while that
/// is cheap; beyond, the normal approximation with continuity correction,
/// which for these sizes (tens of poses on each side) errs on the large
/// side in the far tail (the rank sum is bounded, its tails lighter).
pub(super) fn rank_sum_upper_p(n: usize, m: usize, observed: usize) -> f64 {
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
