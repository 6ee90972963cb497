//! Which parameters the data can separate.
//!
//! The Jacobian's columns are scaled to unit norm (so units do not matter)
//! and taken in a physical priority order; each is kept only if its
//! component orthogonal to the columns already kept is larger than a
//! tolerance (a rank-revealing, ordered Gram-Schmidt done on `JᵀJ` by
//! Cholesky). A rejected column moves T like a combination of kept ones:
//! it is held at nominal and its aliases are named. Written here (not a
//! library QR) because the order encodes which member of an aliased pair a
//! calibration engineer expects to keep (d2 over d3, the tool point over
//! joint 6's offsets, the base pose over joint 1's θ and d).

use nalgebra::DMatrix;

use crate::kinematics::Layout;
use crate::report::{FixedParam, FixedReason};

/// Relative size of the orthogonal part below which a column counts as a
/// combination of the others: 1e-3 in sine (about 0.06°), where the
/// estimate's uncertainty is a thousand times that of a well-placed
/// parameter.
pub const DEFAULT_TOLERANCE: f64 = 1e-3;

/// Sine below which a kept parameter counts as nearly aliased with the
/// others (about 0.6°): its sigma is at least a hundred times that of a
/// well-placed parameter, and what separates it is a detail like the tool
/// point's sub-millimetre offset from the last joint's axis.
pub const NEAR_ALIAS_SINE: f64 = 1e-2;

/// Deviation from nominal, in sigmas, below which a nearly aliased joint
/// parameter counts as not determined by the data (the default of
/// [`undetermined`]'s `max_z`).
pub const UNDETERMINED_Z: f64 = 3.0;

/// Result of the analysis.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Parameters kept free, indices into the full vector, in priority order.
    pub free: Vec<usize>,
    /// Parameters held at nominal, with their aliases.
    pub fixed: Vec<FixedParam>,
    /// Condition number of the column-scaled Jacobian of the kept set.
    pub condition_number: f64,
}

/// Analyse `jtj` (normal matrix over `candidates`, in that order, which is
/// also the priority order).
pub fn select(jtj: &DMatrix<f64>, candidates: &[usize], layout: &Layout, tol: f64) -> Selection {
    let n = candidates.len();
    let scale: Vec<f64> = (0..n).map(|i| jtj[(i, i)].max(0.0).sqrt()).collect();
    let largest = scale.iter().cloned().fold(0.0, f64::max);
    let g = |i: usize, j: usize| jtj[(i, j)] / (scale[i] * scale[j]);
    let mut kept: Vec<usize> = Vec::new(); // positions in candidates
    let mut l: Vec<Vec<f64>> = Vec::new(); // rows of the lower Cholesky factor
    let mut fixed = Vec::new();
    for c in 0..n {
        if scale[c] <= 1e-12 * largest.max(1e-300) {
            fixed.push(FixedParam {
                name: layout.name(candidates[c]),
                aliased_with: vec!["(does not move the measured point)".into()],
                reason: FixedReason::Aliased,
            });
            continue;
        }
        // Forward substitution: y = L⁻¹ G[kept, c].
        let k = kept.len();
        let mut y = vec![0.0; k];
        for i in 0..k {
            let mut s = g(kept[i], c);
            for j in 0..i {
                s -= l[i][j] * y[j];
            }
            y[i] = s / l[i][i];
        }
        let rem = 1.0 - y.iter().map(|v| v * v).sum::<f64>();
        if rem > tol * tol {
            let mut row = y;
            row.push(rem.sqrt());
            l.push(row);
            kept.push(c);
        } else {
            // Coefficients of the combination: z = L⁻ᵀ y.
            let mut z = y.clone();
            for i in (0..k).rev() {
                let mut s = z[i];
                for j in i + 1..k {
                    s -= l[j][i] * z[j];
                }
                z[i] = s / l[i][i];
            }
            let mut idx: Vec<usize> = (0..k).filter(|&i| z[i].abs() > 0.05).collect();
            idx.sort_by(|&a, &b| z[b].abs().total_cmp(&z[a].abs()));
            let aliased_with = idx
                .iter()
                .take(4)
                .map(|&i| layout.name(candidates[kept[i]]))
                .collect();
            fixed.push(FixedParam {
                name: layout.name(candidates[c]),
                aliased_with,
                reason: FixedReason::Aliased,
            });
        }
    }
    let sub = DMatrix::from_fn(kept.len(), kept.len(), |i, j| jtj[(kept[i], kept[j])]);
    Selection {
        free: kept.iter().map(|&c| candidates[c]).collect(),
        fixed,
        condition_number: condition_number(&sub),
    }
}

/// Condition number of the column-scaled Jacobian whose normal matrix is
/// `jtj`; infinite for an empty or singular one.
pub fn condition_number(jtj: &DMatrix<f64>) -> f64 {
    let m = jtj.nrows();
    if m == 0 {
        return f64::INFINITY;
    }
    let d: Vec<f64> = (0..m).map(|i| jtj[(i, i)].max(1e-300).sqrt()).collect();
    let ev = DMatrix::from_fn(m, m, |i, j| jtj[(i, j)] / (d[i] * d[j])).symmetric_eigenvalues();
    let max = ev.iter().cloned().fold(0.0, f64::max);
    let min = ev.iter().cloned().fold(f64::INFINITY, f64::min).max(0.0);
    (max / min).sqrt()
}

/// A free parameter the data do not determine, found by [`undetermined`].
#[derive(Debug, Clone)]
pub struct Undetermined {
    /// Its position in the free list.
    pub at: usize,
    /// Its record, aliased with the free parameters it is most correlated
    /// with.
    pub fixed: FixedParam,
    /// How far the linearised fit moves every free parameter (same order,
    /// internal units) when it is held: itself back to nominal, the others
    /// by their covariance with it. Added to the fit, a good start for the
    /// refit.
    pub shift: Vec<f64>,
}

/// The next free parameter the data do not determine, if any: a joint
/// parameter (`holdable`) nearly aliased with the other free ones (its
/// column within [`NEAR_ALIAS_SINE`] of their span) whose deviation from
/// nominal is under `max_z` sigmas; of several, the least significant.
/// `jtj` is the normal matrix over `free` at the fit, `deviation` each free
/// parameter's distance from nominal in the same order, `sigma` the
/// residual scale.
///
/// The structural test ([`select`]) keeps such a parameter because some
/// detail separates it, but the data pin it down no better than its
/// partner: left free it carries the noise of that weak combination (mm
/// and degrees of spread, a flange orientation off by degrees) for a
/// hundredth of its effect on T. Held at nominal, its partner absorbs it
/// and T moves by at most its deviation times the sine. A significant
/// deviation is real and stays free.
pub fn undetermined(
    jtj: &DMatrix<f64>,
    free: &[usize],
    deviation: &[f64],
    sigma: f64,
    max_z: f64,
    holdable: impl Fn(usize) -> bool,
    layout: &Layout,
) -> Option<Undetermined> {
    let cov = super::unit_covariance(jtj)?;
    let n = free.len();
    let z = |k: usize| deviation[k].abs() / (sigma * cov[(k, k)].sqrt());
    let at = (0..n)
        .filter(|&k| holdable(free[k]))
        // The part of column k orthogonal to the others, as a sine.
        .filter(|&k| 1.0 / (jtj[(k, k)] * cov[(k, k)]).sqrt() < NEAR_ALIAS_SINE)
        .filter(|&k| z(k) < max_z)
        .min_by(|&a, &b| z(a).total_cmp(&z(b)))?;
    let corr = |j: usize| cov[(at, j)] / (cov[(at, at)] * cov[(j, j)]).sqrt();
    let mut partners: Vec<usize> = (0..n).filter(|&j| j != at).collect();
    partners.sort_by(|&a, &b| corr(b).abs().total_cmp(&corr(a).abs()));
    // The strongly correlated ones; at least the strongest.
    let strong = partners.iter().filter(|&&j| corr(j).abs() > 0.5).count();
    partners.truncate(strong.clamp(1, 4));
    let shift = (0..n)
        .map(|j| -cov[(j, at)] / cov[(at, at)] * deviation[at])
        .collect();
    Some(Undetermined {
        at,
        fixed: FixedParam {
            name: layout.name(free[at]),
            aliased_with: partners.iter().map(|&j| layout.name(free[j])).collect(),
            reason: FixedReason::Undetermined,
        },
        shift,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drops_an_exact_alias_and_names_it() {
        // Columns: c0, c1, c2 = c0 + c1 (aliased), c3 independent.
        let j = DMatrix::from_row_slice(
            4,
            4,
            &[
                1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 2.0, 1.0,
            ],
        );
        let jtj = j.transpose() * &j;
        let layout = Layout {
            n_joints: 1,
            n_strings: 0,
        };
        let s = select(&jtj, &[0, 1, 2, 3], &layout, DEFAULT_TOLERANCE);
        assert_eq!(s.free, vec![0, 1, 3]);
        assert_eq!(s.fixed.len(), 1);
        assert_eq!(s.fixed[0].name, "j1.d");
        assert_eq!(s.fixed[0].aliased_with.len(), 2);
        assert!(s.condition_number.is_finite());
    }

    /// Columns: c0 and c1 nearly aliased (sine 5e-3), c2 independent;
    /// every parameter a joint parameter.
    fn near_pair() -> DMatrix<f64> {
        let e = 5e-3;
        let j = DMatrix::from_row_slice(3, 3, &[1.0, 1.0, 0.0, 0.0, e, 0.0, 0.0, 0.0, 1.0]);
        j.transpose() * j
    }

    #[test]
    fn holds_the_less_significant_member_of_an_undetermined_pair() {
        let jtj = near_pair();
        let layout = Layout {
            n_joints: 1,
            n_strings: 0,
        };
        let cov = crate::identify::unit_covariance(&jtj).unwrap();
        let sigma = 0.01;
        let sd = |k: usize| sigma * cov[(k, k)].sqrt();
        let find = |jtj: &DMatrix<f64>, dev: &[f64], max_z: f64, joint: bool| {
            undetermined(jtj, &[0, 1, 2], dev, sigma, max_z, |_| joint, &layout)
        };
        // Both members within 3 sigma: the one nearer nominal is held and
        // named with its partner; the independent column is never a
        // candidate, however small its deviation.
        let dev = [1.0 * sd(0), 0.5 * sd(1), 0.0];
        let u = find(&jtj, &dev, UNDETERMINED_Z, true).expect("an undetermined pair");
        assert_eq!(u.at, 1);
        assert_eq!(u.fixed.name, layout.name(1));
        assert_eq!(u.fixed.aliased_with, vec![layout.name(0)]);
        assert_eq!(u.fixed.reason, FixedReason::Undetermined);
        // The linearised shift takes the held one back to nominal and hands
        // its part to the partner; the independent column does not move.
        assert!((u.shift[1] + dev[1]).abs() < 1e-9 * sd(1));
        assert!(u.shift[0].abs() > 0.1 * sd(0));
        assert!(u.shift[2].abs() < 1e-9 * sd(2));
        // Not with a non-joint parameter, nor with max_z 0.
        assert!(find(&jtj, &dev, UNDETERMINED_Z, false).is_none());
        assert!(find(&jtj, &dev, 0.0, true).is_none());
        // A significant member stays; its partner, within 3 sigma, goes.
        let dev = [1.0 * sd(0), 4.0 * sd(1), 0.0];
        assert_eq!(find(&jtj, &dev, UNDETERMINED_Z, true).unwrap().at, 0);
        // Both significant: none.
        let dev = [3.5 * sd(0), 4.0 * sd(1), 0.0];
        assert!(find(&jtj, &dev, UNDETERMINED_Z, true).is_none());
        // A pair separated by more than the near-alias sine is left alone.
        let j = DMatrix::from_row_slice(3, 3, &[1.0, 1.0, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0, 1.0]);
        assert!(find(&(j.transpose() * j), &[0.0; 3], UNDETERMINED_Z, true).is_none());
    }

    #[test]
    fn condition_number_of_the_scaled_columns() {
        // Column scale does not matter; the angle between columns does.
        let j = DMatrix::from_row_slice(2, 2, &[1000.0, 0.0, 0.0, 0.001]);
        assert!((condition_number(&(j.transpose() * &j)) - 1.0).abs() < 1e-9);
        let c = condition_number(&near_pair());
        assert!(c > 100.0 && c.is_finite(), "{c}");
        assert_eq!(condition_number(&DMatrix::zeros(0, 0)), f64::INFINITY);
    }
}
