//! The built-in robots and rigs, and the robot and rig a spec names.

use super::{Spec, SpecFiles};
use crate::error::{Error, Result};
use crate::model::{BasePose, Convention, JointSpec, LinkMass, Rig, Robot, SensorSpec};

/// A built-in robot and its rig.
pub fn preset(name: &str) -> Option<(Robot, Rig, Vec<f64>)> {
    match name {
        "er3a" => Some((
            Robot::from_json(include_str!(
                "../../../tests/data/er3a_paper_like/robot.json"
            ))
            .ok()?,
            Rig::from_json(include_str!("../../../tests/data/er3a_paper_like/rig.json")).ok()?,
            vec![0.0, 0.0, 0.0, 0.0, 45.0, 0.0],
        )),
        "ur5" => Some((
            Robot::from_json(include_str!("../../../tests/data/ur5_geometric/robot.json")).ok()?,
            Rig::from_json(include_str!("../../../tests/data/ur5_geometric/rig.json")).ok()?,
            vec![0.0, -90.0, 0.0, -90.0, 0.0, 0.0],
        )),
        "arm4_mdh" => {
            let j = |a: f64, al: f64, d: f64, lo: f64, hi: f64| JointSpec {
                a_mm: a,
                alpha_deg: al,
                d_mm: d,
                theta_offset_deg: 0.0,
                beta_deg: 0.0,
                q_min_deg: lo,
                q_max_deg: hi,
            };
            let lm = |m: f64, c: [f64; 3]| LinkMass {
                mass_kg: m,
                com_mm: c,
            };
            let robot = Robot {
                name: "4-axis arm, Craig MDH (drawcal preset)".into(),
                convention: Convention::Mdh,
                joints: vec![
                    j(0.0, 0.0, 300.0, -170.0, 170.0),
                    j(50.0, -90.0, 0.0, -100.0, 100.0),
                    j(350.0, 0.0, 0.0, -130.0, 130.0),
                    j(300.0, 0.0, 0.0, -120.0, 120.0),
                ],
                tool_point_mm: [100.0, 0.0, 0.0],
                links: Some(vec![
                    lm(8.0, [0.0, 0.0, -60.0]),
                    lm(5.0, [175.0, 0.0, 0.0]),
                    lm(3.0, [150.0, 0.0, 10.0]),
                    lm(1.0, [50.0, 0.0, 0.0]),
                ]),
                gravity_in_base: Some([0.0, 0.0, -9.81]),
            };
            let rig = Rig {
                anchors_mm: vec![
                    [0.0, 0.0, 0.0],
                    [0.0, 1000.0, 0.0],
                    [1200.0, 0.0, 0.0],
                    [1200.0, 1000.0, 0.0],
                ],
                anchor_names: Some(vec!["A".into(), "B".into(), "C".into(), "D".into()]),
                r_mm: 35.0,
                base_in_rig: Some(BasePose {
                    xyz_mm: [600.0, 500.0, -450.0],
                    rpy_deg: [0.0, 0.0, 0.0],
                }),
                sensor: Some(SensorSpec {
                    range_mm: Some(2000.0),
                    resolution_mm: Some(0.024),
                    linearity_pct_fs: Some(0.05),
                }),
                instrument: None,
            };
            Some((robot, rig, vec![0.0, -30.0, 60.0, 0.0]))
        }
        _ => None,
    }
}

/// The robot and rig of `spec`: its preset's, or the files the caller read
/// for the paths it names (`files`: robot.json, rig.json; the engine reads
/// no files).
pub(super) fn load(spec: &Spec, files: SpecFiles) -> Result<(Robot, Rig, Vec<f64>, String)> {
    let rig_file = |files: &SpecFiles| match (&spec.rig, &files.rig) {
        (_, Some(rig)) => Ok(Some(rig.clone())),
        (Some(path), None) => Err(Error::field(
            "spec.rig",
            format!("{path}: a rig.json path, but its file was not read (the CLI reads it)"),
        )),
        (None, _) => Ok(None),
    };
    if let Some((robot, rig, home)) = preset(&spec.robot) {
        let rig = rig_file(&files)?.unwrap_or(rig);
        return Ok((robot, rig, home, spec.robot.clone()));
    }
    let Some(robot) = files.robot.clone() else {
        return Err(Error::field(
            "spec.robot",
            format!(
                "{:?} is not a preset (er3a, ur5, arm4_mdh); a robot.json path is read by the CLI",
                spec.robot
            ),
        ));
    };
    let Some(rig) = rig_file(&files)? else {
        return Err(Error::field(
            "spec.rig",
            "a robot.json path needs a rig.json path too",
        ));
    };
    let home = robot
        .joints
        .iter()
        .map(|j| 0.5 * (j.q_min_deg + j.q_max_deg))
        .collect();
    Ok((robot, rig, home, "file".into()))
}
