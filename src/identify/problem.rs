//! The calibration least-squares problem: residuals of the raw measurements
//! (string readings, or measured points) against the model, with any subset
//! of the parameters free.

use nalgebra::{DMatrix, DVector, Vector3};

use super::lm::LeastSquares;
use crate::kinematics::chain::{Chain, OutputFrame, PointJacobian, Trig, joint_trig};
use crate::model::{Measurement, PoseRecord};

/// How a free parameter enters a residual row.
#[derive(Debug, Clone, Copy)]
enum Column {
    /// A geometric parameter: moves T.
    Geom(usize),
    /// Zero offset of string k.
    Offset(usize),
    /// The common r.
    R,
}

/// Residuals of a set of poses for the parameters in `free`; the others are
/// held at their value in `full`.
pub struct CalibrationProblem<'a> {
    /// Kinematic structure.
    pub chain: Chain,
    /// Anchors (empty for point data).
    pub anchors: Vec<Vector3<f64>>,
    /// The poses fitted.
    pub poses: Vec<&'a PoseRecord>,
    /// Per-pose weights (robust loss), 1 by default.
    pub weights: Vec<f64>,
    /// Full parameter vector; free entries are overwritten from `x`.
    pub full: Vec<f64>,
    /// Indices of the free parameters.
    free: Vec<usize>,
    columns: Vec<Column>,
    /// Sines and cosines of each pose's joint angles, computed once.
    q_trig: Vec<Vec<(f64, f64)>>,
}

impl<'a> CalibrationProblem<'a> {
    /// A problem over `poses` with `free` parameters starting from `full`.
    pub fn new(
        chain: Chain,
        anchors: Vec<Vector3<f64>>,
        poses: Vec<&'a PoseRecord>,
        full: Vec<f64>,
        free: Vec<usize>,
    ) -> Self {
        let l = chain.layout;
        let columns = free
            .iter()
            .map(|&i| {
                if i < l.n_geometric() {
                    Column::Geom(i)
                } else if i < l.n_geometric() + l.n_strings {
                    Column::Offset(i - l.n_geometric())
                } else {
                    Column::R
                }
            })
            .collect();
        let weights = vec![1.0; poses.len()];
        let q_trig = poses.iter().map(|p| joint_trig(&p.q_rad)).collect();
        CalibrationProblem {
            chain,
            anchors,
            poses,
            weights,
            full,
            free,
            columns,
            q_trig,
        }
    }

    /// The free parameter indices.
    pub fn free(&self) -> &[usize] {
        &self.free
    }

    /// Current values of the free parameters.
    pub fn x0(&self) -> Vec<f64> {
        self.free.iter().map(|&i| self.full[i]).collect()
    }

    /// The full vector with the free entries from `x`.
    pub fn expand(&self, x: &[f64]) -> Vec<f64> {
        let mut p = self.full.clone();
        for (k, &i) in self.free.iter().enumerate() {
            p[i] = x[k];
        }
        p
    }

    /// Residuals of one pose (predicted minus measured, mm) into `out`.
    pub fn pose_residuals(&self, p: &[f64], pose: &PoseRecord, out: &mut Vec<f64>) {
        let (_, t) = self.chain.point(p, &pose.q_rad, OutputFrame::Rig);
        self.residuals_at(p, &t, pose, out);
    }

    fn residuals_at(&self, p: &[f64], t: &Vector3<f64>, pose: &PoseRecord, out: &mut Vec<f64>) {
        out.clear();
        match &pose.measurement {
            Measurement::Strings(l) => {
                let g = self.chain.layout.n_geometric();
                let r = p[self.chain.layout.r()];
                for (k, a) in self.anchors.iter().enumerate() {
                    out.push(crate::measure::string_residual_mm(
                        (t - a).norm(),
                        r,
                        p[g + k],
                        0.0,
                        l[k],
                    ));
                }
            }
            Measurement::Point(m) => out.extend((t - m).iter()),
        }
    }

    /// Residual rows per pose (4 per pose for four strings, 3 for points).
    pub fn rows_per_pose(&self) -> usize {
        if self.anchors.is_empty() {
            3
        } else {
            self.anchors.len()
        }
    }
}

impl LeastSquares for CalibrationProblem<'_> {
    fn n_params(&self) -> usize {
        self.free.len()
    }

    fn n_residuals(&self) -> usize {
        self.poses.len() * self.rows_per_pose()
    }

    fn cost(&self, x: &[f64]) -> f64 {
        let p = self.expand(x);
        let trig: Trig = self.chain.trig(&p);
        let mut r = Vec::new();
        let mut c = 0.0;
        for ((pose, w), qsc) in self.poses.iter().zip(&self.weights).zip(&self.q_trig) {
            let t = self.chain.point_trig(&p, &trig, qsc);
            self.residuals_at(&p, &t, pose, &mut r);
            c += w * r.iter().map(|v| v * v).sum::<f64>();
        }
        0.5 * c
    }

    fn normal_equations(&self, x: &[f64], jtj: &mut DMatrix<f64>, jtr: &mut DVector<f64>) -> f64 {
        let p = self.expand(x);
        let n = self.free.len();
        jtj.fill(0.0);
        jtr.fill(0.0);
        let mut jac: PointJacobian = self.chain.new_jacobian();
        let mut cost = 0.0;
        let g = self.chain.layout.n_geometric();
        // Rows (scaled by √w) are gathered in column-major blocks and folded
        // in as column dot products over the upper triangle only: half the
        // work of a full matrix product and several times faster than rank-1
        // updates.
        const BLOCK: usize = 256;
        let mut rows = DMatrix::<f64>::zeros(BLOCK, n);
        let mut res = DVector::<f64>::zeros(BLOCK);
        let mut upper = vec![0.0; n * n];
        let mut filled = 0;
        let flush = |rows: &DMatrix<f64>,
                     res: &DVector<f64>,
                     filled: &mut usize,
                     upper: &mut [f64],
                     jtr: &mut DVector<f64>| {
            let m = *filled;
            if m == 0 {
                return;
            }
            let data = rows.as_slice();
            let r = &res.as_slice()[..m];
            for a in 0..n {
                let ca = &data[a * BLOCK..a * BLOCK + m];
                jtr[a] += dot(ca, r);
                for b in a..n {
                    upper[a * n + b] += dot(ca, &data[b * BLOCK..b * BLOCK + m]);
                }
            }
            *filled = 0;
        };
        let trig = self.chain.trig(&p);
        for ((pose, &w), qsc) in self.poses.iter().zip(&self.weights).zip(&self.q_trig) {
            let sw = w.sqrt();
            self.chain
                .point_jacobian_trig(&p, &trig, qsc, OutputFrame::Rig, &mut jac);
            let t = jac.point;
            match &pose.measurement {
                Measurement::Strings(l) => {
                    let rr = p[self.chain.layout.r()];
                    for (k, a) in self.anchors.iter().enumerate() {
                        let v = t - a;
                        let dist = v.norm();
                        let u = v / dist;
                        let r = dist - rr - p[g + k] - l[k];
                        cost += w * r * r;
                        for (f, col) in self.columns.iter().enumerate() {
                            rows[(filled, f)] = sw
                                * match *col {
                                    Column::Geom(i) => u.dot(&jac.d_params[i]),
                                    Column::Offset(s) => {
                                        if s == k {
                                            -1.0
                                        } else {
                                            0.0
                                        }
                                    }
                                    Column::R => -1.0,
                                };
                        }
                        res[filled] = sw * r;
                        filled += 1;
                        if filled == BLOCK {
                            flush(&rows, &res, &mut filled, &mut upper, jtr);
                        }
                    }
                }
                Measurement::Point(m) => {
                    for c in 0..3 {
                        let r = t[c] - m[c];
                        cost += w * r * r;
                        for (f, col) in self.columns.iter().enumerate() {
                            rows[(filled, f)] = sw
                                * match *col {
                                    Column::Geom(i) => jac.d_params[i][c],
                                    _ => 0.0,
                                };
                        }
                        res[filled] = sw * r;
                        filled += 1;
                        if filled == BLOCK {
                            flush(&rows, &res, &mut filled, &mut upper, jtr);
                        }
                    }
                }
            }
        }
        flush(&rows, &res, &mut filled, &mut upper, jtr);
        for a in 0..n {
            for b in a..n {
                jtj[(a, b)] = upper[a * n + b];
                jtj[(b, a)] = upper[a * n + b];
            }
        }
        0.5 * cost
    }
}

/// Dot product with four independent accumulators, so the compiler can keep
/// several multiply-adds in flight (and vectorise) without reassociating.
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let ca = a.chunks_exact(4);
    let cb = b.chunks_exact(4);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            acc[k] += x[k] * y[k];
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}
