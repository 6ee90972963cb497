//! The `drawcal` binary as a user runs it: identify, then compensate with
//! the report, then locate.

use std::path::PathBuf;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_drawcal"))
}

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/er3a_paper_like")
        .join(name)
}

#[test]
fn identify_then_compensate() {
    let dir = std::env::temp_dir().join(format!("drawcal-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let report = dir.join("report.json");
    let out = bin()
        .args(["identify", "--physics", "off", "--robot"])
        .arg(data("robot.json"))
        .arg("--rig")
        .arg(data("rig.json"))
        .arg("--poses")
        .arg(data("poses.csv"))
        .arg("--out")
        .arg(&report)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("RMS 3-D")
            && stdout.contains("test after")
            && stdout.contains("paper test"),
        "{stdout}"
    );
    assert!(stdout.contains("j3.d"), "the alias is named: {stdout}");
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    for key in [
        "method",
        "calibrated_robot",
        "base_in_rig",
        "tool_point_mm",
        "deviations",
        "fixed",
        "stats",
        "noise_floor_mm",
        "held_out",
        "findings",
    ] {
        assert!(rep.get(key).is_some(), "report lacks {key}");
    }
    assert!(rep["deviations"][1].get("theta_offset_deg_sigma").is_some());
    assert!(rep["stats"]["test"]["after"]["x"]["max_abs_mm"].is_number());
    // The calibrated robot can be fed back in as a robot.json.
    drawcal::model::Robot::from_json(&rep["calibrated_robot"].to_string()).unwrap();

    let targets = dir.join("targets.csv");
    std::fs::write(&targets, "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\nt1,10,20,30,40,50,60\nt2,0,300,0,0,0,0\n").unwrap();
    let compensated = dir.join("compensated.csv");
    let out = bin()
        .arg("compensate")
        .arg("--calibration")
        .arg(&report)
        .arg("--targets")
        .arg(&targets)
        .arg("--out")
        .arg(&compensated)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&compensated).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,residual_mm,iterations,status,message"
    );
    assert!(
        lines[1].starts_with("t1,") && lines[1].contains(",ok,"),
        "{}",
        lines[1]
    );
    assert!(
        lines[2].starts_with("t2,") && !lines[2].contains(",ok,"),
        "one bad target, reported per row: {}",
        lines[2]
    );

    // Bad input: a clear error naming the row and column.
    let bad = dir.join("bad.csv");
    let mut poses = std::fs::read_to_string(data("poses.csv")).unwrap();
    poses = poses.replacen("\n2,", "\n2,abc", 1);
    std::fs::write(&bad, poses).unwrap();
    let out = bin()
        .args(["identify", "--robot"])
        .arg(data("robot.json"))
        .arg("--rig")
        .arg(data("rig.json"))
        .arg("--poses")
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("row 2") && err.contains("q1_deg"), "{err}");
}

#[test]
fn locate_compares_closed_form_and_least_squares() {
    let out = bin()
        .arg("locate")
        .arg("--rig")
        .arg(data("rig.json"))
        .arg("--poses")
        .arg(data("poses.csv"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let csv = String::from_utf8_lossy(&out.stdout);
    assert_eq!(csv.lines().count(), 51);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("paper closed form vs least squares"), "{err}");
}
