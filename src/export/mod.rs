//! Results out: a report's calibrated model as a URDF, as robot.json, and
//! as a per-joint CSV table of the DH deviations (`drawcal export`,
//! `GET /calibrations/{id}/export`).
//!
//! The URDF is the calibrated geometry, nothing else: the root link `world`
//! is the rig frame (rig.json's frame M), the fixed joint `world_to_base`
//! carries the identified base pose, each revolute joint `joint_i` turns
//! about its own z with an origin made of the identified link parameters,
//! `tool0` is the flange frame n of the model and `tcp` the identified tool
//! point T (a fixed frame, translation only). Physics findings (compliance,
//! backlash...) are not in it: a URDF has no place for them.

use std::fmt::Write as _;

use nalgebra::{Matrix3, Vector3};

use crate::error::{Error, Result};
use crate::model::urdf::Pose;
use crate::model::{Convention, JointSpec, Robot};
use crate::report::Report;

/// What `export` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    /// The calibrated model as a URDF.
    Urdf,
    /// The calibrated robot.json.
    RobotJson,
    /// The per-parameter table of nominal, calibrated, deviation and sigma.
    Csv,
    /// The extra poses the verdict suggests (`report.extra_poses`), as
    /// targets.csv: what to record next.
    ExtraTargets,
}

impl ExportFormat {
    /// The names `format` accepts.
    pub const NAMES: &'static str = "urdf, robot-json, csv, extra-targets";

    /// From its name (`urdf`, `robot-json`, `csv`, `extra-targets`); an
    /// error on field
    /// `format` otherwise.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "urdf" => Ok(ExportFormat::Urdf),
            "robot-json" | "robot_json" | "json" => Ok(ExportFormat::RobotJson),
            "csv" => Ok(ExportFormat::Csv),
            "extra-targets" => Ok(ExportFormat::ExtraTargets),
            other => Err(Error::field(
                "format",
                format!(
                    "{other:?} is not an export format; use one of {}",
                    Self::NAMES
                ),
            )),
        }
    }

    /// The media type of the text.
    pub fn content_type(self) -> &'static str {
        match self {
            ExportFormat::Urdf => "application/xml",
            ExportFormat::RobotJson => "application/json",
            ExportFormat::Csv | ExportFormat::ExtraTargets => "text/csv",
        }
    }

    /// The file extension (without the dot).
    pub fn extension(self) -> &'static str {
        match self {
            ExportFormat::Urdf => "urdf",
            ExportFormat::RobotJson => "json",
            ExportFormat::Csv | ExportFormat::ExtraTargets => "csv",
        }
    }
}

/// The report's calibrated model in `format` (or its extra poses).
pub fn export(report: &Report, format: ExportFormat) -> Result<String> {
    match format {
        ExportFormat::Urdf => Ok(urdf(report)),
        ExportFormat::RobotJson => robot_json(report),
        ExportFormat::Csv => Ok(deviations_csv(report)),
        ExportFormat::ExtraTargets => match &report.extra_poses {
            Some(x) if !x.poses.is_empty() => Ok(x.targets_csv()),
            _ => Err(Error::field(
                "format",
                "this report suggests no extra poses: its poses determine every parameter \
                 any pose of this rig could (or it was written before reports carried extra \
                 poses)",
            )),
        },
    }
}

/// The calibrated robot.json (with the identified tool point).
pub fn robot_json(report: &Report) -> Result<String> {
    let mut robot = report.calibrated_robot.clone();
    robot.tool_point_mm = report.tool_point_mm;
    let mut s = serde_json::to_string_pretty(&robot)
        .map_err(|e| Error::Numerical(format!("robot.json: {e}")))?;
    s.push('\n');
    Ok(s)
}

/// Roll, pitch, yaw (rad) with `r = Rz(yaw) Ry(pitch) Rx(roll)`, exact at
/// pitch = ±90° too (roll 0 there).
fn rpy_of(r: &Matrix3<f64>) -> [f64; 3] {
    let pitch = (-r[(2, 0)]).atan2(r[(0, 0)].hypot(r[(1, 0)]));
    if r[(0, 0)].hypot(r[(1, 0)]) < 1e-12 {
        return [0.0, pitch, (-r[(0, 1)]).atan2(r[(1, 1)])];
    }
    [
        r[(2, 1)].atan2(r[(2, 2)]),
        pitch,
        r[(1, 0)].atan2(r[(0, 0)]),
    ]
}

/// `<origin>` of a transform, metres and radians at full precision.
fn origin(p: &Pose) -> String {
    let [r, pi, y] = rpy_of(&p.r);
    format!(
        r#"<origin xyz="{} {} {}" rpy="{} {} {}"/>"#,
        p.p.x / 1000.0,
        p.p.y / 1000.0,
        p.p.z / 1000.0,
        r,
        pi,
        y
    )
}

fn rot(axis: usize, t: f64) -> Pose {
    let mut e = [0.0; 3];
    e[axis] = t;
    Pose::from_xyz_rpy([0.0; 3], e)
}

fn trans(axis: usize, d: f64) -> Pose {
    let mut v = [0.0; 3];
    v[axis] = d;
    Pose::from_xyz_rpy(v, [0.0; 3])
}

/// A joint's constant transform: DH's after its rotation, MDH's before.
fn link_constant(convention: Convention, j: &JointSpec) -> Pose {
    let (a, al, d) = (j.a_mm, j.alpha_deg.to_radians(), j.d_mm);
    let (th, be) = (j.theta_offset_deg.to_radians(), j.beta_deg.to_radians());
    match convention {
        Convention::Dh => rot(2, th)
            .then(&trans(2, d))
            .then(&trans(0, a))
            .then(&rot(0, al))
            .then(&rot(1, be)),
        // Rz(q) commutes with Rz(θ) Tz(d): all of it before the rotation.
        Convention::Mdh => rot(0, al)
            .then(&rot(1, be))
            .then(&trans(0, a))
            .then(&rot(2, th))
            .then(&trans(2, d)),
    }
}

/// The calibrated model as a URDF (module docs for its frames).
pub fn urdf(report: &Report) -> String {
    let robot: &Robot = &report.calibrated_robot;
    let n = robot.dof();
    let consts: Vec<Pose> = robot
        .joints
        .iter()
        .map(|j| link_constant(robot.convention, j))
        .collect();
    let mut s = String::new();
    let name = xml_escape(&robot.name);
    let _ = writeln!(s, r#"<?xml version="1.0"?>"#);
    let _ = writeln!(
        s,
        "<!-- The calibrated model of a drawcal report ({}), {} convention: joint origins carry the identified link parameters, world_to_base the identified base pose (world is the rig frame), tcp the identified tool point in tool0 (the flange frame). Geometry only: physics findings are not represented. effort and velocity limits are not known to drawcal and written as 0; inertia tensors likewise. -->",
        xml_escape(&report.format),
        match robot.convention {
            Convention::Dh => "DH (Hayati's beta)",
            Convention::Mdh => "Craig's MDH",
        }
    );
    let _ = writeln!(s, r#"<robot name="{name}">"#);
    let _ = writeln!(s, r#"  <link name="world"/>"#);
    let _ = writeln!(s, r#"  <link name="base_link"/>"#);
    for i in 0..n {
        let inertial = robot.links.as_ref().map(|links| {
            let com = Vector3::from(links[i].com_mm);
            // The URDF link frame is the DH frame i-1 turned by q_i, i.e.
            // the DH frame i before its constant part; MDH's is frame i.
            let c = match robot.convention {
                Convention::Dh => consts[i].apply(&com),
                Convention::Mdh => com,
            };
            format!(
                r#"<inertial><origin xyz="{} {} {}" rpy="0 0 0"/><mass value="{}"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>"#,
                c.x / 1000.0,
                c.y / 1000.0,
                c.z / 1000.0,
                links[i].mass_kg
            )
        });
        match inertial {
            Some(x) => {
                let _ = writeln!(s, r#"  <link name="link_{}">{x}</link>"#, i + 1);
            }
            None => {
                let _ = writeln!(s, r#"  <link name="link_{}"/>"#, i + 1);
            }
        }
    }
    let _ = writeln!(s, r#"  <link name="tool0"/>"#);
    let _ = writeln!(s, r#"  <link name="tcp"/>"#);
    let b = &report.base_in_rig;
    let base = Pose::from_xyz_rpy(b.xyz_mm, b.rpy_deg.map(f64::to_radians));
    let _ = writeln!(
        s,
        r#"  <joint name="world_to_base" type="fixed"><parent link="world"/><child link="base_link"/>{}</joint>"#,
        origin(&base)
    );
    for (i, j) in robot.joints.iter().enumerate() {
        let parent = if i == 0 {
            "base_link".to_string()
        } else {
            format!("link_{i}")
        };
        let o = match robot.convention {
            Convention::Dh if i == 0 => Pose::identity(),
            Convention::Dh => consts[i - 1],
            Convention::Mdh => consts[i],
        };
        let _ = writeln!(
            s,
            r#"  <joint name="joint_{k}" type="revolute"><parent link="{parent}"/><child link="link_{k}"/>{o}<axis xyz="0 0 1"/><limit lower="{lo}" upper="{hi}" effort="0" velocity="0"/></joint>"#,
            k = i + 1,
            o = origin(&o),
            lo = j.q_min_deg.to_radians(),
            hi = j.q_max_deg.to_radians(),
        );
    }
    let flange = match robot.convention {
        Convention::Dh => consts[n - 1],
        Convention::Mdh => Pose::identity(),
    };
    let _ = writeln!(
        s,
        r#"  <joint name="flange" type="fixed"><parent link="link_{n}"/><child link="tool0"/>{}</joint>"#,
        origin(&flange)
    );
    let _ = writeln!(
        s,
        r#"  <joint name="tool0_to_tcp" type="fixed"><parent link="tool0"/><child link="tcp"/>{}</joint>"#,
        origin(&Pose::from_xyz_rpy(report.tool_point_mm, [0.0; 3]))
    );
    s.push_str("</robot>\n");
    s
}

fn xml_escape(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The header of [`deviations_csv`].
pub const CSV_HEADER: &str = "joint,parameter,unit,nominal,calibrated,deviation,sigma,status";

/// One row per joint parameter (a, alpha, d, theta, beta of each joint),
/// then the tool point and the base pose: nominal, calibrated, their
/// difference and the 1-sigma where the report has one (`status`:
/// `identified`, or `held` at nominal). Base: nominal is the starting
/// guess (rig.json's `base_in_rig` or the fitted start).
pub fn deviations_csv(report: &Report) -> String {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    let held = |name: &str| report.fixed.iter().any(|f| f == name);
    let num = |v: f64| {
        if v.is_finite() {
            format!("{v}")
        } else {
            String::new()
        }
    };
    let nom = &report.nominal_robot;
    let cal = &report.calibrated_robot;
    for (i, (a, b)) in nom.joints.iter().zip(&cal.joints).enumerate() {
        let dev = report.deviations.iter().find(|d| d.joint == i + 1);
        let rows = [
            ("a", "mm", a.a_mm, b.a_mm, dev.and_then(|d| d.a_mm_sigma)),
            (
                "alpha",
                "deg",
                a.alpha_deg,
                b.alpha_deg,
                dev.and_then(|d| d.alpha_deg_sigma),
            ),
            ("d", "mm", a.d_mm, b.d_mm, dev.and_then(|d| d.d_mm_sigma)),
            (
                "theta",
                "deg",
                a.theta_offset_deg,
                b.theta_offset_deg,
                dev.and_then(|d| d.theta_offset_deg_sigma),
            ),
            (
                "beta",
                "deg",
                a.beta_deg,
                b.beta_deg,
                dev.and_then(|d| d.beta_deg_sigma),
            ),
        ];
        for (p, unit, n0, c, sigma) in rows {
            let status = if held(&format!("j{}.{p}", i + 1)) || sigma.is_none() {
                "held"
            } else {
                "identified"
            };
            let _ = writeln!(
                s,
                "{},{p},{unit},{},{},{},{},{status}",
                i + 1,
                num(n0),
                num(c),
                num(c - n0),
                sigma.map_or(String::new(), num)
            );
        }
    }
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        let name = format!("tool.{axis}");
        let est = report.parameters.iter().find(|p| p.name == name);
        let (n0, c) = (nom.tool_point_mm[k], report.tool_point_mm[k]);
        let _ = writeln!(
            s,
            "tool,{axis},mm,{},{},{},{},{}",
            num(n0),
            num(c),
            num(c - n0),
            est.map_or(String::new(), |e| num(e.sigma)),
            if est.is_some() { "identified" } else { "held" }
        );
    }
    for (k, axis) in ["x", "y", "z", "roll", "pitch", "yaw"].iter().enumerate() {
        let name = format!("base.{axis}");
        let c = if k < 3 {
            report.base_in_rig.xyz_mm[k]
        } else {
            report.base_in_rig.rpy_deg[k - 3]
        };
        let est = report.parameters.iter().find(|p| p.name == name);
        let (n0, dev) = match est {
            Some(e) => (c - e.deviation, e.deviation),
            None => (c, 0.0),
        };
        let _ = writeln!(
            s,
            "base,{axis},{},{},{},{},{},{}",
            if k < 3 { "mm" } else { "deg" },
            num(n0),
            num(c),
            num(dev),
            est.map_or(String::new(), |e| num(e.sigma)),
            if est.is_some() { "identified" } else { "held" }
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpy_of_inverts_from_xyz_rpy_at_and_off_gimbal_lock() {
        for rpy in [
            [0.3, -0.4, 2.0],
            [0.0, std::f64::consts::FRAC_PI_2, 0.7],
            [0.0, -std::f64::consts::FRAC_PI_2, -2.5],
            [3.0, 1.2, -3.0],
        ] {
            let p = Pose::from_xyz_rpy([0.0; 3], rpy);
            let back = Pose::from_xyz_rpy([0.0; 3], rpy_of(&p.r));
            assert!((p.r - back.r).norm() < 1e-14, "{rpy:?}");
        }
    }

    #[test]
    fn unknown_format_names_the_field() {
        let e = ExportFormat::parse("step").unwrap_err().to_string();
        assert!(
            e.starts_with("format:") && e.contains("urdf, robot-json, csv"),
            "{e}"
        );
    }
}
