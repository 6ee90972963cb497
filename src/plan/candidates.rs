//! Candidate poses: joint angles drawn inside the limits, kept only where
//! the rig can measure T well and the arm stays clear of the floor, the
//! keep-out boxes and the strings. The same test decides which random poses
//! count as "valid" when a plan is judged.

use std::collections::BTreeMap;

use nalgebra::{DMatrix, Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::kinematics::chain::{Chain, OutputFrame, PointJacobian, Trig, joint_trig};
use crate::kinematics::{JointParam, Params};
use crate::model::{BasePose, Rig, Robot};
use crate::rng::Rng;

/// A box the arm, the tool and the strings must stay out of, in the robot
/// base frame (a fixture, a table, a wall), given by two opposite corners.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeepOut {
    /// Smallest x, y, z (mm, robot base frame).
    pub min_mm: [f64; 3],
    /// Largest x, y, z (mm, robot base frame).
    pub max_mm: [f64; 3],
}

impl KeepOut {
    /// Parse `x0,y0,z0,x1,y1,z1` (mm), corners in any order.
    pub fn parse(field: &str, s: &str) -> Result<KeepOut> {
        let v: Vec<f64> = s
            .split(',')
            .map(|t| t.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| Error::field(field, format!("'{s}': expected x0,y0,z0,x1,y1,z1 (mm)")))?;
        if v.len() != 6 || v.iter().any(|x| !x.is_finite()) {
            return Err(Error::field(
                field,
                format!("'{s}': expected six finite numbers x0,y0,z0,x1,y1,z1 (mm)"),
            ));
        }
        Ok(KeepOut {
            min_mm: [v[0].min(v[3]), v[1].min(v[4]), v[2].min(v[5])],
            max_mm: [v[0].max(v[3]), v[1].max(v[4]), v[2].max(v[5])],
        })
    }

    fn contains(&self, p: &Vector3<f64>) -> bool {
        (0..3).all(|c| p[c] >= self.min_mm[c] && p[c] <= self.max_mm[c])
    }
}

/// Where poses may go, beyond the joint limits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Workspace {
    /// Height of the floor in the robot base frame (mm): every joint frame,
    /// the flange and T stay above it.
    #[serde(default)]
    pub floor_z_mm: Option<f64>,
    /// Boxes the links, the tool and the strings stay out of.
    #[serde(default)]
    pub keep_out: Vec<KeepOut>,
    /// Shortest string reading allowed (mm).
    #[serde(default = "min_string")]
    pub min_string_mm: f64,
    /// Distance kept from the end of the sensor's range (mm).
    #[serde(default = "range_margin")]
    pub range_margin_mm: f64,
    /// Distance kept from the plane of coplanar anchors (mm): on it the
    /// point's side of the plane is unknown and its height badly measured.
    #[serde(default = "plane_clearance")]
    pub anchor_plane_clearance_mm: f64,
    /// Distance kept between a string and the arm's links (mm).
    #[serde(default = "string_clearance")]
    pub string_clearance_mm: f64,
}

fn min_string() -> f64 {
    100.0
}
fn range_margin() -> f64 {
    50.0
}
fn plane_clearance() -> f64 {
    100.0
}
fn string_clearance() -> f64 {
    30.0
}

impl Default for Workspace {
    fn default() -> Self {
        Workspace {
            floor_z_mm: None,
            keep_out: vec![],
            min_string_mm: min_string(),
            range_margin_mm: range_margin(),
            anchor_plane_clearance_mm: plane_clearance(),
            string_clearance_mm: string_clearance(),
        }
    }
}

/// Why a drawn pose was not kept (the plan report counts each).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Rejection {
    /// A string would read outside its range (or shorter than the minimum).
    StringRange,
    /// T too close to the plane of the anchors.
    AnchorPlane,
    /// The strings meet T at angles that locate it badly.
    StringGeometry,
    /// A string would touch the arm.
    StringOnArm,
    /// A joint frame, the flange or T below the floor.
    Floor,
    /// The arm, the tool or a string inside a keep-out box.
    KeepOut,
    /// Near a singularity: T or the flange moves badly with the joints.
    Singular,
}

/// Smallest singular value of the strings' unit directions at T: below it
/// the located point's error is more than about 7x the string noise in its
/// worst direction.
const MIN_STRING_GEOMETRY: f64 = 0.15;
/// Smallest singular value of the joint Jacobian of T, over the arm's reach
/// (the simulator's test).
const MIN_POSITION_DEXTERITY: f64 = 0.08;
/// Smallest singular value of the joint Jacobian of the flange (T over the
/// reach, and the rotation) for six joints or more: a wrist singularity.
const MIN_WRIST_DEXTERITY: f64 = 0.05;
/// Spacing of the points checked along links and strings (mm).
const SAMPLE_STEP_MM: f64 = 25.0;
/// Length of a string next to T not checked against the arm (mm): the
/// string is tied to the tool there.
const STRING_TIE_MM: f64 = 80.0;

/// The fixed geometry a pose is checked against.
pub struct Scene<'a> {
    /// The nominal robot.
    pub robot: &'a Robot,
    /// The rig.
    pub rig: &'a Rig,
    /// The constraints.
    pub workspace: &'a Workspace,
    /// Kinematic structure.
    pub chain: Chain,
    /// Nominal parameters with rig.json's base pose.
    pub nominal: Params,
    /// Their trigonometry, for [`Scene::point_jacobian`].
    trig: Trig,
    anchors: Vec<Vector3<f64>>,
    /// Unit normal of the anchors' plane when they are coplanar.
    plane: Option<Vector3<f64>>,
    base_r: Matrix3<f64>,
    base_t: Vector3<f64>,
    reach_mm: f64,
    range_mm: f64,
}

/// A pose the rig can measure, with what the design needs of it.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// Joint angles (deg, to 1e-4 deg as a controller logs them).
    pub q_deg: Vec<f64>,
    /// The same (rad).
    pub q_rad: Vec<f64>,
    /// Nominal T in the rig frame (mm).
    pub t_rig: Vector3<f64>,
}

impl<'a> Scene<'a> {
    /// The scene of a robot on a rig. A string rig must give `base_in_rig`:
    /// the strings' geometry depends on where the robot stands.
    pub fn new(robot: &'a Robot, rig: &'a Rig, workspace: &'a Workspace) -> Result<Self> {
        let m = rig.n_strings();
        let base = match (&rig.base_in_rig, m) {
            (Some(b), _) => *b,
            (None, 0) => BasePose {
                xyz_mm: [0.0; 3],
                rpy_deg: [0.0; 3],
            },
            (None, _) => {
                return Err(Error::field(
                    "rig.json base_in_rig",
                    "a plan for a string rig needs the robot base pose in the rig frame (base_in_rig): the strings' lengths and angles depend on it",
                ));
            }
        };
        for (k, b) in workspace.keep_out.iter().enumerate() {
            if (0..3).any(|c| !(b.min_mm[c] <= b.max_mm[c])) {
                return Err(Error::field(
                    format!("workspace.keep_out[{k}]"),
                    "min_mm must not exceed max_mm on any axis",
                ));
            }
        }
        let chain = Chain::new(robot.convention, robot.dof(), m);
        let nominal = Params::nominal(robot, &base, rig, m);
        let anchors: Vec<Vector3<f64>> = (0..m).map(|k| rig.anchor(k)).collect();
        let (base_r, base_t) = nominal.base_rt();
        let reach_mm = robot
            .joints
            .iter()
            .map(|j| j.a_mm.abs() + j.d_mm.abs())
            .sum::<f64>()
            .max(100.0);
        Ok(Scene {
            robot,
            rig,
            workspace,
            plane: coplanar_normal(&anchors),
            anchors,
            base_r,
            base_t,
            reach_mm,
            range_mm: rig.sensor.and_then(|s| s.range_mm).unwrap_or(2000.0),
            trig: chain.trig(&nominal.values),
            chain,
            nominal,
        })
    }

    /// The nominal T at joint angles `q_rad` and its derivatives by every
    /// parameter, in the rig frame ([`Chain::point_jacobian`] of the
    /// nominal parameters, their trigonometry computed once).
    pub fn point_jacobian(&self, q_rad: &[f64], jac: &mut PointJacobian) {
        self.chain.point_jacobian_trig(
            &self.nominal.values,
            &self.trig,
            &joint_trig(q_rad),
            OutputFrame::Rig,
            jac,
        );
    }

    /// The anchors (rig frame, mm).
    pub fn anchors(&self) -> &[Vector3<f64>] {
        &self.anchors
    }

    /// Draw joint angles uniformly inside the limits (a 2 deg margin; a
    /// joint that turns more than a full turn is drawn in one turn).
    pub fn draw(&self, rng: &mut Rng) -> Vec<f64> {
        self.robot
            .joints
            .iter()
            .map(|j| {
                let (mut lo, mut hi) = (j.q_min_deg + 2.0, j.q_max_deg - 2.0);
                if hi - lo > 360.0 {
                    (lo, hi) = (-180.0, 180.0);
                }
                (rng.range(lo, hi) * 1e4).round() / 1e4
            })
            .collect()
    }

    /// Check a pose; `jac` is a reusable buffer.
    pub fn check(
        &self,
        q_deg: Vec<f64>,
        jac: &mut PointJacobian,
    ) -> std::result::Result<Candidate, Rejection> {
        let q_rad: Vec<f64> = q_deg.iter().map(|v| v.to_radians()).collect();
        self.point_jacobian(&q_rad, jac);
        let t = jac.point;
        let ws = self.workspace;
        // The strings: in range, off the anchors' plane, well spread.
        if !self.anchors.is_empty() {
            for a in &self.anchors {
                let len = (t - a).norm() - self.rig.r_mm;
                if len < ws.min_string_mm || len > self.range_mm - ws.range_margin_mm {
                    return Err(Rejection::StringRange);
                }
            }
            if let Some(n) = self.plane {
                if (t - self.anchors[0]).dot(&n).abs() < ws.anchor_plane_clearance_mm {
                    return Err(Rejection::AnchorPlane);
                }
            }
            let g = DMatrix::from_fn(self.anchors.len(), 3, |k, c| {
                let u = (t - self.anchors[k]).normalize();
                u[c]
            });
            if smallest_singular(&g) < MIN_STRING_GEOMETRY {
                return Err(Rejection::StringGeometry);
            }
        }
        let joints_base = self.arm_points_base(&q_rad, &t);
        let t_base = joints_base[joints_base.len() - 1];
        if let Some(z) = ws.floor_z_mm {
            if joints_base.iter().any(|o| o.z < z) {
                return Err(Rejection::Floor);
            }
        }
        if !ws.keep_out.is_empty() {
            let arm_hit = joints_base
                .windows(2)
                .any(|s| along(&s[0], &s[1]).any(|x| ws.keep_out.iter().any(|b| b.contains(&x))));
            if arm_hit {
                return Err(Rejection::KeepOut);
            }
            let string_hit = self.anchors.iter().any(|a| {
                let a_base = self.base_r.transpose() * (a - self.base_t);
                along(&a_base, &t_base).any(|x| ws.keep_out.iter().any(|b| b.contains(&x)))
            });
            if string_hit {
                return Err(Rejection::KeepOut);
            }
        }
        // The strings clear of the links (in the rig frame), but for the
        // stretch where they are tied to the tool.
        if !self.anchors.is_empty() && ws.string_clearance_mm > 0.0 {
            let mut arm_rig: Vec<Vector3<f64>> = vec![self.base_t];
            arm_rig.extend(joints_base.iter().map(|o| self.base_r * o + self.base_t));
            for a in &self.anchors {
                let d = t - a;
                let len = d.norm();
                if len <= STRING_TIE_MM {
                    continue;
                }
                let end = a + d * ((len - STRING_TIE_MM) / len);
                if arm_rig
                    .windows(2)
                    .any(|s| segment_distance(a, &end, &s[0], &s[1]) < ws.string_clearance_mm)
                {
                    return Err(Rejection::StringOnArm);
                }
            }
        }
        // Away from singularities.
        let n = self.robot.dof();
        let l = self.chain.layout;
        let col = |c: usize| l.joint(c, JointParam::Theta);
        let jq = DMatrix::from_fn(3, n, |r, c| jac.d_params[col(c)][r]);
        if smallest_singular(&jq) < MIN_POSITION_DEXTERITY * self.reach_mm {
            return Err(Rejection::Singular);
        }
        if n >= 6 {
            let j6 = DMatrix::from_fn(6, n, |r, c| {
                if r < 3 {
                    jac.d_params[col(c)][r] / self.reach_mm
                } else {
                    jac.d_orientation[col(c)][r - 3]
                }
            });
            if smallest_singular(&j6) < MIN_WRIST_DEXTERITY {
                return Err(Rejection::Singular);
            }
        }
        Ok(Candidate {
            q_deg,
            q_rad,
            t_rig: t,
        })
    }

    /// The arm in the base frame at `q_rad` with T at `t_rig`: the joint
    /// frames' origins, the flange, then T.
    fn arm_points_base(&self, q_rad: &[f64], t_rig: &Vector3<f64>) -> Vec<Vector3<f64>> {
        let frames = self
            .chain
            .link_frames(&self.nominal.values, q_rad, OutputFrame::Base);
        let mut points: Vec<Vector3<f64>> = frames.iter().map(|f| f.o).collect();
        points.push(self.base_r.transpose() * (t_rig - self.base_t));
        points
    }

    /// A pose as a candidate without checking it (a recorded pose: it was
    /// measured, whatever the checks would say).
    pub fn recorded(&self, q_deg: &[f64]) -> Candidate {
        let q_rad: Vec<f64> = q_deg.iter().map(|v| v.to_radians()).collect();
        let (_, t_rig) = self
            .chain
            .point(&self.nominal.values, &q_rad, OutputFrame::Rig);
        Candidate {
            q_deg: q_deg.to_vec(),
            q_rad,
            t_rig,
        }
    }

    /// The lowest point of the arm (joint frames, flange, T) at a pose, as
    /// a height in the base frame (mm).
    pub fn lowest_z_mm(&self, c: &Candidate) -> f64 {
        self.arm_points_base(&c.q_rad, &c.t_rig)
            .iter()
            .map(|o| o.z)
            .fold(f64::INFINITY, f64::min)
    }

    /// Draw until `n` poses pass (at most `max_draws` tries), counting the
    /// reasons for the others.
    pub fn sample(
        &self,
        n: usize,
        max_draws: usize,
        rng: &mut Rng,
    ) -> (Vec<Candidate>, usize, BTreeMap<Rejection, usize>) {
        let mut jac = self.chain.new_jacobian();
        let mut out = Vec::with_capacity(n);
        let mut rejected = BTreeMap::new();
        let mut draws = 0;
        while out.len() < n && draws < max_draws {
            draws += 1;
            match self.check(self.draw(rng), &mut jac) {
                Ok(c) => out.push(c),
                Err(r) => *rejected.entry(r).or_insert(0) += 1,
            }
        }
        (out, draws, rejected)
    }
}

/// Points every [`SAMPLE_STEP_MM`] along a segment, both ends included.
fn along<'b>(a: &'b Vector3<f64>, b: &'b Vector3<f64>) -> impl Iterator<Item = Vector3<f64>> + 'b {
    let steps = ((b - a).norm() / SAMPLE_STEP_MM).ceil().max(1.0) as usize;
    (0..=steps).map(move |s| a + (b - a) * (s as f64 / steps as f64))
}

/// Unit normal of the anchors' plane when every anchor lies within 1 % of
/// their span of the plane through the first three that are not on a line.
fn coplanar_normal(anchors: &[Vector3<f64>]) -> Option<Vector3<f64>> {
    if anchors.len() < 3 {
        return None;
    }
    let a0 = anchors[0];
    let span = anchors.iter().map(|a| (a - a0).norm()).fold(0.0, f64::max);
    let mut best: Option<Vector3<f64>> = None;
    for i in 1..anchors.len() {
        for j in i + 1..anchors.len() {
            let n = (anchors[i] - a0).cross(&(anchors[j] - a0));
            if best.is_none_or(|b| n.norm() > b.norm()) {
                best = Some(n);
            }
        }
    }
    let n = best?.try_normalize(1e-9)?;
    anchors
        .iter()
        .all(|a| (a - a0).dot(&n).abs() <= 0.01 * span)
        .then_some(n)
}

fn smallest_singular(m: &DMatrix<f64>) -> f64 {
    m.singular_values()
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min)
}

/// Shortest distance between segments `[p0, p1]` and `[q0, q1]`.
pub(crate) fn segment_distance(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    q0: &Vector3<f64>,
    q1: &Vector3<f64>,
) -> f64 {
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, f) = (d1.dot(&d1), d2.dot(&d2), d2.dot(&r));
    let (s, t) = if a <= 1e-12 && e <= 1e-12 {
        (0.0, 0.0)
    } else if a <= 1e-12 {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(&r);
        if e <= 1e-12 {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s = if denom > 1e-12 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    ((p0 + d1 * s) - (q0 + d2 * t)).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_distance_matches_brute_force() {
        let mut rng = Rng::new(3);
        for _ in 0..200 {
            let mut v = || {
                Vector3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                )
            };
            let (p0, p1, q0, q1) = (v(), v(), v(), v());
            let mut best = f64::INFINITY;
            for i in 0..=200 {
                for j in 0..=200 {
                    let x = p0 + (p1 - p0) * (i as f64 / 200.0);
                    let y = q0 + (q1 - q0) * (j as f64 / 200.0);
                    best = best.min((x - y).norm());
                }
            }
            let d = segment_distance(&p0, &p1, &q0, &q1);
            assert!(d <= best + 1e-12 && d > best - 0.02, "{d} vs {best}");
        }
    }

    #[test]
    fn keep_out_parses_corners_in_any_order() {
        let b = KeepOut::parse("keep_out", "100, 0, -50, 0, 200, 50").unwrap();
        assert_eq!(b.min_mm, [0.0, 0.0, -50.0]);
        assert_eq!(b.max_mm, [100.0, 200.0, 50.0]);
        assert!(KeepOut::parse("keep_out", "1,2,3").is_err());
        assert!(KeepOut::parse("keep_out", "1,2,3,4,5,x").is_err());
    }

    #[test]
    fn coplanar_anchors_have_a_normal_and_a_tetrahedron_none() {
        let flat = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1000.0, 0.0, 0.0),
            Vector3::new(0.0, 900.0, 0.0),
            Vector3::new(1000.0, 900.0, 1.0),
        ];
        let n = coplanar_normal(&flat).unwrap();
        assert!((n.z.abs() - 1.0).abs() < 1e-3);
        let tet = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1000.0, 0.0, 0.0),
            Vector3::new(0.0, 900.0, 0.0),
            Vector3::new(0.0, 0.0, 800.0),
        ];
        assert!(coplanar_normal(&tet).is_none());
    }
}
