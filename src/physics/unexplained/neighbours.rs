//! Do residuals of neighbouring poses agree more than independent noise
//! allows? Every ordering and every scalar test, with one family-wise
//! threshold; each test past it is a place.

use super::orderings::{driver_of, time_and_workspace_at};
use super::scalar::{ScalarTest, ScalarTestKind};
use crate::report::Place;
use crate::stats::normal_quantile;

/// What a neighbour test of an ordering compared between neighbours.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Along {
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

/// How far the agreement of poses close in time and T's position at once
/// must pass that of the clock's and the workspace's orderings alone to be
/// a place of its own. On 19 cross-check recordings whose error is a field
/// over the workspace alone (gen3 workspace_field, gen5 frame_tension_sway,
/// gen6 tracker_transit_tilt and drum_exit_walk, gen9
/// tracker_tripod_unbalance) its z less the workspace's was -0.35 on
/// average, spread 0.72 (largest +1.06): 1.5 is 2.6 spreads above. (Read
/// with a temporary print of the three z's, not kept; EVAL.md, stop 42.)
const BOTH_MARGIN: f64 = 1.5;

/// What the neighbour test found over every ordering (see [`neighbours`]).
pub(super) struct Neighbours {
    /// The z the agreement of neighbours must pass (Bonferroni over the
    /// orderings tested); time and T's position together must also pass
    /// [`BOTH_MARGIN`] above each alone.
    pub(super) zcrit: f64,
    /// The strongest agreement past its bar: its z and what it ran along.
    pub(super) best: Option<(f64, String)>,
    /// The bar the winning test passed (`zcrit`, or higher for time and
    /// T's position together).
    pub(super) winner_threshold: f64,
    /// Per ordering of the pairings (the plot's layout), the larger of the
    /// raw and the along-the-joint z for the joints (NaN: none).
    pub(super) zs: Vec<f64>,
    /// The winning test: an ordering of the pairings and what it ran on,
    /// or (index at or past the pairings) a string's own test,
    /// `pairings.len() + k` for `extra[k]`.
    pub(super) winner_at: Option<(usize, Along)>,
    /// Every test past its bar, strongest first.
    pub(super) places: Vec<Place>,
}

/// Do neighbours agree more than independent noise allows? Per ordering,
/// the z of the summed products of neighbouring residuals `res` (`rpp`
/// per pose), and for the first `n` orderings (the joints) also of their
/// components `along` the direction the joint moves T; then each string's
/// own test of `extra`. Every z is kept for the plot; every one past the
/// threshold is a place, and the largest locates the mismatch.
pub(super) fn neighbours(
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
    let mut lead = Leader::default();
    let mut zs = vec![f64::NAN; n_plain];
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
    let both_at = time_and_workspace_at(n, with_temp);
    for (pk, (name, pairs)) in pairings.iter().enumerate() {
        let tries = ordering_tries(pk, n, pairs, along, flange, res, rpp);
        let (driver, joint) = driver_of(pk, n, with_temp);
        // Time and T's position together must also beat each alone
        // (computed before it) by [`BOTH_MARGIN`]: a field over the
        // workspace, or a change in time, agrees between poses close in
        // both as well.
        let bar = if pk == both_at {
            zcrit.max(zs[n].max(zs[pk - 1]) + BOTH_MARGIN)
        } else {
            zcrit
        };
        let mut strongest: Option<Place> = None;
        for (z, on) in tries {
            let Some(z) = z else { continue };
            // (NaN, not yet set, is replaced.)
            if zs[pk].is_nan() || z > zs[pk] {
                zs[pk] = z;
            }
            if z > bar {
                let side = if on == Along::Raw { whole } else { "robot" };
                let joint = match on {
                    Along::JointInTime(b) => Some(b + 1),
                    _ => joint,
                };
                if strongest.as_ref().is_none_or(|p| z > p.z) {
                    strongest = Some(Place {
                        threshold: bar,
                        ..place(driver, joint, None, side, z)
                    });
                }
                lead.offer(z, || on.label(name, pk), (pk, on), bar);
            }
        }
        // It is then the clock's place on the whole residual (one such
        // place per driver), at its z.
        if pk == both_at && strongest.is_some() {
            places.retain(|q| !(q.driver == "time" && q.joint.is_none() && q.side == whole));
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
            lead.offer(z, || t.name.clone(), (n_plain + k, Along::Raw), zcrit);
        }
    }
    places.sort_by(|a, b| b.z.total_cmp(&a.z));
    Neighbours {
        zcrit,
        best: lead.best,
        winner_threshold: lead.threshold.unwrap_or(zcrit),
        zs,
        winner_at: lead.at,
        places,
    }
}

/// The strongest test so far past its bar: its z and label, where it ran
/// and the bar it passed.
#[derive(Default)]
struct Leader {
    best: Option<(f64, String)>,
    at: Option<(usize, Along)>,
    threshold: Option<f64>,
}

impl Leader {
    /// Take the lead with the test `at` (z past its `bar`) if it is
    /// stronger than the lead so far.
    fn offer(&mut self, z: f64, label: impl FnOnce() -> String, at: (usize, Along), bar: f64) {
        if self.best.as_ref().is_none_or(|b| z > b.0) {
            self.best = Some((z, label()));
            self.at = Some(at);
            self.threshold = Some(bar);
        }
    }
}

/// How much more neighbours agree than independent noise allows: per pair
/// the product `d` of their residuals, summed over its own scale, or
/// their signs counted, whichever is the larger z.
pub(super) fn agreement_z(
    pairs: &[(usize, usize)],
    d: &dyn Fn(usize, usize) -> f64,
) -> Option<f64> {
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
pub(super) fn ordering_tries(
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

/// Names of the flange's axes, for a sentence.
pub(super) const AXES: [&str; 3] = ["x", "y", "z"];
