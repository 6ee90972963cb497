//! rig.json: the drawstring anchors (or none, for a tracker or camera).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::finite;
use crate::error::{Error, Result};

/// A rigid pose given as translation and roll-pitch-yaw, applied as
/// `Rz(yaw) Ry(pitch) Rx(roll)` (DATA_FORMAT.md).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BasePose {
    /// Translation (mm).
    pub xyz_mm: [f64; 3],
    /// Roll, pitch, yaw (deg).
    pub rpy_deg: [f64; 3],
}

/// Sensor data sheet values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
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

impl Rig {
    /// Parse and validate rig.json text.
    pub fn from_json(text: &str) -> Result<Self> {
        let rig: Rig =
            serde_json::from_str(text).map_err(|e| Error::field("rig.json", e.to_string()))?;
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
                finite(&format!("anchors_mm[{k}][{c}]"), *v)?;
            }
        }
        finite("r_mm", self.r_mm)?;
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
            // position around that line is then unknown.
            let a0 = self.anchor(0);
            let span = (1..m)
                .map(|k| (self.anchor(k) - a0).norm())
                .fold(0.0, f64::max);
            if span < 1.0 {
                return Err(Error::field(
                    "anchors_mm",
                    "anchors coincide: the rig is degenerate",
                ));
            }
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
    fn two_anchors_are_refused() {
        let t = r#"{"anchors_mm":[[0,0,0],[500,0,0]],"r_mm":35}"#;
        assert!(Rig::from_json(t).is_err());
    }

    #[test]
    fn tracker_rig_has_no_strings() {
        let t = r#"{"anchors_mm":[],"r_mm":0,"instrument":"tracker"}"#;
        assert_eq!(Rig::from_json(t).unwrap().n_strings(), 0);
    }
}
