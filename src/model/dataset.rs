//! poses.csv: the recorded poses, validated row by row.

use std::collections::HashSet;
use std::io::Read;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{Rig, Robot};
use crate::error::{Error, Result};

/// Which side of the train/test split a pose is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// Used to identify the parameters.
    Train,
    /// Held out to check them.
    Test,
}

/// What the instrument recorded at a pose.
#[derive(Debug, Clone, PartialEq)]
pub enum Measurement {
    /// Drawstring readings `l_k` (mm), one per anchor.
    Strings(Vec<f64>),
    /// The point T measured directly in the rig frame (mm).
    Point(Vector3<f64>),
}

/// One recorded pose.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseRecord {
    /// Id, unique in the dataset.
    pub id: String,
    /// Commanded joint angles (rad).
    pub q_rad: Vec<f64>,
    /// The measurement.
    pub measurement: Measurement,
    /// Seconds since the session began.
    pub time_s: Option<f64>,
    /// Ambient temperature (°C).
    pub temp_c: Option<f64>,
    /// Payload (kg).
    pub payload_kg: Option<f64>,
    /// Split given in the file.
    pub split: Option<Split>,
}

/// A validated set of poses, in visiting order.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// The poses.
    pub poses: Vec<PoseRecord>,
    /// Number of strings per pose (0 for point data).
    pub n_strings: usize,
    /// Columns of the file that were not read, in file order (a
    /// measured point beside string readings, a column of the user's own).
    pub ignored_columns: Vec<String>,
}

fn parse_opt(
    row: usize,
    col: Option<(usize, &str)>,
    rec: &csv::StringRecord,
) -> Result<Option<f64>> {
    match col {
        Some((i, name)) => {
            let raw = rec.get(i).unwrap_or("").trim();
            if raw.is_empty() {
                Ok(None)
            } else {
                super::parse_cell(row, name, raw).map(Some)
            }
        }
        None => Ok(None),
    }
}

/// Largest |time_s| accepted (s).
const MAX_TIME_S: f64 = 1e12;
/// Largest |x|, |y|, |z| of a measured point accepted (mm).
const MAX_COORD_MM: f64 = 1e7;

impl Dataset {
    /// Parse poses.csv for this robot and rig. Every row is checked before
    /// anything is returned; the first problem is reported with its row
    /// (1-based, header excluded) and column.
    pub fn from_csv<R: Read>(input: R, robot: &Robot, rig: &Rig) -> Result<Self> {
        let (mut rdr, headers) = super::csv_with_header(input)?;
        let cols = Columns::find(&headers, robot, rig)?;
        let mut poses = Vec::new();
        let mut seen = HashSet::new();
        for (r, rec) in rdr.records().enumerate() {
            let row = r + 1;
            let rec = super::csv_record(row, rec, &headers)?;
            let id = cols.id(row, &rec)?;
            if !seen.insert(id.clone()) {
                return Err(Error::cell(
                    row,
                    "pose",
                    format!("duplicate pose id '{id}'"),
                ));
            }
            poses.push(cols.pose(row, &rec, id, robot, rig)?);
        }
        if poses.is_empty() {
            return Err(Error::InsufficientData("the file holds no poses".into()));
        }
        Ok(Dataset {
            poses,
            n_strings: if cols.strings.is_some() {
                rig.n_strings()
            } else {
                0
            },
            ignored_columns: cols.ignored(&headers),
        })
    }

    /// True when the poses carry string readings (not points).
    pub fn is_strings(&self) -> bool {
        self.n_strings > 0
    }
}

/// Where each column of a poses.csv is, checked against the robot and the
/// rig once, before the rows are read.
struct Columns {
    pose: usize,
    q: Vec<usize>,
    /// The string columns, when the file has every one the rig needs.
    strings: Option<Vec<usize>>,
    /// x_mm, y_mm, z_mm (used without string columns).
    xyz: [Option<usize>; 3],
    time: Option<(usize, &'static str)>,
    temp: Option<(usize, &'static str)>,
    payload: Option<(usize, &'static str)>,
    split: Option<usize>,
}

impl Columns {
    /// The columns of `headers`: every joint of the robot, every string of
    /// the rig or a measured point, no more joints or strings than those.
    fn find(headers: &csv::StringRecord, robot: &Robot, rig: &Rig) -> Result<Columns> {
        let idx = |name: &str| headers.iter().position(|h| h == name);
        let n = robot.dof();
        let pose = idx("pose").ok_or_else(|| Error::field("pose", "missing column 'pose'"))?;
        let mut q = Vec::with_capacity(n);
        for j in 1..=n {
            let name = format!("q{j}_deg");
            q.push(idx(&name).ok_or_else(|| {
                Error::field(&name, format!("missing column (the robot has {n} joints)"))
            })?);
        }
        if idx(&format!("q{}_deg", n + 1)).is_some() {
            return Err(Error::field(
                format!("q{}_deg", n + 1),
                format!("the file has more joint columns than the robot's {n} joints"),
            ));
        }
        let m = rig.n_strings();
        let l_cols: Vec<Option<usize>> = (1..=m).map(|k| idx(&format!("l{k}_mm"))).collect();
        let has_strings = m > 0 && l_cols.iter().all(|c| c.is_some());
        if m > 0 && !has_strings && l_cols.iter().any(|c| c.is_some()) {
            let k = l_cols.iter().position(|c| c.is_none()).unwrap() + 1;
            return Err(Error::field(
                format!("l{k}_mm"),
                format!("missing column (the rig has {m} strings)"),
            ));
        }
        if has_strings && idx(&format!("l{}_mm", m + 1)).is_some() {
            return Err(Error::field(
                format!("l{}_mm", m + 1),
                format!("the file has more string columns than the rig's {m} anchors"),
            ));
        }
        let xyz = [idx("x_mm"), idx("y_mm"), idx("z_mm")];
        if !has_strings && !xyz.iter().all(|c| c.is_some()) {
            return Err(Error::field(
                "header",
                if m > 0 {
                    format!("no measurement columns: expected l1_mm..l{m}_mm (or x_mm,y_mm,z_mm)")
                } else {
                    "no measurement columns: expected x_mm,y_mm,z_mm (the rig has no strings)"
                        .to_string()
                },
            ));
        }
        Ok(Columns {
            pose,
            q,
            strings: has_strings.then(|| l_cols.into_iter().flatten().collect()),
            xyz,
            time: idx("time_s").map(|i| (i, "time_s")),
            temp: idx("temp_c").map(|i| (i, "temp_c")),
            payload: idx("payload_kg").map(|i| (i, "payload_kg")),
            split: idx("split"),
        })
    }

    /// The headers of `headers` that no column read.
    fn ignored(&self, headers: &csv::StringRecord) -> Vec<String> {
        let point = if self.strings.is_some() {
            &[][..]
        } else {
            &self.xyz[..]
        };
        let read: HashSet<usize> = [Some(self.pose), self.split]
            .into_iter()
            .chain(self.q.iter().map(|&i| Some(i)))
            .chain(self.strings.iter().flatten().map(|&i| Some(i)))
            .chain(point.iter().copied())
            .chain([self.time, self.temp, self.payload].map(|c| c.map(|(i, _)| i)))
            .flatten()
            .collect();
        headers
            .iter()
            .enumerate()
            .filter(|(i, _)| !read.contains(i))
            .map(|(_, h)| h.to_string())
            .collect()
    }

    /// A row's pose id, not empty.
    fn id(&self, row: usize, rec: &csv::StringRecord) -> Result<String> {
        let id = rec.get(self.pose).unwrap_or("").trim().to_string();
        if id.is_empty() {
            return Err(Error::cell(row, "pose", "empty pose id"));
        }
        Ok(id)
    }

    /// One row as the pose `id`, every cell checked.
    fn pose(
        &self,
        row: usize,
        rec: &csv::StringRecord,
        id: String,
        robot: &Robot,
        rig: &Rig,
    ) -> Result<PoseRecord> {
        let q_rad = self.joint_angles(row, rec, robot)?;
        let measurement = match &self.strings {
            Some(cols) => Measurement::Strings(string_readings(row, rec, cols, rig)?),
            None => Measurement::Point(self.point(row, rec)?),
        };
        let split = self.split(row, rec)?;
        let (time_s, temp_c, payload_kg) = self.conditions(row, rec)?;
        Ok(PoseRecord {
            id,
            q_rad,
            measurement,
            time_s,
            temp_c,
            payload_kg,
            split,
        })
    }

    /// The joint angles (rad), each within the robot's limits.
    fn joint_angles(&self, row: usize, rec: &csv::StringRecord, robot: &Robot) -> Result<Vec<f64>> {
        let mut q_rad = Vec::with_capacity(self.q.len());
        for (j, &c) in self.q.iter().enumerate() {
            let name = format!("q{}_deg", j + 1);
            let v = super::parse_cell(row, &name, rec.get(c).unwrap_or(""))?;
            let js = &robot.joints[j];
            if v < js.q_min_deg - 1e-6 || v > js.q_max_deg + 1e-6 {
                return Err(Error::cell(
                    row,
                    &name,
                    format!(
                        "{} deg is outside the joint limits [{}, {}]",
                        super::shown(v),
                        js.q_min_deg,
                        js.q_max_deg
                    ),
                ));
            }
            q_rad.push(v.to_radians());
        }
        Ok(q_rad)
    }

    /// A measured point (mm), within 10 km.
    fn point(&self, row: usize, rec: &csv::StringRecord) -> Result<Vector3<f64>> {
        let mut p = [0.0; 3];
        for (c, name) in ["x_mm", "y_mm", "z_mm"].iter().enumerate() {
            let col = self.xyz[c].expect("checked by Columns::find");
            p[c] = super::parse_cell(row, name, rec.get(col).unwrap_or(""))?;
            if p[c].abs() > MAX_COORD_MM {
                return Err(Error::cell(
                    row,
                    *name,
                    format!(
                        "{} mm: a measured point more than 10 km away",
                        super::shown(p[c])
                    ),
                ));
            }
        }
        Ok(Vector3::from(p))
    }

    /// The `split` cell: train, test or empty.
    fn split(&self, row: usize, rec: &csv::StringRecord) -> Result<Option<Split>> {
        match self.split.map(|c| rec.get(c).unwrap_or("").trim()) {
            None | Some("") => Ok(None),
            Some(s) if s.eq_ignore_ascii_case("train") => Ok(Some(Split::Train)),
            Some(s) if s.eq_ignore_ascii_case("test") => Ok(Some(Split::Test)),
            Some(s) => Err(Error::cell(
                row,
                "split",
                format!("'{s}': expected train or test"),
            )),
        }
    }

    /// Time (s), temperature (°C) and payload (kg), each plausible.
    #[allow(clippy::type_complexity)]
    fn conditions(
        &self,
        row: usize,
        rec: &csv::StringRecord,
    ) -> Result<(Option<f64>, Option<f64>, Option<f64>)> {
        let time_s = parse_opt(row, self.time, rec)?;
        if let Some(t) = time_s.filter(|t| t.abs() > MAX_TIME_S) {
            // Differences of times must stay finite (drifts are per hour
            // since the first pose); epoch seconds are far inside this.
            return Err(Error::cell(
                row,
                "time_s",
                format!(
                    "{} s is not a plausible time (more than 10^12 s)",
                    super::shown(t)
                ),
            ));
        }
        let temp_c = parse_opt(row, self.temp, rec)?;
        if let Some(t) = temp_c.filter(|t| !(-100.0..=300.0).contains(t)) {
            return Err(Error::cell(
                row,
                "temp_c",
                format!("{} °C is outside -100..300 °C", super::shown(t)),
            ));
        }
        let payload_kg = parse_opt(row, self.payload, rec)?;
        if let Some(p) = payload_kg.filter(|p| !(0.0..=super::MAX_PAYLOAD_KG).contains(p)) {
            return Err(Error::cell(
                row,
                "payload_kg",
                format!(
                    "{} kg is outside 0..{} kg",
                    super::shown(p),
                    super::MAX_PAYLOAD_KG
                ),
            ));
        }
        Ok((time_s, temp_c, payload_kg))
    }
}

/// The string readings (mm) of a row, none negative or past the sensor's
/// range.
fn string_readings(
    row: usize,
    rec: &csv::StringRecord,
    cols: &[usize],
    rig: &Rig,
) -> Result<Vec<f64>> {
    let range = rig.sensor.and_then(|s| s.range_mm);
    let mut ls = Vec::with_capacity(cols.len());
    for (k, &c) in cols.iter().enumerate() {
        let name = format!("l{}_mm", k + 1);
        let v = super::parse_cell(row, &name, rec.get(c).unwrap_or(""))?;
        if v < 0.0 {
            return Err(Error::cell(
                row,
                &name,
                format!(
                    "{} mm: a string reading cannot be negative",
                    super::shown(v)
                ),
            ));
        }
        if let Some(rg) = range.filter(|&rg| v > rg) {
            return Err(Error::cell(
                row,
                &name,
                format!(
                    "{} mm is past the sensor's range of {rg} mm",
                    super::shown(v)
                ),
            ));
        }
        ls.push(v);
    }
    Ok(ls)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot() -> Robot {
        Robot::from_json(r#"{"joints":[{"a_mm":100,"alpha_deg":0,"d_mm":0,"q_min_deg":-90,"q_max_deg":90},{"a_mm":100,"alpha_deg":0,"d_mm":0}],"tool_point_mm":[0,0,0]}"#).unwrap()
    }
    fn rig() -> Rig {
        Rig::from_json(
            r#"{"anchors_mm":[[0,0,0],[0,900,0],[1200,0,0]],"r_mm":35,"sensor":{"range_mm":2000}}"#,
        )
        .unwrap()
    }

    #[test]
    fn implausible_time_and_temperature_are_refused_with_row_and_column() {
        for (cells, col) in [
            ("1e308,20", "time_s"),
            ("5,1e9", "temp_c"),
            ("5,-300", "temp_c"),
        ] {
            let csv = format!(
                "pose,q1_deg,q2_deg,l1_mm,l2_mm,l3_mm,time_s,temp_c\n1,10,20,100,200,300,{cells}\n"
            );
            let e = Dataset::from_csv(csv.as_bytes(), &robot(), &rig())
                .unwrap_err()
                .to_string();
            assert!(e.contains(col) && e.contains("row 1"), "{e}");
        }
    }

    #[test]
    fn parses_strings_and_context() {
        let csv = "pose,q1_deg,q2_deg,l1_mm,l2_mm,l3_mm,time_s,split,extra\n1,10,20,100,200,300,1.5,test,x\n";
        let d = Dataset::from_csv(csv.as_bytes(), &robot(), &rig()).unwrap();
        assert_eq!(d.poses.len(), 1);
        assert_eq!(d.poses[0].split, Some(Split::Test));
        assert_eq!(d.poses[0].time_s, Some(1.5));
        assert!(
            matches!(d.poses[0].measurement, Measurement::Strings(ref l) if l == &vec![100.0, 200.0, 300.0])
        );
    }

    #[test]
    fn names_row_and_column() {
        let csv =
            "pose,q1_deg,q2_deg,l1_mm,l2_mm,l3_mm\n1,10,20,100,200,300\n2,10,NaN,100,200,300\n";
        let e = Dataset::from_csv(csv.as_bytes(), &robot(), &rig()).unwrap_err();
        assert!(
            matches!(e, Error::Input { ref field, row: Some(2), .. } if field.as_deref() == Some("q2_deg")),
            "{e}"
        );
    }

    #[test]
    fn refuses_readings_past_range_and_short_rows() {
        let csv = "pose,q1_deg,q2_deg,l1_mm,l2_mm,l3_mm\n1,10,20,100,2500,300\n";
        let e = Dataset::from_csv(csv.as_bytes(), &robot(), &rig())
            .unwrap_err()
            .to_string();
        assert!(e.contains("l2_mm") && e.contains("range"), "{e}");
        let csv = "pose,q1_deg,q2_deg,l1_mm,l2_mm,l3_mm\n1,10,20,100,200\n";
        let e = Dataset::from_csv(csv.as_bytes(), &robot(), &rig())
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "row 1 after the header: 5 cells where the header has 6 columns"
        );
    }

    #[test]
    fn short_long_and_unreadable_rows_name_the_row_not_a_column() {
        let head = "pose,q1_deg,q2_deg,l1_mm,l2_mm,l3_mm\n1,10,20,100,200,300\n";
        for (rest, want) in [
            (
                "2,10,20,100,200,300,7\n",
                "7 cells where the header has 6 columns",
            ),
            (
                "\n\n2,10,20,100\n",
                "4 cells where the header has 6 columns",
            ),
            ("  \n", "an empty row where the header has 6 columns"),
        ] {
            let e = Dataset::from_csv(format!("{head}{rest}").as_bytes(), &robot(), &rig())
                .unwrap_err();
            assert!(
                matches!(e, Error::Input { field: None, row: Some(2), ref message } if message.contains(want)),
                "{e:?}"
            );
        }
        let mut bytes = head.as_bytes().to_vec();
        bytes.extend_from_slice(b"2,10,20,100,\xff\xfe,300\n");
        let e = Dataset::from_csv(&bytes[..], &robot(), &rig()).unwrap_err();
        assert!(
            matches!(e, Error::Input { ref field, row: Some(2), ref message }
                if field.as_deref() == Some("l2_mm") && message.contains("UTF-8")),
            "{e:?}"
        );
    }

    #[test]
    fn a_semicolon_or_tab_separated_file_is_told_to_use_commas() {
        for sep in [";", "\t"] {
            let csv = format!(
                "pose{sep}q1_deg{sep}q2_deg{sep}l1_mm{sep}l2_mm{sep}l3_mm\n1{sep}10,5{sep}20{sep}1{sep}2{sep}3\n"
            );
            let e = Dataset::from_csv(csv.as_bytes(), &robot(), &rig())
                .unwrap_err()
                .to_string();
            assert!(
                e.starts_with("header: the file must be comma-separated"),
                "{e}"
            );
        }
        let e = string_readings_from_csv("pose;l1_mm;l2_mm;l3_mm\n1;1;2;3\n".as_bytes(), &rig())
            .unwrap_err()
            .to_string();
        assert!(e.contains("comma-separated"), "{e}");
    }

    #[test]
    fn refuses_duplicate_ids_and_limits() {
        let csv = "pose,q1_deg,q2_deg,l1_mm,l2_mm,l3_mm\n1,10,20,1,2,3\n1,10,20,1,2,3\n";
        assert!(
            Dataset::from_csv(csv.as_bytes(), &robot(), &rig())
                .unwrap_err()
                .to_string()
                .contains("duplicate")
        );
        let csv = "pose,q1_deg,q2_deg,l1_mm,l2_mm,l3_mm\n1,100,20,1,2,3\n";
        assert!(
            Dataset::from_csv(csv.as_bytes(), &robot(), &rig())
                .unwrap_err()
                .to_string()
                .contains("limits")
        );
    }
}

/// Only the pose ids and string readings of a poses.csv (for locating
/// points without a robot model). Readings are checked as in
/// [`Dataset::from_csv`].
pub fn string_readings_from_csv<R: Read>(input: R, rig: &Rig) -> Result<Vec<(String, Vec<f64>)>> {
    let m = rig.n_strings();
    if m == 0 {
        return Err(Error::field(
            "anchors_mm",
            "the rig has no strings to locate from",
        ));
    }
    let (mut rdr, headers) = super::csv_with_header(input)?;
    let idx = |name: &str| headers.iter().position(|h| h == name);
    let pose_col = idx("pose").ok_or_else(|| Error::field("pose", "missing column 'pose'"))?;
    let mut cols = Vec::with_capacity(m);
    for k in 1..=m {
        let name = format!("l{k}_mm");
        cols.push(idx(&name).ok_or_else(|| {
            Error::field(&name, format!("missing column (the rig has {m} strings)"))
        })?);
    }
    let range = rig.sensor.and_then(|s| s.range_mm);
    let mut out = Vec::new();
    for (r, rec) in rdr.records().enumerate() {
        let row = r + 1;
        let rec = super::csv_record(row, rec, &headers)?;
        let id = rec.get(pose_col).unwrap_or("").trim().to_string();
        let mut ls = Vec::with_capacity(m);
        for (k, &c) in cols.iter().enumerate() {
            let name = format!("l{}_mm", k + 1);
            let v = super::parse_cell(row, &name, rec.get(c).unwrap_or(""))?;
            if v < 0.0 || range.is_some_and(|rg| v > rg) {
                return Err(Error::cell(
                    row,
                    &name,
                    format!("{} mm is outside the sensor's range", super::shown(v)),
                ));
            }
            ls.push(v);
        }
        out.push((id, ls));
    }
    if out.is_empty() {
        return Err(Error::InsufficientData("the file holds no poses".into()));
    }
    Ok(out)
}
