//! Identification on recordings synthesised here from a known model: Craig's
//! MDH convention, a three-string rig, outlier poses under the robust loss.

mod common;

use drawcal::identify::{IdentifyOptions, NoProgress, identify};
use drawcal::kinematics::Params;
use drawcal::kinematics::chain::{Chain, OutputFrame};
use drawcal::model::{BasePose, Convention, Dataset, Measurement, PoseRecord, Rig, Robot, Split};
use drawcal::rng::Rng;

/// A 6-axis arm in Craig's MDH form (a PUMA-like table).
fn mdh_robot() -> Robot {
    Robot::from_json(
        r#"{"name":"mdh arm","convention":"mdh","joints":[
        {"a_mm":0,"alpha_deg":0,"d_mm":0,"q_min_deg":-170,"q_max_deg":170},
        {"a_mm":0,"alpha_deg":-90,"d_mm":0,"q_min_deg":-170,"q_max_deg":170},
        {"a_mm":430,"alpha_deg":0,"d_mm":120,"q_min_deg":-170,"q_max_deg":170},
        {"a_mm":20,"alpha_deg":-90,"d_mm":430,"q_min_deg":-170,"q_max_deg":170},
        {"a_mm":0,"alpha_deg":90,"d_mm":0,"q_min_deg":-120,"q_max_deg":120},
        {"a_mm":0,"alpha_deg":-90,"d_mm":0,"q_min_deg":-360,"q_max_deg":360}],
        "tool_point_mm":[0,0,120]}"#,
    )
    .unwrap()
}

/// Readings of a perturbed `robot` at random poses; returns the data and the
/// true parameters.
fn synthesise(
    robot: &Robot,
    rig: &Rig,
    base: &BasePose,
    n: usize,
    sigma: f64,
    seed: u64,
) -> (Dataset, Params) {
    let m = rig.n_strings();
    let mut truth = Params::nominal(robot, base, rig, m);
    let mut rng = Rng::new(seed);
    for j in 0..robot.dof() {
        for k in 0..4 {
            let i = 5 * j + k;
            truth.values[i] += if truth.layout.is_angle(i) {
                0.003 * rng.normal()
            } else {
                0.5 * rng.normal()
            };
        }
    }
    let chain = Chain::new(robot.convention, robot.dof(), m);
    let mut poses = Vec::new();
    while poses.len() < n {
        let q: Vec<f64> = robot
            .joints
            .iter()
            .map(|j| {
                rng.range(j.q_min_deg.max(-150.0), j.q_max_deg.min(150.0))
                    .to_radians()
            })
            .collect();
        let (_, t) = chain.point(&truth.values, &q, OutputFrame::Rig);
        if t.z < 150.0 {
            continue; // stay well above the anchor plane
        }
        let l: Vec<f64> = (0..m)
            .map(|k| (t - rig.anchor(k)).norm() - rig.r_mm + sigma * rng.normal())
            .collect();
        let i = poses.len();
        poses.push(PoseRecord {
            id: format!("{}", i + 1),
            q_rad: q,
            measurement: Measurement::Strings(l),
            time_s: Some(i as f64),
            temp_c: None,
            payload_kg: None,
            split: Some(if i % 4 == 3 {
                Split::Test
            } else {
                Split::Train
            }),
        });
    }
    (
        Dataset {
            poses,
            n_strings: m,
        },
        truth,
    )
}

fn rig(anchors: &str) -> Rig {
    Rig::from_json(&format!(r#"{{"anchors_mm":{anchors},"r_mm":35}}"#)).unwrap()
}

#[test]
fn mdh_robot_calibrates_to_the_noise() {
    let robot = mdh_robot();
    let rig = rig("[[-900,-900,0],[-900,900,0],[900,-900,0],[900,900,0]]");
    let base = BasePose {
        xyz_mm: [0.0, 0.0, -400.0],
        rpy_deg: [0.0, 0.0, 0.0],
    };
    let (data, truth) = synthesise(&robot, &rig, &base, 120, 0.02, 7);
    let rep = identify(
        &robot,
        &rig,
        &data,
        &IdentifyOptions {
            physics: false,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    assert!(
        rep.stats.test.before.rms_mm > 1.0,
        "{}",
        rep.stats.test.before.rms_mm
    );
    let floor = rep.noise_floor_mm.unwrap();
    assert!(
        rep.stats.test.after.rms_mm < 1.2 * floor,
        "after {} floor {floor}",
        rep.stats.test.after.rms_mm
    );
    // The calibrated model predicts the true T at new poses.
    let chain = Chain::new(Convention::Mdh, 6, 4);
    let cal = Params::nominal(&rep.calibrated_robot, &rep.base_in_rig, &rig, 4);
    let mut rng = Rng::new(99);
    for _ in 0..50 {
        let q: Vec<f64> = (0..6).map(|_| rng.range(-1.5, 1.5)).collect();
        let a = chain.point(&cal.values, &q, OutputFrame::Rig).1;
        let b = chain.point(&truth.values, &q, OutputFrame::Rig).1;
        assert!((a - b).norm() < 0.1, "{}", (a - b).norm());
    }
}

#[test]
fn three_strings_and_robust_outliers() {
    let robot = Robot::from_json(include_str!("data/ur5_geometric/robot.json")).unwrap();
    let rig3 = rig("[[0,0,0],[0,1100,0],[1500,0,0]]");
    let base = BasePose {
        xyz_mm: [750.0, 550.0, -150.0],
        rpy_deg: [0.0, 0.0, 180.0],
    };
    let (mut data, _) = synthesise(&robot, &rig3, &base, 150, 0.02, 3);
    let plain = identify(
        &robot,
        &rig3,
        &data,
        &IdentifyOptions {
            physics: false,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    assert!(
        plain.string_sigma_mm.is_some(),
        "three strings: sigma from the fit residual"
    );
    assert!(
        plain.stats.test.after.rms_mm < 0.2,
        "{}",
        plain.stats.test.after.rms_mm
    );
    // Spoil three train poses by 3 mm on one string (a snagged string).
    for i in [4, 40, 90] {
        if let Measurement::Strings(l) = &mut data.poses[i].measurement {
            l[1] += 3.0;
        }
    }
    let robust = identify(
        &robot,
        &rig3,
        &data,
        &IdentifyOptions {
            physics: false,
            robust: true,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let flagged: Vec<&str> = robust.outliers.iter().map(|o| o.pose.as_str()).collect();
    for id in ["5", "41", "91"] {
        assert!(flagged.contains(&id), "pose {id} not flagged: {flagged:?}");
    }
    let naive = identify(
        &robot,
        &rig3,
        &data,
        &IdentifyOptions {
            physics: false,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    assert!(
        robust.stats.test.after.rms_mm < naive.stats.test.after.rms_mm,
        "robust {} naive {}",
        robust.stats.test.after.rms_mm,
        naive.stats.test.after.rms_mm
    );
    // The iteration count covers every reweighting pass, not the last one.
    assert!(
        robust.convergence.iterations > naive.convergence.iterations,
        "robust {} naive {}",
        robust.convergence.iterations,
        naive.convergence.iterations
    );
}

/// The expected held-out RMS of an exact model (noise floor plus the
/// identified parameters' spread) is what repeated sessions actually show:
/// few train poses for many parameters (the paper's 30 for 27), so the
/// spread is a large part of it and the floor alone falls short.
#[test]
fn expected_test_rms_matches_repeated_sessions() {
    use drawcal::physics::simulate::{Spec, generate};
    let (mut after2, mut expected2, mut floor2) = (0.0, 0.0, 0.0);
    let (mut within_floor, mut within_point_noise) = (0, 0);
    let runs = 60;
    for seed in 0..runs {
        let spec: Spec = serde_json::from_value(serde_json::json!({
            "robot": "er3a", "n_poses": 50, "test_fraction": 0.4, "seed": 500 + seed
        }))
        .unwrap();
        let sim = generate(&spec).unwrap();
        let rep = identify(
            &sim.robot,
            &sim.rig,
            &sim.dataset,
            &IdentifyOptions {
                physics: false,
                ..Default::default()
            },
            &NoProgress,
        )
        .unwrap();
        let after = rep.stats.test.after.rms_mm;
        let floor = rep.noise_floor_mm.unwrap();
        after2 += after.powi(2);
        expected2 += rep.expected_test_rms_mm.unwrap().powi(2);
        floor2 += floor.powi(2);
        within_floor += usize::from(after <= 1.2 * floor);
        within_point_noise += usize::from(after <= 1.2 * sim.point_noise_mm);
    }
    let ratio = (after2 / expected2).sqrt();
    let floor_ratio = (after2 / floor2).sqrt();
    eprintln!(
        "held-out / expected {ratio:.3}, held-out / floor {floor_ratio:.3}; \
         within 1.2x the floor in {within_floor} of {runs} sessions, \
         within 1.2x the simulated point noise in {within_point_noise}"
    );
    assert!((ratio - 1.0).abs() < 0.08, "held-out / expected {ratio}");
    // The spread matters here: the floor alone would be clearly short, and
    // an estimator that is on average exactly where it should be still ends
    // above 1.2x the floor in a good share of sessions (the README quotes
    // the printed counts).
    assert!(floor_ratio > 1.08, "held-out / floor {floor_ratio}");
    assert!(
        within_floor >= runs / 2,
        "within 1.2x the floor in {within_floor} of {runs}"
    );
}

/// The reported 1-sigma uncertainties are what repeated sessions show: over
/// many simulated sessions of each robot, every identified parameter's
/// error against the truth (mapped into the same parametrisation by fitting
/// exact readings of the true points at the same poses) divided by its
/// reported sigma has an RMS near 1, and |z| > 3 stays as rare as a normal
/// distribution makes it. A covariance scaled by the wrong sigma, or built
/// from the wrong Jacobian, moves the RMS far from 1.
#[test]
fn reported_sigmas_cover_the_truth_over_repeated_sessions() {
    use drawcal::physics::simulate::{Spec, generate};
    use nalgebra::Vector3;
    let sessions = 30;
    for robot in ["er3a", "ur5", "arm4_mdh"] {
        let (mut z2, mut n_z, mut over3, mut skipped) = (0.0, 0usize, 0usize, 0);
        for seed in 0..sessions {
            let spec: Spec = serde_json::from_value(serde_json::json!({
                "robot": robot, "n_poses": 50, "test_fraction": 0.4, "seed": 700 + seed
            }))
            .unwrap();
            let sim = generate(&spec).unwrap();
            let opts = IdentifyOptions {
                physics: false,
                ..Default::default()
            };
            let rep = identify(&sim.robot, &sim.rig, &sim.dataset, &opts, &NoProgress).unwrap();
            let mut exact = sim.dataset.clone();
            let true_points = sim.truth["true_points_mm"].as_array().unwrap();
            for (pose, t) in exact.poses.iter_mut().zip(true_points) {
                let t = Vector3::from_iterator((0..3).map(|c| t[c].as_f64().unwrap()));
                pose.measurement = Measurement::Strings(
                    (0..sim.rig.n_strings())
                        .map(|k| (t - sim.rig.anchor(k)).norm() - sim.rig.r_mm)
                        .collect(),
                );
            }
            let mapped = identify(&sim.robot, &sim.rig, &exact, &opts, &NoProgress).unwrap();
            // A nearly aliased pair (the wrist's a5/theta5 when T sits
            // almost on the joint-6 axis) may be kept on one side of the
            // identifiability threshold and fixed on the other; the two
            // parametrisations are then not comparable name by name.
            if mapped.fixed != rep.fixed {
                skipped += 1;
                continue;
            }
            assert!(
                mapped.stats.train.after.rms_mm < 5e-3,
                "{robot} seed {seed}: the identified parametrisation must represent the truth"
            );
            for p in &rep.parameters {
                let t = mapped.parameters.iter().find(|q| q.name == p.name).unwrap();
                let z = (p.value - t.value) / p.sigma;
                z2 += z * z;
                n_z += 1;
                over3 += usize::from(z.abs() > 3.0);
            }
        }
        let rms_z = (z2 / n_z as f64).sqrt();
        eprintln!(
            "{robot}: {n_z} pulls, RMS {rms_z:.3}, {over3} beyond 3 sigma, {skipped} sessions skipped"
        );
        assert!(
            skipped <= sessions / 10,
            "{robot}: {skipped} sessions skipped"
        );
        assert!((0.85..1.15).contains(&rms_z), "{robot}: pull RMS {rms_z}");
        // A normal gives 0.27 %; allow for the near-aliased pairs' tails.
        assert!(
            (over3 as f64) < 0.015 * n_z as f64,
            "{robot}: {over3} of {n_z} beyond 3 sigma"
        );
    }
}
