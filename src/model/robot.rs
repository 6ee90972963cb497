//! robot.json: the nominal kinematic model.

use serde::{Deserialize, Serialize};

use super::{finite, length};
use crate::error::{Error, Result};

/// Which link-transform convention the joint table follows (DATA_FORMAT.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Convention {
    /// `T_i = Rz(q+θ) Tz(d) Tx(a) Rx(α) Ry(β)`: DH with Hayati's β (the paper).
    #[default]
    Dh,
    /// Craig's modified DH: `T_i = Rx(α) Ry(β) Tx(a) Rz(q+θ) Tz(d)`.
    Mdh,
}

/// One joint's nominal geometry and limits, units as in the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    /// Link length a (mm).
    pub a_mm: f64,
    /// Link twist α (deg).
    pub alpha_deg: f64,
    /// Link offset d (mm).
    pub d_mm: f64,
    /// Joint angle offset θ (deg), added to the commanded angle.
    #[serde(default)]
    pub theta_offset_deg: f64,
    /// Hayati's rotation about the new y axis (deg).
    #[serde(default)]
    pub beta_deg: f64,
    /// Lower joint limit (deg).
    #[serde(default = "default_qmin")]
    pub q_min_deg: f64,
    /// Upper joint limit (deg).
    #[serde(default = "default_qmax")]
    pub q_max_deg: f64,
}

fn default_qmin() -> f64 {
    -360.0
}
fn default_qmax() -> f64 {
    360.0
}

/// Mass and centre of mass of a link in its own DH frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkMass {
    /// Mass (kg).
    pub mass_kg: f64,
    /// Centre of mass in the link's frame (mm).
    pub com_mm: [f64; 3],
}

/// A robot model as in robot.json. Every key is one DATA_FORMAT.md lists:
/// an unknown one (a typo) is refused, never ignored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Robot {
    /// Human-readable name.
    #[serde(default)]
    pub name: String,
    /// Link convention.
    #[serde(default)]
    pub convention: Convention,
    /// Joints, base to flange.
    pub joints: Vec<JointSpec>,
    /// The measured point T in the flange frame (mm).
    pub tool_point_mm: [f64; 3],
    /// Optional link masses, one per joint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub links: Option<Vec<LinkMass>>,
    /// Optional gravity vector in the robot base frame (m/s²).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gravity_in_base: Option<[f64; 3]>,
}

impl Robot {
    /// Parse and validate robot.json text.
    pub fn from_json(text: &str) -> Result<Self> {
        let robot: Robot = super::parse_strict("robot.json", text)?;
        robot.validate()?;
        Ok(robot)
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    /// Check every number and the table's shape.
    pub fn validate(&self) -> Result<()> {
        if self.joints.is_empty() {
            return Err(Error::field("joints", "a robot needs at least one joint"));
        }
        if self.joints.len() > 12 {
            return Err(Error::field(
                "joints",
                format!("{} joints: at most 12 are supported", self.joints.len()),
            ));
        }
        for (i, j) in self.joints.iter().enumerate() {
            let p = |f: &str| format!("joints[{i}].{f}");
            length(&p("a_mm"), j.a_mm)?;
            finite(&p("alpha_deg"), j.alpha_deg)?;
            length(&p("d_mm"), j.d_mm)?;
            finite(&p("theta_offset_deg"), j.theta_offset_deg)?;
            finite(&p("beta_deg"), j.beta_deg)?;
            finite(&p("q_min_deg"), j.q_min_deg)?;
            finite(&p("q_max_deg"), j.q_max_deg)?;
            if j.q_min_deg >= j.q_max_deg {
                return Err(Error::field(p("q_min_deg"), "must be below q_max_deg"));
            }
        }
        for (k, v) in self.tool_point_mm.iter().enumerate() {
            length(&format!("tool_point_mm[{k}]"), *v)?;
        }
        if let Some(links) = &self.links {
            if links.len() != self.joints.len() {
                return Err(Error::field(
                    "links",
                    format!(
                        "{} links for {} joints: give one per joint",
                        links.len(),
                        self.joints.len()
                    ),
                ));
            }
            for (i, l) in links.iter().enumerate() {
                if !(l.mass_kg.is_finite() && l.mass_kg >= 0.0) {
                    return Err(Error::field(
                        format!("links[{i}].mass_kg"),
                        "must be a finite mass >= 0",
                    ));
                }
                for (k, v) in l.com_mm.iter().enumerate() {
                    length(&format!("links[{i}].com_mm[{k}]"), *v)?;
                }
            }
        }
        if let Some(g) = &self.gravity_in_base {
            for (k, v) in g.iter().enumerate() {
                finite(&format!("gravity_in_base[{k}]"), *v)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_limits_and_names_the_field() {
        let t = r#"{"joints":[{"a_mm":0,"alpha_deg":0,"d_mm":0,"q_min_deg":10,"q_max_deg":-10}],"tool_point_mm":[0,0,0]}"#;
        let e = Robot::from_json(t).unwrap_err().to_string();
        assert!(e.contains("joints[0].q_min_deg"), "{e}");
    }

    #[test]
    fn defaults_to_dh() {
        let t = r#"{"joints":[{"a_mm":1,"alpha_deg":0,"d_mm":0}],"tool_point_mm":[0,0,0]}"#;
        let r = Robot::from_json(t).unwrap();
        assert_eq!(r.convention, Convention::Dh);
        assert_eq!(r.joints[0].q_max_deg, 360.0);
    }
}
