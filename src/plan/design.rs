//! The choice of poses: greedy I-optimal selection with a Fedorov exchange.
//!
//! Each candidate contributes `m` rows `J_i` (one per string, or three for a
//! point instrument) over the parameters to determine, column-scaled by each
//! parameter's prior size and divided by the reading noise, so that the
//! information of a set `S` is `M = I + Σ_{i∈S} J_iᵀ J_i` (the `I` is the
//! prior: a deviation of the nominal tolerance). The criterion is the
//! expected squared error of the calibrated model's T at random valid poses,
//! `trace(W M⁻¹)` with `W` the mean of `J_Tᵀ J_T` over such poses: the
//! quantity compensation delivers, where D-optimality would weigh a
//! parameter no pose's T depends on like one every pose's does.
//!
//! Adding or removing pose `s` changes `M⁻¹` by a rank-`m` term; each
//! candidate keeps `G_i = J_i M⁻¹ J_iᵀ` and `H_i = J_i M⁻¹ W M⁻¹ J_iᵀ`
//! (`m × m`), updated in `O(m² p)` per candidate, so that its gain
//! `trace((I + G_i)⁻¹ H_i)` costs `O(m³)`: a step over 10,000 candidates is
//! a few million operations rather than a `p × p` solve per candidate.
//! Written here rather than taken from a crate: no Rust crate does
//! optimal experimental design, and the updates are what make 10,000
//! candidates cheap.

use nalgebra::DMatrix;

mod kernel;

use kernel::{rows_times, transpose};

/// Candidates' scaled rows and the prediction weight.
pub struct Pool {
    /// Rows per candidate.
    pub m: usize,
    /// Columns (parameters and effect coefficients).
    pub p: usize,
    /// Per candidate, `m × p` row-major.
    pub rows: Vec<Vec<f64>>,
    /// `p × p`: mean over prediction poses of `J_Tᵀ J_T` (mm² per unit²).
    pub w: DMatrix<f64>,
}

/// What a selection minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Criterion {
    /// `trace(W M⁻¹)`: the expected squared error of T at random valid
    /// poses (the module's comment).
    #[default]
    IOptimal,
    /// `-log det M`: the volume of the parameters' confidence region,
    /// every scaled parameter weighed alike.
    DOptimal,
}

/// The running state of a selection.
struct State<'a> {
    pool: &'a Pool,
    criterion: Criterion,
    minv: DMatrix<f64>,
    g: Vec<Vec<f64>>,
    h: Vec<Vec<f64>>,
    chosen: Vec<bool>,
    /// `trace(W M⁻¹)`.
    objective: f64,
    /// The candidates kept up to date and compared (all, until the
    /// exchange narrows them to a shortlist).
    active: Vec<usize>,
}

/// What a rank-`m` change of `M⁻¹` takes to every kept `G_i` and `H_i`
/// (see [`State::update`]): per parameter `k`, `U`'s and `R`'s rows side
/// by side (`p × 2m`), `S⁻¹` and `S⁻¹ UᵀWU S⁻¹` (`m × m`), row-major.
struct Change {
    ur: Vec<f64>,
    sinv: Vec<f64>,
    core: Vec<f64>,
}

impl<'a> State<'a> {
    fn new(pool: &'a Pool) -> Self {
        let (m, p) = (pool.m, pool.p);
        let mut g = Vec::with_capacity(pool.rows.len());
        let mut h = Vec::with_capacity(pool.rows.len());
        // Row a of wj: W J_aᵀ (W column-major: its k-th column's entries
        // side by side, as `rows_times` takes them).
        let mut wj = vec![0.0; m * p];
        let mut t = vec![0.0; p * m];
        for j in &pool.rows {
            let mut gi = vec![0.0; m * m];
            let mut hi = vec![0.0; m * m];
            rows_times(j, p, pool.w.as_slice(), p, &mut wj);
            // G = J Jᵀ; H = J W Jᵀ (row b, column a: J_b · W J_aᵀ).
            transpose(j, p, &mut t);
            rows_times(j, p, &t, m, &mut gi);
            transpose(&wj, p, &mut t);
            rows_times(j, p, &t, m, &mut hi);
            g.push(gi);
            h.push(hi);
        }
        State {
            pool,
            criterion: Criterion::IOptimal,
            minv: DMatrix::identity(p, p),
            g,
            h,
            chosen: vec![false; pool.rows.len()],
            active: (0..pool.rows.len()).collect(),
            objective: pool.w.trace(),
        }
    }

    /// Recompute every candidate's `G_i` and `H_i` from `M⁻¹`. The rank-m
    /// updates subtract numbers of the size the first steps had (the
    /// prior's) to leave ones thousands of times smaller: without a
    /// refresh their rounding reorders the late gains.
    fn refresh(&mut self) {
        let (m, p) = (self.pool.m, self.pool.p);
        // M⁻¹ and M⁻¹ W M⁻¹, column-major: the k-th entries of every row
        // side by side, as `rows_times` takes them.
        let a = &self.minv * &self.pool.w * &self.minv;
        let mut x = vec![0.0; m * p];
        let mut y = vec![0.0; m * p];
        let mut jt = vec![0.0; p * m];
        for &i in &self.active {
            let rows = &self.pool.rows[i];
            // x = J M⁻¹, y = J M⁻¹ W M⁻¹ (both symmetric on the right).
            rows_times(rows, p, self.minv.as_slice(), p, &mut x);
            rows_times(rows, p, a.as_slice(), p, &mut y);
            transpose(rows, p, &mut jt);
            rows_times(&x, p, &jt, m, &mut self.g[i]);
            rows_times(&y, p, &jt, m, &mut self.h[i]);
        }
    }

    /// Reduction of the objective if `i` were added:
    /// `trace((I + G_i)⁻¹ H_i)`.
    fn gain(&self, i: usize) -> f64 {
        match self.criterion {
            Criterion::IOptimal => trace_solve(&self.g[i], &self.h[i], self.pool.m, 1.0),
            Criterion::DOptimal => log_det(&self.g[i], self.pool.m, 1.0),
        }
        .unwrap_or(f64::NEG_INFINITY)
    }

    /// Increase of the objective if chosen `i` were removed:
    /// `trace((I - G_i)⁻¹ H_i)`.
    fn loss(&self, i: usize) -> f64 {
        match self.criterion {
            Criterion::IOptimal => trace_solve(&self.g[i], &self.h[i], self.pool.m, -1.0),
            // det(M - JᵀJ) = det M · det(I - G).
            Criterion::DOptimal => log_det(&self.g[i], self.pool.m, -1.0).map(|v| -v),
        }
        .unwrap_or(f64::INFINITY)
    }

    /// Add (`sign` +1) or remove (-1) candidate `s`. False when the
    /// update does not solve (numerically degenerate): nothing changed,
    /// and a candidate that could not be added is dropped from the pool,
    /// so that the greedy steps do not pick it again and again.
    #[must_use]
    fn update(&mut self, s: usize, sign: f64) -> bool {
        let Some(change) = self.change(s, sign) else {
            return false;
        };
        self.update_kept(&change);
        true
    }

    /// The part of [`State::update`] that is not every kept `G_i` and
    /// `H_i`: `M⁻¹`, the objective and the chosen set, and the terms the
    /// kept ones then take ([`State::update_kept`]); `None` as `update`'s
    /// false.
    fn change(&mut self, s: usize, sign: f64) -> Option<Change> {
        let (m, p) = (self.pool.m, self.pool.p);
        let js = DMatrix::from_row_slice(m, p, &self.pool.rows[s]);
        let u = &self.minv * js.transpose(); // p × m
        let smat = DMatrix::from_fn(m, m, |a, b| {
            self.g[s][a * m + b] + if a == b { sign } else { 0.0 }
        });
        let Some(sinv) = smat.try_inverse() else {
            if sign > 0.0 {
                self.active.retain(|&i| i != s);
            }
            return None;
        };
        let wu = &self.pool.w * &u;
        let r = &self.minv * &wu; // p × m
        let uwu = u.transpose() * &wu;
        let core = &sinv * &uwu * &sinv;
        self.objective -= (&sinv * &uwu).trace();
        self.minv -= &u * &sinv * u.transpose();
        self.chosen[s] = sign > 0.0;
        // Per parameter k, u's and r's rows side by side (`rows_times`):
        // the kept terms' loop runs over every candidate.
        let mut ur = vec![0.0; p * 2 * m];
        for (k, row) in ur.chunks_exact_mut(2 * m).enumerate() {
            for b in 0..m {
                row[b] = u[(k, b)];
                row[m + b] = r[(k, b)];
            }
        }
        Some(Change {
            ur,
            sinv: (0..m * m).map(|k| sinv[(k / m, k % m)]).collect(),
            core: (0..m * m).map(|k| core[(k / m, k % m)]).collect(),
        })
    }

    /// Every compared candidate's `G_i` and `H_i` after `change`, the
    /// usual numbers of rows as constants so that the small loops unroll
    /// (the same operations in the same order).
    fn update_kept(&mut self, change: &Change) {
        let (m, p) = (self.pool.m, self.pool.p);
        match m {
            3 => self.update_kept_m(3, p, change),
            4 => self.update_kept_m(4, p, change),
            _ => self.update_kept_m(m, p, change),
        }
    }

    /// [`State::update_kept`] for `m` rows.
    #[inline(always)]
    fn update_kept_m(&mut self, m: usize, p: usize, change: &Change) {
        let Change { ur, sinv, core } = change;
        // P = J_i U and Q = J_i R side by side: row a of P is
        // pq[a·2m..a·2m + m], of Q the m after.
        let mut pq = vec![0.0; m * 2 * m];
        let mut ps = vec![0.0; m * m];
        let mut pc = vec![0.0; m * m];
        let w = 2 * m;
        for &i in &self.active {
            rows_times(&self.pool.rows[i], p, ur, w, &mut pq);
            // ps = P Sinv, pc = P core.
            for a in 0..m {
                for b in 0..m {
                    let (mut x, mut y) = (0.0, 0.0);
                    for k in 0..m {
                        x += pq[a * w + k] * sinv[k * m + b];
                        y += pq[a * w + k] * core[k * m + b];
                    }
                    ps[a * m + b] = x;
                    pc[a * m + b] = y;
                }
            }
            let (gi, hi) = (&mut self.g[i], &mut self.h[i]);
            for a in 0..m {
                for b in 0..m {
                    let (mut dg, mut dh, mut quad) = (0.0, 0.0, 0.0);
                    for k in 0..m {
                        // P Sinv Pᵀ; P Sinv Qᵀ + Q Sinv Pᵀ; P core Pᵀ.
                        dg += ps[a * m + k] * pq[b * w + k];
                        dh += ps[a * m + k] * pq[b * w + m + k] + ps[b * m + k] * pq[a * w + m + k];
                        quad += pc[a * m + k] * pq[b * w + k];
                    }
                    gi[a * m + b] -= dg;
                    hi[a * m + b] += quad - dh;
                }
            }
        }
    }

    /// Add the best candidate left, refreshing the bookkeeping when the
    /// objective has dropped far since `refreshed_at` (the objective at
    /// the last refresh); `None` when no candidate is left.
    fn add_best(&mut self, refreshed_at: &mut f64) -> Option<usize> {
        loop {
            let (i, _) = self.best()?;
            // A candidate that does not solve left the pool: try the next.
            let Some(change) = self.change(i, 1.0) else {
                continue;
            };
            if self.objective < REFRESH_DROP * *refreshed_at {
                // The refresh recomputes every kept G_i and H_i from M⁻¹
                // alone: the change to them would be overwritten.
                self.refresh();
                *refreshed_at = self.objective;
            } else {
                self.update_kept(&change);
            }
            return Some(i);
        }
    }

    /// The unchosen candidate with the largest gain.
    fn best(&self) -> Option<(usize, f64)> {
        self.active
            .iter()
            .copied()
            .filter(|&i| !self.chosen[i])
            .map(|i| (i, self.gain(i)))
            .filter(|(_, g)| g.is_finite())
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }
}

/// `trace((I + sign·G)⁻¹ H)` for `m × m` row-major `g` and `h` by an
/// in-place Cholesky factorisation (no allocation, unrolled for each `m`
/// up to 8); `None` when `I + sign·G` is not positive definite.
fn trace_solve(g: &[f64], h: &[f64], m: usize, sign: f64) -> Option<f64> {
    match m {
        1 => trace_solve_m::<1>(g, h, sign),
        2 => trace_solve_m::<2>(g, h, sign),
        3 => trace_solve_m::<3>(g, h, sign),
        4 => trace_solve_m::<4>(g, h, sign),
        5 => trace_solve_m::<5>(g, h, sign),
        6 => trace_solve_m::<6>(g, h, sign),
        7 => trace_solve_m::<7>(g, h, sign),
        8 => trace_solve_m::<8>(g, h, sign),
        _ => {
            let s = DMatrix::from_fn(m, m, |a, b| {
                sign * g[a * m + b] + if a == b { 1.0 } else { 0.0 }
            });
            s.cholesky()
                .map(|c| c.solve(&DMatrix::from_row_slice(m, m, h)).trace())
        }
    }
}

/// [`trace_solve`] for `M` rows.
fn trace_solve_m<const M: usize>(g: &[f64], h: &[f64], sign: f64) -> Option<f64> {
    let mut l = [[0.0; M]; M];
    for a in 0..M {
        for b in 0..=a {
            let mut v = sign * g[a * M + b] + if a == b { 1.0 } else { 0.0 };
            for k in 0..b {
                v -= l[a][k] * l[b][k];
            }
            if a == b {
                if v <= 0.0 {
                    return None;
                }
                l[a][a] = v.sqrt();
            } else {
                l[a][b] = v / l[b][b];
            }
        }
    }
    // trace(S⁻¹ H) = Σ_c (S⁻¹ H)[c][c]: solve L Lᵀ x = H e_c per column c.
    let mut total = 0.0;
    let mut x = [0.0; M];
    for c in 0..M {
        for a in 0..M {
            let mut v = h[a * M + c];
            for k in 0..a {
                v -= l[a][k] * x[k];
            }
            x[a] = v / l[a][a];
        }
        for a in (0..M).rev() {
            let mut v = x[a];
            for k in a + 1..M {
                v -= l[k][a] * x[k];
            }
            x[a] = v / l[a][a];
        }
        total += x[c];
    }
    Some(total)
}

/// The best design with weights over the pool (summing to one), without
/// the prior: `min trace(W M(w)⁻¹)` with `M(w) = Σ w_i J_iᵀ J_i`, by the
/// multiplicative algorithm (`w_i ← w_i √(d_i / φ)`, `d_i = trace(J_i M⁻¹ W
/// M⁻¹ J_iᵀ)`, which converges for such linear criteria) for `iterations`
/// steps. Returns `φ` of the weights reached and a lower bound on the
/// optimum, `2φ - max_i d_i` (φ is convex and its derivative towards
/// candidate `i` is `φ - d_i`). `n` poses chosen from the pool have
/// `trace(W (Σ J_iᵀ J_i)⁻¹) >= bound / n`: `1/n` of their information
/// is such a weighted design.
pub fn continuous_bound(pool: &Pool, iterations: usize) -> (f64, f64) {
    let (m, p, n) = (pool.m, pool.p, pool.rows.len());
    let mut w = vec![1.0 / n as f64; n];
    let mut d = vec![0.0; n];
    let (mut phi, mut lower) = (f64::INFINITY, 0.0);
    for _ in 0..iterations {
        let mut mm = DMatrix::zeros(p, p);
        for (r, wi) in pool.rows.iter().zip(&w) {
            if *wi < 1e-12 {
                continue;
            }
            let j = DMatrix::from_row_slice(m, p, r);
            mm.gemm_tr(*wi, &j, &j, 1.0);
        }
        let Some(minv) = mm.try_inverse() else {
            return (f64::INFINITY, 0.0);
        };
        let a = &minv * &pool.w * &minv;
        phi = (&pool.w * &minv).trace();
        let mut dmax = 0.0f64;
        for (r, di) in pool.rows.iter().zip(d.iter_mut()) {
            let j = DMatrix::from_row_slice(m, p, r);
            *di = (&j * &a).component_mul(&j).sum();
            dmax = dmax.max(*di);
        }
        lower = 2.0 * phi - dmax;
        let mut total = 0.0;
        for (wi, di) in w.iter_mut().zip(&d) {
            *wi *= (di / phi).sqrt();
            total += *wi;
        }
        w.iter_mut().for_each(|v| *v /= total);
    }
    (phi, lower)
}

/// `log det(I + sign·G)` for `m × m` row-major `g`; `None` when not
/// positive definite.
fn log_det(g: &[f64], m: usize, sign: f64) -> Option<f64> {
    let s = DMatrix::from_fn(m, m, |a, b| {
        sign * g[a * m + b] + if a == b { 1.0 } else { 0.0 }
    });
    s.cholesky()
        .map(|c| 2.0 * c.l().diagonal().iter().map(|v| v.ln()).sum::<f64>())
}

/// Candidates (besides the chosen) the exchange compares.
const EXCHANGE_SHORTLIST: usize = 1000;

/// Fall of the objective after which the kept `G_i`, `H_i` are recomputed
/// (see `State::refresh`).
const REFRESH_DROP: f64 = 0.25;

/// The selection and what it predicts.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Chosen candidates, in the order greedy chose them (before exchange:
    /// its prefixes are the nested smaller designs).
    pub greedy_order: Vec<usize>,
    /// `trace(W M⁻¹)` after each greedy step (mm², with the prior).
    pub greedy_objective: Vec<f64>,
    /// The final `n` candidates after the exchange.
    pub chosen: Vec<usize>,
    /// `trace(W M⁻¹)` of the final set (mm², with the prior).
    pub objective: f64,
    /// Swaps the exchange made.
    pub swaps: usize,
}

/// Add candidates greedily to poses already recorded, whose information
/// (`M = I + Σ JᵀJ` over them, in the pool's scaling, prior included) is
/// `information`, until `done(objective)` or `max_n` poses: what to record
/// next when a session leaves some parameters undetermined. Returns the
/// candidates in the order chosen and `M⁻¹` after them; `None` when
/// `information` is singular.
pub fn extend(
    pool: &Pool,
    information: &DMatrix<f64>,
    max_n: usize,
    done: impl Fn(&DMatrix<f64>) -> bool,
) -> Option<(Vec<usize>, DMatrix<f64>)> {
    let mut st = State::new(pool);
    st.minv = information.clone().try_inverse()?;
    st.objective = (&pool.w * &st.minv).trace();
    st.refresh();
    let mut refreshed_at = st.objective;
    let mut order = Vec::new();
    while order.len() < max_n && !done(&st.minv) {
        let Some(i) = st.add_best(&mut refreshed_at) else {
            break;
        };
        order.push(i);
    }
    Some((order, st.minv))
}

/// Choose `n` of the pool's candidates: greedily up to `n_greedy >= n`
/// (the prefixes give the curve over N), then improve the first `n` by
/// exchanges (each chosen pose swapped for the candidate that lowers the
/// objective most) for at most `passes` passes.
pub fn select(pool: &Pool, n: usize, n_greedy: usize, passes: usize) -> Selection {
    select_by(pool, n, n_greedy, passes, Criterion::IOptimal)
}

/// [`select`] by `criterion`.
pub fn select_by(
    pool: &Pool,
    n: usize,
    n_greedy: usize,
    passes: usize,
    criterion: Criterion,
) -> Selection {
    let n_greedy = n_greedy.max(n).min(pool.rows.len());
    let n = n.min(n_greedy);
    let mut st = State::new(pool);
    st.criterion = criterion;
    let mut order = Vec::new();
    let mut objective = Vec::new();
    let mut at_n: Option<State> = None;
    let mut refreshed_at = st.objective;
    while order.len() < n_greedy {
        let Some(i) = st.add_best(&mut refreshed_at) else {
            break;
        };
        order.push(i);
        objective.push(st.objective);
        if order.len() == n {
            at_n = Some(State {
                pool,
                criterion,
                minv: st.minv.clone(),
                g: st.g.clone(),
                h: st.h.clone(),
                chosen: st.chosen.clone(),
                objective: st.objective,
                active: st.active.clone(),
            });
        }
    }
    let Some(mut st) = at_n else {
        return Selection {
            chosen: order.clone(),
            objective: st.objective,
            greedy_order: order,
            greedy_objective: objective,
            swaps: 0,
        };
    };
    let mut chosen: Vec<usize> = order[..n].to_vec();
    // The exchange compares the chosen poses with the candidates that
    // would help most now: a swap from outside them is rare, and each
    // exchange step costs an update of every candidate compared.
    let mut ranked: Vec<(usize, f64)> = (0..pool.rows.len())
        .filter(|&i| !st.chosen[i])
        .map(|i| (i, st.gain(i)))
        .collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
    st.active = chosen
        .iter()
        .copied()
        .chain(ranked.iter().take(EXCHANGE_SHORTLIST).map(|&(i, _)| i))
        .collect();
    let mut swaps = 0;
    for _ in 0..passes {
        st.refresh();
        let mut improved = false;
        for slot in 0..chosen.len() {
            let out = chosen[slot];
            let loss = st.loss(out);
            let before = st.objective;
            if !st.update(out, -1.0) {
                continue;
            }
            match st.best() {
                Some((inn, gain))
                    if inn != out && gain > loss * (1.0 + 1e-6) && st.update(inn, 1.0) =>
                {
                    chosen[slot] = inn;
                    swaps += 1;
                    improved = true;
                }
                _ => {
                    let _ = st.update(out, 1.0);
                    // Rounding only: keep the bookkeeping exact.
                    st.objective = before;
                }
            }
        }
        if !improved {
            break;
        }
    }
    Selection {
        greedy_order: order,
        greedy_objective: objective,
        chosen,
        objective: st.objective,
        swaps,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn random_pool(seed: u64, n: usize, m: usize, p: usize) -> Pool {
        let mut rng = Rng::new(seed);
        let rows = (0..n)
            .map(|_| (0..m * p).map(|_| rng.normal() * 3.0).collect())
            .collect();
        let c = DMatrix::from_fn(p + 2, p, |_, _| rng.normal());
        Pool {
            m,
            p,
            rows,
            w: c.transpose() * c,
        }
    }

    /// `trace(W M⁻¹)` computed directly.
    fn direct(pool: &Pool, set: &[usize]) -> f64 {
        let mut mm = DMatrix::identity(pool.p, pool.p);
        for &i in set {
            let j = DMatrix::from_row_slice(pool.m, pool.p, &pool.rows[i]);
            mm += j.transpose() * j;
        }
        (&pool.w * mm.try_inverse().unwrap()).trace()
    }

    #[test]
    fn the_rank_m_updates_equal_a_direct_computation() {
        let pool = random_pool(1, 60, 4, 9);
        let sel = select(&pool, 12, 15, 3);
        for (k, &obj) in sel.greedy_objective.iter().enumerate() {
            let d = direct(&pool, &sel.greedy_order[..=k]);
            assert!(
                (obj - d).abs() < 1e-8 * d.max(1.0),
                "step {k}: {obj} vs {d}"
            );
        }
        let d = direct(&pool, &sel.chosen);
        assert!(
            (sel.objective - d).abs() < 1e-8 * d.max(1.0),
            "{} vs {d}",
            sel.objective
        );
        let mut c = sel.chosen.clone();
        c.sort();
        c.dedup();
        assert_eq!(c.len(), 12, "no pose twice");
    }

    /// At realistic scales (rows of hundreds, 30 columns) the kept `G_i`
    /// and `H_i` of every candidate still equal their definitions after
    /// many updates with the refreshes `select` makes, so the gains the
    /// greedy step compares are right.
    #[test]
    fn kept_gains_stay_exact_at_realistic_scales() {
        let mut pool = random_pool(4, 300, 4, 30);
        for r in pool.rows.iter_mut() {
            r.iter_mut().for_each(|v| *v *= 40.0);
        }
        let mut st = State::new(&pool);
        let mut refreshed_at = st.objective;
        for step in 0..40 {
            let (i, _) = st.best().unwrap();
            assert!(st.update(i, 1.0));
            if st.objective < REFRESH_DROP * refreshed_at {
                st.refresh();
                refreshed_at = st.objective;
            }
            if step % 13 == 12 {
                let mm = st.minv.clone();
                for c in (0..300).step_by(17) {
                    let j = DMatrix::from_row_slice(4, 30, &pool.rows[c]);
                    let g = &j * &mm * j.transpose();
                    let h = &j * &mm * &pool.w * &mm * j.transpose();
                    for k in 0..16 {
                        assert!(
                            (g[(k / 4, k % 4)] - st.g[c][k]).abs() < 1e-4 * g.norm(),
                            "G of {c} at {step}"
                        );
                        assert!(
                            (h[(k / 4, k % 4)] - st.h[c][k]).abs() < 1e-4 * h.norm(),
                            "H of {c} at {step}: {} vs {}",
                            h[(k / 4, k % 4)],
                            st.h[c][k]
                        );
                    }
                }
            }
        }
    }

    /// Extending from recorded poses equals the greedy choice made with
    /// the recorded poses' information as the start, and stops as asked.
    #[test]
    fn extension_starts_from_the_recorded_information() {
        let pool = random_pool(5, 80, 3, 8);
        let recorded = [3usize, 17, 40];
        let mut m0 = DMatrix::identity(8, 8);
        for &i in &recorded {
            let j = DMatrix::from_row_slice(3, 8, &pool.rows[i]);
            m0 += j.transpose() * j;
        }
        let (order, minv) = extend(&pool, &m0, 4, |_| false).unwrap();
        assert_eq!(order.len(), 4);
        let mut set: Vec<usize> = recorded.to_vec();
        for (k, &i) in order.iter().enumerate() {
            // Each step is the best single addition to what is there (the
            // recorded poses are not candidates: they may come again).
            let best = (0..80)
                .filter(|c| !order[..k].contains(c))
                .map(|c| {
                    let mut s = set.clone();
                    s.push(c);
                    (c, direct(&pool, &s))
                })
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            assert_eq!(i, best.0);
            set.push(i);
        }
        let d = direct(&pool, &set);
        assert!(((&pool.w * &minv).trace() - d).abs() < 1e-8 * d.max(1.0));
        let (none, _) = extend(&pool, &m0, 4, |_| true).unwrap();
        assert!(none.is_empty());
    }

    /// No set of n poses beats the weighted design's bound, the greedy
    /// set comes near it, and the bound is near the weighted optimum.
    #[test]
    fn the_weighted_bound_bounds_every_set() {
        let pool = random_pool(6, 300, 3, 8);
        let (phi, lower) = continuous_bound(&pool, 400);
        assert!(
            lower > 0.0 && lower <= phi && lower > 0.95 * phi,
            "{lower} {phi}"
        );
        // Without the prior: `direct` with the prior's I, taken out.
        let plain = |set: &[usize]| {
            let mut mm = DMatrix::zeros(pool.p, pool.p);
            for &i in set {
                let j = DMatrix::from_row_slice(pool.m, pool.p, &pool.rows[i]);
                mm += j.transpose() * j;
            }
            (&pool.w * mm.try_inverse().unwrap()).trace()
        };
        let n = 20;
        let sel = select(&pool, n, n, 5);
        let chosen = plain(&sel.chosen) * n as f64;
        assert!(
            chosen >= lower && chosen < 1.3 * phi,
            "{chosen} {lower} {phi}"
        );
        let mut rng = Rng::new(3);
        for _ in 0..20 {
            let mut idx: Vec<usize> = (0..300).collect();
            rng.shuffle(&mut idx);
            assert!(plain(&idx[..n]) * n as f64 >= lower);
        }
    }

    /// D-optimal: the first pose is the one whose information has the
    /// largest determinant with the prior, and the exchange never lowers
    /// `det M`.
    #[test]
    fn d_optimal_selection_maximises_the_determinant() {
        let pool = random_pool(7, 60, 3, 6);
        let det = |set: &[usize]| {
            let mut mm = DMatrix::identity(pool.p, pool.p);
            for &i in set {
                let j = DMatrix::from_row_slice(pool.m, pool.p, &pool.rows[i]);
                mm += j.transpose() * j;
            }
            mm.determinant()
        };
        let first = select_by(&pool, 1, 1, 0, Criterion::DOptimal);
        let best = (0..60)
            .max_by(|&a, &b| det(&[a]).total_cmp(&det(&[b])))
            .unwrap();
        assert_eq!(first.chosen, vec![best]);
        let sel = select_by(&pool, 8, 8, 5, Criterion::DOptimal);
        assert!(det(&sel.chosen) >= det(&sel.greedy_order[..8]) * (1.0 - 1e-9));
        let i_opt = select_by(&pool, 8, 8, 5, Criterion::IOptimal);
        assert!(det(&sel.chosen) >= det(&i_opt.chosen) * (1.0 - 1e-9));
    }

    #[test]
    fn greedy_gain_is_the_true_best_single_addition() {
        let pool = random_pool(2, 40, 3, 6);
        let sel = select(&pool, 1, 1, 0);
        let best = (0..40)
            .map(|i| (i, direct(&pool, &[i])))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        assert_eq!(sel.chosen, vec![best.0]);
    }

    #[test]
    fn exchange_never_makes_the_design_worse_and_beats_random_sets() {
        let pool = random_pool(3, 200, 4, 12);
        let sel = select(&pool, 10, 10, 5);
        let greedy = direct(&pool, &sel.greedy_order[..10]);
        assert!(sel.objective <= greedy * (1.0 + 1e-9));
        let mut rng = Rng::new(9);
        for _ in 0..50 {
            let mut idx: Vec<usize> = (0..200).collect();
            rng.shuffle(&mut idx);
            assert!(sel.objective < direct(&pool, &idx[..10]));
        }
    }
}
