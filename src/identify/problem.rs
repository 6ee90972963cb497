//! The calibration least-squares problem: residuals of the raw measurements
//! (string readings, or measured points) against the model, with any subset
//! of the parameters free.

use nalgebra::{DMatrix, DVector, Vector3};

use super::lm::LeastSquares;
use super::rig::AnchorModes;
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
    /// Shape mode j of the anchors.
    Anchor(usize),
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
    /// The anchors' shape modes when they are identified: the anchors are
    /// then `modes.anchors(z)` with `z` the entries past the layout's
    /// (see [`crate::identify::rig`]), and `anchors` is not used.
    modes: Option<AnchorModes>,
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
                } else if i < l.len() {
                    Column::R
                } else {
                    Column::Anchor(i - l.len())
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
            modes: None,
        }
    }

    /// The same problem with the anchors moved by their shape modes, whose
    /// coordinates are the entries of the parameter vector past the
    /// layout's (`full` must hold them).
    pub fn with_anchor_modes(mut self, modes: AnchorModes) -> Self {
        self.modes = Some(modes);
        self
    }

    /// The anchors at parameters `p`: moved by their modes when those are
    /// identified.
    pub fn anchors_at(&self, p: &[f64]) -> std::borrow::Cow<'_, [Vector3<f64>]> {
        match &self.modes {
            Some(m) => std::borrow::Cow::Owned(m.anchors(&p[self.chain.layout.len()..])),
            None => std::borrow::Cow::Borrowed(&self.anchors),
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
        self.residuals_at(p, &self.anchors_at(p), &t, pose, out);
    }

    fn residuals_at(
        &self,
        p: &[f64],
        anchors: &[Vector3<f64>],
        t: &Vector3<f64>,
        pose: &PoseRecord,
        out: &mut Vec<f64>,
    ) {
        out.clear();
        match &pose.measurement {
            Measurement::Strings(l) => {
                let g = self.chain.layout.n_geometric();
                let r = p[self.chain.layout.r()];
                for (k, a) in anchors.iter().enumerate() {
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

    /// Derivative of string k's residual by free column `col`, with `u` the
    /// unit vector from the anchor to T and `jac` T's Jacobian: one
    /// expression for the solver's rows and for [`Self::rows`].
    #[inline(always)]
    fn string_derivative(
        &self,
        col: Column,
        k: usize,
        u: &Vector3<f64>,
        jac: &PointJacobian,
    ) -> f64 {
        match col {
            Column::Geom(i) => u.dot(&jac.d_params[i]),
            Column::Offset(s) => {
                if s == k {
                    -1.0
                } else {
                    0.0
                }
            }
            Column::R => -1.0,
            // |T - A_k| shrinks as A_k moves towards T.
            Column::Anchor(j) => match &self.modes {
                Some(m) => -u.dot(&m.column(k, j)),
                None => 0.0,
            },
        }
    }

    /// Every residual row at `x` (unweighted): `each(row, residual)` with
    /// the row's derivatives by the free parameters, in pose order. The
    /// solver accumulates the same rows into the normal equations; this
    /// is for checking them (finite differences) and for inspection.
    pub fn rows(&self, x: &[f64], mut each: impl FnMut(&[f64], f64)) {
        let p = self.expand(x);
        let anchors = self.anchors_at(&p);
        let mut jac: PointJacobian = self.chain.new_jacobian();
        let trig = self.chain.trig(&p);
        let g = self.chain.layout.n_geometric();
        let mut row = vec![0.0; self.free.len()];
        for (pose, qsc) in self.poses.iter().zip(&self.q_trig) {
            self.chain
                .point_jacobian_trig(&p, &trig, qsc, OutputFrame::Rig, &mut jac);
            let t = jac.point;
            match &pose.measurement {
                Measurement::Strings(l) => {
                    let rr = p[self.chain.layout.r()];
                    for (k, a) in anchors.iter().enumerate() {
                        let v = t - a;
                        let u = v / v.norm();
                        for (f, col) in self.columns.iter().enumerate() {
                            row[f] = self.string_derivative(*col, k, &u, &jac);
                        }
                        each(&row, v.norm() - rr - p[g + k] - l[k]);
                    }
                }
                Measurement::Point(m) => {
                    for c in 0..3 {
                        for (f, col) in self.columns.iter().enumerate() {
                            row[f] = match *col {
                                Column::Geom(i) => jac.d_params[i][c],
                                _ => 0.0,
                            };
                        }
                        each(&row, t[c] - m[c]);
                    }
                }
            }
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
        let anchors = self.anchors_at(&p);
        let mut r = Vec::new();
        let mut c = 0.0;
        for ((pose, w), qsc) in self.poses.iter().zip(&self.weights).zip(&self.q_trig) {
            let t = self.chain.point_trig(&p, &trig, qsc);
            self.residuals_at(&p, &anchors, &t, pose, &mut r);
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
        let anchors = self.anchors_at(&p);
        for ((pose, &w), qsc) in self.poses.iter().zip(&self.weights).zip(&self.q_trig) {
            let sw = w.sqrt();
            self.chain
                .point_jacobian_trig(&p, &trig, qsc, OutputFrame::Rig, &mut jac);
            let t = jac.point;
            match &pose.measurement {
                Measurement::Strings(l) => {
                    let rr = p[self.chain.layout.r()];
                    for (k, a) in anchors.iter().enumerate() {
                        let v = t - a;
                        let dist = v.norm();
                        let u = v / dist;
                        let r = dist - rr - p[g + k] - l[k];
                        cost += w * r * r;
                        for (f, col) in self.columns.iter().enumerate() {
                            rows[(filled, f)] = sw * self.string_derivative(*col, k, &u, &jac);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{IdentifyOptions, Observations};
    use crate::kinematics::{JointParam, Params};
    use crate::model::{Dataset, Rig, Robot};

    /// Every column of the rows the solver accumulates, the anchors' shape
    /// modes among them, against central differences of the residuals;
    /// and the normal equations against the rows.
    #[test]
    fn rows_with_anchor_modes_match_finite_differences() {
        let robot =
            Robot::from_json(include_str!("../../tests/data/er3a_paper_like/robot.json")).unwrap();
        let rig =
            Rig::from_json(include_str!("../../tests/data/er3a_paper_like/rig.json")).unwrap();
        let data = Dataset::from_csv(
            &include_bytes!("../../tests/data/er3a_paper_like/poses.csv")[..],
            &robot,
            &rig,
        )
        .unwrap();
        let opts = IdentifyOptions {
            rig_anchors: true,
            ..IdentifyOptions::default()
        };
        let obs = Observations::new(&robot, &rig, &data, &opts).unwrap();
        let modes = obs.anchor_modes.clone().unwrap();
        let l = obs.chain.layout;
        let mut p = Params::nominal(&robot, &rig.base_in_rig.unwrap(), &rig, 4).values;
        // Away from zero, so that the anchors have moved.
        p.extend((0..modes.len()).map(|j| 0.3 * (j as f64 - 2.5)));
        let mut free = vec![
            l.joint(1, JointParam::Theta),
            l.joint(2, JointParam::A),
            l.base() + 1,
            l.base() + 4,
            l.tool() + 2,
            l.string_offset(1),
            l.r(),
        ];
        free.extend((0..modes.len()).map(|j| l.anchor_mode(j)));
        let mut problem = obs.problem(p, free);
        problem.poses.truncate(20);
        problem.weights.truncate(20);
        problem.q_trig.truncate(20);
        let x = problem.x0();
        let mut rows: Vec<Vec<f64>> = Vec::new();
        let mut res0 = Vec::new();
        problem.rows(&x, |row, r| {
            rows.push(row.to_vec());
            res0.push(r);
        });
        let residuals = |x: &[f64]| {
            let p = problem.expand(x);
            let mut all = Vec::new();
            let mut r = Vec::new();
            for pose in &problem.poses {
                problem.pose_residuals(&p, pose, &mut r);
                all.extend_from_slice(&r);
            }
            all
        };
        // The rows' residuals are the residuals.
        for (a, b) in res0.iter().zip(residuals(&x)) {
            assert!((a - b).abs() < 1e-9, "{a} {b}");
        }
        for c in 0..x.len() {
            // A step that moves the residuals by about a micrometre: small
            // enough for the curvature, large against rounding.
            let slope = rows
                .iter()
                .map(|r| r[c].abs())
                .fold(0.0, f64::max)
                .max(1e-12);
            let h = 1e-3 / slope;
            let mut xp = x.clone();
            xp[c] += h;
            let mut xm = x.clone();
            xm[c] -= h;
            let (rp, rm) = (residuals(&xp), residuals(&xm));
            for (i, row) in rows.iter().enumerate() {
                let fd = (rp[i] - rm[i]) / (2.0 * h);
                let scale = 1.0 + fd.abs().max(row[c].abs());
                assert!(
                    (fd - row[c]).abs() < 2e-5 * scale,
                    "column {} row {i}: analytic {} finite difference {fd}",
                    l.name(problem.free()[c]),
                    row[c]
                );
            }
        }
        // The solver's normal equations are these rows'.
        let n = x.len();
        let mut jtj = DMatrix::zeros(n, n);
        let mut jtr = DVector::zeros(n);
        let cost = problem.normal_equations(&x, &mut jtj, &mut jtr);
        let mut jtj2 = DMatrix::zeros(n, n);
        let mut jtr2 = DVector::zeros(n);
        for (row, r) in rows.iter().zip(&res0) {
            let v = DVector::from_column_slice(row);
            jtj2 += &v * v.transpose();
            jtr2 += &v * *r;
        }
        assert!((jtj - &jtj2).norm() < 1e-9 * (1.0 + jtj2.norm()));
        assert!((jtr - &jtr2).norm() < 1e-9 * (1.0 + jtr2.norm()));
        let cost2 = 0.5 * res0.iter().map(|r| r * r).sum::<f64>();
        assert!((cost - cost2).abs() < 1e-9 * (1.0 + cost2));
        assert!((problem.cost(&x) - cost2).abs() < 1e-9 * (1.0 + cost2));
    }
}
