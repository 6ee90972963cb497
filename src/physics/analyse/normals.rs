//! The linearised problem of a round: the normal equations of the train
//! poses split by cross-validation fold, the SSE drop of a column subset,
//! its cross-validated SSE, and the alias check of a candidate's columns.

use nalgebra::DMatrix;

use super::ALIAS_SINE;
use crate::identify::Observations;
use crate::physics::effects::{Context, EffectModel, Kind};
use crate::physics::problem::{EffectProblem, accumulate};

/// Cross-validation folds.
pub(super) const FOLDS: usize = 5;

/// Normal equations of the train poses, linearised at `p` with the
/// accepted effects at their fitted values and `extra` effects appended at
/// zero (their columns are what a candidate would add).
pub(super) fn train_normals(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    free: &[usize],
    accepted: &[EffectModel],
    extra: impl IntoIterator<Item = Kind>,
    fold_of: &[usize],
) -> Normals {
    let mut effects = accepted.to_vec();
    effects.extend(extra.into_iter().map(EffectModel::zero));
    let problem =
        EffectProblem::of_observations(obs, ctx, obs.train.clone(), p, free.to_vec(), effects);
    normals(&problem, &problem.x0(), fold_of)
}

/// Normal equations of a column set, split by fold.
pub(super) struct Normals {
    pub(super) n: usize,
    /// `JᵀJ` of each fold.
    pub(super) a: Vec<DMatrix<f64>>,
    /// `Jᵀr` of each fold.
    pub(super) b: Vec<Vec<f64>>,
    /// `rᵀr` of each fold.
    pub(super) rr: Vec<f64>,
    pub(super) rows: usize,
}

impl Normals {
    /// The normal equations of all folds together: `(JᵀJ, Jᵀr, rᵀr)`.
    pub(super) fn total(&self) -> (DMatrix<f64>, Vec<f64>, f64) {
        let mut a = DMatrix::zeros(self.n, self.n);
        let mut b = vec![0.0; self.n];
        let mut rr = 0.0;
        for f in 0..self.a.len() {
            a += &self.a[f];
            for i in 0..self.n {
                b[i] += self.b[f][i];
            }
            rr += self.rr[f];
        }
        (a, b, rr)
    }
}

/// One pass over the rows of `problem` at `x`, accumulated into the fold
/// each row's pose belongs to.
pub(super) fn normals(problem: &EffectProblem, x: &[f64], fold_of: &[usize]) -> Normals {
    let n = x.len();
    let mut up = vec![vec![0.0; n * n]; FOLDS];
    let mut g = vec![vec![0.0; n]; FOLDS];
    let mut rr = vec![0.0; FOLDS];
    let mut rows = 0;
    let mut runs = Vec::new();
    problem.rows(x, |pos, r, row| {
        let f = fold_of[pos];
        accumulate(&mut up[f], &mut g[f], n, row, r, &mut runs);
        rr[f] += r * r;
        rows += 1;
    });
    let a = up
        .iter()
        .map(|u| {
            DMatrix::from_fn(
                n,
                n,
                |i, j| if i <= j { u[i * n + j] } else { u[j * n + i] },
            )
        })
        .collect();
    Normals {
        n,
        a,
        b: g,
        rr,
        rows,
    }
}

/// `min |r + J δ|²` over the columns `cols`: the SSE drop `bᵀA⁻¹b` and `δ`.
/// A column no row supports (all zero, e.g. a backlash's unknown-approach
/// offset when cross-validation holds out the poses it covers) stays at 0.
pub(super) fn solve_subset(a: &DMatrix<f64>, b: &[f64], cols: &[usize]) -> Option<(f64, Vec<f64>)> {
    if cols.iter().any(|&i| a[(i, i)] == 0.0) {
        let live: Vec<usize> = cols.iter().copied().filter(|&i| a[(i, i)] != 0.0).collect();
        let (drop, d) = solve_subset(a, b, &live)?;
        let mut it = d.into_iter();
        let full = cols
            .iter()
            .map(|&i| {
                if a[(i, i)] == 0.0 {
                    0.0
                } else {
                    it.next().unwrap_or(0.0)
                }
            })
            .collect();
        return Some((drop, full));
    }
    let k = cols.len();
    if k == 0 {
        return Some((0.0, vec![]));
    }
    let d: Vec<f64> = cols.iter().map(|&i| a[(i, i)].sqrt().max(1e-300)).collect();
    let mut s = DMatrix::from_fn(k, k, |i, j| a[(cols[i], cols[j])] / (d[i] * d[j]));
    for i in 0..k {
        s[(i, i)] += 1e-12;
    }
    let rhs = nalgebra::DVector::from_fn(k, |i, _| b[cols[i]] / d[i]);
    let ch = s.cholesky()?;
    let y = ch.solve(&rhs);
    let drop = rhs.dot(&y);
    Some((drop, (0..k).map(|i| -y[i] / d[i]).collect()))
}

/// Cross-validated SSE of the column set `cols` (linearised refits).
pub(super) fn cv_sse(nm: &Normals, a: &DMatrix<f64>, b: &[f64], cols: &[usize]) -> f64 {
    let mut total = 0.0;
    for f in 0..nm.a.len() {
        let af = &nm.a[f];
        let bf = &nm.b[f];
        let a_tr = a - af;
        let b_tr: Vec<f64> = b.iter().zip(bf).map(|(x, y)| x - y).collect();
        let delta = match solve_subset(&a_tr, &b_tr, cols) {
            Some((_, d)) => d,
            None => return f64::INFINITY,
        };
        let mut sse = nm.rr[f];
        for (i, &ci) in cols.iter().enumerate() {
            sse += 2.0 * delta[i] * bf[ci];
            for (j, &cj) in cols.iter().enumerate() {
                sse += delta[i] * af[(ci, cj)] * delta[j];
            }
        }
        total += sse;
    }
    total
}

/// Columns of `cand` (absolute indices) that are not aliased with `base`.
pub(super) fn unaliased(a: &DMatrix<f64>, base: &[usize], cand: &[usize]) -> Vec<usize> {
    let mut keep = Vec::new();
    for &c in cand {
        let aii = a[(c, c)];
        if aii <= 0.0 {
            continue;
        }
        let mut cols = base.to_vec();
        cols.extend(&keep);
        let bcol: Vec<f64> = (0..a.nrows()).map(|r| a[(r, c)]).collect();
        // Part of column c explained by the others: the "drop" of fitting
        // column c's own values with them.
        let explained = solve_subset(a, &bcol, &cols).map(|(d, _)| d).unwrap_or(aii);
        let sin2 = ((aii - explained) / aii).max(0.0);
        if sin2.sqrt() > ALIAS_SINE {
            keep.push(c);
        }
    }
    keep
}
