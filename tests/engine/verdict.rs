//! "Is my result good?": the verdict a report carries, and the extra poses
//! it suggests when the recorded ones leave parameters undetermined.
//! Judged end to end: the suggested poses, recorded (simulated with the
//! same truth) beside the session's, determine what was undetermined.

use drawcal::export::{self, ExportFormat};
use drawcal::identify::NoProgress;
use drawcal::model::{Rig, Robot};
use drawcal::physics::simulate::{self, GivenPose, Simulated, Spec, SpecFiles};
use drawcal::plan::{Scene, Workspace};
use drawcal::report::verdict::{Level, Verdict};
use drawcal::report::{FixedReason, Report};
use drawcal::rng::Rng;

fn preset(name: &str) -> (Robot, Rig) {
    let (r, g, _) = simulate::preset(name).unwrap();
    (r, g)
}

/// Random valid poses (the planner's own test of validity).
fn random_valid(robot: &Robot, rig: &Rig, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let ws = Workspace::default();
    let scene = Scene::new(robot, rig, &ws).unwrap();
    let (c, _, _) = scene.sample(n, 100 * n, &mut Rng::new(seed));
    assert_eq!(c.len(), n);
    c.into_iter().map(|c| c.q_deg).collect()
}

/// Record `train` and `test` (in that order) on the preset with `seed`'s
/// truth.
fn record(name: &str, seed: u64, train: &[Vec<f64>], test: &[Vec<f64>]) -> Simulated {
    let spec: Spec =
        serde_json::from_value(serde_json::json!({ "robot": name, "seed": seed })).unwrap();
    let poses = train
        .iter()
        .map(|q| (q, false))
        .chain(test.iter().map(|q| (q, true)))
        .enumerate()
        .map(|(i, (q, test))| GivenPose {
            id: format!("p{}", i + 1),
            q_deg: q.clone(),
            test: Some(test),
            payload_kg: None,
        })
        .collect();
    simulate::generate_with(
        &spec,
        SpecFiles {
            poses: Some(poses),
            ..Default::default()
        },
    )
    .unwrap()
}

fn calibrate(sim: &Simulated) -> Report {
    let opts = drawcal::pipeline::Options {
        physics: false,
        ..Default::default()
    };
    drawcal::pipeline::calibrate(&sim.robot, &sim.rig, &sim.dataset, &opts, &NoProgress).unwrap()
}

/// The parameters held at nominal, not by request.
fn held(r: &Report) -> Vec<String> {
    r.identifiability
        .fixed
        .iter()
        .filter(|f| f.reason != FixedReason::Requested)
        .map(|f| f.name.clone())
        .collect()
}

#[test]
fn extra_poses_determine_what_a_short_session_left_undetermined() {
    let (robot, rig) = preset("er3a");
    // 30 poses, but joint 4 never moves: what only its turning shows is
    // held at nominal.
    let mut train = random_valid(&robot, &rig, 30, 7);
    for q in &mut train {
        q[3] = 10.0;
    }
    let test = random_valid(&robot, &rig, 10, 8);
    let short = calibrate(&record("er3a", 3, &train, &test));
    let before = held(&short);
    let x = short.extra_poses.as_ref().expect("extra poses suggested");
    assert!(
        !x.poses.is_empty() && x.poses.len() <= 20,
        "{}",
        x.poses.len()
    );
    // Every parameter aimed at was held for want of data, and the extra
    // poses are predicted to do better on it than the recorded ones.
    for p in &x.parameters {
        assert!(before.contains(&p.name), "{} not held: {before:?}", p.name);
        let after = p.sigma_with_extra.expect("determined with the extra poses");
        assert!(
            p.sigma_recorded.is_none_or(|s| after < s),
            "{}: {:?} -> {after}",
            p.name,
            p.sigma_recorded
        );
    }
    // Within the joint limits.
    for p in &x.poses {
        for (j, q) in p.q_deg.iter().enumerate() {
            let (lo, hi) = (robot.joints[j].q_min_deg, robot.joints[j].q_max_deg);
            assert!((lo..=hi).contains(q), "{} q{}: {q}", p.id, j + 1);
        }
    }
    // The verdict says so: amber, naming the export.
    let v = short
        .verdict
        .clone()
        .expect("the report carries its verdict");
    assert_eq!(v, Verdict::of(&short));
    assert!(v.level >= Level::Amber, "{v:?}");
    assert!(
        v.reasons
            .iter()
            .any(|r| r.contains("--format extra-targets")),
        "{v:?}"
    );
    // The export writes them as targets.csv, and the HTML report shows
    // the verdict and the poses.
    let csv = export::export(&short, ExportFormat::ExtraTargets).unwrap();
    let targets = drawcal::model::targets_from_csv(csv.as_bytes(), robot.dof()).unwrap();
    assert_eq!(targets.len(), x.poses.len());
    assert_eq!(targets[0].target, "e01");
    let html = drawcal::report_html::render(&short, "t", None);
    assert!(
        html.contains(r#"id="verdict" data-level=""#),
        "no verdict section"
    );
    assert!(html.contains(r#"id="extra-targets""#) && html.contains("<td>e01</td>"));
    // Recorded as well, with the same truth, they determine the parameters
    // aimed at (those predicted to a third of their tolerance).
    let mut more = train.clone();
    more.extend(x.poses.iter().map(|p| p.q_deg.clone()));
    let longer = calibrate(&record("er3a", 3, &more, &test));
    let still = held(&longer);
    for p in &x.parameters {
        if p.sigma_with_extra.is_some_and(|s| s <= p.tolerance / 3.0) {
            assert!(!still.contains(&p.name), "{} still held: {still:?}", p.name);
        }
    }
    // Measured 2026-12-04: 1.82 -> 0.044 mm, red -> green, with 2 poses.
    assert_eq!(longer.verdict.as_ref().map(|v| v.level), Some(Level::Green));
    assert!(
        longer.stats.test.after.rms_mm <= 0.1 * short.stats.test.after.rms_mm,
        "{} -> {}",
        short.stats.test.after.rms_mm,
        longer.stats.test.after.rms_mm
    );
}

/// A session with enough poses suggests none, and its verdict reads back
/// from the report as written.
#[test]
fn enough_poses_suggest_none_and_the_verdict_reads_back() {
    let (robot, rig) = preset("er3a");
    let train = random_valid(&robot, &rig, 40, 11);
    let test = random_valid(&robot, &rig, 15, 12);
    let r = calibrate(&record("er3a", 4, &train, &test));
    assert!(
        r.extra_poses.as_ref().is_none_or(|x| x.poses.is_empty()),
        "{:?}",
        r.extra_poses
    );
    let back = Report::from_json(&serde_json::to_string(&r).unwrap()).unwrap();
    assert_eq!(back.verdict, r.verdict);
    assert_eq!(Verdict::read(&back), Verdict::of(&r));
    assert_eq!(r.verdict.unwrap().level, Level::Green);
}

/// Few poses: cross-validation frees a smaller set, and the verdict says
/// what it held and that more poses would free it; nothing to export.
#[test]
fn a_reduced_free_set_is_amber_and_says_why() {
    let (robot, rig) = preset("er3a");
    let train = random_valid(&robot, &rig, 11, 7);
    let test = random_valid(&robot, &rig, 10, 8);
    let r = calibrate(&record("er3a", 3, &train, &test));
    let f = r.free_set.as_ref().unwrap();
    assert_eq!(
        (f.how.as_str(), f.chosen != "all"),
        ("cross_validation", true),
        "{f:?}"
    );
    let v = r.verdict.clone().unwrap();
    assert!(v.level >= Level::Amber, "{v:?}");
    assert!(
        v.reasons
            .iter()
            .any(|s| s.contains("a smaller model predicts better")),
        "{v:?}"
    );
    assert!(r.extra_poses.as_ref().is_none_or(|x| x.poses.is_empty()));
    let err = export::export(&r, ExportFormat::ExtraTargets).unwrap_err();
    assert!(err.to_string().contains("format"), "{err}");
}
