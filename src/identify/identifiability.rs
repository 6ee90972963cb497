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

use super::report::FixedParam;
use crate::kinematics::Layout;

/// Relative size of the orthogonal part below which a column counts as a
/// combination of the others: 1e-3 in sine (about 0.06°), where the
/// estimate's uncertainty is a thousand times that of a well-placed
/// parameter.
pub const DEFAULT_TOLERANCE: f64 = 1e-3;

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
            });
        }
    }
    let m = kept.len();
    let condition_number = if m == 0 {
        f64::INFINITY
    } else {
        let sub = DMatrix::from_fn(m, m, |i, j| g(kept[i], kept[j]));
        let ev = sub.symmetric_eigenvalues();
        let max = ev.iter().cloned().fold(0.0, f64::max);
        let min = ev.iter().cloned().fold(f64::INFINITY, f64::min).max(0.0);
        (max / min).sqrt()
    };
    Selection {
        free: kept.iter().map(|&c| candidates[c]).collect(),
        fixed,
        condition_number,
    }
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
}
