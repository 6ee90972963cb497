//! Joint-target compensation answers, printed to the last digit, so that a
//! change to the solver's arithmetic can be checked against the answers of
//! the build before it (BENCHMARKS.md, "compensate one nominal joint
//! target"); and a loop of the benchmark's target for a profiler.
//!
//! ```sh
//! cargo run --example compensate_answers > before.txt   # on the old build
//! cargo run --example compensate_answers > after.txt    # on the new one
//! cargo run --example compensate_answers -- --compare before.txt after.txt
//! # instructions per solve (release build with line tables):
//! valgrind --tool=callgrind target/release/examples/compensate_answers --loop 20000
//! ```
//!
//! The targets: random taught joints inside the limits (each within ±180°)
//! on the arms of `tests/data` (the simulator's true robot as the
//! calibration, a UR10 with millimetre deviations, a calibration with a
//! joint compliance, a two-joint positioner), with and without the flange
//! orientation, and the UR10's singular taught poses of
//! `tests/engine/compensate_ik.rs`.

use std::path::PathBuf;

use drawcal::compensate::Compensator;
use drawcal::identify::NoProgress;
use drawcal::model::{Dataset, Rig, Robot, Target, TargetKind};
use drawcal::rng::Rng;

fn dir(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn robot(name: &str) -> Robot {
    Robot::from_json(&std::fs::read_to_string(dir(name).join("robot.json")).unwrap()).unwrap()
}

/// The simulator's true robot of a dataset, as a calibration.
fn truth(name: &str) -> Robot {
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir(name).join("truth.json")).unwrap())
            .unwrap();
    serde_json::from_value(t["true_robot"].clone()).unwrap()
}

/// A compensator from a whole calibration of a dataset (with whatever joint
/// effects the analysis accepts when `physics`).
fn calibrated(name: &str, physics: bool) -> Compensator {
    let d = dir(name);
    let robot = robot(name);
    let rig = Rig::from_json(&std::fs::read_to_string(d.join("rig.json")).unwrap()).unwrap();
    let file = std::fs::File::open(d.join("poses.csv")).unwrap();
    let data = Dataset::from_csv(file, &robot, &rig).unwrap();
    let report = {
        let opts = drawcal::pipeline::Options {
            physics,
            ..Default::default()
        };
        drawcal::pipeline::calibrate(&robot, &rig, &data, &opts, &NoProgress).unwrap()
    };
    Compensator::from_report(&report).unwrap()
}

fn joints(q_deg: &[f64]) -> Target {
    Target {
        target: "t".into(),
        kind: TargetKind::Joints {
            q_deg: q_deg.to_vec(),
        },
    }
}

/// The largest differences between two printouts, line by line: joints
/// (rad), residual (mm); and how many lines differ in status or iterations.
fn compare(before: &str, after: &str) {
    let read = |p: &str| std::fs::read_to_string(p).unwrap();
    let (a, b) = (read(before), read(after));
    let (a, b): (Vec<&str>, Vec<&str>) = (a.lines().collect(), b.lines().collect());
    assert_eq!(a.len(), b.len(), "not the same targets");
    let nums = |s: &str| -> Vec<f64> {
        s.trim_matches(|c| c == '[' || c == ']')
            .split(',')
            .filter(|v| !v.is_empty())
            .map(|v| v.parse().unwrap())
            .collect()
    };
    let (mut dq, mut dr, mut other, mut identical) = (0.0f64, 0.0f64, 0, 0);
    for (x, y) in a.iter().zip(&b) {
        identical += usize::from(x == y);
        let (x, y): (Vec<&str>, Vec<&str>) = (x.split(' ').collect(), y.split(' ').collect());
        assert_eq!(x[..3], y[..3], "not the same targets");
        if x[3..5] != y[3..5] {
            other += 1;
            println!("differs: {} / {}", x.join(" "), y.join(" "));
            continue;
        }
        if let (Ok(r1), Ok(r2)) = (x[5].parse::<f64>(), y[5].parse::<f64>()) {
            dr = dr.max((r1 - r2).abs());
        }
        for (u, v) in nums(x[6]).iter().zip(nums(y[6])) {
            dq = dq.max((u - v).abs().to_radians());
        }
    }
    println!(
        "{} answers: {identical} identical to the digit; largest joint difference {dq:e} rad, \
         residual {dr:e} mm; {other} differ in status or iterations",
        a.len()
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("--compare") {
        return compare(&args[2], &args[3]);
    }
    if let Some(i) = args.iter().position(|a| a == "--loop") {
        // The benchmark's target (benches/engine.rs, without physics).
        let n: usize = args[i + 1].parse().unwrap();
        // `--physics`: calibrated as `POST /sessions/{id}/jobs` does, with
        // the physics analysis; `--q a,b,..`: another target (the load
        // test's is 10,-20,30,0,40,0).
        let comp = calibrated("er3a_paper_like", args.iter().any(|a| a == "--physics"));
        let q: Vec<f64> = match args.iter().position(|a| a == "--q") {
            Some(k) => args[k + 1].split(',').map(|v| v.parse().unwrap()).collect(),
            None => vec![10.0, 20.0, 30.0, 40.0, 50.0, 60.0],
        };
        let t = joints(&q);
        let orientation = args.iter().any(|a| a == "--orientation");
        let mut iterations = 0;
        for _ in 0..n {
            iterations +=
                std::hint::black_box(comp.compensate(std::hint::black_box(&t), orientation))
                    .iterations;
        }
        println!("{n} solves, {iterations} iterations");
        return;
    }
    let ur10 = robot("real_ur10_ipa_random");
    let mut ur10_cal = ur10.clone();
    let mut rng = Rng::new(10);
    for j in &mut ur10_cal.joints {
        j.a_mm += rng.normal();
        j.d_mm += rng.normal();
        j.alpha_deg += 0.05 * rng.normal();
        j.theta_offset_deg += 0.05 * rng.normal();
    }
    let mut ur10_tool = ur10_cal.clone();
    ur10_tool.tool_point_mm[2] -= 16.0;
    ur10_tool.tool_point_mm[1] += 0.3;
    let positioner = robot("real_positioner2ax_rosi");
    let mut positioner_cal = positioner.clone();
    positioner_cal.tool_point_mm[0] += 10.0;
    let arms: Vec<(&str, Robot, Compensator)> = vec![
        (
            "er3a",
            robot("er3a_paper_like"),
            Compensator::new(&robot("er3a_paper_like"), &truth("er3a_paper_like")).unwrap(),
        ),
        (
            "ur5",
            robot("ur5_geometric"),
            Compensator::new(&robot("ur5_geometric"), &truth("ur5_geometric")).unwrap(),
        ),
        (
            "ur10",
            ur10.clone(),
            Compensator::new(&ur10, &ur10_cal).unwrap(),
        ),
        ("ur10_tool16", ur10.clone(), {
            let mut c = Compensator::new(&ur10, &ur10_tool).unwrap();
            c.max_joint_change_deg = 360.0;
            c
        }),
        (
            "er3a_compliance",
            robot("er3a_compliance_j2"),
            calibrated("er3a_compliance_j2", true),
        ),
        (
            "er3a_calibrated",
            robot("er3a_paper_like"),
            calibrated("er3a_paper_like", true),
        ),
        (
            "positioner",
            positioner.clone(),
            Compensator::new(&positioner, &positioner_cal).unwrap(),
        ),
    ];
    let mut rng = Rng::new(7);
    for (name, robot, comp) in &arms {
        let mut targets: Vec<Vec<f64>> = (0..300)
            .map(|_| {
                robot
                    .joints
                    .iter()
                    .map(|j| rng.range(j.q_min_deg.max(-180.0), j.q_max_deg.min(180.0)))
                    .collect()
            })
            .collect();
        if name.starts_with("ur10") {
            targets.extend(
                [
                    [-90.0, -90.0, 0.0, -90.0, 0.0, 0.0],
                    [-90.0, -90.0, 10.0, -90.0, 0.0, 0.0],
                    [-90.0, -90.0, 30.0, -90.0, 0.0, 0.0],
                    [0.0, -90.0, 0.0, 0.0, 0.0, 0.0],
                    [0.0; 6],
                ]
                .map(|q| q.to_vec()),
            );
        }
        for (i, q) in targets.iter().enumerate() {
            for orientation in [false, true] {
                let c = comp.compensate(&joints(q), orientation);
                let qs: Vec<String> = c.q_deg.iter().flatten().map(|v| format!("{v:e}")).collect();
                println!(
                    "{name} {i} {orientation} {:?} {} {} [{}]",
                    c.status,
                    c.iterations,
                    c.residual_mm.map_or("-".into(), |r| format!("{r:e}")),
                    qs.join(",")
                );
            }
        }
    }
}
