//! Identification on recordings synthesised here from a known model: Craig's
//! MDH convention, a three-string rig, outlier poses under the robust loss.

use crate::common;

use drawcal::identify::{IdentifyOptions, NoProgress, identifiability};
use drawcal::kinematics::Params;
use drawcal::kinematics::chain::{Chain, OutputFrame};
use drawcal::model::{BasePose, Convention, Dataset, Measurement, PoseRecord, Rig, Robot, Split};
use drawcal::pipeline::{self, calibrate};
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
            ignored_columns: vec![],
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
    let rep = calibrate(
        &robot,
        &rig,
        &data,
        &pipeline::Options {
            identify: IdentifyOptions {
                ..IdentifyOptions::default()
            },
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
    let robot = Robot::from_json(include_str!("../data/ur5_geometric/robot.json")).unwrap();
    let rig3 = rig("[[0,0,0],[0,1100,0],[1500,0,0]]");
    let base = BasePose {
        xyz_mm: [750.0, 550.0, -150.0],
        rpy_deg: [0.0, 0.0, 180.0],
    };
    let (mut data, _) = synthesise(&robot, &rig3, &base, 150, 0.02, 3);
    let plain = calibrate(
        &robot,
        &rig3,
        &data,
        &pipeline::Options {
            identify: IdentifyOptions {
                ..IdentifyOptions::default()
            },
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
    let robust = calibrate(
        &robot,
        &rig3,
        &data,
        &pipeline::Options {
            identify: IdentifyOptions {
                robust: true,
                ..IdentifyOptions::default()
            },
            physics: false,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let flagged: Vec<&str> = robust.outliers.iter().map(|o| o.pose.as_str()).collect();
    for id in ["5", "41", "91"] {
        assert!(flagged.contains(&id), "pose {id} not flagged: {flagged:?}");
    }
    let naive = calibrate(
        &robot,
        &rig3,
        &data,
        &pipeline::Options {
            identify: IdentifyOptions {
                ..IdentifyOptions::default()
            },
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
        let rep = calibrate(
            &sim.robot,
            &sim.rig,
            &sim.dataset,
            &pipeline::Options {
                identify: IdentifyOptions {
                    ..IdentifyOptions::default()
                },
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
    // above 1.2x the floor in a good share of sessions (docs/CLI.md quotes
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
    let sessions = 30;
    for robot in ["er3a", "ur5", "arm4_mdh"] {
        let (mut z2, mut n_z, mut over3) = (0.0, 0usize, 0usize);
        for seed in 0..sessions {
            let spec: Spec = serde_json::from_value(serde_json::json!({
                "robot": robot, "n_poses": 50, "test_fraction": 0.4, "seed": 700 + seed
            }))
            .unwrap();
            let sim = generate(&spec).unwrap();
            let opts = pipeline::Options {
                identify: IdentifyOptions {
                    ..IdentifyOptions::default()
                },
                physics: false,
                ..Default::default()
            };
            let rep = calibrate(&sim.robot, &sim.rig, &sim.dataset, &opts, &NoProgress).unwrap();
            // The truth in the parametrisation the noisy session chose.
            let mapped = common::mapped_truth(
                &sim.robot,
                &sim.rig,
                &sim.dataset,
                &common::true_points(&sim.truth),
                &rep,
            );
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
        eprintln!("{robot}: {n_z} pulls, RMS {rms_z:.3}, {over3} beyond 3 sigma");
        assert!((0.85..1.15).contains(&rms_z), "{robot}: pull RMS {rms_z}");
        // A normal gives 0.27 %; allow for some tail.
        assert!(
            (over3 as f64) < 0.015 * n_z as f64,
            "{robot}: {over3} of {n_z} beyond 3 sigma"
        );
    }
}

/// Holding the nearly aliased joint parameters the data do not determine
/// (`undetermined_z`, see `identifiability::undetermined`) leaves the
/// held-out position where it was and brings the calibrated flange
/// orientation back to the truth: with the tool point within a millimetre of
/// the joint-6 axis (the simulator's default tool deviations), the wrist
/// pairs a5/θ5 and α5/d5 are separated only by that offset, and left free
/// they tilt the flange by degrees. Orientation error: the angle between the
/// calibrated and the true flange frames (rig frame) at the held-out poses.
/// The report's `flange_orientation_sigma_deg` says how well the data
/// determine that orientation.
#[test]
fn undetermined_wrist_pairs_are_held_for_the_flange_orientation() {
    use drawcal::physics::simulate::{Spec, generate};
    let sessions = 30;
    for robot in ["er3a", "ur5"] {
        // [held, all free]: sums of squares over sessions / held-out poses.
        let (mut held_out2, mut orient2, mut n_poses) = ([0.0; 2], [0.0; 2], 0.0);
        let mut sessions_holding = 0;
        let (mut reported2, mut reported2_last) = (0.0, 0.0);
        for seed in 0..sessions {
            let spec: Spec = serde_json::from_value(serde_json::json!({
                "robot": robot, "n_poses": 50, "test_fraction": 0.4, "seed": 900 + seed
            }))
            .unwrap();
            let sim = generate(&spec).unwrap();
            let m = sim.rig.n_strings();
            let true_robot: Robot =
                serde_json::from_value(sim.truth["true_robot"].clone()).unwrap();
            let true_base: BasePose =
                serde_json::from_value(sim.truth["base_in_rig"].clone()).unwrap();
            let truth = Params::nominal(&true_robot, &true_base, &sim.rig, m);
            let chain = Chain::new(sim.robot.convention, sim.robot.dof(), m);
            let mut n_fixed = [0; 2];
            for (i, z) in [identifiability::UNDETERMINED_Z, 0.0]
                .into_iter()
                .enumerate()
            {
                let opts = pipeline::Options {
                    identify: IdentifyOptions {
                        undetermined_z: z,
                        ..IdentifyOptions::default()
                    },
                    physics: false,
                    ..Default::default()
                };
                let rep =
                    calibrate(&sim.robot, &sim.rig, &sim.dataset, &opts, &NoProgress).unwrap();
                n_fixed[i] = rep.fixed.len();
                let o = rep.flange_orientation_sigma_deg.unwrap();
                if i == 0 {
                    reported2 += o * o;
                } else {
                    // Taken before the holds: the same with none.
                    assert!(
                        (o * o - reported2_last).abs() < 1e-9 * o * o,
                        "{robot} {seed}"
                    );
                }
                reported2_last = o * o;
                held_out2[i] += rep.stats.test.after.rms_mm.powi(2);
                let cal = Params::nominal(&rep.calibrated_robot, &rep.base_in_rig, &sim.rig, m);
                for pose in sim
                    .dataset
                    .poses
                    .iter()
                    .filter(|p| rep.held_out.contains(&p.id))
                {
                    let (a, _) = chain.point(&cal.values, &pose.q_rad, OutputFrame::Rig);
                    let (b, _) = chain.point(&truth.values, &pose.q_rad, OutputFrame::Rig);
                    let angle = nalgebra::Rotation3::from_matrix_unchecked(a.r.transpose() * b.r)
                        .angle()
                        .to_degrees();
                    orient2[i] += angle * angle;
                    n_poses += if i == 0 { 1.0 } else { 0.0 };
                }
            }
            sessions_holding += usize::from(n_fixed[0] > n_fixed[1]);
        }
        let rms = |v: f64, n: f64| (v / n).sqrt();
        let s = sessions as f64;
        let (pos_held, pos_free) = (rms(held_out2[0], s), rms(held_out2[1], s));
        let (or_held, or_free) = (rms(orient2[0], n_poses), rms(orient2[1], n_poses));
        let reported = rms(reported2, s);
        eprintln!(
            "{robot}: {sessions_holding} of {sessions} sessions hold a wrist parameter; \
             held-out RMS {pos_held:.4} mm held, {pos_free:.4} mm all free; \
             flange orientation error {or_held:.3} deg held, {or_free:.3} deg all free, \
             reported 1 sigma {reported:.3} deg"
        );
        assert!(
            sessions_holding > sessions / 3,
            "{robot}: {sessions_holding}"
        );
        assert!(
            (pos_held / pos_free - 1.0).abs() < 0.03,
            "{robot}: held-out {pos_held} vs {pos_free}"
        );
        assert!(
            or_held < 0.7 * or_free,
            "{robot}: orientation {or_held} vs {or_free} deg"
        );
        // The reported sigma is how well the data determine the orientation
        // (the spread of the free fit, which also carries joint 6's unseen
        // offsets here); holding the undetermined pair does better than it.
        assert!(
            (0.7..1.5).contains(&(or_free / reported)) && or_held < reported,
            "{robot}: reported {reported} deg, errors {or_held} held, {or_free} free"
        );
    }
}
