//! Forward kinematics of the measured point T with analytic derivatives.
//!
//! The chain rig → base → joints → flange → T is a product of elementary
//! rotations and translations about the running frame's own axes. The
//! derivative of T with respect to a translation along axis `w` is `w`; with
//! respect to a rotation about `w` through origin `o` it is `w × (T - o)`
//! (axes and origins in the output frame). One forward pass records them, so
//! the full Jacobian costs little more than the point itself.

use nalgebra::{Matrix3, Vector3};

use super::params::{JointParam, Layout};
use crate::model::Convention;

/// A rigid frame: rotation and origin in the output frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Orientation (columns are the frame's axes).
    pub r: Matrix3<f64>,
    /// Origin (mm).
    pub o: Vector3<f64>,
}

impl Frame {
    /// The identity frame.
    pub fn identity() -> Self {
        Frame {
            r: Matrix3::identity(),
            o: Vector3::zeros(),
        }
    }

    #[inline(always)]
    fn rot_sc(&mut self, axis: usize, s: f64, c: f64) {
        let (i, j) = match axis {
            0 => (1, 2),
            1 => (2, 0),
            _ => (0, 1),
        };
        for row in 0..3 {
            let a = self.r[(row, i)];
            let b = self.r[(row, j)];
            self.r[(row, i)] = c * a + s * b;
            self.r[(row, j)] = c * b - s * a;
        }
    }

    #[inline(always)]
    fn trans(&mut self, axis: usize, d: f64) {
        for row in 0..3 {
            self.o[row] += d * self.r[(row, axis)];
        }
    }

    #[inline(always)]
    fn axis(&self, axis: usize) -> Vector3<f64> {
        Vector3::new(self.r[(0, axis)], self.r[(1, axis)], self.r[(2, axis)])
    }

    /// Map a point from this frame to the output frame.
    pub fn apply(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.r * p + self.o
    }
}

/// Sines and cosines of the angles that do not change from pose to pose
/// (base roll/pitch/yaw, each joint's α, β and θ offset), computed once per
/// parameter vector: with the joint angles' own sines cached per pose, the
/// hot loops of identification need no trigonometric calls at all.
#[derive(Debug, Clone)]
pub struct Trig {
    base: [(f64, f64); 3],
    joints: Vec<[(f64, f64); 3]>,
}

/// `(sin, cos)` of each joint angle of a pose.
pub fn joint_trig(q: &[f64]) -> Vec<(f64, f64)> {
    q.iter().map(|v| v.sin_cos()).collect()
}

#[inline(always)]
fn add_angles((s1, c1): (f64, f64), (s2, c2): (f64, f64)) -> (f64, f64) {
    (s1 * c2 + c1 * s2, c1 * c2 - s1 * s2)
}

/// T with its derivatives, and the flange's rotation per parameter.
#[derive(Debug, Clone)]
pub struct PointJacobian {
    /// The point T (mm).
    pub point: Vector3<f64>,
    /// The flange frame.
    pub flange: Frame,
    /// dT/dp for every geometric parameter (length `Layout::n_geometric`).
    pub d_params: Vec<Vector3<f64>>,
    /// The flange frame's rotation per unit of each geometric parameter, as
    /// a rotation vector (`dR/dp = [ω]× R`): a rotation parameter's world
    /// axis, zero for lengths and the tool point.
    pub d_orientation: Vec<Vector3<f64>>,
}

/// The kinematic structure: convention and number of joints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Chain {
    /// Link convention.
    pub convention: Convention,
    /// Parameter layout.
    pub layout: Layout,
}

const X: usize = 0;
const Y: usize = 1;
const Z: usize = 2;

/// Which frame the result is expressed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFrame {
    /// The rig frame: the base pose parameters are applied.
    Rig,
    /// The robot base frame: the base pose parameters are ignored.
    Base,
}

impl Chain {
    /// A chain for `n_joints` joints and `n_strings` strings.
    pub fn new(convention: Convention, n_joints: usize, n_strings: usize) -> Self {
        Chain {
            convention,
            layout: Layout {
                n_joints,
                n_strings,
            },
        }
    }

    /// The flange frame and T, without derivatives.
    pub fn point(&self, p: &[f64], q: &[f64], out: OutputFrame) -> (Frame, Vector3<f64>) {
        let mut f = self.base_frame(p, out);
        self.walk(p, q, &mut f, |_| {});
        let t = self.layout.tool();
        let tool = Vector3::new(p[t], p[t + 1], p[t + 2]);
        (f, f.apply(&tool))
    }

    /// Advance `f` through every joint's link transform, calling `each`
    /// with the frame after each joint.
    #[inline(always)]
    fn walk(&self, p: &[f64], q: &[f64], f: &mut Frame, mut each: impl FnMut(&Frame)) {
        for (j, &qj) in q.iter().enumerate().take(self.layout.n_joints) {
            let k = 5 * j;
            let jt = [p[k + 3].sin_cos(), p[k + 1].sin_cos(), p[k + 4].sin_cos()];
            self.link(f, p[k], p[k + 2], qj.sin_cos(), jt);
            each(f);
        }
    }

    /// One joint's link transform (DH or MDH) from the sines and cosines of
    /// its joint angle `qsc` and of its `[θ, α, β]`.
    #[inline(always)]
    fn link(&self, f: &mut Frame, a: f64, d: f64, qsc: (f64, f64), [th, al, be]: [(f64, f64); 3]) {
        let (sz, cz) = add_angles(qsc, th);
        match self.convention {
            Convention::Dh => {
                f.rot_sc(Z, sz, cz);
                f.trans(Z, d);
                f.trans(X, a);
                f.rot_sc(X, al.0, al.1);
                f.rot_sc(Y, be.0, be.1);
            }
            Convention::Mdh => {
                f.rot_sc(X, al.0, al.1);
                f.rot_sc(Y, be.0, be.1);
                f.trans(X, a);
                f.rot_sc(Z, sz, cz);
                f.trans(Z, d);
            }
        }
    }

    /// The per-parameter-vector trigonometry for [`Chain::point_jacobian_trig`].
    pub fn trig(&self, p: &[f64]) -> Trig {
        let b = self.layout.base();
        Trig {
            base: [p[b + 5].sin_cos(), p[b + 4].sin_cos(), p[b + 3].sin_cos()],
            joints: (0..self.layout.n_joints)
                .map(|j| {
                    [
                        p[5 * j + 3].sin_cos(),
                        p[5 * j + 1].sin_cos(),
                        p[5 * j + 4].sin_cos(),
                    ]
                })
                .collect(),
        }
    }

    /// T and its derivatives with respect to every geometric parameter.
    /// `dT/dq_j` equals the column of `θ_j`. Columns of the base pose are
    /// zero in the base frame. `out.d_params` and `out.d_orientation` are
    /// resized as needed, so a caller looping over poses reuses one buffer.
    pub fn point_jacobian(
        &self,
        p: &[f64],
        q: &[f64],
        frame: OutputFrame,
        out: &mut PointJacobian,
    ) {
        self.point_jacobian_trig(p, &self.trig(p), &joint_trig(q), frame, out);
    }

    /// [`Chain::point_jacobian`] with precomputed trigonometry: `trig` from
    /// [`Chain::trig`] of the same `p`, `qsc` from [`joint_trig`].
    pub fn point_jacobian_trig(
        &self,
        p: &[f64],
        trig: &Trig,
        qsc: &[(f64, f64)],
        frame: OutputFrame,
        out: &mut PointJacobian,
    ) {
        let l = &self.layout;
        let ng = l.n_geometric();
        out.d_params.clear();
        out.d_params.resize(ng, Vector3::zeros());
        out.d_orientation.clear();
        out.d_orientation.resize(ng, Vector3::zeros());
        // Rotations are recorded as (parameter index, world axis, origin) and
        // turned into columns once T is known.
        let mut rots: [(usize, Vector3<f64>, Vector3<f64>); 3 + 3 * 12] =
            [(usize::MAX, Vector3::zeros(), Vector3::zeros()); 39];
        let mut nr = 0;
        let mut f = Frame::identity();
        macro_rules! rot {
            ($axis:expr, $sc:expr, $idx:expr) => {{
                rots[nr] = ($idx, f.axis($axis), f.o);
                nr += 1;
                let (s, c) = $sc;
                f.rot_sc($axis, s, c);
            }};
        }
        macro_rules! trans {
            ($axis:expr, $d:expr, $idx:expr) => {{
                out.d_params[$idx] = f.axis($axis);
                f.trans($axis, $d);
            }};
        }
        if frame == OutputFrame::Rig {
            let b = l.base();
            f.o = Vector3::new(p[b], p[b + 1], p[b + 2]);
            out.d_params[b] = Vector3::x();
            out.d_params[b + 1] = Vector3::y();
            out.d_params[b + 2] = Vector3::z();
            rot!(Z, trig.base[0], b + 5);
            rot!(Y, trig.base[1], b + 4);
            rot!(X, trig.base[2], b + 3);
        }
        for (j, &qj) in qsc.iter().enumerate().take(l.n_joints) {
            let k = 5 * j;
            let (a, d) = (p[k], p[k + 2]);
            let [th, al, be] = trig.joints[j];
            let (ia, ial, id, ith, ibe) = (
                k + JointParam::A as usize,
                k + JointParam::Alpha as usize,
                k + JointParam::D as usize,
                k + JointParam::Theta as usize,
                k + JointParam::Beta as usize,
            );
            match self.convention {
                Convention::Dh => {
                    rot!(Z, add_angles(qj, th), ith);
                    trans!(Z, d, id);
                    trans!(X, a, ia);
                    rot!(X, al, ial);
                    rot!(Y, be, ibe);
                }
                Convention::Mdh => {
                    rot!(X, al, ial);
                    rot!(Y, be, ibe);
                    trans!(X, a, ia);
                    rot!(Z, add_angles(qj, th), ith);
                    trans!(Z, d, id);
                }
            }
        }
        let t = l.tool();
        let tool = Vector3::new(p[t], p[t + 1], p[t + 2]);
        let point = f.apply(&tool);
        for c in 0..3 {
            out.d_params[t + c] = f.axis(c);
        }
        for (idx, w, o) in rots.iter().take(nr) {
            out.d_params[*idx] = w.cross(&(point - o));
            out.d_orientation[*idx] = *w;
        }
        out.point = point;
        out.flange = f;
    }

    /// T in the rig frame with precomputed trigonometry (see
    /// [`Chain::point_jacobian_trig`]).
    pub fn point_trig(&self, p: &[f64], trig: &Trig, qsc: &[(f64, f64)]) -> Vector3<f64> {
        let mut f = self.base_frame_sc(p, trig.base);
        for (j, &qj) in qsc.iter().enumerate().take(self.layout.n_joints) {
            self.link(&mut f, p[5 * j], p[5 * j + 2], qj, trig.joints[j]);
        }
        let t = self.layout.tool();
        f.apply(&Vector3::new(p[t], p[t + 1], p[t + 2]))
    }

    /// A fresh output buffer.
    pub fn new_jacobian(&self) -> PointJacobian {
        PointJacobian {
            point: Vector3::zeros(),
            flange: Frame::identity(),
            d_params: vec![Vector3::zeros(); self.layout.n_geometric()],
            d_orientation: vec![Vector3::zeros(); self.layout.n_geometric()],
        }
    }

    /// Each joint's axis and a point on it, in the chosen output frame (for
    /// inverse kinematics and gravity torques).
    pub fn joint_axes(
        &self,
        p: &[f64],
        q: &[f64],
        frame: OutputFrame,
    ) -> Vec<(Vector3<f64>, Vector3<f64>)> {
        let frames = self.link_frames(p, q, frame);
        match self.convention {
            // DH: joint j turns about z of the frame before it.
            Convention::Dh => {
                let base = self.base_frame(p, frame);
                (0..frames.len())
                    .map(|j| {
                        let f = if j == 0 { &base } else { &frames[j - 1] };
                        (f.axis(Z), f.o)
                    })
                    .collect()
            }
            // MDH: about z of its own frame (Rz and Tz leave that line fixed).
            Convention::Mdh => frames.iter().map(|f| (f.axis(Z), f.o)).collect(),
        }
    }

    fn base_frame(&self, p: &[f64], frame: OutputFrame) -> Frame {
        match frame {
            OutputFrame::Rig => {
                let b = self.layout.base();
                self.base_frame_sc(
                    p,
                    [p[b + 5].sin_cos(), p[b + 4].sin_cos(), p[b + 3].sin_cos()],
                )
            }
            OutputFrame::Base => Frame::identity(),
        }
    }

    /// The base pose in the rig frame from the sines and cosines of yaw,
    /// pitch and roll.
    fn base_frame_sc(&self, p: &[f64], [yaw, pitch, roll]: [(f64, f64); 3]) -> Frame {
        let b = self.layout.base();
        let mut f = Frame::identity();
        f.o = Vector3::new(p[b], p[b + 1], p[b + 2]);
        f.rot_sc(Z, yaw.0, yaw.1);
        f.rot_sc(Y, pitch.0, pitch.1);
        f.rot_sc(X, roll.0, roll.1);
        f
    }

    /// The frames after each joint (link frames 1..n), in the chosen output
    /// frame; used for gravity torques from link masses.
    pub fn link_frames(&self, p: &[f64], q: &[f64], frame: OutputFrame) -> Vec<Frame> {
        let mut frames = Vec::with_capacity(q.len());
        let mut f = self.base_frame(p, frame);
        self.walk(p, q, &mut f, |fr| frames.push(*fr));
        frames
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::Params;
    use crate::model::{BasePose, Rig, Robot};
    use crate::rng::Rng;

    fn er3a() -> Robot {
        Robot::from_json(include_str!("../../tests/data/er3a_paper_like/robot.json")).unwrap()
    }

    fn perturbed(robot: &Robot, seed: u64) -> Params {
        let rig =
            Rig::from_json(include_str!("../../tests/data/er3a_paper_like/rig.json")).unwrap();
        let base = BasePose {
            xyz_mm: [600.0, 450.0, -250.0],
            rpy_deg: [3.0, -4.0, 90.0],
        };
        let mut p = Params::nominal(robot, &base, &rig, 4);
        let mut rng = Rng::new(seed);
        for v in p.values.iter_mut() {
            *v += 0.01 * rng.normal();
        }
        p
    }

    fn check_fd(conv: Convention, frame: OutputFrame) {
        let mut robot = er3a();
        robot.convention = conv;
        let p = perturbed(&robot, 3);
        let chain = Chain::new(conv, 6, 4);
        let mut rng = Rng::new(11);
        let mut jac = chain.new_jacobian();
        for _ in 0..20 {
            let q: Vec<f64> = (0..6).map(|_| rng.range(-2.0, 2.0)).collect();
            chain.point_jacobian(&p.values, &q, frame, &mut jac);
            let (_, pt) = chain.point(&p.values, &q, frame);
            assert!((pt - jac.point).norm() < 1e-9);
            for i in 0..chain.layout.n_geometric() {
                let h = if chain.layout.is_angle(i) { 1e-7 } else { 1e-5 };
                let mut pp = p.values.clone();
                pp[i] += h;
                let (_, a) = chain.point(&pp, &q, frame);
                pp[i] -= 2.0 * h;
                let (_, b) = chain.point(&pp, &q, frame);
                let fd = (a - b) / (2.0 * h);
                let err = (fd - jac.d_params[i]).norm();
                assert!(
                    err < 1e-5 * (1.0 + fd.norm()),
                    "{conv:?} {} fd {fd:?} analytic {:?}",
                    chain.layout.name(i),
                    jac.d_params[i]
                );
                // The flange's rotation: the skew part of R(p+h) R(p-h)ᵀ
                // over 2h (an angle taken from the trace would lose its
                // digits at 2e-7 rad).
                pp[i] += 2.0 * h;
                let (fa, _) = chain.point(&pp, &q, frame);
                pp[i] -= 2.0 * h;
                let (fb, _) = chain.point(&pp, &q, frame);
                let m = fa.r * fb.r.transpose();
                let w = Vector3::new(
                    m[(2, 1)] - m[(1, 2)],
                    m[(0, 2)] - m[(2, 0)],
                    m[(1, 0)] - m[(0, 1)],
                ) / (4.0 * h);
                assert!(
                    (w - jac.d_orientation[i]).norm() < 1e-5 * (1.0 + w.norm()),
                    "{conv:?} {} orientation fd {w:?} analytic {:?}",
                    chain.layout.name(i),
                    jac.d_orientation[i]
                );
            }
        }
    }

    #[test]
    fn jacobian_matches_finite_differences_dh() {
        check_fd(Convention::Dh, OutputFrame::Rig);
        check_fd(Convention::Dh, OutputFrame::Base);
    }

    #[test]
    fn jacobian_matches_finite_differences_mdh() {
        check_fd(Convention::Mdh, OutputFrame::Rig);
    }

    /// The compensation solver takes each joint's axis from the Jacobian's
    /// flange rotation per radian of its θ instead of walking the chain again
    /// (`Chain::joint_axes`): the two must be the same numbers, to the bit,
    /// in either convention.
    #[test]
    fn theta_rotation_columns_are_the_joint_axes() {
        for conv in [Convention::Dh, Convention::Mdh] {
            let mut robot = er3a();
            robot.convention = conv;
            let p = perturbed(&robot, 7);
            let chain = Chain::new(conv, 6, 4);
            let mut rng = Rng::new(13);
            let mut jac = chain.new_jacobian();
            for _ in 0..20 {
                let q: Vec<f64> = (0..6).map(|_| rng.range(-3.0, 3.0)).collect();
                chain.point_jacobian(&p.values, &q, OutputFrame::Base, &mut jac);
                let axes = chain.joint_axes(&p.values, &q, OutputFrame::Base);
                for (c, (axis, _)) in axes.iter().enumerate() {
                    assert_eq!(
                        *axis,
                        jac.d_orientation[5 * c + JointParam::Theta as usize],
                        "{conv:?} joint {}",
                        c + 1
                    );
                }
            }
        }
    }

    #[test]
    fn dh_matches_matrix_product() {
        // The elementary-rotation implementation against plain 4x4 products.
        use nalgebra::{Matrix4, Rotation3, Translation3};
        let robot = er3a();
        let p = perturbed(&robot, 5);
        let chain = Chain::new(Convention::Dh, 6, 4);
        let q = [0.3, -0.2, 0.5, 1.0, -0.7, 0.4];
        let h = |m: Matrix4<f64>| m;
        let rz = |t: f64| h(Rotation3::from_axis_angle(&Vector3::z_axis(), t).to_homogeneous());
        let rx = |t: f64| h(Rotation3::from_axis_angle(&Vector3::x_axis(), t).to_homogeneous());
        let ry = |t: f64| h(Rotation3::from_axis_angle(&Vector3::y_axis(), t).to_homogeneous());
        let tr = |x: f64, y: f64, z: f64| h(Translation3::new(x, y, z).to_homogeneous());
        let v = &p.values;
        let b = chain.layout.base();
        let mut m = tr(v[b], v[b + 1], v[b + 2]) * rz(v[b + 5]) * ry(v[b + 4]) * rx(v[b + 3]);
        for j in 0..6 {
            let k = 5 * j;
            m = m
                * rz(q[j] + v[k + 3])
                * tr(0.0, 0.0, v[k + 2])
                * tr(v[k], 0.0, 0.0)
                * rx(v[k + 1])
                * ry(v[k + 4]);
        }
        let t = chain.layout.tool();
        let pt = m * nalgebra::Vector4::new(v[t], v[t + 1], v[t + 2], 1.0);
        let (_, ours) = chain.point(v, &q, OutputFrame::Rig);
        assert!((ours - pt.xyz()).norm() < 1e-9);
    }
}
