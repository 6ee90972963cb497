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
        let (p, effects) = self.unpack(x);
        let l = self.chain.layout;
        let g = l.n_geometric();
        let n = l.n_joints;
        let ncol = x.len();
        let mut row = vec![0.0; ncol];
        let mut jac: PointJacobian = self.chain.new_jacobian();
        let mut buf = Basis::default();
        let mut pp = p.clone();
        let mut q = vec![0.0; n];
        let thermal_used = effects
            .iter()
            .any(|e| matches!(e.kind, super::effects::Kind::ThermalExpansion { .. }));
        // dT/dcoef for every coefficient, reused per pose.
        let nc = ncol - self.free.len();
        let mut dt = vec![Vector3::zeros(); nc];
        let mut dl = vec![0.0; nc * self.data.n_strings.max(1)];
        for (pos, &i) in self.poses.iter().enumerate() {
            let pose = &self.data.poses[i];
            let delta = self.ctx.apply(&effects, i, &mut buf);
            pp.copy_from_slice(&p);
            self.ctx.apply_thermal(&mut pp, delta.thermal);
            for j in 0..n {
                q[j] = pose.q_rad[j] + delta.dq[j];
            }
            self.chain
                .point_jacobian(&pp, &q, OutputFrame::Rig, &mut jac);
            let t = jac.point + delta.dp;
            let dlen = if thermal_used {
                self.ctx
                    .lengths
                    .iter()
                    .fold(Vector3::zeros(), |acc, &(k, v)| acc + jac.d_params[k] * v)
            } else {
                Vector3::zeros()
            };
            let m = self.data.n_strings;
            let mut c0 = 0;
            for e in &effects {
                self.ctx.basis(&e.kind, i, &mut buf);
                for c in 0..e.kind.n_coef() {
                    let mut v = dlen * buf.thermal[c];
                    for j in 0..n {
                        let b = buf.dq[c * n + j];
                        if b != 0.0 {
                            v += jac.d_params[l.joint(j, JointParam::Theta)] * b;
                        }
                    }
                    dt[c0 + c] =
                        v + Vector3::new(buf.dp[c * 3], buf.dp[c * 3 + 1], buf.dp[c * 3 + 2]);
                    for k in 0..m {
                        dl[(c0 + c) * m + k] = buf.dl[c * m + k];
                    }
                }
                c0 += e.kind.n_coef();
            }
            let nf = self.free.len();
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
                        for (col, &fi) in self.free.iter().enumerate() {
                            row[col] = if fi < g {
                                u.dot(&jac.d_params[fi])
                            } else if fi < g + l.n_strings {
                                if fi - g == k { -1.0 } else { 0.0 }
                            } else {
                                -1.0
                            };
                        }
                        for c in 0..nc {
                            row[nf + c] = u.dot(&dt[c]) + dl[c * m + k];
                        }
                        f(pos, res, &row);
                    }
                }
                Measurement::Point(meas) => {
                    for comp in 0..3 {
                        let res = t[comp] - meas[comp];
                        for (col, &fi) in self.free.iter().enumerate() {
                            row[col] = if fi < g { jac.d_params[fi][comp] } else { 0.0 };
                        }
                        for c in 0..nc {
                            row[nf + c] = dt[c][comp];
                        }
                        f(pos, res, &row);
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
        self.rows(x, |_, r, _| c += r * r);
        0.5 * c
    }

    fn normal_equations(&self, x: &[f64], jtj: &mut DMatrix<f64>, jtr: &mut DVector<f64>) -> f64 {
        let n = x.len();
        let mut upper = vec![0.0; n * n];
        let mut g = vec![0.0; n];
        let mut cost = 0.0;
        self.rows(x, |_, r, row| {
            cost += r * r;
            accumulate(&mut upper, &mut g, n, row, r);
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

/// Add `row rowᵀ` (upper triangle) and `row · r` to flat accumulators.
#[inline]
pub fn accumulate(upper: &mut [f64], g: &mut [f64], n: usize, row: &[f64], r: f64) {
    // Rows are sparse where effects are local (a change point, a
    // data-driven correction's two knots): visit the nonzeros only.
    let nz: Vec<usize> = (0..n).filter(|&a| row[a] != 0.0).collect();
    for (k, &a) in nz.iter().enumerate() {
        let ra = row[a];
        g[a] += ra * r;
        let base = a * n;
        for &b in &nz[k..] {
            upper[base + b] += ra * row[b];
        }
    }
}
