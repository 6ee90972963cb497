//! The linearised problem of a round: the normal equations of the train
//! poses split by cross-validation fold, the SSE drop of a column subset,
//! its cross-validated SSE, and the alias check of a candidate's columns.

use nalgebra::{DMatrix, DVector};

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
    let mut acc = FoldAccumulator::new(x.len());
    problem.rows(x, |pos, r, row| acc.add(fold_of[pos], r, row));
    acc.finish()
}

/// The normal equations of rows given one at a time, by fold: what
/// [`normals`] sums, for a caller that visits the rows for more.
pub(super) struct FoldAccumulator {
    n: usize,
    up: Vec<Vec<f64>>,
    g: Vec<Vec<f64>>,
    rr: Vec<f64>,
    rows: usize,
    runs: Vec<(usize, usize)>,
}

impl FoldAccumulator {
    /// Nothing yet, for rows of `n` columns.
    pub(super) fn new(n: usize) -> Self {
        FoldAccumulator {
            n,
            up: vec![vec![0.0; n * n]; FOLDS],
            g: vec![vec![0.0; n]; FOLDS],
            rr: vec![0.0; FOLDS],
            rows: 0,
            runs: Vec::new(),
        }
    }

    /// Row `row` with residual `r`, into fold `f`.
    pub(super) fn add(&mut self, f: usize, r: f64, row: &[f64]) {
        accumulate(
            &mut self.up[f],
            &mut self.g[f],
            self.n,
            row,
            r,
            &mut self.runs,
        );
        self.rr[f] += r * r;
        self.rows += 1;
    }

    /// The normal equations of the rows added.
    pub(super) fn finish(self) -> Normals {
        let n = self.n;
        let a = self
            .up
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
            b: self.g,
            rr: self.rr,
            rows: self.rows,
        }
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

/// The tiny jitter added to a scaled block's unit diagonal, so that what
/// is singular by rounding still factors.
const RIDGE: f64 = 1e-12;

/// A candidate's columns appended to a base of `nb` columns, by fold: its
/// cross block with the base (`cross[f][c * nb + i]`: candidate column `c`
/// against base column `i`), its own block (`own[f][c * k + c2]`, upper:
/// `c <= c2`) and its `Jᵀr`. The blocks a full [`Normals`] of the augmented
/// problem would hold beyond the base's.
pub(super) struct Appended {
    pub(super) nb: usize,
    pub(super) k: usize,
    pub(super) cross: Vec<Vec<f64>>,
    pub(super) own: Vec<Vec<f64>>,
    pub(super) g: Vec<Vec<f64>>,
}

impl Appended {
    /// The blocks of all folds together.
    fn total(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let sum = |v: &[Vec<f64>]| {
            let mut t = vec![0.0; v[0].len()];
            for f in v {
                for (x, y) in t.iter_mut().zip(f) {
                    *x += y;
                }
            }
            t
        };
        (sum(&self.cross), sum(&self.own), sum(&self.g))
    }

    /// Entry `(c, c2)` of an own block (stored upper).
    fn own_at(&self, own: &[f64], c: usize, c2: usize) -> f64 {
        let (a, b) = if c <= c2 { (c, c2) } else { (c2, c) };
        own[a * self.k + b]
    }
}

/// The base columns of a linearised problem, scaled and factored once (all
/// folds together, and each fold's training part), so that each of many
/// candidates is checked for aliasing and cross-validated by block
/// elimination at the cost of its own columns: the numbers of
/// [`unaliased`] and [`cv_sse`] over the base and the candidate's columns,
/// to rounding. Refactoring the whole block for every candidate (and, in
/// the alias check, for every one of its columns) was most of the cost of
/// scoring a long session's corrections.
pub(super) struct BaseFactors {
    /// All folds together (`None`: the base does not factor).
    total: Option<Scaled>,
    /// Each fold's training part (all folds but that one).
    folds: Vec<Option<Scaled>>,
}

/// A block `A[cols, cols]` scaled to a unit diagonal plus [`RIDGE`], its
/// lower Cholesky factor `l`, and `z = l⁻¹ (b[cols] / d)`, as
/// [`solve_subset`] forms them.
struct Scaled {
    /// The base columns with a nonzero diagonal (absolute indices).
    cols: Vec<usize>,
    /// Their `sqrt(A[i, i])`.
    d: Vec<f64>,
    l: DMatrix<f64>,
    z: DVector<f64>,
}

impl Scaled {
    fn of(a: &DMatrix<f64>, b: &[f64], base: &[usize]) -> Option<Self> {
        let cols: Vec<usize> = base.iter().copied().filter(|&i| a[(i, i)] != 0.0).collect();
        let d: Vec<f64> = cols.iter().map(|&i| a[(i, i)].sqrt().max(1e-300)).collect();
        let k = cols.len();
        let mut s = DMatrix::from_fn(k, k, |i, j| a[(cols[i], cols[j])] / (d[i] * d[j]));
        for i in 0..k {
            s[(i, i)] += RIDGE;
        }
        let l = s.cholesky()?.unpack();
        let rhs = DVector::from_fn(k, |i, _| b[cols[i]] / d[i]);
        let z = l.solve_lower_triangular(&rhs)?;
        Some(Scaled { cols, d, l, z })
    }
}

impl BaseFactors {
    /// The columns `base` of `nm` (the base problem's normal equations).
    pub(super) fn new(nm: &Normals, base: &[usize]) -> Self {
        let (a, b, _) = nm.total();
        let total = Scaled::of(&a, &b, base);
        let folds = (0..nm.a.len())
            .map(|f| {
                let a_tr = &a - &nm.a[f];
                let b_tr: Vec<f64> = b.iter().zip(&nm.b[f]).map(|(x, y)| x - y).collect();
                Scaled::of(&a_tr, &b_tr, base)
            })
            .collect();
        BaseFactors { total, folds }
    }

    /// [`unaliased`] of the candidate columns `cand` (indices into `app`,
    /// checked in order) against the base: those kept.
    pub(super) fn unaliased(&self, app: &Appended, cand: &[usize]) -> Vec<usize> {
        let Some(t) = &self.total else {
            return Vec::new();
        };
        let (cross, own, _) = app.total();
        let nb = app.nb;
        // Each kept column's row of the growing factor: against the base,
        // against the columns kept before it, and its pivot.
        let mut rows: Vec<(DVector<f64>, Vec<f64>, f64)> = Vec::new();
        let mut keep: Vec<usize> = Vec::new();
        for &c in cand {
            let aii = app.own_at(&own, c, c);
            if aii <= 0.0 {
                continue;
            }
            let sc = aii.sqrt();
            let v = DVector::from_fn(t.cols.len(), |i, _| {
                cross[c * nb + t.cols[i]] / (t.d[i] * sc)
            });
            let Some(lb) = t.l.solve_lower_triangular(&v) else {
                continue;
            };
            let mut lk: Vec<f64> = Vec::with_capacity(keep.len());
            for (&cj, (ljb, ljk, pivot)) in keep.iter().zip(&rows) {
                let dj = app.own_at(&own, cj, cj).sqrt();
                let s = app.own_at(&own, cj, c) / (dj * sc)
                    - ljb.dot(&lb)
                    - ljk.iter().zip(&lk).map(|(x, y)| x * y).sum::<f64>();
                lk.push(s / pivot);
            }
            let norm2 = lb.norm_squared() + lk.iter().map(|x| x * x).sum::<f64>();
            let sin2 = (1.0 - norm2).max(0.0);
            if sin2.sqrt() > ALIAS_SINE {
                rows.push((lb, lk, (1.0 + RIDGE - norm2).sqrt()));
                keep.push(c);
            }
        }
        keep
    }

    /// [`cv_sse`] of the base with the candidate columns `cols` (indices
    /// into `app`); `nm` is the base problem's normal equations.
    pub(super) fn cv_sse(&self, nm: &Normals, app: &Appended, cols: &[usize]) -> f64 {
        let (cross_t, own_t, g_t) = app.total();
        let nb = app.nb;
        let mut total = 0.0;
        for (f, fold) in self.folds.iter().enumerate() {
            let Some(fb) = fold else {
                return f64::INFINITY;
            };
            let (cross_f, own_f, g_f) = (&app.cross[f], &app.own[f], &app.g[f]);
            let tr = |c: usize, c2: usize| app.own_at(&own_t, c, c2) - app.own_at(own_f, c, c2);
            let kl: Vec<usize> = cols.iter().copied().filter(|&c| tr(c, c) != 0.0).collect();
            let dk: Vec<f64> = kl.iter().map(|&c| tr(c, c).sqrt().max(1e-300)).collect();
            let (nbl, kk) = (fb.cols.len(), kl.len());
            let s_bk = DMatrix::from_fn(nbl, kk, |i, j| {
                let at = kl[j] * nb + fb.cols[i];
                (cross_t[at] - cross_f[at]) / (fb.d[i] * dk[j])
            });
            let Some(w) = fb.l.solve_lower_triangular(&s_bk) else {
                return f64::INFINITY;
            };
            let mut schur = DMatrix::from_fn(kk, kk, |i, j| tr(kl[i], kl[j]) / (dk[i] * dk[j]));
            for i in 0..kk {
                schur[(i, i)] += RIDGE;
            }
            schur -= w.tr_mul(&w);
            let Some(lk) = schur.cholesky().map(|c| c.unpack()) else {
                return f64::INFINITY;
            };
            let rhs_k = DVector::from_fn(kk, |i, _| (g_t[kl[i]] - g_f[kl[i]]) / dk[i]);
            let solved = lk
                .solve_lower_triangular(&(rhs_k - w.tr_mul(&fb.z)))
                .and_then(|zk| lk.tr_solve_lower_triangular(&zk))
                .and_then(|xk| {
                    let xb = fb.l.tr_solve_lower_triangular(&(&fb.z - &w * &xk))?;
                    Some((xb, xk))
                });
            let Some((xb, xk)) = solved else {
                return f64::INFINITY;
            };
            let db: Vec<f64> = (0..nbl).map(|i| -xb[i] / fb.d[i]).collect();
            let dkv: Vec<f64> = (0..kk).map(|j| -xk[j] / dk[j]).collect();
            let (af, bf) = (&nm.a[f], &nm.b[f]);
            let mut sse = nm.rr[f];
            for (i, &ci) in fb.cols.iter().enumerate() {
                sse += 2.0 * db[i] * bf[ci];
                for (j, &cj) in fb.cols.iter().enumerate() {
                    sse += db[i] * af[(ci, cj)] * db[j];
                }
                for (j, &c) in kl.iter().enumerate() {
                    sse += 2.0 * db[i] * cross_f[c * nb + ci] * dkv[j];
                }
            }
            for (i, &c) in kl.iter().enumerate() {
                sse += 2.0 * dkv[i] * g_f[c];
                for (j, &c2) in kl.iter().enumerate() {
                    sse += dkv[i] * app.own_at(own_f, c, c2) * dkv[j];
                }
            }
            total += sse;
        }
        total
    }
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
