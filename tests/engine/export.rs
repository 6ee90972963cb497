//! Results out (issue 19, item 3): the calibrated model of
//! tests/data/er3a_paper_like as a URDF, checked with an independent URDF
//! implementation (tests/engine/urdf_fk.py: python3, stdlib only), as
//! robot.json and as the CSV of deviations.

use std::io::Write;
use std::process::{Command, Stdio};

use drawcal::export::{self, ExportFormat};
use drawcal::kinematics::chain::OutputFrame;
use drawcal::kinematics::{Chain, Params};
use drawcal::model::Robot;
use drawcal::model::urdf::{UrdfOptions, robot_from_urdf};
use nalgebra::Vector3;

use super::common;

/// T from the URDF file at each joint vector (rad), by the Python script.
fn python_fk(urdf: &str, base: &str, tip: &str, qs: &[Vec<f64>]) -> Vec<Vector3<f64>> {
    let dir = std::env::temp_dir().join(format!("drawcal-export-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("calibrated.urdf");
    std::fs::write(&file, urdf).unwrap();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/engine/urdf_fk.py");
    let mut child = Command::new("python3")
        .arg(script)
        .arg(&file)
        .arg(base)
        .arg(tip)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| {
            panic!("python3 is needed for the independent URDF check (install python3): {e}")
        });
    let mut input = String::new();
    for q in qs {
        let row: Vec<String> = q.iter().map(|v| format!("{:?}", v.to_degrees())).collect();
        input.push_str(&row.join(" "));
        input.push('\n');
    }
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "urdf_fk.py failed: {out:?}");
    let _ = std::fs::remove_dir_all(&dir);
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            Vector3::new(v[0], v[1], v[2])
        })
        .collect()
}

#[test]
fn export_urdf_matches_the_calibrated_model_by_an_independent_implementation() {
    let (robot, rig, data) = common::load("er3a_paper_like");
    let report = common::identify_default(&robot, &rig, &data);
    let text = export::export(&report, ExportFormat::Urdf).unwrap();
    // drawcal's calibrated model, in the rig frame, at the held-out poses.
    let cal = &report.calibrated_robot;
    let mut p = Params::of_robot(cal);
    p.set_base(&report.base_in_rig);
    let chain = Chain::new(cal.convention, cal.dof(), 0);
    let qs: Vec<Vec<f64>> = data
        .poses
        .iter()
        .filter(|r| report.held_out.contains(&r.id))
        .map(|r| r.q_rad.clone())
        .collect();
    assert!(qs.len() >= 5, "{} held-out poses", qs.len());
    let theirs = python_fk(&text, "world", "tcp", &qs);
    assert_eq!(theirs.len(), qs.len());
    let mut worst: f64 = 0.0;
    for (q, t) in qs.iter().zip(&theirs) {
        let (_, ours) = chain.point(&p.values, q, OutputFrame::Rig);
        worst = worst.max((ours - t).norm());
    }
    assert!(
        worst < 1e-3,
        "the exported URDF misses the calibrated model by {worst:e} mm"
    );
    // And read back by drawcal's own URDF in, base_link to tcp: the same
    // model in the robot base frame.
    let back = robot_from_urdf(
        &text,
        &UrdfOptions {
            tool_link: Some("tcp".into()),
            base_link: Some("base_link".into()),
            ..Default::default()
        },
    )
    .unwrap();
    let pb = Params::of_robot(&back);
    let cb = Chain::new(back.convention, back.dof(), 0);
    let pc = Params::of_robot(cal);
    for q in &qs {
        let (_, a) = chain.point(&pc.values, q, OutputFrame::Base);
        let (_, b) = cb.point(&pb.values, q, OutputFrame::Base);
        assert!(
            (a - b).norm() < 1e-9,
            "round trip off by {:e} mm",
            (a - b).norm()
        );
    }
}

#[test]
fn export_robot_json_and_csv() {
    let (robot, rig, data) = common::load("er3a_paper_like");
    let report = common::identify_default(&robot, &rig, &data);
    let json = export::export(&report, ExportFormat::RobotJson).unwrap();
    let back = Robot::from_json(&json).unwrap();
    assert_eq!(back.joints, report.calibrated_robot.joints);
    assert_eq!(back.tool_point_mm, report.tool_point_mm);

    let csv = export::export(&report, ExportFormat::Csv).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(export::CSV_HEADER));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 5 * 6 + 3 + 6);
    for r in &rows {
        assert_eq!(r.len(), 8, "{r:?}");
        let (n0, c, d): (f64, f64, f64) = (
            r[3].parse().unwrap(),
            r[4].parse().unwrap(),
            r[5].parse().unwrap(),
        );
        assert!((c - n0 - d).abs() < 1e-9, "{r:?}");
        assert!(r[7] == "identified" || r[7] == "held");
        assert_eq!(r[7] == "identified", !r[6].is_empty(), "{r:?}");
    }
    // j2.a of the report's deviations, with its sigma.
    let j2a = rows.iter().find(|r| r[0] == "2" && r[1] == "a").unwrap();
    let dev = &report.deviations[1];
    assert!((j2a[5].parse::<f64>().unwrap() - dev.a_mm).abs() < 1e-9);
    if let Some(s) = dev.a_mm_sigma {
        assert!((j2a[6].parse::<f64>().unwrap() - s).abs() < 1e-12);
    }
}
