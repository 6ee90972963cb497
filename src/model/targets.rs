//! targets.csv: what is to be compensated, one row per target.

use std::io::Read;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// A compensation target.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Target {
    /// Id, unique in the file.
    pub target: String,
    /// What the target asks for.
    #[serde(flatten)]
    pub kind: TargetKind,
}

/// Nominal joints, or a point (and optionally the flange orientation) in the
/// robot base frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum TargetKind {
    /// Joint angles as taught with the nominal model (deg): T should go
    /// where the nominal model says these angles put it.
    Joints {
        /// Nominal joint angles (deg).
        q_deg: Vec<f64>,
    },
    /// T in the robot base frame (mm), optionally with the flange
    /// orientation as roll-pitch-yaw (deg).
    Cartesian {
        /// Position of T (mm).
        xyz_mm: [f64; 3],
        /// Wanted flange orientation, `Rz(yaw) Ry(pitch) Rx(roll)` (deg).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        rpy_deg: Option<[f64; 3]>,
    },
}

/// targets.csv of joint targets: `target,q1_deg..qn_deg,split`, one row
/// per `(id, q_deg, split)` (the split column is drawcal's addition, read
/// by `drawcal simulate --targets` and carried into poses.csv).
pub fn joint_targets_csv<'a>(
    rows: impl IntoIterator<Item = (&'a str, &'a [f64], &'a str)>,
) -> String {
    let mut rows = rows.into_iter().peekable();
    let n = rows.peek().map_or(0, |r| r.1.len());
    let mut out = String::from("target");
    for j in 1..=n {
        out.push_str(&format!(",q{j}_deg"));
    }
    out.push_str(",split\n");
    for (id, q_deg, split) in rows {
        out.push_str(id);
        for v in q_deg {
            out.push_str(&format!(",{v:.4}"));
        }
        out.push_str(&format!(",{split}\n"));
    }
    out
}

/// targets.csv of joint targets with a payload per row:
/// `target,q1_deg..qn_deg,payload_kg,split` (both last columns are
/// drawcal's additions, written by `drawcal plan --payload-kg`: `drawcal
/// simulate --targets` carries them into poses.csv; compensation ignores
/// them).
pub fn joint_targets_payload_csv<'a>(
    rows: impl IntoIterator<Item = (&'a str, &'a [f64], f64, &'a str)>,
) -> String {
    let mut rows = rows.into_iter().peekable();
    let n = rows.peek().map_or(0, |r| r.1.len());
    let mut out = String::from("target");
    for j in 1..=n {
        out.push_str(&format!(",q{j}_deg"));
    }
    out.push_str(",payload_kg,split\n");
    for (id, q_deg, payload_kg, split) in rows {
        out.push_str(id);
        for v in q_deg {
            out.push_str(&format!(",{v:.4}"));
        }
        out.push_str(&format!(",{payload_kg},{split}\n"));
    }
    out
}

/// Parse targets.csv for a robot with `dof` joints.
pub fn targets_from_csv<R: Read>(input: R, dof: usize) -> Result<Vec<Target>> {
    let (mut rdr, headers) = super::csv_with_header(input)?;
    let idx = |name: &str| headers.iter().position(|h| h == name);
    let id_col = idx("target").ok_or_else(|| Error::field("target", "missing column 'target'"))?;
    let q_cols: Vec<Option<usize>> = (1..=dof).map(|j| idx(&format!("q{j}_deg"))).collect();
    let joints = q_cols.iter().all(|c| c.is_some());
    let xyz: Vec<Option<usize>> = ["x_mm", "y_mm", "z_mm"].iter().map(|n| idx(n)).collect();
    let rpy: Vec<Option<usize>> = ["roll_deg", "pitch_deg", "yaw_deg"]
        .iter()
        .map(|n| idx(n))
        .collect();
    let cart = xyz.iter().all(|c| c.is_some());
    if !joints && !cart {
        return Err(Error::field(
            "header",
            format!("expected q1_deg..q{dof}_deg or x_mm,y_mm,z_mm"),
        ));
    }
    if joints && idx(&format!("q{}_deg", dof + 1)).is_some() {
        return Err(Error::field(
            format!("q{}_deg", dof + 1),
            format!("more joint columns than the robot's {dof} joints"),
        ));
    }
    let with_rpy = rpy.iter().all(|c| c.is_some());
    if !with_rpy && rpy.iter().any(|c| c.is_some()) {
        return Err(Error::field(
            "roll_deg",
            "give all of roll_deg, pitch_deg, yaw_deg or none",
        ));
    }
    let mut out = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for (r, rec) in rdr.records().enumerate() {
        let row = r + 1;
        let rec = super::csv_record(row, rec, &headers)?;
        let id = rec.get(id_col).unwrap_or("").trim().to_string();
        if id.is_empty() {
            return Err(Error::cell(row, "target", "empty target id"));
        }
        if !seen.insert(id.clone()) {
            return Err(Error::cell(
                row,
                "target",
                format!("duplicate target id '{id}'"),
            ));
        }
        let kind = if joints {
            let mut q = Vec::with_capacity(dof);
            for (j, c) in q_cols.iter().enumerate() {
                q.push(super::parse_cell(
                    row,
                    &format!("q{}_deg", j + 1),
                    rec.get(c.unwrap()).unwrap_or(""),
                )?);
            }
            TargetKind::Joints { q_deg: q }
        } else {
            let mut p = [0.0; 3];
            for (k, n) in ["x_mm", "y_mm", "z_mm"].iter().enumerate() {
                p[k] = super::parse_cell(row, n, rec.get(xyz[k].unwrap()).unwrap_or(""))?;
            }
            let rpy_deg = if with_rpy {
                let mut a = [0.0; 3];
                for (k, n) in ["roll_deg", "pitch_deg", "yaw_deg"].iter().enumerate() {
                    a[k] = super::parse_cell(row, n, rec.get(rpy[k].unwrap()).unwrap_or(""))?;
                }
                Some(a)
            } else {
                None
            };
            TargetKind::Cartesian { xyz_mm: p, rpy_deg }
        };
        out.push(Target { target: id, kind });
    }
    Ok(out)
}

/// The optional `split` column of a targets.csv (drawcal's addition, as
/// written by `drawcal plan`): per row `true` for `test`, `false` for
/// `train`; `None` when the file has no such column.
pub fn target_splits<R: Read>(input: R) -> Result<Option<Vec<bool>>> {
    let (mut rdr, headers) = super::csv_with_header(input)?;
    let Some(col) = headers.iter().position(|h| h == "split") else {
        return Ok(None);
    };
    let mut out = Vec::new();
    for (r, rec) in rdr.records().enumerate() {
        let rec = super::csv_record(r + 1, rec, &headers)?;
        out.push(match rec.get(col).unwrap_or("").trim() {
            "test" => true,
            "train" => false,
            other => {
                return Err(Error::cell(
                    r + 1,
                    "split",
                    format!("'{other}': expected train or test"),
                ));
            }
        });
    }
    Ok(Some(out))
}

/// The optional `payload_kg` column of a targets.csv (drawcal's addition,
/// as written by `drawcal plan --payload-kg`): per row the payload at T
/// (kg, 0 to 5000); `None` when the file has no such column.
pub fn target_payloads<R: Read>(input: R) -> Result<Option<Vec<f64>>> {
    let (mut rdr, headers) = super::csv_with_header(input)?;
    let Some(col) = headers.iter().position(|h| h == "payload_kg") else {
        return Ok(None);
    };
    let mut out = Vec::new();
    for (r, rec) in rdr.records().enumerate() {
        let rec = super::csv_record(r + 1, rec, &headers)?;
        let v: f64 = super::parse_cell(r + 1, "payload_kg", rec.get(col).unwrap_or(""))?;
        if !(0.0..=5000.0).contains(&v) {
            return Err(Error::cell(
                r + 1,
                "payload_kg",
                format!("{v}: a payload from 0 to 5000 kg"),
            ));
        }
        out.push(v);
    }
    Ok(Some(out))
}

/// A warning when joint targets look like radians: a robot with three or
/// more joints, at least one joint target, not all at zero, and every angle
/// of every joint target within ±2π (a single target too: one taught pose
/// sent in radians is as dangerous as a file of them). The numbers alone
/// cannot be sure (a program may really move only a few degrees), so they
/// are compensated as degrees and the warning says so; these joints go to
/// the robot.
pub fn radians_warning(targets: &[Target], dof: usize) -> Option<String> {
    let bound = super::RADIANS_BOUND;
    let joints: Vec<&Vec<f64>> = targets
        .iter()
        .filter_map(|t| match &t.kind {
            TargetKind::Joints { q_deg } => Some(q_deg),
            TargetKind::Cartesian { .. } => None,
        })
        .collect();
    let all = joints.iter().flat_map(|q| q.iter());
    let suspect = dof >= 3
        && !joints.is_empty()
        && all.clone().all(|v| v.abs() <= bound)
        && all.clone().any(|v| v.abs() > 1e-9);
    suspect.then(|| {
        let these = match joints.len() {
            1 => "this joint target".to_string(),
            n => format!("these {n} joint targets"),
        };
        format!(
            "every joint angle of {these} lies between -6.28 and 6.28: if they are radians, convert them to degrees (the q*_deg columns hold degrees); they were compensated as degrees"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_both_kinds() {
        let t = targets_from_csv("target,q1_deg,q2_deg\na,1,2\n".as_bytes(), 2).unwrap();
        assert_eq!(
            t[0].kind,
            TargetKind::Joints {
                q_deg: vec![1.0, 2.0]
            }
        );
        let t = targets_from_csv("target,x_mm,y_mm,z_mm\na,1,2,3\n".as_bytes(), 6).unwrap();
        assert_eq!(
            t[0].kind,
            TargetKind::Cartesian {
                xyz_mm: [1.0, 2.0, 3.0],
                rpy_deg: None
            }
        );
        let e = targets_from_csv("target,x_mm,y_mm,z_mm\na,1,x,3\n".as_bytes(), 6)
            .unwrap_err()
            .to_string();
        assert!(e.contains("row 1") && e.contains("y_mm"), "{e}");
    }

    #[test]
    fn short_rows_and_other_separators_are_named() {
        let e = targets_from_csv("target,q1_deg,q2_deg\na,1,2\nb,1\n".as_bytes(), 2).unwrap_err();
        assert_eq!(
            e.to_string(),
            "row 2 after the header: 2 cells where the header has 3 columns"
        );
        let e = targets_from_csv("target;q1_deg;q2_deg\na;1;2\n".as_bytes(), 2)
            .unwrap_err()
            .to_string();
        assert!(e.contains("must be comma-separated"), "{e}");
    }

    #[test]
    fn joint_targets_in_radians_are_suspected() {
        let t = |q: &[f64]| Target {
            target: "t".into(),
            kind: TargetKind::Joints { q_deg: q.to_vec() },
        };
        let rad = [
            t(&[0.1, 0.5, 1.2]),
            t(&[0.2, 0.6, -1.1]),
            t(&[0.3, 0.4, 1.3]),
        ];
        assert!(radians_warning(&rad, 3).unwrap().contains("radians"));
        // One target alone is warned about too.
        let one = radians_warning(&rad[..1], 3).unwrap();
        assert!(one.contains("of this joint target"), "{one}");
        // A two-joint positioner, all at zero, one real angle: no.
        assert!(radians_warning(&rad, 2).is_none());
        let zeros = [t(&[0.0; 3]), t(&[0.0; 3]), t(&[0.0; 3])];
        assert!(radians_warning(&zeros, 3).is_none());
        let deg = [
            t(&[10.0, 0.5, 1.2]),
            t(&[0.2, 0.6, -1.1]),
            t(&[0.3, 0.4, 1.3]),
        ];
        assert!(radians_warning(&deg, 3).is_none());
    }
}
