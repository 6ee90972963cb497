//! The calibration problem augmented with effect coefficients: the free
//! geometric parameters plus every coefficient of a list of effects, on the
//! raw readings (strings or points), with analytic derivatives.

use nalgebra::{DMatrix, DVector, Vector3};

use super::effects::{Basis, Context, EffectModel};
use crate::identify::Observations;
use crate::identify::lm::LeastSquares;
use crate::kinematics::JointParam;
use crate::kinematics::chain::{Chain, OutputFrame, PointJacobian};
use crate::model::{Dataset, Measurement};

/// Geometric parameters (free ones from `free`, the rest from `full`) plus
/// all coefficients of `effects`. `x = [free values..., coefficients...]`.
pub struct EffectProblem<'a> {
    /// Kinematic structure.
    pub chain: Chain,
    /// Effect context of every pose of `data`.
    pub ctx: &'a Context,
    /// The recordings.
    pub data: &'a Dataset,
    /// Poses fitted (indices into `data.poses`).
    pub poses: Vec<usize>,
    /// Full geometric vector; free entries overwritten from `x`.
    pub full: Vec<f64>,
    /// Free geometric parameter indices.
    pub free: Vec<usize>,
    /// Effects whose coefficients are unknowns (their `coef` give `x0`).
    pub effects: Vec<EffectModel>,
}

impl<'a> EffectProblem<'a> {
    /// The problem over `poses` of a session's recordings, at geometry `p`
    /// with the parameters `free` unknown beside the effects' coefficients.
    pub fn of_observations(
        obs: &Observations<'a>,
        ctx: &'a Context,
        poses: Vec<usize>,
        p: &[f64],
        free: Vec<usize>,
        effects: Vec<EffectModel>,
    ) -> Self {
        EffectProblem {
            chain: obs.chain,
            ctx,
            data: obs.data,
            poses,
            full: p.to_vec(),
            free,
            effects,
        }
    }

    /// Total number of effect coefficients.
    pub fn n_coef(&self) -> usize {
        self.effects.iter().map(|e| e.kind.n_coef()).sum()
    }

    /// Starting point from `full` and the effects' coefficients.
    pub fn x0(&self) -> Vec<f64> {
        let mut x: Vec<f64> = self.free.iter().map(|&i| self.full[i]).collect();
        for e in &self.effects {
            x.extend_from_slice(&e.coef);
        }
        x
    }

    /// Geometric vector and effects at `x`.
    pub fn unpack(&self, x: &[f64]) -> (Vec<f64>, Vec<EffectModel>) {
        let mut p = self.full.clone();
        for (k, &i) in self.free.iter().enumerate() {
            p[i] = x[k];
        }
        let mut o = self.free.len();
        let effects = self
            .effects
            .iter()
            .map(|e| {
                let nc = e.kind.n_coef();
                let m = EffectModel {
                    kind: e.kind.clone(),
                    coef: x[o..o + nc].to_vec(),
                };
                o += nc;
                m
            })
            .collect();
        (p, effects)
    }

    /// Residual rows per pose.
    pub fn rows_per_pose(&self) -> usize {
        if self.data.n_strings > 0 {
            self.data.n_strings
        } else {
            3
        }
    }

    /// Visit every residual row at `x`: `f(position in poses, residual,
    /// derivative row)`. Residuals are predicted minus measured (mm).
    pub fn rows(&self, x: &[f64], mut f: impl FnMut(usize, f64, &[f64])) {
        self.visit::<false, true>(x, |_, _| {}, |pos, r, row, _| f(pos, r, row));
    }

    /// [`Self::rows`] without the derivative rows: `f(position in poses,
    /// residual)`, the same residuals (for costs and held-out errors).
    pub fn residuals(&self, x: &[f64], mut f: impl FnMut(usize, f64)) {
        self.visit::<false, false>(x, |_, _| {}, |pos, r, _, _| f(pos, r));
    }

    /// [`Self::rows`], with what a further effect's columns need: before a
    /// pose's rows, `pose_f(position in poses, frame)` (T's derivatives by
    /// each joint angle and by the thermal multiplier), and with each row
    /// its [`RowDir`]. A further effect's column at a row is then
    /// [`PoseFrame::column`] (the same arithmetic as the rows' own effect
    /// columns), so candidates can be fitted against a linearisation made
    /// once (`physics::analyse`'s fixed base).
    pub fn rows_framed(
        &self,
        x: &[f64],
        pose_f: impl FnMut(usize, &PoseFrame),
        f: impl FnMut(usize, f64, &[f64], RowDir),
    ) {
        self.visit::<true, true>(x, pose_f, f);
    }

    /// The one pass behind [`Self::rows`], [`Self::rows_framed`] and
    /// [`Self::residuals`]; with `FRAMES` false no frame is built (the
    /// thermal derivative only when an effect uses it), with `DERIV` false
    /// the derivative row is left unfilled (the residuals are the same).
    fn visit<const FRAMES: bool, const DERIV: bool>(
        &self,
        x: &[f64],
        mut pose_f: impl FnMut(usize, &PoseFrame),
        mut f: impl FnMut(usize, f64, &[f64], RowDir),
    ) {
        let (p, effects) = self.unpack(x);
        let l = self.chain.layout;
        let g = l.n_geometric();
        let n = l.n_joints;
        let ncol = x.len();
        let mut row = vec![0.0; ncol];
        let mut jac: PointJacobian = self.chain.new_jacobian();
        let mut pp = p.clone();
        let mut q = vec![0.0; n];
        let thermal_used = effects
            .iter()
            .any(|e| matches!(e.kind, super::effects::Kind::ThermalExpansion { .. }));
        let m = self.data.n_strings;
        let nf = self.free.len();
        let mut cols = LiveColumns::new(ncol - nf, m);
        let mut frame = PoseFrame::default();
        let mut bases = vec![Basis::default(); effects.len()];
        for (pos, &i) in self.poses.iter().enumerate() {
            let pose = &self.data.poses[i];
            // Each effect's basis once: the delta and the columns both
            // read it.
            for (e, b) in effects.iter().zip(bases.iter_mut()) {
                self.ctx.basis(&e.kind, i, b);
            }
            let delta = self.ctx.apply_bases(&effects, &bases);
            pp.copy_from_slice(&p);
            self.ctx.apply_thermal(&mut pp, delta.thermal);
            for j in 0..n {
                q[j] = pose.q_rad[j] + delta.dq[j];
            }
            self.chain
                .point_jacobian(&pp, &q, OutputFrame::Rig, &mut jac);
            let t = jac.point + delta.dp;
            let dlen = if thermal_used || FRAMES {
                self.ctx
                    .lengths
                    .iter()
                    .fold(Vector3::zeros(), |acc, &(k, v)| acc + jac.d_params[k] * v)
            } else {
                Vector3::zeros()
            };
            if DERIV || FRAMES {
                frame.d_theta.clear();
                frame
                    .d_theta
                    .extend((0..n).map(|j| jac.d_params[l.joint(j, JointParam::Theta)]));
                frame.dlen = dlen;
            }
            if DERIV {
                cols.set(&effects, &bases, &frame, &mut row[nf..]);
            }
            if FRAMES {
                pose_f(pos, &frame);
            }
            match &pose.measurement {
                Measurement::Strings(readings) => {
                    let r = p[l.r()];
                    for (k, a) in self.ctx.anchors.iter().enumerate() {
                        let v = t - a;
                        let dist = v.norm();
                        let u = v / dist;
                        let res = crate::measure::string_residual_mm(
                            dist,
                            r,
                            p[g + k],
                            delta.dl[k],
                            readings[k],
                        );
                        for (col, &fi) in self.free.iter().enumerate().filter(|_| DERIV) {
                            row[col] = if fi < g {
                                u.dot(&jac.d_params[fi])
                            } else if fi < g + l.n_strings {
                                if fi - g == k { -1.0 } else { 0.0 }
                            } else {
                                -1.0
                            };
                        }
                        for &c in cols.live.iter().filter(|_| DERIV) {
                            row[nf + c] = u.dot(&cols.dt[c]) + cols.dl[c * m + k];
                        }
                        f(pos, res, &row, RowDir::String { u, k });
                    }
                }
                Measurement::Point(meas) => {
                    for comp in 0..3 {
                        let res = t[comp] - meas[comp];
                        for (col, &fi) in self.free.iter().enumerate().filter(|_| DERIV) {
                            row[col] = if fi < g { jac.d_params[fi][comp] } else { 0.0 };
                        }
                        for &c in cols.live.iter().filter(|_| DERIV) {
                            row[nf + c] = cols.dt[c][comp];
                        }
                        f(pos, res, &row, RowDir::Point { comp });
                    }
                }
            }
        }
    }

    /// Model point T (rig frame) of pose `i` with the effects' robot side.
    pub fn model_point(
        chain: &Chain,
        ctx: &Context,
        p: &[f64],
        effects: &[EffectModel],
        i: usize,
        q_rad: &[f64],
    ) -> (Vector3<f64>, Vec<f64>) {
        let mut buf = Basis::default();
        let delta = ctx.apply(effects, i, &mut buf);
        let mut pp = p.to_vec();
        ctx.apply_thermal(&mut pp, delta.thermal);
        let q: Vec<f64> = q_rad.iter().zip(&delta.dq).map(|(a, b)| a + b).collect();
        (
            chain.point(&pp, &q, OutputFrame::Rig).1 + delta.dp,
            delta.dl,
        )
    }
}

impl LeastSquares for EffectProblem<'_> {
    fn n_params(&self) -> usize {
        self.free.len() + self.n_coef()
    }

    fn n_residuals(&self) -> usize {
        self.poses.len() * self.rows_per_pose()
    }

    fn cost(&self, x: &[f64]) -> f64 {
        let mut c = 0.0;
        self.residuals(x, |_, r| c += r * r);
        0.5 * c
    }

    fn normal_equations(&self, x: &[f64], jtj: &mut DMatrix<f64>, jtr: &mut DVector<f64>) -> f64 {
        let n = x.len();
        let mut upper = vec![0.0; n * n];
        let mut g = vec![0.0; n];
        let mut cost = 0.0;
        let mut runs = Vec::new();
        self.rows(x, |_, r, row| {
            cost += r * r;
            accumulate(&mut upper, &mut g, n, row, r, &mut runs);
        });
        for a in 0..n {
            jtr[a] = g[a];
            for b in a..n {
                jtj[(a, b)] = upper[a * n + b];
                jtj[(b, a)] = upper[a * n + b];
            }
        }
        0.5 * cost
    }
}

/// The effect coefficients live at one pose (see [`Basis::live`], indices
/// into all the effects' coefficients) and, for each, T's derivative `dt`
/// (rig frame, mm) and the readings' `dl` (`m` per coefficient); every
/// other coefficient's entries stay zero.
struct LiveColumns {
    m: usize,
    live: Vec<usize>,
    dt: Vec<Vector3<f64>>,
    dl: Vec<f64>,
}

impl LiveColumns {
    /// For `nc` coefficients and `m` strings, none live.
    fn new(nc: usize, m: usize) -> Self {
        LiveColumns {
            m,
            live: Vec::new(),
            dt: vec![Vector3::zeros(); nc],
            dl: vec![0.0; nc * m],
        }
    }

    /// The pose whose effects' bases are `bases` and whose frame is
    /// `frame`: the last pose's entries (and their row entries in
    /// `row_effects`, a row's effect part) cleared, this pose's set.
    fn set(
        &mut self,
        effects: &[EffectModel],
        bases: &[Basis],
        frame: &PoseFrame,
        row_effects: &mut [f64],
    ) {
        let m = self.m;
        for &c in &self.live {
            self.dt[c] = Vector3::zeros();
            self.dl[c * m..(c + 1) * m].fill(0.0);
            row_effects[c] = 0.0;
        }
        self.live.clear();
        let mut c0 = 0;
        for (e, buf) in effects.iter().zip(bases) {
            for &c in &buf.live {
                self.live.push(c0 + c);
                self.dt[c0 + c] = frame.d_point(buf, c);
                self.dl[(c0 + c) * m..(c0 + c + 1) * m]
                    .copy_from_slice(&buf.dl[c * m..(c + 1) * m]);
            }
            c0 += e.kind.n_coef();
        }
    }
}

/// What a residual row measures: string `k`'s length along the unit
/// vector `u` from its anchor to T (rig frame), or T's coordinate `comp`.
#[derive(Debug, Clone, Copy)]
pub enum RowDir {
    /// A string reading.
    String {
        /// Unit vector from the anchor to T.
        u: Vector3<f64>,
        /// The string.
        k: usize,
    },
    /// A coordinate of a measured point.
    Point {
        /// 0, 1 or 2.
        comp: usize,
    },
}

/// What an effect's columns need at one pose, beside its basis: T's
/// derivative (rig frame, mm) by each joint's angle and by the thermal
/// multiplier of the nominal lengths.
#[derive(Debug, Clone, Default)]
pub struct PoseFrame {
    /// `dT/dθ_j` for every joint `j` (mm/rad).
    pub d_theta: Vec<Vector3<f64>>,
    /// `dT/d(thermal multiplier)` (mm).
    pub dlen: Vector3<f64>,
}

impl PoseFrame {
    /// T's derivative by coefficient `c` of an effect whose basis at this
    /// pose is `buf` (as [`EffectProblem::rows`] forms it).
    pub fn d_point(&self, buf: &Basis, c: usize) -> Vector3<f64> {
        let n = self.d_theta.len();
        let mut v = self.dlen * buf.thermal[c];
        for j in 0..n {
            let b = buf.dq[c * n + j];
            if b != 0.0 {
                v += self.d_theta[j] * b;
            }
        }
        v + Vector3::new(buf.dp[c * 3], buf.dp[c * 3 + 1], buf.dp[c * 3 + 2])
    }

    /// The column of coefficient `c` at a row `dir`, from its
    /// [`Self::d_point`] `dt` and the basis `buf` of `m` strings: the same
    /// value [`EffectProblem::rows`] gives that column.
    pub fn column(dir: RowDir, dt: &Vector3<f64>, buf: &Basis, c: usize, m: usize) -> f64 {
        match dir {
            RowDir::String { u, k } => u.dot(dt) + buf.dl[c * m + k],
            RowDir::Point { comp } => dt[comp],
        }
    }
}

/// Add `row rowᵀ` (upper triangle) and `row · r` to flat accumulators.
/// `runs` is scratch space (reused between rows: no allocation per row).
#[inline]
pub fn accumulate(
    upper: &mut [f64],
    g: &mut [f64],
    n: usize,
    row: &[f64],
    r: f64,
    runs: &mut Vec<(usize, usize)>,
) {
    // Rows are sparse where effects are local (a change point, a
    // data-driven correction's two knots): visit the nonzeros only, as
    // runs of consecutive columns (the geometry's are one run), so the
    // inner loops are over contiguous slices. Each entry adds the same
    // products in the same row order as an entry-by-entry loop.
    runs.clear();
    let mut a = 0;
    while a < n {
        if row[a] == 0.0 {
            a += 1;
            continue;
        }
        let start = a;
        while a < n && row[a] != 0.0 {
            a += 1;
        }
        runs.push((start, a));
    }
    for (k, &(s, e)) in runs.iter().enumerate() {
        for a in s..e {
            let ra = row[a];
            g[a] += ra * r;
            let urow = &mut upper[a * n..(a + 1) * n];
            for (u, &rb) in urow[a..e].iter_mut().zip(&row[a..e]) {
                *u += ra * rb;
            }
            for &(s2, e2) in &runs[k + 1..] {
                for (u, &rb) in urow[s2..e2].iter_mut().zip(&row[s2..e2]) {
                    *u += ra * rb;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::accumulate;

    /// The run-wise accumulation gives exactly the sums of an entry-by-
    /// entry loop over the nonzeros, on rows with dense and sparse parts.
    #[test]
    fn accumulate_equals_the_entrywise_sums() {
        let mut rng = crate::rng::Rng::new(5);
        let n = 23;
        let (mut up, mut g) = (vec![0.0; n * n], vec![0.0; n]);
        let (mut up0, mut g0) = (vec![0.0; n * n], vec![0.0; n]);
        let mut runs = Vec::new();
        for _ in 0..200 {
            let row: Vec<f64> = (0..n)
                .map(|i| {
                    if i < 8 || rng.uniform() < 0.2 {
                        rng.normal()
                    } else {
                        0.0
                    }
                })
                .collect();
            let r = rng.normal();
            accumulate(&mut up, &mut g, n, &row, r, &mut runs);
            for a in (0..n).filter(|&a| row[a] != 0.0) {
                g0[a] += row[a] * r;
                for b in (a..n).filter(|&b| row[b] != 0.0) {
                    up0[a * n + b] += row[a] * row[b];
                }
            }
        }
        assert_eq!(up, up0);
        assert_eq!(g, g0);
        assert!(up.iter().any(|&v| v != 0.0));
    }
}
