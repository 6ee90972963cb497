//! Property tests (proptest) of the physics analysis on recordings that are
//! valid but awkward: simulated sessions on every preset with up to two
//! random effects at any size, then reshaped the way real files come:
//! without time or temperature, a temperature that never changes, repeated
//! time stamps, rows reversed or repeated, few poses, no split column or
//! everything in train, a payload column, a string missing. The rule: the
//! whole identification with the analysis answers Ok with finite figures
//! (or a clear error), never panics, and what it accepted compensates.
//!
//! CI runs a few dozen cases; `PROPTEST_CASES=2000 cargo test --release
//! --test engine fuzz_physics` runs a long campaign (see EVAL.md).

use crate::common;

use drawcal::compensate::Compensator;
use drawcal::identify::NoProgress;
use drawcal::model::targets::{Target, TargetKind};
use drawcal::model::{Dataset, Rig};
use drawcal::physics::simulate;
use drawcal::pipeline::evaluate::CATALOGUE;
use drawcal::pipeline::{self, calibrate};
use proptest::prelude::*;

const ROBOTS: [&str; 3] = ["er3a", "ur5", "arm4_mdh"];

/// How the simulated file is reshaped before it is read.
#[derive(Debug, Clone, Copy)]
enum Reshape {
    AsIs,
    NoTime,
    NoTemperature,
    NoTimeNoTemperature,
    ConstantTemperature,
    RepeatedTimes,
    Reversed,
    RowsRepeated,
    NoSplit,
    AllTrain,
    DropLastString,
}

const RESHAPES: [Reshape; 11] = [
    Reshape::AsIs,
    Reshape::NoTime,
    Reshape::NoTemperature,
    Reshape::NoTimeNoTemperature,
    Reshape::ConstantTemperature,
    Reshape::RepeatedTimes,
    Reshape::Reversed,
    Reshape::RowsRepeated,
    Reshape::NoSplit,
    Reshape::AllTrain,
    Reshape::DropLastString,
];

/// The CSV with column `name` removed (if present).
fn drop_column(rows: &mut [Vec<String>], name: &str) {
    if let Some(c) = rows[0].iter().position(|h| h == name) {
        for r in rows.iter_mut() {
            r.remove(c);
        }
    }
}

fn set_column(rows: &mut [Vec<String>], name: &str, f: impl Fn(usize, &str) -> String) {
    if let Some(c) = rows[0].iter().position(|h| h == name) {
        for (i, r) in rows.iter_mut().enumerate().skip(1) {
            r[c] = f(i, &r[c]);
        }
    }
}

fn reshape(sim: &simulate::Simulated, how: Reshape) -> (Rig, String) {
    let mut rows: Vec<Vec<String>> = sim
        .poses_csv
        .lines()
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    let mut rig = sim.rig.clone();
    match how {
        Reshape::AsIs => {}
        Reshape::NoTime => drop_column(&mut rows, "time_s"),
        Reshape::NoTemperature => drop_column(&mut rows, "temp_c"),
        Reshape::NoTimeNoTemperature => {
            drop_column(&mut rows, "time_s");
            drop_column(&mut rows, "temp_c");
        }
        Reshape::ConstantTemperature => set_column(&mut rows, "temp_c", |_, _| "21.5".into()),
        // Pairs of poses stamped with the same second.
        Reshape::RepeatedTimes => {
            let t: Vec<String> = {
                let c = rows[0].iter().position(|h| h == "time_s").unwrap();
                rows.iter().map(|r| r[c].clone()).collect()
            };
            set_column(&mut rows, "time_s", |i, v| {
                if i % 2 == 0 {
                    t[i - 1].clone()
                } else {
                    v.into()
                }
            });
        }
        Reshape::Reversed => rows[1..].reverse(),
        // Every pose measured twice in a row (new ids).
        Reshape::RowsRepeated => {
            let mut out = vec![rows[0].clone()];
            for (k, r) in rows[1..].iter().enumerate() {
                for copy in 0..2 {
                    let mut r = r.clone();
                    r[0] = format!("{}", 2 * k + copy + 1);
                    out.push(r);
                }
            }
            rows = out;
        }
        Reshape::NoSplit => drop_column(&mut rows, "split"),
        Reshape::AllTrain => set_column(&mut rows, "split", |_, _| "train".into()),
        Reshape::DropLastString => {
            let m = rig.anchors_mm.len();
            if m > 3 {
                drop_column(&mut rows, &format!("l{m}_mm"));
                rig.anchors_mm.pop();
                if let Some(names) = rig.anchor_names.as_mut() {
                    names.pop();
                }
            }
        }
    }
    let csv = rows
        .iter()
        .map(|r| r.join(","))
        .collect::<Vec<_>>()
        .join("\n");
    (rig, csv)
}

proptest! {
    #![proptest_config(common::proptest_cases(24))]

    #[test]
    fn awkward_recordings_never_break_the_analysis(
        robot in 0..ROBOTS.len(),
        n_poses in 20usize..110,
        seed in 0u64..1_000_000,
        effects in proptest::collection::vec(
            (0..CATALOGUE.len(), 1usize..7, 1usize..5, 0.0f64..12.0), 0..3),
        payload in any::<bool>(),
        how in 0..RESHAPES.len(),
    ) {
        let robot_name = ROBOTS[robot];
        let n_joints = if robot_name == "arm4_mdh" { 4 } else { 6 };
        let effects: Vec<serde_json::Value> = effects
            .iter()
            .map(|&(e, j, k, size)| serde_json::json!({
                "effect": CATALOGUE[e],
                "joint": 1 + (j - 1) % n_joints,
                "sensor": k,
                "size_x_noise": size,
            }))
            .collect();
        let mut spec = serde_json::json!({
            "robot": robot_name,
            "n_poses": n_poses,
            "seed": seed,
            "effects": effects,
        });
        if payload {
            spec["session"] = serde_json::json!({"payload_kg": [0.0, 7.5]});
        }
        let spec: simulate::Spec = serde_json::from_value(spec).unwrap();
        // Some draws are impossible (an effect that moves nothing on these
        // poses): the simulator says so, which is fine.
        let Ok(sim) = simulate::generate(&spec) else { return Ok(()); };
        let how = RESHAPES[how];
        let (rig, csv) = reshape(&sim, how);
        let Ok(data) = Dataset::from_csv(csv.as_bytes(), &sim.robot, &rig) else {
            return Ok(());
        };
        let report = match calibrate(&sim.robot, &rig, &data, &pipeline::Options::default(), &NoProgress) {
            Ok(r) => r,
            // A clear refusal (e.g. too few poses for the parameters).
            Err(e) => {
                prop_assert!(!e.to_string().is_empty());
                return Ok(());
            }
        };
        let t = &report.stats.test;
        prop_assert!(t.after.rms_mm.is_finite() || t.n == 0, "{how:?}: {:?}", t.after);
        for f in &report.findings {
            prop_assert!(f.magnitude.is_finite(), "{how:?}: {f:?}");
            prop_assert!(
                f.test_rms_before_mm.is_finite() && f.test_rms_after_mm.is_finite(),
                "{how:?}: {f:?}"
            );
        }
        // What was accepted compensates one in-limit joint target.
        let comp = Compensator::from_report(&report).unwrap();
        let q_deg: Vec<f64> = sim
            .robot
            .joints
            .iter()
            .map(|j| 0.5 * (j.q_min_deg + j.q_max_deg) + 0.1 * (j.q_max_deg - j.q_min_deg))
            .collect();
        let out = comp.compensate(
            &Target { target: "t".into(), kind: TargetKind::Joints { q_deg } },
            false,
        );
        if let Some(r) = out.residual_mm {
            prop_assert!(r.is_finite());
        }
    }
}
