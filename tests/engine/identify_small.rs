//! Small recordings: every prefix of the shared datasets from one pose up,
//! identified with the default options (the paper's method beside, the
//! physics analysis after). Each gives a report or a clear error, never a
//! panic, and a report reads back (as `compensate` and `report` read it).
//! Found by hand: with fewer train rows than the paper method's columns
//! (fewer than about 10 train poses of a 6-axis arm) its pseudo-inverse
//! sliced past the end of a matrix and the CLI panicked; found by a fuzzing
//! run: with 10-11 poses the covariance is singular, every sigma unknown,
//! written as null and refused when read back.

use crate::common;

use drawcal::compensate::Compensator;
use drawcal::identify::{IdentifyOptions, NoProgress};
use drawcal::model::Dataset;
use drawcal::pipeline::{self, calibrate};
use drawcal::report::Report;

#[test]
fn every_prefix_identifies_or_says_why() {
    for name in [
        "er3a_paper_like",
        "ur5_geometric",
        "real_positioner2ax_rosi",
        "er3a_compliance_j2",
    ] {
        let (robot, rig, _) = common::load(name);
        let csv = std::fs::read_to_string(common::dir(name).join("poses.csv")).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        let mut reports = 0;
        // With the file's split, and with the tool choosing its own.
        // Up to 24 poses one by one, then a few more.
        let sizes = (1..=24).chain([30, 36, 45]).filter(|&n| n < lines.len());
        let prefixes = sizes.flat_map(|n| {
            let prefix = lines[..=n].join("\n");
            [(n, common::drop_columns(&prefix, &["split"])), (n, prefix)]
        });
        for (n, prefix) in prefixes {
            let Ok(data) = Dataset::from_csv(prefix.as_bytes(), &robot, &rig) else {
                continue;
            };
            // Also with nothing held out: no test statistics at all.
            let no_test = IdentifyOptions {
                holdout_fraction: 0.0,
                ..IdentifyOptions::default()
            };
            for opts in [IdentifyOptions::default(), no_test].map(pipeline::Options::from) {
                match calibrate(&robot, &rig, &data, &opts, &NoProgress) {
                    Ok(rep) => {
                        reports += 1;
                        assert!(rep.stats.train.after.rms_mm.is_finite(), "{name} n={n}");
                        // What identify writes, compensate and report read
                        // back (an unknown sigma is written as null).
                        let text = serde_json::to_string(&rep).unwrap();
                        let back: Report = serde_json::from_str(&text)
                            .unwrap_or_else(|e| panic!("{name} n={n}: {e}"));
                        Compensator::from_report(&back)
                            .unwrap_or_else(|e| panic!("{name} n={n}: {e}"));
                    }
                    Err(e) => assert!(!e.to_string().is_empty(), "{name} n={n}"),
                }
            }
        }
        assert!(reports > 0, "{name}: no prefix calibrated");
    }
}

/// A split column that marks every pose train is not silently ignored: the
/// hold-out the tool chooses instead says why.
#[test]
fn a_split_without_test_poses_says_so() {
    let (robot, rig, _) = common::load("er3a_paper_like");
    let csv = std::fs::read_to_string(common::dir("er3a_paper_like").join("poses.csv")).unwrap();
    let all_train = csv.replace(",test", ",train");
    let data = Dataset::from_csv(all_train.as_bytes(), &robot, &rig).unwrap();
    let rep = common::identify_default(&robot, &rig, &data);
    assert!(
        rep.split_source
            .starts_with("chosen: the split column marks no pose test; 15 of 50 poses held out"),
        "{}",
        rep.split_source
    );
    assert_eq!(rep.stats.test.n, 15);
}

/// Too few distinct train poses for the parameters they identify: with no
/// more equations (3 per pose) than parameters it is an error that says how
/// many are needed, not a fit through the readings; with fewer poses than
/// parameters but more equations, a warning. 20 and 8 train poses of a
/// 6-axis arm (27 parameters), 50 recordings of one pose, and 30 poses with
/// the hold-out chosen by the tool (21 train).
#[test]
fn too_few_poses_for_the_parameters() {
    let (robot, rig, _) = common::load("er3a_paper_like");
    let csv = std::fs::read_to_string(common::dir("er3a_paper_like").join("poses.csv")).unwrap();
    let lines: Vec<String> = csv.lines().map(String::from).collect();
    let split = lines[0].split(',').position(|h| h == "split").unwrap();
    // The first `n` rows train, the rest test.
    let with_train = |n: usize| {
        let mut out = vec![lines[0].clone()];
        for (i, line) in lines.iter().enumerate().skip(1) {
            let mut cells: Vec<&str> = line.split(',').collect();
            cells[split] = if i <= n { "train" } else { "test" };
            out.push(cells.join(","));
        }
        out.join("\n")
    };
    let run = |csv: String| {
        let data = Dataset::from_csv(csv.as_bytes(), &robot, &rig).unwrap();
        calibrate(
            &robot,
            &rig,
            &data,
            &pipeline::Options::default(),
            &NoProgress,
        )
    };
    let rep = run(with_train(20)).unwrap();
    assert!(
        rep.warnings
            .iter()
            .any(|w| w.contains("20 usable train poses") && w.contains("27 parameters")),
        "{:?}",
        rep.warnings
    );
    let e = run(with_train(8)).unwrap_err().to_string();
    assert!(
        e.contains("8 usable train poses") && e.contains("record at least"),
        "{e}"
    );
    assert!(!e.contains("--holdout"), "the file's split: {e}");

    // One pose recorded 50 times: readings, not information.
    let first = lines[1].clone();
    let same: Vec<String> = std::iter::once(lines[0].clone())
        .chain((0..50).map(|k| {
            let mut cells: Vec<String> = first.split(',').map(String::from).collect();
            cells[0] = format!("p{k}");
            cells[split] = String::new();
            cells.join(",")
        }))
        .collect();
    let e = run(same.join("\n")).unwrap_err().to_string();
    assert!(e.contains("1 usable train poses"), "{e}");

    // 30 poses, no split: 21 train, a warning that names the hold-out.
    let no_split = common::drop_columns(&lines[..=30].join("\n"), &["split"]);
    let rep = run(no_split).unwrap();
    let w = rep.warnings.join(" ");
    assert!(
        w.contains("21 usable train poses") && w.contains("--holdout 0.3"),
        "{w}"
    );
}
