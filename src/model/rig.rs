//! rig.json: the drawstring anchors (or none, for a tracker or camera).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{finite, length};
use crate::error::{Error, Result};

/// A rigid pose given as translation and roll-pitch-yaw, applied as
/// `Rz(yaw) Ry(pitch) Rx(roll)` (DATA_FORMAT.md).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BasePose {
    /// Translation (mm).
    pub xyz_mm: [f64; 3],
    /// Roll, pitch, yaw (deg).
    pub rpy_deg: [f64; 3],
}

/// Sensor data sheet values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    /// Measuring range (mm): a reading beyond it is refused.
    #[serde(default)]
    pub range_mm: Option<f64>,
    /// Resolution (mm).
    #[serde(default)]
    pub resolution_mm: Option<f64>,
    /// Linearity, percent of full scale.
    #[serde(default)]
    pub linearity_pct_fs: Option<f64>,
}

/// The measuring rig, as in rig.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RigFile")]
pub struct Rig {
    /// String exit points in the rig frame (mm); empty for a point instrument.
    #[serde(default)]
    pub anchors_mm: Vec<[f64; 3]>,
    /// Optional names, in anchor order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anchor_names: Option<Vec<String>>,
    /// Distance from a string's reading to the anchor-to-T distance: `|T-A| = l + r` (mm).
    #[serde(default)]
    pub r_mm: f64,
    /// Starting guess of the robot base pose in the rig frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_in_rig: Option<BasePose>,
    /// Sensor data sheet.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<SensorSpec>,
    /// Free text naming another instrument (tracker, camera).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instrument: Option<String>,
}

/// rig.json as written: `r_mm` may be left out only by a rig without
/// strings (a tracker or camera), where it means nothing.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RigFile {
    #[serde(default)]
    anchors_mm: Vec<[f64; 3]>,
    #[serde(default)]
    anchor_names: Option<Vec<String>>,
    #[serde(default)]
    r_mm: Option<f64>,
    #[serde(default)]
    base_in_rig: Option<BasePose>,
    #[serde(default)]
    sensor: Option<SensorSpec>,
    #[serde(default)]
    instrument: Option<String>,
}

impl TryFrom<RigFile> for Rig {
    type Error = String;

    fn try_from(f: RigFile) -> std::result::Result<Self, String> {
        let r_mm = match f.r_mm {
            Some(r) => r,
            None if f.anchors_mm.is_empty() => 0.0,
            // A silent 0 would put every point r_mm too close to every
            // anchor, and the error would surface as poses that cannot be
            // located.
            None => {
                return Err("missing field `r_mm`: the reading plus r_mm is the anchor-to-T distance (0 if the readings are that distance)".into());
            }
        };
        Ok(Rig {
            anchors_mm: f.anchors_mm,
            anchor_names: f.anchor_names,
            r_mm,
            base_in_rig: f.base_in_rig,
            sensor: f.sensor,
            instrument: f.instrument,
        })
    }
}

impl Rig {
    /// Parse and validate rig.json text.
    pub fn from_json(text: &str) -> Result<Self> {
        let rig: Rig = super::parse_strict("rig.json", text)?;
        rig.validate()?;
        Ok(rig)
    }

    /// Number of strings.
    pub fn n_strings(&self) -> usize {
        self.anchors_mm.len()
    }

    /// Anchor k as a vector.
    pub fn anchor(&self, k: usize) -> Vector3<f64> {
        Vector3::from(self.anchors_mm[k])
    }

    /// Display name of sensor k (its anchor name, or `s{k+1}`).
    pub fn sensor_name(&self, k: usize) -> String {
        self.anchor_names
            .as_ref()
            .and_then(|n| n.get(k).cloned())
            .unwrap_or_else(|| format!("s{}", k + 1))
    }

    /// Check the numbers and that the anchors can locate a point.
    pub fn validate(&self) -> Result<()> {
        let m = self.anchors_mm.len();
        if m > 0 && m < 3 {
            return Err(Error::field(
                "anchors_mm",
                format!("{m} anchors: at least 3 are needed to locate a point"),
            ));
        }
        for (k, a) in self.anchors_mm.iter().enumerate() {
            for (c, v) in a.iter().enumerate() {
                length(&format!("anchors_mm[{k}][{c}]"), *v)?;
            }
        }
        // Two strings from one point measure one distance twice: the point
        // is then located from one string fewer than the rig claims.
        for k in 1..m {
            if let Some(i) = (0..k).find(|&i| (self.anchor(k) - self.anchor(i)).norm() < 1.0) {
                return Err(Error::field(
                    format!("anchors_mm[{k}]"),
                    format!(
                        "coincides with anchors_mm[{i}] (less than 1 mm apart): each string needs its own anchor"
                    ),
                ));
            }
        }
        length("r_mm", self.r_mm)?;
        if self.r_mm < 0.0 {
            return Err(Error::field(
                "r_mm",
                format!(
                    "{} mm: r_mm is the distance from a string's zero to T (the reading plus r_mm is the anchor-to-T distance) and cannot be negative",
                    self.r_mm
                ),
            ));
        }
        if let Some(names) = &self.anchor_names {
            if !names.is_empty() && names.len() != m {
                return Err(Error::field(
                    "anchor_names",
                    format!("{} names for {m} anchors", names.len()),
                ));
            }
        }
        if m >= 3 {
            // Degenerate if all anchors lie (nearly) on one line: the point's
            // position around that line is then unknown. (No two coincide,
            // checked above, so the span is at least 1 mm.)
            let a0 = self.anchor(0);
            let span = (1..m)
                .map(|k| (self.anchor(k) - a0).norm())
                .fold(0.0, f64::max);
            let far = (1..m)
                .max_by(|&i, &j| {
                    (self.anchor(i) - a0)
                        .norm()
                        .total_cmp(&(self.anchor(j) - a0).norm())
                })
                .unwrap();
            let axis = (self.anchor(far) - a0).normalize();
            let off_line = (1..m)
                .map(|k| (self.anchor(k) - a0).cross(&axis).norm())
                .fold(0.0, f64::max);
            if off_line < 1e-3 * span {
                return Err(Error::field(
                    "anchors_mm",
                    "all anchors lie on one line: the rig is degenerate",
                ));
            }
        }
        if let Some(b) = &self.base_in_rig {
            for c in 0..3 {
                finite(&format!("base_in_rig.xyz_mm[{c}]"), b.xyz_mm[c])?;
                finite(&format!("base_in_rig.rpy_deg[{c}]"), b.rpy_deg[c])?;
            }
        }
        if let Some(s) = &self.sensor {
            if let Some(r) = s.range_mm {
                if !(r.is_finite() && r > 0.0) {
                    return Err(Error::field("sensor.range_mm", "must be a positive length"));
                }
            }
            for (field, v) in [
                ("sensor.resolution_mm", s.resolution_mm),
                ("sensor.linearity_pct_fs", s.linearity_pct_fs),
            ] {
                if let Some(v) = v {
                    if !(v.is_finite() && v >= 0.0) {
                        return Err(Error::field(field, "must be a finite number >= 0"));
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn collinear_anchors_are_degenerate() {
        let t = r#"{"anchors_mm":[[0,0,0],[500,0,0],[1000,0,0]],"r_mm":35}"#;
        let e = Rig::from_json(t).unwrap_err().to_string();
        assert!(e.contains("anchors_mm") && e.contains("degenerate"), "{e}");
    }

    #[test]
    fn a_rig_is_an_object_never_an_array() {
        // serde reads a struct from a sequence too: `[]` must not pass for
        // a rig (it once stored one without anchors).
        for t in ["[]", "[[[0,0,0]], 35]", "null", "\"rig\""] {
            assert!(Rig::from_json(t).is_err(), "{t}");
        }
    }

    #[test]
    fn two_anchors_are_refused() {
        let t = r#"{"anchors_mm":[[0,0,0],[500,0,0]],"r_mm":35}"#;
        assert!(Rig::from_json(t).is_err());
    }

    #[test]
    fn two_coincident_anchors_are_named() {
        let t = r#"{"anchors_mm":[[0,0,0],[0,900,0],[1200,0,0],[0,0,0.5]],"r_mm":35}"#;
        let e = Rig::from_json(t).unwrap_err().to_string();
        assert!(
            e.contains("anchors_mm[3]") && e.contains("coincides with anchors_mm[0]"),
            "{e}"
        );
    }

    #[test]
    fn r_mm_is_required_with_strings_and_not_negative() {
        let e = Rig::from_json(r#"{"anchors_mm":[[0,0,0],[0,900,0],[1200,0,0]]}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing field `r_mm`"), "{e}");
        let e = Rig::from_json(r#"{"anchors_mm":[[0,0,0],[0,900,0],[1200,0,0]],"r_mm":-35}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("r_mm") && e.contains("negative"), "{e}");
        let e = Rig::from_json(r#"{"anchors_mm":[[0,0,0],[0,900,0],[1e300,0,0]],"r_mm":35}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("anchors_mm[2][0]") && e.contains("1e300"), "{e}");
        // A tracker's rig needs none, and reads back as it was written.
        let rig = Rig::from_json(r#"{"instrument":"tracker"}"#).unwrap();
        assert_eq!(rig.r_mm, 0.0);
        let back = Rig::from_json(&serde_json::to_string(&rig).unwrap()).unwrap();
        assert_eq!(back, rig);
    }

    #[test]
    fn tracker_rig_has_no_strings() {
        let t = r#"{"anchors_mm":[],"r_mm":0,"instrument":"tracker"}"#;
        assert_eq!(Rig::from_json(t).unwrap().n_strings(), 0);
    }
}
