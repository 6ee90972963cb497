//! The pose planner (`drawcal plan`): its poses obey the workspace, and a
//! planned session calibrates better than random poses, judged against
//! the simulator's truth at independent random valid poses.
//!
//! The full comparison of issue 19 (three robots, N = 20, 30, 50, 30
//! sessions each) is `#[ignore]`d; EVAL.md quotes it:
//!
//!     cargo test --release --test engine plan::planned_against_random_sweep -- --ignored --nocapture
//!
//! It also prints what the error is made of (`print_anatomy`); the
//! anatomy test repeats that for a part of the sweep (`PLAN_SWEEP_ROBOTS`,
//! `PLAN_SWEEP_NS`), with the bound no N poses can beat (`PLAN_BOUND=1`)
//! and other selections (`PLAN_CRITERION=d`, `PLAN_PASSES`,
//! `PLAN_CANDIDATES`).

use drawcal::identify::NoProgress;
use drawcal::kinematics::chain::{Chain, OutputFrame};
use drawcal::model::{Rig, Robot};
use drawcal::physics::simulate::{self, GivenPose, Spec, SpecFiles};
use drawcal::plan::{self, PlanOptions, Scene, Workspace};
use drawcal::report::FixedReason;
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
    /// What the error is made of (see [`Anatomy`]).
    anatomy: Anatomy,
}

/// The calibrated model's error at the check poses split, using the
/// truth: the part no refit of the parameters the identification freed
/// can remove (the floor: held parameters keep their true deviations),
/// and how far the floor falls when each group of held parameters is freed
/// too. RMS over the check poses (mm), by least squares on the model's
/// Jacobian at the calibrated parameters (the errors are small: linear).
#[derive(Debug, Clone, Copy, Default)]
struct Anatomy {
    /// Error left after the best refit of the freed parameters.
    floor_mm: f64,
    /// The same with the parameters held by the free-set choice freed.
    floor_freeset_freed_mm: f64,
    /// The same with those held as undetermined freed.
    floor_undetermined_freed_mm: f64,
    /// The same with every held joint parameter freed.
    floor_all_freed_mm: f64,
    /// Parameters held by the free-set choice.
    n_freeset: usize,
    /// Parameters held as undetermined.
    n_undetermined: usize,
    /// Parameters freed.
    n_free: usize,
    /// Error of the same calibration (the same parameters held) from
    /// noise-free readings: the floor plus what the poses' weighting of it
    /// adds (the bias), without the noise's part.
    bias_mm: f64,
}

/// RMS over poses of what least squares on `cols` of the point Jacobian at
/// `values` leaves of the errors `err` (per pose).
fn residual_rms(
    chain: &Chain,
    values: &[f64],
    qs: &[Vec<f64>],
    err: &[nalgebra::Vector3<f64>],
    cols: &[usize],
) -> f64 {
    let mut jac = chain.new_jacobian();
    let mut a = nalgebra::DMatrix::zeros(3 * qs.len(), cols.len());
    let mut b = nalgebra::DVector::zeros(3 * qs.len());
    for (r, (q, e)) in qs.iter().zip(err).enumerate() {
        chain.point_jacobian(values, q, OutputFrame::Rig, &mut jac);
        for c in 0..3 {
            for (k, &p) in cols.iter().enumerate() {
                a[(3 * r + c, k)] = jac.d_params[p][c];
            }
            b[3 * r + c] = e[c];
        }
    }
    // Column-scaled: angles (rad) and lengths (mm) differ by 1e3.
    let scale: Vec<f64> = (0..cols.len())
        .map(|k| a.column(k).norm().max(1e-300))
        .collect();
    for (k, s) in scale.iter().enumerate() {
        a.column_mut(k).unscale_mut(*s);
    }
    let x = a.clone().svd(true, true).solve(&b, 1e-9).unwrap();
    ((b - a * x).norm_squared() / qs.len() as f64).sqrt()
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
            payload_kg: None,
        })
        .collect();
    let sim = simulate::generate_with(
        &spec,
        SpecFiles {
            poses: Some(poses.clone()),
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
    let anatomy = {
        let l = chain.layout;
        let values = &run.geo.after.values;
        let qs: Vec<Vec<f64>> = (design.len()..design.len() + check.len())
            .map(|i| sim.dataset.poses[i].q_rad.clone())
            .collect();
        let err: Vec<nalgebra::Vector3<f64>> = (design.len()..design.len() + check.len())
            .zip(&qs)
            .map(|(i, q)| sim.true_point[i] - chain.point(values, q, OutputFrame::Rig).1)
            .collect();
        let sel = &run.geo.selection;
        let free: Vec<usize> = sel.free.iter().copied().filter(|&k| k < l.len()).collect();
        let index = |name: &str| (0..l.len()).find(|&k| l.name(k) == name);
        let held = |pick: &dyn Fn(FixedReason) -> bool| -> Vec<usize> {
            sel.fixed
                .iter()
                .filter(|f| pick(f.reason))
                .filter_map(|f| index(&f.name))
                .collect()
        };
        let with = |extra: Vec<usize>| {
            let mut c = free.clone();
            c.extend(extra);
            residual_rms(&chain, values, &qs, &err, &c)
        };
        let bias_mm = {
            let spec: Spec = serde_json::from_value(serde_json::json!({
                "robot": preset, "seed": seed,
                "noise": {"sigma_mm": 0.0, "resolution_mm": 0.0}
            }))
            .unwrap();
            let exact = simulate::generate_with(
                &spec,
                SpecFiles {
                    poses: Some(poses.clone()),
                    ..Default::default()
                },
            )
            .unwrap();
            let mut o = opts.clone();
            o.identify.free_set = drawcal::identify::freeset::FreeSet::All;
            o.identify.hold = sel
                .fixed
                .iter()
                .filter(|f| matches!(f.reason, FixedReason::FreeSet | FixedReason::Undetermined))
                .map(|f| f.name.clone())
                .collect();
            let r =
                drawcal::pipeline::run(&exact.robot, &exact.rig, &exact.dataset, &o, &NoProgress)
                    .unwrap();
            let sq: f64 = (design.len()..design.len() + check.len())
                .zip(&qs)
                .map(|(i, q)| {
                    (chain.point(&r.geo.after.values, q, OutputFrame::Rig).1 - exact.true_point[i])
                        .norm_squared()
                })
                .sum();
            (sq / check.len() as f64).sqrt()
        };
        if std::env::var("PLAN_VERBOSE").is_ok() {
            let names: Vec<String> = sel
                .fixed
                .iter()
                .map(|f| format!("{} ({:?})", f.name, f.reason))
                .collect();
            println!("{preset} seed {seed} N {}: held {names:?}", design.len());
        }
        let fs = held(&|r| r == FixedReason::FreeSet);
        let und = held(&|r| r == FixedReason::Undetermined);
        Anatomy {
            floor_mm: with(vec![]),
            floor_freeset_freed_mm: with(fs.clone()),
            floor_undetermined_freed_mm: with(und.clone()),
            floor_all_freed_mm: with(held(&|_| true)),
            n_freeset: fs.len(),
            n_undetermined: und.len(),
            n_free: free.len(),
            bias_mm,
        }
    };
    Judged {
        anatomy,
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
    /// The plan's predicted model RMS (mm) for its poses and for random ones.
    predicted_model_mm: f64,
    predicted_random_model_mm: f64,
    /// The best any N of the plan's candidates could do (`PLAN_BOUND`).
    bound: Option<plan::DesignBound>,
}

fn compare(name: &str, n: usize, session: u64, candidates: usize) -> Comparison {
    compare_tuned(name, n, session, candidates, &plan::Tuning::default())
}

fn compare_tuned(
    name: &str,
    n: usize,
    session: u64,
    candidates: usize,
    tuning: &plan::Tuning,
) -> Comparison {
    let (robot, rig) = preset(name);
    let mut opts = PlanOptions::new(n);
    opts.seed = 1000 + session;
    opts.candidates = candidates;
    opts.n_check = Some(0);
    let (p, bound) = if std::env::var("PLAN_BOUND").is_ok() {
        let (p, b) = plan::plan_with_bound(&robot, &rig, &opts, tuning).unwrap();
        (p, Some(b))
    } else {
        (plan::plan_tuned(&robot, &rig, &opts, tuning).unwrap(), None)
    };
    let design: Vec<Vec<f64>> = p.poses.iter().map(|p| p.q_deg.clone()).collect();
    let check = random_valid(&robot, &rig, 200, 5000 + session);
    let random = random_valid(&robot, &rig, (3 * n).div_ceil(2), 9000 + session);
    Comparison {
        planned: judge(name, session, &design, &check),
        random: judge(name, session, &random[..n], &check),
        random_1_5: judge(name, session, &random, &check),
        predicted_holdout_mm: p.report.predicted.holdout_rms_mm,
        predicted_model_mm: p.report.predicted.model_rms_mm,
        predicted_random_model_mm: p.report.random.model_rms_mm,
        bound,
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// `mean(a) / mean(b)` over paired sessions and its standard error (delta
/// method: the sessions' scatter of `a - r b`).
fn ratio_of_means(a: &[f64], b: &[f64]) -> (f64, f64) {
    let n = a.len() as f64;
    let r = mean(a) / mean(b);
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - r * y).collect();
    let var = d.iter().map(|v| v * v).sum::<f64>() / (n - 1.0).max(1.0);
    (r, (var / n).sqrt() / mean(b))
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
#[ignore = "the issue's sweep: five to thirteen minutes in release on the shared machine"]
fn planned_against_random_sweep() {
    println!(
        "| robot | N | planned/random RMS | planned/random worst | planned/random(1.5N) RMS | predicted/realised held-out | sessions |"
    );
    println!("|---|---|---|---|---|---|---|");
    // Each ratio is followed by its standard error over the sessions.
    let sessions: u64 = std::env::var("PLAN_SWEEP_SESSIONS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(30);
    let mut cells = Vec::new();
    for (name, n) in sweep_cells() {
        {
            let runs: Vec<Comparison> = (1..=sessions)
                .map(|s| compare(name, n, s, 10_000))
                .collect();
            let of = |f: &dyn Fn(&Comparison) -> f64| runs.iter().map(f).collect::<Vec<_>>();
            let (rms, rms_se) =
                ratio_of_means(&of(&|c| c.planned.rms_mm), &of(&|c| c.random.rms_mm));
            let (worst, worst_se) =
                ratio_of_means(&of(&|c| c.planned.worst_mm), &of(&|c| c.random.worst_mm));
            let (vs15, vs15_se) =
                ratio_of_means(&of(&|c| c.planned.rms_mm), &of(&|c| c.random_1_5.rms_mm));
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
                "| {name} | {n} | {rms:.3} ± {rms_se:.3} | {worst:.3} ± {worst_se:.3} | {vs15:.3} ± {vs15_se:.3} | {pred:.3} ({:.2}-{:.2}) | {} |",
                pred_range.0,
                pred_range.1,
                runs.len()
            );
            cells.push((name, n, runs));
        }
    }
    // Why (see `planned_against_random_anatomy`).
    println!("\n{ANATOMY_HEADER}");
    for (name, n, runs) in &cells {
        print_anatomy(name, *n, runs);
    }
}

/// The sweep's cells: every robot and N, or those `PLAN_SWEEP_ROBOTS`
/// (comma-separated) and `PLAN_SWEEP_NS` name (for iterating on a part).
fn sweep_cells() -> Vec<(&'static str, usize)> {
    let robots: Vec<&'static str> = match std::env::var("PLAN_SWEEP_ROBOTS") {
        Ok(s) => ["er3a", "ur5", "arm4_mdh"]
            .into_iter()
            .filter(|r| s.split(',').any(|x| x == *r))
            .collect(),
        Err(_) => vec!["er3a", "ur5", "arm4_mdh"],
    };
    let ns: Vec<usize> = match std::env::var("PLAN_SWEEP_NS") {
        Ok(s) => s.split(',').filter_map(|x| x.parse().ok()).collect(),
        Err(_) => vec![20, 30, 50],
    };
    robots
        .into_iter()
        .flat_map(|r| ns.iter().map(move |&n| (r, n)))
        .collect()
}

/// Why the planned poses' advantage shrinks with N: per cell, the RMS
/// error against the truth, the floor no refit of the freed parameters
/// removes (held parameters keep their true deviations) and the floor with
/// each group of held parameters freed too, for the planned and the random
/// poses (root mean squares over the sessions, mm), with the mean number
/// of parameters held by the free-set choice and as undetermined.
#[test]
#[ignore = "a diagnosis of the sweep, printed"]
fn planned_against_random_anatomy() {
    let sessions: u64 = std::env::var("PLAN_SWEEP_SESSIONS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(8);
    let mut tuning = plan::Tuning::default();
    if std::env::var("PLAN_CRITERION").as_deref() == Ok("d") {
        tuning.criterion = plan::design::Criterion::DOptimal;
    }
    if let Some(p) = std::env::var("PLAN_PASSES")
        .ok()
        .and_then(|s| s.parse().ok())
    {
        tuning.exchange_passes = p;
    }
    let candidates: usize = std::env::var("PLAN_CANDIDATES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10_000);
    println!("{tuning:?}, {candidates} candidates, {sessions} sessions");
    println!("{ANATOMY_HEADER}");
    for (name, n) in sweep_cells() {
        let runs: Vec<Comparison> = (1..=sessions)
            .map(|s| compare_tuned(name, n, s, candidates, &tuning))
            .collect();
        let ratio = |f: &dyn Fn(&Comparison) -> f64, g: &dyn Fn(&Comparison) -> f64| {
            mean(&runs.iter().map(f).collect::<Vec<_>>())
                / mean(&runs.iter().map(g).collect::<Vec<_>>())
        };
        println!(
            "| {name} | {n} | ratios: RMS {:.3}, worst {:.3}, vs 1.5N {:.3} |",
            ratio(&|c| c.planned.rms_mm, &|c| c.random.rms_mm),
            ratio(&|c| c.planned.worst_mm, &|c| c.random.worst_mm),
            ratio(&|c| c.planned.rms_mm, &|c| c.random_1_5.rms_mm),
        );
        print_anatomy(name, n, &runs);
    }
}

const ANATOMY_HEADER: &str = "| robot | N | design | RMS | bias (noise-free) | floor | floor, free-set held freed | floor, undetermined freed | floor, all held freed | held by free set | held undetermined | free | predicted model RMS |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|";

/// A cell's rows of the anatomy (root mean squares over the sessions, mm;
/// counts are means), and the design bound when it was computed.
fn print_anatomy(name: &str, n: usize, runs: &[Comparison]) {
    let rms = |f: &dyn Fn(&Comparison) -> f64| {
        (runs.iter().map(|c| f(c).powi(2)).sum::<f64>() / runs.len() as f64).sqrt()
    };
    if runs[0].bound.is_some() {
        let b = |f: &dyn Fn(&plan::DesignBound) -> f64| rms(&|c| f(&c.bound.unwrap()));
        println!(
            "| {name} | {n} | predicted model RMS: planned {:.4}, random {:.4}; best weighted design {:.4}, no N poses below {:.4} |",
            rms(&|c| c.predicted_model_mm),
            rms(&|c| c.predicted_random_model_mm),
            b(&|d| d.weighted_model_rms_mm),
            b(&|d| d.lower_model_rms_mm),
        );
    }
    let avg = |f: &dyn Fn(&Comparison) -> f64| mean(&runs.iter().map(f).collect::<Vec<_>>());
    for (label, pick) in [
        (
            "planned",
            &(|c: &Comparison| c.planned) as &dyn Fn(&Comparison) -> Judged,
        ),
        ("random", &|c: &Comparison| c.random),
        ("random 1.5N", &|c: &Comparison| c.random_1_5),
    ] {
        let predicted = match label {
            "planned" => rms(&|c| c.predicted_model_mm),
            "random" => rms(&|c| c.predicted_random_model_mm),
            _ => f64::NAN,
        };
        println!(
            "| {name} | {n} | {label} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.1} | {:.1} | {:.1} | {predicted:.4} |",
            rms(&|c| pick(c).rms_mm),
            rms(&|c| pick(c).anatomy.bias_mm),
            rms(&|c| pick(c).anatomy.floor_mm),
            rms(&|c| pick(c).anatomy.floor_freeset_freed_mm),
            rms(&|c| pick(c).anatomy.floor_undetermined_freed_mm),
            rms(&|c| pick(c).anatomy.floor_all_freed_mm),
            avg(&|c| pick(c).anatomy.n_freeset as f64),
            avg(&|c| pick(c).anatomy.n_undetermined as f64),
            avg(&|c| pick(c).anatomy.n_free as f64),
        );
    }
}
