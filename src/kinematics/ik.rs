//! Closed-form inverse kinematics of the nominal arm.
//!
//! Compensation refines joint angles on the calibrated model by damped least
//! squares; what it needs from here is a good start. For the two families of
//! six-axis arms that cover most industrial robots the nominal joint table
//! allows every solution in closed form:
//!
//! - [`Geometry::SphericalWrist`] (Pieper): the last three axes meet at one
//!   point, the wrist centre, and joints 2 and 3 are parallel (EFORT ER3A,
//!   KUKA, ABB, Fanuc, PUMA...). The wrist centre fixes joints 1-3 (two
//!   shoulders × two elbows; a shoulder offset `a1`, a lateral offset
//!   `d2 + d3` and an elbow offset `a3` are allowed), the orientation fixes
//!   joints 4-6 (two wrists): up to 8 solutions.
//! - [`Geometry::ParallelMiddle`]: joints 2, 3 and 4 parallel, joints 5 and 6
//!   offset (Universal Robots UR3/UR5/UR10/UR16): joint 1 from the point on
//!   axis 6 at the end of `d5`, joint 5 and joint 6 from how axis 6 and the
//!   flange frame sit relative to the parallel axes, joints 2-4 as a planar
//!   arm: up to 8 solutions.
//!
//! Both conventions are handled (a Craig MDH table is rewritten as the
//! equivalent DH table behind a fixed base transform); Hayati's β must be
//! zero. Any other geometry gives `None` from [`ClosedFormIk::new`] and the
//! caller falls back to a numerical solver. Every solution is checked by
//! forward kinematics on the nominal model before it is returned, so a
//! solution is never wrong, only possibly missing (at a singularity, where
//! the numerical solver takes over).
//!
//! The targets are the measured point T (the tool point, in the robot base
//! frame) and the flange orientation, as in targets.csv. A position-only
//! target leaves a six-axis arm three degrees of freedom;
//! [`ClosedFormIk::solve_position`] fixes them with a documented canonical
//! orientation.
//!
//! ```
//! use drawcal::kinematics::ik::{ClosedFormIk, Geometry};
//! use drawcal::model::Robot;
//!
//! // Universal Robots UR5, nominal DH.
//! let joint = |a: f64, alpha: f64, d: f64| {
//!     format!(r#"{{"a_mm": {a}, "alpha_deg": {alpha}, "d_mm": {d}}}"#)
//! };
//! let json = format!(
//!     r#"{{"convention": "dh", "tool_point_mm": [0, 0, 50], "joints": [{}]}}"#,
//!     [
//!         joint(0.0, 90.0, 89.159),
//!         joint(-425.0, 0.0, 0.0),
//!         joint(-392.25, 0.0, 0.0),
//!         joint(0.0, 90.0, 109.15),
//!         joint(0.0, -90.0, 94.65),
//!         joint(0.0, 0.0, 82.3),
//!     ]
//!     .join(",")
//! );
//! let ur5 = Robot::from_json(&json).unwrap();
//! let ik = ClosedFormIk::from_robot(&ur5).unwrap();
//! assert_eq!(ik.geometry(), Geometry::ParallelMiddle);
//!
//! let q = [0.3, -1.2, 1.4, -0.5, 1.1, 2.0];
//! let (t, r) = ik.forward(&q);
//! let solutions = ik.solve(&t, &r, &[0.0; 6]);
//! assert_eq!(solutions.len(), 8);
//! // One of the eight branches is the one we started from.
//! assert!(solutions.iter().any(|s| {
//!     s.iter().zip(&q).all(|(a, b)| (a - b).abs() < 1e-9)
//! }));
//! ```

use std::f64::consts::PI;

use nalgebra::{Matrix3, Vector3};

use super::chain::{Chain, OutputFrame};
use super::params::{JointParam, Params};
use crate::model::{Convention, Robot};

/// A closed-form solution is returned only if the nominal model's T is
/// this close to the target (mm)...
pub const VERIFY_POSITION_MM: f64 = 1e-6;
/// ...and its flange orientation this close (rad).
pub const VERIFY_ROTATION_RAD: f64 = 1e-9;

/// A geometric condition on the joint table holds to this (mm, or the sine
/// or cosine of an angle).
const EXACT: f64 = 1e-9;
/// A sine that must not vanish is at least this.
const NONZERO: f64 = 1e-6;

/// Which closed form the nominal arm allows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Geometry {
    /// Pieper: axes 4, 5 and 6 meet at the wrist centre; axes 2 and 3 are
    /// parallel.
    SphericalWrist,
    /// Universal Robots: axes 2, 3 and 4 parallel; 5 and 6 offset.
    ParallelMiddle,
}

/// One link of the equivalent DH table: `Rz(q + θ) Tz(d) Tx(a) Rx(α)`.
#[derive(Debug, Clone, Copy)]
struct Link {
    a: f64,
    d: f64,
    theta: f64,
    sa: f64,
    ca: f64,
}

impl Link {
    fn rx(&self) -> Matrix3<f64> {
        rx(self.sa, self.ca)
    }
}

/// Closed-form inverse kinematics of a nominal six-axis arm.
#[derive(Debug, Clone)]
pub struct ClosedFormIk {
    geometry: Geometry,
    /// The equivalent DH table (`Rz Tz Tx Rx` per joint).
    links: [Link; 6],
    /// Robot base frame to DH frame 0: identity for DH, `Rx(α1) Tx(a1)` for
    /// MDH.
    base_r: Matrix3<f64>,
    base_o: Vector3<f64>,
    /// T in the flange frame (mm).
    tool: Vector3<f64>,
    chain: Chain,
    nominal: Vec<f64>,
}

fn rz(phi: f64) -> Matrix3<f64> {
    let (s, c) = phi.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

fn rx(s: f64, c: f64) -> Matrix3<f64> {
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

/// `angle` in (-π, π].
fn wrap_pi(angle: f64) -> f64 {
    let a = angle.rem_euclid(2.0 * PI);
    if a > PI { a - 2.0 * PI } else { a }
}

/// acos of a cosine that may exceed ±1 by rounding; `None` beyond that.
fn acos_checked(c: f64) -> Option<f64> {
    (c.abs() <= 1.0 + 1e-9).then(|| c.clamp(-1.0, 1.0).acos())
}

/// The angle between two rotations (rad), accurate near zero.
pub fn rotation_angle(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    let d = a.transpose() * b;
    let v = Vector3::new(
        d[(2, 1)] - d[(1, 2)],
        d[(0, 2)] - d[(2, 0)],
        d[(1, 0)] - d[(0, 1)],
    );
    (0.5 * v.norm()).atan2(0.5 * (d.trace() - 1.0))
}

/// Both elbows of a planar two-link arm: `(φ2, φ3)` with
/// `Rz(φ2) [(a2, 0) + Rz(φ3) v] = (x, y)`.
fn planar(a2: f64, v: (f64, f64), x: f64, y: f64) -> Vec<(f64, f64)> {
    let l2 = v.0.hypot(v.1);
    let gamma = v.1.atan2(v.0);
    let Some(psi) = acos_checked((x * x + y * y - a2 * a2 - l2 * l2) / (2.0 * a2 * l2)) else {
        return vec![];
    };
    let mut out = Vec::with_capacity(2);
    for psi in [psi, -psi] {
        let (s, c) = psi.sin_cos();
        let (kx, ky) = (a2 + l2 * c, l2 * s);
        if kx.hypot(ky) < EXACT {
            continue;
        }
        out.push((y.atan2(x) - ky.atan2(kx), psi - gamma));
    }
    out
}

impl ClosedFormIk {
    /// The closed form for a nominal parameter vector (robot base frame;
    /// base pose and strings ignored), or `None` when the joint table has
    /// neither geometry.
    pub fn new(convention: Convention, nominal: &Params) -> Option<Self> {
        let l = nominal.layout;
        if l.n_joints != 6 {
            return None;
        }
        let get = |j: usize, p: JointParam| nominal.joint(j, p);
        if (0..6).any(|j| get(j, JointParam::Beta).abs() > EXACT) {
            return None;
        }
        let link = |a: f64, alpha: f64, d: f64, theta: f64| {
            let (sa, ca) = alpha.sin_cos();
            Link {
                a,
                d,
                theta,
                sa,
                ca,
            }
        };
        let (links, base_r, base_o) = match convention {
            Convention::Dh => (
                std::array::from_fn(|j| {
                    link(
                        get(j, JointParam::A),
                        get(j, JointParam::Alpha),
                        get(j, JointParam::D),
                        get(j, JointParam::Theta),
                    )
                }),
                Matrix3::identity(),
                Vector3::zeros(),
            ),
            // Rx(α1)Tx(a1) · [Rz(φ1)Tz(d1) Rx(α2)Tx(a2)] · ... · Rz(φ6)Tz(d6),
            // and Rx, Tx commute: the DH table (a_{j+1}, α_{j+1}, d_j, θ_j)
            // behind a fixed base transform.
            Convention::Mdh => {
                let (s1, c1) = get(0, JointParam::Alpha).sin_cos();
                (
                    std::array::from_fn(|j| {
                        let (a, alpha) = if j < 5 {
                            (get(j + 1, JointParam::A), get(j + 1, JointParam::Alpha))
                        } else {
                            (0.0, 0.0)
                        };
                        link(a, alpha, get(j, JointParam::D), get(j, JointParam::Theta))
                    }),
                    rx(s1, c1),
                    Vector3::new(get(0, JointParam::A), 0.0, 0.0),
                )
            }
        };
        let [l1, l2, l3, l4, l5, _] = links;
        let zero = |v: f64| v.abs() <= EXACT;
        let parallel = |l: &Link| zero(l.sa) && l.ca > 0.0;
        let crossed = |l: &Link| l.sa.abs() >= NONZERO;
        // Both: joint 1 crosses joint 2, joints 2 and 3 parallel, a planar
        // arm of non-zero links, joints 4-5 and 5-6 crossed and meeting
        // (a4 = a5 = 0).
        let common = crossed(&l1)
            && parallel(&l2)
            && l2.a.abs() >= NONZERO
            && zero(l4.a)
            && zero(l5.a)
            && crossed(&l4)
            && crossed(&l5);
        if !common {
            return None;
        }
        let geometry = if zero(l5.d) && l3.a.hypot(l4.d * l3.sa) >= NONZERO {
            Geometry::SphericalWrist
        } else if parallel(&l3) && l3.a.abs() >= NONZERO {
            Geometry::ParallelMiddle
        } else {
            return None;
        };
        let t = l.tool();
        Some(ClosedFormIk {
            geometry,
            links,
            base_r,
            base_o,
            tool: Vector3::new(
                nominal.values[t],
                nominal.values[t + 1],
                nominal.values[t + 2],
            ),
            chain: Chain::new(convention, 6, 0),
            nominal: nominal.values[..l.n_geometric()].to_vec(),
        })
    }

    /// The closed form of a robot.json's nominal model.
    pub fn from_robot(robot: &Robot) -> Option<Self> {
        Self::new(robot.convention, &Params::of_robot(robot))
    }

    /// Which closed form applies.
    pub fn geometry(&self) -> Geometry {
        self.geometry
    }

    /// The nominal model's T and flange orientation at `q` (rad), robot
    /// base frame.
    pub fn forward(&self, q: &[f64]) -> (Vector3<f64>, Matrix3<f64>) {
        let (f, t) = self.chain.point(&self.nominal, q, OutputFrame::Base);
        (t, f.r)
    }

    /// Every joint vector (rad, each angle in (-π, π]) that puts T at `t`
    /// with the flange at orientation `r` on the nominal model, verified by
    /// forward kinematics. Empty when the pose is out of reach (or at a
    /// singularity the closed form does not resolve). Where a wrist
    /// singularity leaves a sum of angles free, the free angle is taken
    /// from `reference`.
    pub fn solve(&self, t: &Vector3<f64>, r: &Matrix3<f64>, reference: &[f64]) -> Vec<Vec<f64>> {
        // The flange in DH frame 0.
        let r6 = self.base_r.transpose() * r;
        let o6 = self.base_r.transpose() * (t - r * self.tool - self.base_o);
        let l = &self.links;
        // Frame 5 rotated by joint 6 (before α6), its z axis (axis 6) and the
        // point where axis 6 meets the common normal of axes 5 and 6.
        let r6p = r6 * l[5].rx().transpose();
        let z5 = r6p.column(2).into_owned();
        let p = o6 - l[5].d * z5 - l[5].a * r6.column(0);
        let reference_phi = |j: usize| reference.get(j).copied().unwrap_or(0.0) + l[j].theta;
        let mut phis: Vec<[f64; 6]> = Vec::with_capacity(8);
        let h = match self.geometry {
            Geometry::SphericalWrist => l[1].d + l[2].d + l[3].d * l[2].ca,
            Geometry::ParallelMiddle => l[1].d + l[2].d + l[3].d + l[4].d * l[3].ca,
        };
        for phi1 in self.shoulder(&p, h) {
            let r1 = rz(phi1) * l[0].rx();
            let o1 = Vector3::new(l[0].a * phi1.cos(), l[0].a * phi1.sin(), l[0].d);
            match self.geometry {
                Geometry::SphericalWrist => {
                    let w = r1.transpose() * (p - o1);
                    let v = (l[2].a, -l[3].d * l[2].sa);
                    for (phi2, phi3) in planar(l[1].a, v, w.x, w.y) {
                        let r3 = r1 * rz(phi2 + phi3) * l[2].rx();
                        let m = r3.transpose() * r6p;
                        for (phi4, phi5, phi6) in self.wrist(&m, reference_phi(3)) {
                            phis.push([phi1, phi2, phi3, phi4, phi5, phi6]);
                        }
                    }
                }
                Geometry::ParallelMiddle => {
                    let (l4, l5) = (&l[3], &l[4]);
                    let z1 = r1.column(2).into_owned();
                    let Some(phi5) = acos_checked((l4.ca * l5.ca - z5.dot(&z1)) / (l4.sa * l5.sa))
                    else {
                        continue;
                    };
                    // Axis 1 (= 2, 3, 4) in the frame of r6p.
                    let n = r6p.transpose() * z1;
                    for phi5 in [phi5, -phi5] {
                        let (s5, c5) = phi5.sin_cos();
                        let (u, v) = (l4.sa * s5, l4.sa * c5 * l5.ca + l4.ca * l5.sa);
                        let phi6 = if u.hypot(v) > NONZERO {
                            (v * n.x - u * n.y).atan2(u * n.x + v * n.y)
                        } else {
                            reference_phi(5)
                        };
                        let r4 =
                            r6p * rz(phi6).transpose() * l5.rx().transpose() * rz(phi5).transpose();
                        let o4 = p - l5.d * r4.column(2);
                        let k = r1.transpose() * r4 * l4.rx().transpose();
                        let phi234 = k[(1, 0)].atan2(k[(0, 0)]);
                        let w = r1.transpose() * (o4 - o1);
                        for (phi2, phi3) in planar(l[1].a, (l[2].a, 0.0), w.x, w.y) {
                            phis.push([phi1, phi2, phi3, phi234 - phi2 - phi3, phi5, phi6]);
                        }
                    }
                }
            }
        }
        let mut out: Vec<Vec<f64>> = Vec::with_capacity(phis.len());
        for phi in phis {
            let q: Vec<f64> = phi
                .iter()
                .zip(l)
                .map(|(f, link)| wrap_pi(f - link.theta))
                .collect();
            let (tq, rq) = self.forward(&q);
            let ok = (tq - t).norm() <= VERIFY_POSITION_MM
                && rotation_angle(&rq, r) <= VERIFY_ROTATION_RAD;
            let duplicate = out
                .iter()
                .any(|s| s.iter().zip(&q).all(|(a, b)| wrap_pi(a - b).abs() < 1e-9));
            if ok && !duplicate {
                out.push(q);
            }
        }
        out
    }

    /// Joints for a position-only target (T at `t`, orientation free).
    ///
    /// A six-axis arm has three degrees of freedom left; they are fixed by
    /// a canonical orientation: the flange orientation the nominal model has
    /// at `reference`, turned about axis 1 by the angle that brings T's
    /// azimuth about that axis to the target's (so the wrist keeps the pose
    /// it has at `reference` relative to the arm, only the arm turns to face
    /// the target). Every branch with that orientation is returned,
    /// verified; empty when the target is out of reach with it (the caller's
    /// numerical solver then searches the other orientations).
    pub fn solve_position(&self, t: &Vector3<f64>, reference: &[f64]) -> Vec<Vec<f64>> {
        let r = self.canonical_orientation(t, reference);
        self.solve(t, &r, reference)
    }

    /// The orientation [`ClosedFormIk::solve_position`] holds.
    pub fn canonical_orientation(&self, t: &Vector3<f64>, reference: &[f64]) -> Matrix3<f64> {
        let axes = self
            .chain
            .joint_axes(&self.nominal, reference, OutputFrame::Base);
        let (u, c) = axes[0];
        let (t_ref, _) = self.forward(reference);
        let flat = |v: Vector3<f64>| v - u * u.dot(&v);
        let (a, b) = (flat(t_ref - c), flat(t - c));
        let turn = if a.norm() > EXACT && b.norm() > EXACT {
            u.dot(&a.cross(&b)).atan2(a.dot(&b))
        } else {
            0.0
        };
        let mut q = reference.to_vec();
        q[0] += turn;
        self.forward(&q).1
    }

    /// Joint 1 (φ = q + θ) both ways such that the point `p` (DH frame 0)
    /// lies at height `h` along axis 2 measured from frame 1.
    fn shoulder(&self, p: &Vector3<f64>, h: f64) -> Vec<f64> {
        let l1 = &self.links[0];
        // (p - o1)·z1 = h with z1 = Rz(φ)(0, -sα, cα), o1 = Rz(φ)(a, 0, d).
        let (a, b) = (-l1.sa * p.y, l1.sa * p.x);
        let c = h - l1.ca * (p.z - l1.d);
        let rho = a.hypot(b);
        if rho < EXACT * (1.0 + p.norm()) {
            // p on axis 1: any φ1 would do; the numerical solver decides.
            return vec![];
        }
        let Some(delta) = acos_checked(c / rho) else {
            return vec![];
        };
        let mid = b.atan2(a);
        vec![mid + delta, mid - delta]
    }

    /// Joints 4-6 (φ) with `Rz(φ4) Rx(α4) Rz(φ5) Rx(α5) Rz(φ6) = m`, both
    /// wrists; at the wrist singularity φ4 is `phi4_ref`.
    fn wrist(&self, m: &Matrix3<f64>, phi4_ref: f64) -> Vec<(f64, f64, f64)> {
        let (l4, l5) = (&self.links[3], &self.links[4]);
        let Some(phi5) = acos_checked((l4.ca * l5.ca - m[(2, 2)]) / (l4.sa * l5.sa)) else {
            return vec![];
        };
        let (mx, my) = (m[(0, 2)], m[(1, 2)]);
        let mut out = Vec::with_capacity(2);
        for phi5 in [phi5, -phi5] {
            let (s5, c5) = phi5.sin_cos();
            // m e_z = Rz(φ4) (p, q, ·).
            let (p, q) = (l5.sa * s5, -l4.ca * l5.sa * c5 - l4.sa * l5.ca);
            let phi4 = if p.hypot(q) > NONZERO {
                (p * my - q * mx).atan2(p * mx + q * my)
            } else {
                phi4_ref
            };
            let k = (rz(phi4) * l4.rx() * rz(phi5) * l5.rx()).transpose() * m;
            out.push((phi4, phi5, k[(1, 0)].atan2(k[(0, 0)])));
        }
        out
    }
}

/// Move each angle of `q` by whole turns to the value nearest `reference`
/// inside `limits` (rad): the same pose, so never a clamp. An angle with no
/// turn inside its limits goes to the turn nearest `reference`.
pub fn turn_near(q: &mut [f64], reference: &[f64], limits: &[(f64, f64)]) {
    let turn = 2.0 * PI;
    for ((v, r), (lo, hi)) in q.iter_mut().zip(reference).zip(limits) {
        let want = ((r - *v) / turn).round();
        let k_min = ((lo - 1e-9 - *v) / turn).ceil();
        let k_max = ((hi + 1e-9 - *v) / turn).floor();
        let k = if k_min <= k_max {
            want.clamp(k_min, k_max)
        } else {
            want
        };
        *v += k * turn;
    }
}

/// Order closed-form solutions for use as seeds: each is moved by
/// [`turn_near`], duplicates are dropped, solutions inside the limits come
/// first, then by squared distance to `reference`.
pub fn order_near(solutions: &mut Vec<Vec<f64>>, reference: &[f64], limits: &[(f64, f64)]) {
    for q in solutions.iter_mut() {
        turn_near(q, reference, limits);
    }
    let key = |q: &Vec<f64>| {
        let outside = q
            .iter()
            .zip(limits)
            .any(|(v, (lo, hi))| *v < lo - 1e-9 || *v > hi + 1e-9);
        let dist: f64 = q.iter().zip(reference).map(|(a, b)| (a - b).powi(2)).sum();
        (outside, dist)
    };
    solutions.sort_by(|a, b| {
        let (ka, kb) = (key(a), key(b));
        ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
    });
    // Equal solutions have equal keys, so they are now neighbours.
    solutions.dedup_by(|a, b| a.iter().zip(b.iter()).all(|(x, y)| (x - y).abs() < 1e-9));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn robot(name: &str) -> Robot {
        let text = match name {
            "er3a" => include_str!("../../tests/data/er3a_paper_like/robot.json"),
            "ur5" => include_str!("../../tests/data/ur5_geometric/robot.json"),
            "ur10" => include_str!("../../tests/data/real_ur10_ipa_random/robot.json"),
            "positioner" => include_str!("../../tests/data/real_positioner2ax_rosi/robot.json"),
            _ => unreachable!(),
        };
        Robot::from_json(text).unwrap()
    }

    /// The ER3A's table in Craig's MDH: the same arm.
    fn er3a_mdh() -> Robot {
        let dh = robot("er3a");
        let mut mdh = dh.clone();
        mdh.convention = Convention::Mdh;
        for j in 0..6 {
            let (a, alpha) = if j == 0 {
                (0.0, 0.0)
            } else {
                (dh.joints[j - 1].a_mm, dh.joints[j - 1].alpha_deg)
            };
            mdh.joints[j].a_mm = a;
            mdh.joints[j].alpha_deg = alpha;
        }
        mdh
    }

    /// Random joints inside the limits (within ±180° each), FK, closed
    /// form: one branch reproduces the pose; every returned branch does.
    fn round_trip(robot: &Robot, geometry: Geometry, n: usize, seed: u64) {
        let ik = ClosedFormIk::from_robot(robot).expect("closed form");
        assert_eq!(ik.geometry(), geometry);
        let mut rng = Rng::new(seed);
        let (mut worst_pos, mut worst_rot, mut total) = (0.0f64, 0.0f64, 0);
        for _ in 0..n {
            let q: Vec<f64> = robot
                .joints
                .iter()
                .map(|j| {
                    rng.range(j.q_min_deg.max(-180.0), j.q_max_deg.min(180.0))
                        .to_radians()
                })
                .collect();
            let (t, r) = ik.forward(&q);
            let sols = ik.solve(&t, &r, &q);
            assert!(!sols.is_empty(), "{} no solution at {q:?}", robot.name);
            total += sols.len();
            let mut best = f64::INFINITY;
            for s in &sols {
                let (ts, rs) = ik.forward(s);
                let (dp, dr) = ((ts - t).norm(), rotation_angle(&rs, &r));
                worst_pos = worst_pos.max(dp);
                worst_rot = worst_rot.max(dr);
                assert!(dp < 1e-9 && dr < 1e-9, "{dp} mm {dr} rad");
                let dq = s
                    .iter()
                    .zip(&q)
                    .map(|(a, b)| wrap_pi(a - b).abs())
                    .fold(0.0, f64::max);
                best = best.min(dq);
            }
            // The branch we came from is among them.
            assert!(best < 1e-6, "{}: {q:?} not among {sols:?}", robot.name);
        }
        eprintln!(
            "{} {geometry:?}: {n} poses, {:.2} solutions each, worst {worst_pos:.1e} mm {worst_rot:.1e} rad",
            robot.name,
            total as f64 / n as f64
        );
    }

    #[test]
    fn er3a_spherical_wrist_round_trip() {
        round_trip(&robot("er3a"), Geometry::SphericalWrist, 2000, 1);
    }

    #[test]
    fn er3a_mdh_round_trip_matches_dh() {
        let mdh = er3a_mdh();
        let (dh, m) = (
            ClosedFormIk::from_robot(&robot("er3a")).unwrap(),
            ClosedFormIk::from_robot(&mdh).unwrap(),
        );
        let q = [0.2, -0.3, 0.4, 1.0, -0.6, 0.8];
        let (a, b) = (dh.forward(&q), m.forward(&q));
        assert!((a.0 - b.0).norm() < 1e-9 && rotation_angle(&a.1, &b.1) < 1e-12);
        round_trip(&mdh, Geometry::SphericalWrist, 500, 2);
    }

    #[test]
    fn ur5_and_ur10_all_eight_branches() {
        round_trip(&robot("ur5"), Geometry::ParallelMiddle, 2000, 3);
        round_trip(&robot("ur10"), Geometry::ParallelMiddle, 2000, 4);
        // Away from singularities all eight branches exist.
        let ik = ClosedFormIk::from_robot(&robot("ur5")).unwrap();
        let (t, r) = ik.forward(&[0.3, -1.2, 1.4, -0.5, 1.1, 2.0]);
        assert_eq!(ik.solve(&t, &r, &[0.0; 6]).len(), 8);
    }

    #[test]
    fn er3a_has_eight_branches_away_from_singularities() {
        let ik = ClosedFormIk::from_robot(&robot("er3a")).unwrap();
        // A point near the base (inside the reach both ways) has all eight.
        let (t, r) = ik.forward(&[0.3, -0.9, 0.3, 0.5, 0.8, 0.2]);
        let sols = ik.solve(&t, &r, &[0.0; 6]);
        assert_eq!(sols.len(), 8, "{sols:?}");
    }

    #[test]
    fn shoulder_and_elbow_offsets_and_nonzero_theta() {
        // A spherical-wrist arm with every offset the solver allows: a1,
        // d2 + d3 sideways, a3, θ offsets, a flange twist and a tool.
        let mut r = robot("er3a");
        r.joints[0].a_mm = 150.0;
        r.joints[1].d_mm = 40.0;
        r.joints[2].d_mm = -15.0;
        r.joints[2].a_mm = 110.0;
        r.joints[3].theta_offset_deg = 12.0;
        r.joints[5].theta_offset_deg = -30.0;
        r.joints[5].alpha_deg = 20.0;
        r.joints[5].a_mm = 5.0;
        r.tool_point_mm = [10.0, -20.0, 80.0];
        round_trip(&r, Geometry::SphericalWrist, 500, 5);
        // A UR with a shoulder offset and α4 = -90, α5 = 90.
        let mut u = robot("ur10");
        u.joints[0].a_mm = 50.0;
        u.joints[3].alpha_deg = -90.0;
        u.joints[4].alpha_deg = 90.0;
        u.joints[1].theta_offset_deg = -90.0;
        u.tool_point_mm = [30.0, 0.0, 100.0];
        round_trip(&u, Geometry::ParallelMiddle, 500, 6);
    }

    #[test]
    fn other_geometries_give_none() {
        assert!(ClosedFormIk::from_robot(&robot("positioner")).is_none());
        // A wrist whose axes do not meet (a5 ≠ 0) on an ER3A.
        let mut r = robot("er3a");
        r.joints[4].a_mm = 10.0;
        assert!(ClosedFormIk::from_robot(&r).is_none());
        // Hayati's β on joint 3.
        let mut r = robot("er3a");
        r.joints[2].beta_deg = 0.5;
        assert!(ClosedFormIk::from_robot(&r).is_none());
        // Joints 2 and 3 not parallel.
        let mut r = robot("ur5");
        r.joints[1].alpha_deg = 10.0;
        assert!(ClosedFormIk::from_robot(&r).is_none());
        // Joint 1 parallel to joint 2.
        let mut r = robot("ur5");
        r.joints[0].alpha_deg = 0.0;
        assert!(ClosedFormIk::from_robot(&r).is_none());
        // Five joints.
        let mut r = robot("ur5");
        r.joints.pop();
        assert!(ClosedFormIk::from_robot(&r).is_none());
    }

    #[test]
    fn out_of_reach_gives_no_solution() {
        for name in ["er3a", "ur5"] {
            let ik = ClosedFormIk::from_robot(&robot(name)).unwrap();
            let far = Vector3::new(3000.0, 0.0, 0.0);
            assert!(ik.solve(&far, &Matrix3::identity(), &[0.0; 6]).is_empty());
            assert!(ik.solve_position(&far, &[0.0; 6]).is_empty());
        }
    }

    #[test]
    fn position_only_keeps_the_turned_reference_orientation() {
        for name in ["er3a", "ur5"] {
            let ik = ClosedFormIk::from_robot(&robot(name)).unwrap();
            let reference = [0.0, 0.2, 0.3, 0.0, 0.4, 0.0];
            // The reference's own pose turned about axis 1 by 1 rad.
            let turned = [1.0, 0.2, 0.3, 0.0, 0.4, 0.0];
            let (t, r) = ik.forward(&turned);
            assert!(rotation_angle(&ik.canonical_orientation(&t, &reference), &r) < 1e-12);
            let sols = ik.solve_position(&t, &reference);
            assert!(!sols.is_empty());
            for s in &sols {
                let (ts, rs) = ik.forward(s);
                assert!((ts - t).norm() < 1e-9);
                assert!(rotation_angle(&rs, &r) < 1e-9);
            }
        }
    }

    #[test]
    fn order_near_moves_whole_turns_into_the_limits() {
        let limits = [(-2.0 * PI, 2.0 * PI), (-1.0, 1.0)];
        let mut sols = vec![vec![3.0, 2.0], vec![-3.0, 0.5], vec![3.0 - 2.0 * PI, 0.5]];
        order_near(&mut sols, &[-3.0, 0.0], &limits);
        // [3, 2]: joint 2 is out at any turn, so last. [-3, 0.5] and
        // [3 - 2π, 0.5] both stay; the nearer first.
        assert_eq!(sols.len(), 3);
        assert_eq!(sols[0], vec![-3.0, 0.5]);
        assert!((sols[1][0] - (3.0 - 2.0 * PI)).abs() < 1e-12);
        assert_eq!(sols[2][1], 2.0);
        // Turned to the reference: 3 - 2π is nearer -3 than 3 is.
        assert!((sols[2][0] - (3.0 - 2.0 * PI)).abs() < 1e-12);
    }
}
