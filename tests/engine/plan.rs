//! The pose planner (`drawcal plan`): its poses obey the workspace, and a
//! planned session calibrates better than random poses, judged against
//! the simulator's truth at independent random valid poses.
//!
//! The full comparison of issue 19 (three robots, N = 20, 30, 50, 30
//! sessions each) is `#[ignore]`d; EVAL.md quotes it:
//!
//!     cargo test --release --test engine plan::planned_against_random_sweep -- --ignored --nocapture

use drawcal::identify::NoProgress;
use drawcal::kinematics::chain::{Chain, OutputFrame};
use drawcal::model::{Rig, Robot};
use drawcal::physics::simulate::{self, GivenPose, Spec, SpecFiles};
use drawcal::plan::{self, PlanOptions, Scene, Workspace};
use drawcal::rng::Rng;

/// One session's figures.
#[derive(Debug, Clone, Copy)]
struct Judged {
    /// RMS error of the calibrated model's T against the truth (mm).
    rms_mm: f64,
    /// Largest such error (mm).
    worst_mm: f64,
    /// Held-out RMS as the report states it (located points, mm).
    holdout_mm: f64,
}

/// Simulate `design` (train) plus `check` (test) for the preset with
/// `seed`'s truth, calibrate (geometry only) and judge at `check`.
fn judge(preset: &str, seed: u64, design: &[Vec<f64>], check: &[Vec<f64>]) -> Judged {
    let spec: Spec = serde_json::from_value(serde_json::json!({
        "robot": preset, "seed": seed
    }))
    .unwrap();
    let poses: Vec<GivenPose> = design
        .iter()
        .map(|q| (q, false))
        .chain(check.iter().map(|q| (q, true)))
        .enumerate()
        .map(|(i, (q, test))| GivenPose {
            id: format!("{}", i + 1),
            q_deg: q.clone(),
            test: Some(test),
        })
        .collect();
    let sim = simulate::generate_with(
        &spec,
        SpecFiles {
            poses: Some(poses),
            ..Default::default()
        },
    )
    .unwrap();
    let opts = drawcal::pipeline::Options {
        physics: false,
        ..Default::default()
    };
    let run =
        drawcal::pipeline::run(&sim.robot, &sim.rig, &sim.dataset, &opts, &NoProgress).unwrap();
    let chain = Chain::new(sim.robot.convention, sim.robot.dof(), sim.rig.n_strings());
    let errs: Vec<f64> = (design.len()..design.len() + check.len())
        .map(|i| {
            let q: Vec<f64> = sim.dataset.poses[i].q_rad.clone();
            let t = chain.point(&run.geo.after.values, &q, OutputFrame::Rig).1;
            (t - sim.true_point[i]).norm()
        })
        .collect();
    let report =
        drawcal::pipeline::calibrate(&sim.robot, &sim.rig, &sim.dataset, &opts, &NoProgress)
            .unwrap();
    Judged {
        rms_mm: (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt(),
        worst_mm: errs.iter().cloned().fold(0.0, f64::max),
        holdout_mm: report.stats.test.after.rms_mm,
    }
}

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

struct Comparison {
    planned: Judged,
    random: Judged,
    random_1_5: Judged,
    predicted_holdout_mm: f64,
}

fn compare(name: &str, n: usize, session: u64, candidates: usize) -> Comparison {
    let (robot, rig) = preset(name);
    let mut opts = PlanOptions::new(n);
    opts.seed = 1000 + session;
    opts.candidates = candidates;
    opts.n_check = Some(0);
    let p = plan::plan(&robot, &rig, &opts).unwrap();
    let design: Vec<Vec<f64>> = p.poses.iter().map(|p| p.q_deg.clone()).collect();
    let check = random_valid(&robot, &rig, 200, 5000 + session);
    let random = random_valid(&robot, &rig, (3 * n).div_ceil(2), 9000 + session);
    Comparison {
        planned: judge(name, session, &design, &check),
        random: judge(name, session, &random[..n], &check),
        random_1_5: judge(name, session, &random, &check),
        predicted_holdout_mm: p.report.predicted.holdout_rms_mm,
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn geo_mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x.ln(), n + 1));
    (s / n as f64).exp()
}

#[test]
fn planned_poses_obey_the_workspace_and_beat_random_ones() {
    let (robot, rig) = preset("er3a");
    let mut opts = PlanOptions::new(30);
    opts.candidates = 2000;
    // A table in front of the robot: the arm, the tool and the strings
    // stay out of it (the anchors are at z = 250 mm in the base frame).
    opts.workspace.floor_z_mm = Some(-50.0);
    opts.workspace.keep_out = vec![plan::KeepOut {
        min_mm: [300.0, -300.0, -250.0],
        max_mm: [800.0, 300.0, 50.0],
    }];
    let p = plan::plan(&robot, &rig, &opts).unwrap();
    assert_eq!(p.poses.iter().filter(|p| p.split == "train").count(), 30);
    assert_eq!(p.poses.iter().filter(|p| p.split == "test").count(), 7);
    assert!(
        p.report.rejected.contains_key(&plan::Rejection::KeepOut),
        "{:?}",
        p.report.rejected
    );
    // Every planned pose passes the workspace test again, and no link
    // frame enters the box or goes below the floor.
    let scene = Scene::new(&robot, &rig, &opts.workspace).unwrap();
    let mut jac = scene.chain.new_jacobian();
    let chain = Chain::new(robot.convention, robot.dof(), 0);
    let nominal = drawcal::kinematics::Params::of_robot(&robot);
    for pose in &p.poses {
        assert!(
            scene.check(pose.q_deg.clone(), &mut jac).is_ok(),
            "{pose:?}"
        );
        let q: Vec<f64> = pose.q_deg.iter().map(|v| v.to_radians()).collect();
        for f in chain.link_frames(&nominal.values, &q, OutputFrame::Base) {
            assert!(f.o.z >= -50.0);
            let inside = f.o.x >= 300.0 && f.o.x <= 800.0 && f.o.y >= -300.0 && f.o.y <= 300.0;
            assert!(!(inside && f.o.z <= 50.0), "{pose:?} enters the box");
        }
        for (j, q) in pose.q_deg.iter().enumerate() {
            assert!(*q >= robot.joints[j].q_min_deg && *q <= robot.joints[j].q_max_deg);
        }
    }
    // The prediction says the plan beats random poses, and by N.
    let r = &p.report;
    assert!(
        r.predicted.model_rms_mm < 0.8 * r.random.model_rms_mm,
        "{r:?}"
    );
    let at = |n: usize| r.by_n.iter().find(|b| b.n_poses == n).unwrap().model_rms_mm;
    assert!(at(15) > at(30) && at(30) > at(60), "{:?}", r.by_n);
    // targets.csv reads back as joint targets with their split.
    let csv = p.targets_csv();
    let t = drawcal::model::targets_from_csv(csv.as_bytes(), 6).unwrap();
    assert_eq!(t.len(), 37);
    let split = drawcal::model::target_splits(csv.as_bytes())
        .unwrap()
        .unwrap();
    assert_eq!(split.iter().filter(|s| **s).count(), 7);
}

/// Three sessions of the ER3A at N = 30: planned poses calibrate the model
/// clearly better than random ones, and the prediction is near what is
/// realised. (The sweep below measures the figures.)
#[test]
fn a_planned_er3a_session_beats_random_poses_against_the_truth() {
    let runs: Vec<Comparison> = (1..=3).map(|s| compare("er3a", 30, s, 2000)).collect();
    let ratio = geo_mean(runs.iter().map(|c| c.planned.rms_mm / c.random.rms_mm));
    assert!(ratio < 0.85, "planned / random RMS {ratio}");
    for c in &runs {
        let r = c.predicted_holdout_mm / c.planned.holdout_mm;
        assert!(
            (0.7..1.3).contains(&r),
            "predicted {} realised {}",
            c.predicted_holdout_mm,
            c.planned.holdout_mm
        );
    }
}

#[test]
#[ignore = "the issue's sweep: about ten minutes in release"]
fn planned_against_random_sweep() {
    println!(
        "| robot | N | planned/random RMS | planned/random worst | planned/random(1.5N) RMS | predicted/realised held-out | sessions |"
    );
    println!("|---|---|---|---|---|---|---|");
    let sessions: u64 = std::env::var("PLAN_SWEEP_SESSIONS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(30);
    for name in ["er3a", "ur5", "arm4_mdh"] {
        for n in [20, 30, 50] {
            let runs: Vec<Comparison> = (1..=sessions)
                .map(|s| compare(name, n, s, 10_000))
                .collect();
            let rms = mean(&runs.iter().map(|c| c.planned.rms_mm).collect::<Vec<_>>())
                / mean(&runs.iter().map(|c| c.random.rms_mm).collect::<Vec<_>>());
            let worst = mean(&runs.iter().map(|c| c.planned.worst_mm).collect::<Vec<_>>())
                / mean(&runs.iter().map(|c| c.random.worst_mm).collect::<Vec<_>>());
            let vs15 = mean(&runs.iter().map(|c| c.planned.rms_mm).collect::<Vec<_>>())
                / mean(&runs.iter().map(|c| c.random_1_5.rms_mm).collect::<Vec<_>>());
            let pred = geo_mean(
                runs.iter()
                    .map(|c| c.predicted_holdout_mm / c.planned.holdout_mm),
            );
            let pred_range = runs
                .iter()
                .map(|c| c.predicted_holdout_mm / c.planned.holdout_mm)
                .fold((f64::INFINITY, 0.0f64), |(lo, hi), r| {
                    (lo.min(r), hi.max(r))
                });
            println!(
                "| {name} | {n} | {rms:.3} | {worst:.3} | {vs15:.3} | {pred:.3} ({:.2}-{:.2}) | {} |",
                pred_range.0,
                pred_range.1,
                runs.len()
            );
        }
    }
}
