//! The calibration parameter vector: per joint a, α, d, θ, β; the base pose
//! in the rig frame; the tool point; each string's zero offset and r.
//!
//! Internally lengths are mm and angles rad; files keep their own units.

use nalgebra::Vector3;

use super::{matrix_rpy, rpy_matrix};
use crate::model::{BasePose, JointSpec, Rig, Robot};

/// The five geometric parameters of a joint, in vector order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointParam {
    /// Link length a (mm).
    A = 0,
    /// Link twist α (rad).
    Alpha = 1,
    /// Link offset d (mm).
    D = 2,
    /// Joint offset θ (rad).
    Theta = 3,
    /// Hayati's β (rad).
    Beta = 4,
}

impl JointParam {
    /// All five, in vector order.
    pub const ALL: [JointParam; 5] = [
        JointParam::A,
        JointParam::Alpha,
        JointParam::D,
        JointParam::Theta,
        JointParam::Beta,
    ];

    /// Short name used in reports (`j3.d`).
    pub fn short(self) -> &'static str {
        match self {
            JointParam::A => "a",
            JointParam::Alpha => "alpha",
            JointParam::D => "d",
            JointParam::Theta => "theta",
            JointParam::Beta => "beta",
        }
    }

    /// True for angles (stored in rad, reported in deg).
    pub fn is_angle(self) -> bool {
        matches!(
            self,
            JointParam::Alpha | JointParam::Theta | JointParam::Beta
        )
    }
}

/// Where each parameter sits in the vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// Number of joints.
    pub n_joints: usize,
    /// Number of strings (0 for point instruments).
    pub n_strings: usize,
}

impl Layout {
    /// Index of a joint parameter (joint 0-based).
    pub fn joint(&self, j: usize, p: JointParam) -> usize {
        5 * j + p as usize
    }
    /// First of the six base parameters: x, y, z (mm), roll, pitch, yaw (rad).
    pub fn base(&self) -> usize {
        5 * self.n_joints
    }
    /// First of the three tool point coordinates (mm, flange frame).
    pub fn tool(&self) -> usize {
        5 * self.n_joints + 6
    }
    /// Number of parameters that move the point T.
    pub fn n_geometric(&self) -> usize {
        5 * self.n_joints + 9
    }
    /// Zero offset of string k (mm): the reading is `|T - A_k| - r - offset_k`.
    pub fn string_offset(&self, k: usize) -> usize {
        self.n_geometric() + k
    }
    /// The common `r` of the strings (mm).
    pub fn r(&self) -> usize {
        self.n_geometric() + self.n_strings
    }
    /// Total number of parameters.
    pub fn len(&self) -> usize {
        self.n_geometric()
            + if self.n_strings > 0 {
                self.n_strings + 1
            } else {
                0
            }
    }
    /// Shape mode j of the anchors (mm), when the rig's anchors are
    /// identified (`identify::rig`): past the rest, so that a vector without
    /// them is an ordinary one.
    pub fn anchor_mode(&self, j: usize) -> usize {
        self.len() + j
    }
    /// How the report names an anchor shape mode (`rig.mode1`...).
    pub const ANCHOR_MODE_PREFIX: &'static str = "rig.mode";
    /// Never empty: a robot has a joint.
    pub fn is_empty(&self) -> bool {
        false
    }
    /// Report name of parameter i (`j2.theta`, `base.x`, `tool.z`, `s3.offset`, `r`,
    /// `rig.mode2`).
    pub fn name(&self, i: usize) -> String {
        let g = self.n_geometric();
        if i < 5 * self.n_joints {
            format!("j{}.{}", i / 5 + 1, JointParam::ALL[i % 5].short())
        } else if i < self.tool() {
            [
                "base.x",
                "base.y",
                "base.z",
                "base.roll",
                "base.pitch",
                "base.yaw",
            ][i - self.base()]
            .to_string()
        } else if i < g {
            ["tool.x", "tool.y", "tool.z"][i - self.tool()].to_string()
        } else if i < g + self.n_strings {
            format!("s{}.offset", i - g + 1)
        } else if i < self.len() {
            "r".to_string()
        } else {
            format!("{}{}", Self::ANCHOR_MODE_PREFIX, i - self.len() + 1)
        }
    }
    /// True if parameter i is an angle (rad internally).
    pub fn is_angle(&self, i: usize) -> bool {
        if i < 5 * self.n_joints {
            JointParam::ALL[i % 5].is_angle()
        } else {
            (self.base() + 3..self.base() + 6).contains(&i)
        }
    }
    /// Parameter index from its report name.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        (0..self.len()).find(|&i| self.name(i) == name)
    }
}

/// A full parameter vector with its layout.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// Layout.
    pub layout: Layout,
    /// Values, mm and rad.
    pub values: Vec<f64>,
}

impl Params {
    /// Nominal parameters of a robot, a base pose guess and the rig's strings.
    pub fn nominal(robot: &Robot, base: &BasePose, rig: &Rig, n_strings: usize) -> Self {
        let layout = Layout {
            n_joints: robot.dof(),
            n_strings,
        };
        let mut values = vec![0.0; layout.len()];
        for (j, js) in robot.joints.iter().enumerate() {
            values[layout.joint(j, JointParam::A)] = js.a_mm;
            values[layout.joint(j, JointParam::Alpha)] = js.alpha_deg.to_radians();
            values[layout.joint(j, JointParam::D)] = js.d_mm;
            values[layout.joint(j, JointParam::Theta)] = js.theta_offset_deg.to_radians();
            values[layout.joint(j, JointParam::Beta)] = js.beta_deg.to_radians();
        }
        let mut p = Params { layout, values };
        p.set_base(base);
        p.values[layout.tool()..layout.tool() + 3].copy_from_slice(&robot.tool_point_mm);
        if n_strings > 0 {
            p.values[layout.r()] = rig.r_mm;
        }
        p
    }

    /// Value of a joint parameter.
    pub fn joint(&self, j: usize, p: JointParam) -> f64 {
        self.values[self.layout.joint(j, p)]
    }

    /// The base pose in the rig frame.
    pub fn base(&self) -> BasePose {
        let b = self.layout.base();
        let v = &self.values;
        BasePose {
            xyz_mm: [v[b], v[b + 1], v[b + 2]],
            rpy_deg: [
                v[b + 3].to_degrees(),
                v[b + 4].to_degrees(),
                v[b + 5].to_degrees(),
            ],
        }
    }

    /// Set the base pose.
    pub fn set_base(&mut self, base: &BasePose) {
        let b = self.layout.base();
        self.values[b..b + 3].copy_from_slice(&base.xyz_mm);
        for k in 0..3 {
            self.values[b + 3 + k] = base.rpy_deg[k].to_radians();
        }
    }

    /// Set the base from a rotation and translation, keeping rpy continuous.
    pub fn set_base_rt(&mut self, r: &nalgebra::Matrix3<f64>, t: &Vector3<f64>) {
        let rpy = matrix_rpy(r);
        let b = self.layout.base();
        for k in 0..3 {
            self.values[b + k] = t[k];
            self.values[b + 3 + k] = rpy[k];
        }
    }

    /// Base rotation and translation.
    pub fn base_rt(&self) -> (nalgebra::Matrix3<f64>, Vector3<f64>) {
        let b = self.layout.base();
        let v = &self.values;
        (
            rpy_matrix(v[b + 3], v[b + 4], v[b + 5]),
            Vector3::new(v[b], v[b + 1], v[b + 2]),
        )
    }

    /// Tool point (mm, flange frame).
    pub fn tool(&self) -> [f64; 3] {
        let t = self.layout.tool();
        [self.values[t], self.values[t + 1], self.values[t + 2]]
    }

    /// The robot these parameters describe, in robot.json form, keeping the
    /// nominal model's name, limits and masses.
    pub fn to_robot(&self, nominal: &Robot, name: &str) -> Robot {
        let mut r = nominal.clone();
        r.name = name.to_string();
        for (j, js) in r.joints.iter_mut().enumerate() {
            *js = JointSpec {
                a_mm: self.joint(j, JointParam::A),
                alpha_deg: self.joint(j, JointParam::Alpha).to_degrees(),
                d_mm: self.joint(j, JointParam::D),
                theta_offset_deg: self.joint(j, JointParam::Theta).to_degrees(),
                beta_deg: self.joint(j, JointParam::Beta).to_degrees(),
                q_min_deg: js.q_min_deg,
                q_max_deg: js.q_max_deg,
            };
        }
        r.tool_point_mm = self.tool();
        r
    }

    /// Parameters of a robot.json (no base, no strings), e.g. to evaluate a
    /// calibrated model in its own base frame.
    pub fn of_robot(robot: &Robot) -> Self {
        let zero = BasePose {
            xyz_mm: [0.0; 3],
            rpy_deg: [0.0; 3],
        };
        let rig = Rig {
            anchors_mm: vec![],
            anchor_names: None,
            r_mm: 0.0,
            base_in_rig: None,
            sensor: None,
            instrument: None,
        };
        Params::nominal(robot, &zero, &rig, 0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        let l = Layout {
            n_joints: 6,
            n_strings: 4,
        };
        assert_eq!(l.len(), 30 + 9 + 5);
        for i in 0..l.len() {
            assert_eq!(l.index_of(&l.name(i)), Some(i));
        }
        assert_eq!(l.name(l.joint(2, JointParam::D)), "j3.d");
        assert_eq!(l.name(l.r()), "r");
        assert_eq!(l.name(l.anchor_mode(1)), "rig.mode2");
    }
}
