//! Property tests (proptest) of every input parser: robot.json, rig.json,
//! poses.csv, targets.csv. Arbitrary bytes, and valid files with cells,
//! rows and keys mutated into the nasty values users send (empty, NaN,
//! infinities, huge or tiny numbers, text, radians, extra or missing
//! columns). The rule: a parser answers Ok or a clear error, never panics;
//! what parses runs through the engine (session, identification, one
//! compensation) without panicking either.
//!
//! Case counts are set for CI (a few seconds); `PROPTEST_CASES=100000 cargo
//! test --release --test engine fuzz_parsers` runs a long campaign (see docs/CLI.md).

use crate::common;

use drawcal::compensate::Compensator;
use drawcal::identify::{IdentifyOptions, NoProgress, Observations};
use drawcal::model::targets::targets_from_csv;
use drawcal::model::{Dataset, Rig, Robot};
use drawcal::pipeline::{self, calibrate};
use proptest::prelude::*;

const NASTY: &[&str] = &[
    "",
    " ",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e400",
    "-1e400",
    "1e-320",
    "0",
    "-0",
    "-1",
    "1e308",
    "abc",
    "1,2",
    "\"x\"",
    "0x10",
    "3.14159",
    "6.2832",
    "99999999999999999999",
    "train",
    "test",
    "\u{feff}1",
    "1e",
    "--1",
    ".",
    "+",
    "\t",
];

fn read(name: &str, file: &str) -> String {
    std::fs::read_to_string(common::dir(name).join(file)).unwrap()
}

/// A valid CSV with up to `n` cells replaced by nasty values, rows dropped,
/// duplicated or cut short.
fn mutate_csv(text: &str, edits: &[(usize, usize, usize, u8)]) -> String {
    let mut rows: Vec<Vec<String>> = text
        .lines()
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    for &(r, c, v, op) in edits {
        if rows.is_empty() {
            break;
        }
        let r = r % rows.len();
        match op % 6 {
            0 | 1 | 2 => {
                let c = c % rows[r].len().max(1);
                if let Some(cell) = rows[r].get_mut(c) {
                    *cell = NASTY[v % NASTY.len()].to_string();
                }
            }
            3 => {
                rows.remove(r);
            }
            4 => {
                let dup = rows[r].clone();
                rows.insert(r, dup);
            }
            _ => {
                let keep = c % (rows[r].len() + 2);
                rows[r].truncate(keep);
                if keep > rows[r].len() {
                    rows[r].push("7".into());
                }
            }
        }
    }
    rows.iter()
        .map(|r| r.join(","))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Replace up to a few JSON numbers with nasty tokens (may break the JSON).
fn mutate_json(text: &str, edits: &[(usize, usize)]) -> String {
    let mut out = text.to_string();
    for &(at, v) in edits {
        let digits: Vec<usize> = out
            .char_indices()
            .filter(|(_, ch)| ch.is_ascii_digit())
            .map(|(i, _)| i)
            .collect();
        if digits.is_empty() {
            break;
        }
        let i = digits[at % digits.len()];
        let end = out[i..]
            .find(|ch: char| !(ch.is_ascii_digit() || ch == '.' || ch == 'e' || ch == '-'))
            .map_or(out.len(), |e| i + e);
        out.replace_range(i..end, NASTY[v % NASTY.len()]);
    }
    out
}

/// Everything after a successful parse must not panic either.
fn run_engine(robot: &Robot, rig: &Rig, data: &Dataset) {
    let opts = pipeline::Options {
        identify: IdentifyOptions {
            ..IdentifyOptions::default()
        },
        physics: false,
        ..Default::default()
    };
    if Observations::new(robot, rig, data, &opts.identify).is_ok() {
        if let Ok(report) = calibrate(robot, rig, data, &opts, &NoProgress) {
            if let Ok(comp) = Compensator::from_report(&report) {
                let q: Vec<f64> = robot.joints.iter().map(|_| 10.0).collect();
                let t = format!(
                    "target,{}\nt,{}\n",
                    (1..=q.len())
                        .map(|j| format!("q{j}_deg"))
                        .collect::<Vec<_>>()
                        .join(","),
                    q.iter()
                        .map(|v| v.to_string())
                        .collect::<Vec<_>>()
                        .join(",")
                );
                for target in targets_from_csv(t.as_bytes(), robot.dof()).unwrap() {
                    let _ = comp.compensate(&target, false);
                }
            }
        }
    }
}

/// One calibration of er3a_paper_like, shared by the cases.
fn er3a_compensator() -> &'static Compensator {
    static COMP: std::sync::OnceLock<Compensator> = std::sync::OnceLock::new();
    COMP.get_or_init(|| {
        let (robot, rig, data) = common::load("er3a_paper_like");
        let opts = pipeline::Options {
            identify: IdentifyOptions {
                ..IdentifyOptions::default()
            },
            physics: false,
            ..Default::default()
        };
        let report = calibrate(&robot, &rig, &data, &opts, &NoProgress).unwrap();
        Compensator::from_report(&report).unwrap()
    })
}

proptest! {
    #![proptest_config(common::proptest_cases(256))]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let text = String::from_utf8_lossy(&bytes);
        let _ = Robot::from_json(&text);
        let _ = Rig::from_json(&text);
        let (robot, rig, _) = common::load("er3a_paper_like");
        let _ = Dataset::from_csv(&bytes[..], &robot, &rig);
        let _ = targets_from_csv(&bytes[..], 6);
    }

    #[test]
    fn mutated_robot_and_rig_json_never_panic(
        robot_edits in proptest::collection::vec((any::<usize>(), any::<usize>()), 0..4),
        rig_edits in proptest::collection::vec((any::<usize>(), any::<usize>()), 0..4),
    ) {
        let robot_text = mutate_json(&read("er3a_paper_like", "robot.json"), &robot_edits);
        let rig_text = mutate_json(&read("er3a_paper_like", "rig.json"), &rig_edits);
        if let (Ok(robot), Ok(rig)) = (Robot::from_json(&robot_text), Rig::from_json(&rig_text)) {
            let poses = read("er3a_paper_like", "poses.csv");
            if let Ok(data) = Dataset::from_csv(poses.as_bytes(), &robot, &rig) {
                run_engine(&robot, &rig, &data);
            }
        }
    }

    #[test]
    fn mutated_poses_csv_never_panics(
        edits in proptest::collection::vec(
            (any::<usize>(), any::<usize>(), any::<usize>(), any::<u8>()), 0..6),
        tracker in any::<bool>(),
    ) {
        let name = if tracker { "real_positioner2ax_rosi" } else { "er3a_paper_like" };
        let (robot, rig, _) = common::load(name);
        let text = mutate_csv(&read(name, "poses.csv"), &edits);
        if let Ok(data) = Dataset::from_csv(text.as_bytes(), &robot, &rig) {
            run_engine(&robot, &rig, &data);
        }
    }

    #[test]
    fn mutated_targets_csv_never_panics(
        edits in proptest::collection::vec(
            (any::<usize>(), any::<usize>(), any::<usize>(), any::<u8>()), 0..6),
        cartesian in any::<bool>(),
    ) {
        let valid = if cartesian {
            "target,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\na,300,50,450,180,0,0\nb,250,-80,500,170,10,5\n"
        } else {
            "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\na,10,20,30,40,50,60\nb,-10,5,0,90,-45,30\n"
        };
        let text = mutate_csv(valid, &edits);
        if let Ok(targets) = targets_from_csv(text.as_bytes(), 6) {
            for t in &targets {
                let _ = er3a_compensator().compensate(t, cartesian);
            }
        }
    }
}
