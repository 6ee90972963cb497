//! Each pose with its nearest other pose, by any coordinates (joint
//! angles, T's position, a string's direction), through a k-d tree.

use crate::physics::effects::Context;

/// Each train pose (position in `train`) paired with its nearest other
/// train pose in joint space, each pair once (mutual neighbours would
/// otherwise count twice and inflate the agreement statistic). Above
/// 12,000 poses a deterministic stride subsample bounds the search.
pub(super) fn nearest_in_joint_space(ctx: &Context, train: &[usize]) -> Vec<(usize, usize)> {
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
pub(super) fn nearest_in_workspace(ctx: &Context, train: &[usize]) -> Vec<(usize, usize)> {
    let t = |a: usize| ctx.poses[train[a]].point_rig;
    nearest_pairs(
        train.len(),
        3,
        |a, c| t(a)[c],
        |a, b| (t(a) - t(b)).norm_squared(),
    )
}

/// Each train pose paired with its nearest other train pose in time and
/// T's position at once: the clock and each coordinate (rig frame) over
/// its own spread, so an hour and the workspace's size weigh alike. An
/// error that changes during the session by an amount that depends on
/// where T is (an instrument turning, a camera's extrinsics creeping:
/// its depth error grows with the depth) changes sign across the workspace
/// and across the session, so neither poses neighbouring in time nor in
/// the workspace share it; poses close in both do.
pub(super) fn nearest_in_time_and_workspace(ctx: &Context, train: &[usize]) -> Vec<(usize, usize)> {
    let spread = |v: &dyn Fn(usize) -> f64| {
        let n = train.len().max(1) as f64;
        let mean = (0..train.len()).map(v).sum::<f64>() / n;
        let var = (0..train.len()).map(|a| (v(a) - mean).powi(2)).sum::<f64>() / n;
        if var > 0.0 { var.sqrt() } else { 1.0 }
    };
    let t = |a: usize| ctx.poses[train[a]].time_s;
    let p = |a: usize| ctx.poses[train[a]].point_rig;
    let scale = [
        spread(&t),
        spread(&|a| p(a).x),
        spread(&|a| p(a).y),
        spread(&|a| p(a).z),
    ];
    let coord = |a: usize, c: usize| {
        let v = if c == 0 { t(a) } else { p(a)[c - 1] };
        v / scale[c]
    };
    nearest_pairs(train.len(), 4, coord, |a, b| {
        (0..4).map(|c| (coord(a, c) - coord(b, c)).powi(2)).sum()
    })
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
pub(super) fn nearest_pairs(
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
pub(super) struct KdTree {
    /// The items, each node's a contiguous range.
    pub(super) items: Vec<usize>,
    pub(super) nodes: Vec<KdNode>,
}

/// A leaf (a range of `KdTree::items`) or a split: items of `left` have
/// coordinate `axis` at most `value`, those of `right` at least `value`.
pub(super) enum KdNode {
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
