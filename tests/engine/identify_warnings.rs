//! The report's `warnings`: joint angles that look like radians in the
//! `q*_deg` columns (the whole file, or single poses) are warned about and
//! the data is still identified; degrees are not, including a positioner
//! or an arm that really moves only a few degrees and a home pose among
//! large moves.

use crate::common;

use drawcal::identify::warnings::input_warnings;
use drawcal::identify::{IdentifyOptions, NoProgress, Observations};
use drawcal::kinematics::Params;
use drawcal::kinematics::chain::{Chain, OutputFrame};
use drawcal::model::{Dataset, Measurement, PoseRecord, Rig, Robot};
use drawcal::pipeline;
use drawcal::report::Report;
use drawcal::rng::Rng;

fn no_physics() -> IdentifyOptions {
    IdentifyOptions::default()
}

fn warnings_of(robot: &Robot, rig: &Rig, data: &Dataset) -> Vec<String> {
    let session = Observations::new(robot, rig, data, &no_physics()).unwrap();
    input_warnings(&session)
}

/// A dataset's poses.csv with the joint columns of the given data rows
/// (0-based; every row when `None`) rewritten in radians.
fn in_radians(name: &str, rows: Option<&[usize]>) -> String {
    let text = std::fs::read_to_string(common::dir(name).join("poses.csv")).unwrap();
    common::q_columns_in_radians(&text, rows)
}

/// A file in radians is not calibrated unless forced: the error says why
/// and how to insist; forced, the report carries the warning.
#[test]
fn a_file_in_radians_is_refused_and_forced_with_a_warning() {
    let (robot, rig, _) = common::load("er3a_paper_like");
    let csv = in_radians("er3a_paper_like", None);
    let data = Dataset::from_csv(csv.as_bytes(), &robot, &rig).unwrap();
    let e = pipeline::calibrate(&robot, &rig, &data, &Default::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("not calibrated: the joint angles look like radians") && e.contains("--force"),
        "{e}"
    );
    let forced = pipeline::Options {
        physics: false,
        force: true,
        ..Default::default()
    };
    let report = pipeline::calibrate(&robot, &rig, &data, &forced, &NoProgress).unwrap();
    assert_eq!(report.warnings.len(), 1, "{:?}", report.warnings);
    let w = &report.warnings[0];
    assert!(
        w.starts_with("the joint angles look like radians, not degrees")
            && w.contains("±2π")
            && w.contains("deg = rad × 180/π"),
        "{w}"
    );
    // The report carries them as a list of strings; a report written
    // before the field existed still reads, with no warnings.
    let mut json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["warnings"][0], w.as_str());
    json.as_object_mut().unwrap().remove("warnings");
    let old: Report = serde_json::from_value(json).unwrap();
    assert!(old.warnings.is_empty());

    // The same poses in degrees: no warning, and the list is there, empty.
    let (_, _, data) = common::load("er3a_paper_like");
    let report =
        common::calibrate_geometric(&robot, &rig, &data, &no_physics(), &NoProgress).unwrap();
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    assert_eq!(
        serde_json::to_value(&report).unwrap()["warnings"],
        serde_json::json!([])
    );
}

#[test]
fn the_shared_datasets_in_degrees_are_not_warned_about() {
    for name in [
        "er3a_paper_like",
        "er3a_compliance_j2",
        "ur5_geometric",
        "real_positioner2ax_rosi",
        "real_ur10_ipa_random",
        "real_ur10_ipa_grid",
    ] {
        let (robot, rig, data) = common::load(name);
        let w = warnings_of(&robot, &rig, &data);
        assert!(w.is_empty(), "{name}: {w:?}");
    }
}

#[test]
fn single_poses_in_radians_are_named() {
    let (robot, rig, _) = common::load("er3a_paper_like");
    let csv = in_radians("er3a_paper_like", Some(&[6]));
    let data = Dataset::from_csv(csv.as_bytes(), &robot, &rig).unwrap();
    let w = warnings_of(&robot, &rig, &data);
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].starts_with("pose 7 (row 7 after the header): its joint angles look like radians"),
        "{}",
        w[0]
    );
    // Many: five described, the rest listed by id.
    let rows: Vec<usize> = (0..8).collect();
    let csv = in_radians("er3a_paper_like", Some(&rows));
    let data = Dataset::from_csv(csv.as_bytes(), &robot, &rig).unwrap();
    let w = warnings_of(&robot, &rig, &data);
    assert_eq!(w.len(), 6, "{w:?}");
    assert_eq!(
        w[5],
        "3 more poses' joint angles look like radians in the same way: 6, 7, 8"
    );
}

/// Point measurements of T from the nominal model at the given true joint
/// angles (rad), with 0.05 mm noise; `recorded` maps a true angle to the
/// number written in the q*_deg column.
fn simulated(
    robot: &Robot,
    rig: &Rig,
    true_q_rad: &[Vec<f64>],
    recorded: impl Fn(f64) -> f64,
) -> Dataset {
    let chain = Chain::new(robot.convention, robot.dof(), 0);
    let base = rig.base_in_rig.unwrap();
    let nominal = Params::nominal(robot, &base, rig, 0);
    let mut rng = Rng::new(11);
    let poses = true_q_rad
        .iter()
        .enumerate()
        .map(|(i, q)| {
            let t = chain.point(&nominal.values, q, OutputFrame::Rig).1;
            let noise = nalgebra::Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.05;
            PoseRecord {
                id: format!("p{}", i + 1),
                q_rad: q.iter().map(|&v| recorded(v).to_radians()).collect(),
                measurement: Measurement::Point(t + noise),
                time_s: None,
                temp_c: None,
                payload_kg: None,
                split: None,
            }
        })
        .collect();
    Dataset {
        poses,
        n_strings: 0,
        ignored_columns: vec![],
    }
}

/// `n` random poses with every joint within ±`half_range_deg` (and its
/// limits), in radians.
fn random_poses(robot: &Robot, n: usize, half_range_deg: f64, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            robot
                .joints
                .iter()
                .map(|j| {
                    rng.range(
                        j.q_min_deg.max(-half_range_deg),
                        j.q_max_deg.min(half_range_deg),
                    )
                    .to_radians()
                })
                .collect()
        })
        .collect()
}

#[test]
fn small_moves_in_degrees_are_not_mistaken_for_radians() {
    let (positioner, tracker, _) = common::load("real_positioner2ax_rosi");
    let (arm, _, _) = common::load("er3a_paper_like");
    for (name, robot) in [("positioner", &positioner), ("arm", &arm)] {
        // Every joint within ±4 deg: all numbers within ±2π, and right.
        let small = random_poses(robot, 40, 4.0, 3);
        let data = simulated(robot, &tracker, &small, f64::to_degrees);
        let w = warnings_of(robot, &tracker, &data);
        assert!(w.is_empty(), "{name}, a few degrees: {w:?}");
        // Large moves written in radians: warned.
        let large = random_poses(robot, 40, 150.0, 4);
        let data = simulated(robot, &tracker, &large, |q| q);
        let w = warnings_of(robot, &tracker, &data);
        assert_eq!(w.len(), 1, "{name}, radians: {w:?}");
        assert!(w[0].contains("look like radians"), "{}", w[0]);
        // Large moves in degrees with a few home-like poses (every joint
        // within ±4 deg) among them: nothing; one large pose in radians
        // among them: that pose only.
        let mut mixed = random_poses(robot, 40, 150.0, 5);
        mixed.extend(random_poses(robot, 3, 4.0, 6));
        let data = simulated(robot, &tracker, &mixed, f64::to_degrees);
        let w = warnings_of(robot, &tracker, &data);
        assert!(w.is_empty(), "{name}, home poses: {w:?}");
        let mut data = simulated(robot, &tracker, &mixed, f64::to_degrees);
        data.poses[10].q_rad = mixed[10].iter().map(|q| q.to_radians()).collect();
        let w = warnings_of(robot, &tracker, &data);
        assert_eq!(w.len(), 1, "{name}, one row: {w:?}");
        assert!(
            w[0].starts_with("pose p11 (row 11 after the header)"),
            "{}",
            w[0]
        );
    }
}
