//! Engine benchmarks: one pose's point with its full Jacobian, an
//! identification of 50 and of 2000 string poses, the 11,911-pose tracker
//! grid, the physics analysis of 2000 string poses, one compensation (joint
//! and Cartesian targets, reachable and unreachable). Run:
//! `cargo bench --bench engine`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use drawcal::compensate::{CompensationStatus, Compensator};
use drawcal::identify::{IdentifyOptions, NoProgress, Observations, geometric};
use drawcal::kinematics::Params;
use drawcal::kinematics::chain::{Chain, OutputFrame};
use drawcal::model::{Dataset, Measurement, PoseRecord, Rig, Robot, Split, Target, TargetKind};
use drawcal::physics::{self, simulate};
use drawcal::pipeline::{self, calibrate};
use drawcal::rng::Rng;

fn load(name: &str) -> (Robot, Rig, Dataset) {
    let d = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name);
    let robot = Robot::from_json(&std::fs::read_to_string(d.join("robot.json")).unwrap()).unwrap();
    let rig = Rig::from_json(&std::fs::read_to_string(d.join("rig.json")).unwrap()).unwrap();
    let data = Dataset::from_csv(
        std::fs::File::open(d.join("poses.csv")).unwrap(),
        &robot,
        &rig,
    )
    .unwrap();
    (robot, rig, data)
}

/// `n` string poses of the true UR5 of `ur5_geometric` (its truth.json
/// robot and base), 0.02 mm noise.
pub fn ur5_strings(n: usize) -> (Robot, Rig, Dataset) {
    let (robot, rig, _) = load("ur5_geometric");
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/ur5_geometric");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    let true_robot: Robot = serde_json::from_value(truth["true_robot"].clone()).unwrap();
    let base = serde_json::from_value(truth["base_in_rig"].clone()).unwrap();
    let p = Params::nominal(&true_robot, &base, &rig, 4);
    let chain = Chain::new(robot.convention, 6, 4);
    let mut rng = Rng::new(42);
    let mut poses = Vec::with_capacity(n);
    while poses.len() < n {
        let q: Vec<f64> = (0..6).map(|_| rng.range(-3.0, 3.0)).collect();
        let (_, t) = chain.point(&p.values, &q, OutputFrame::Rig);
        let l: Vec<f64> = (0..4)
            .map(|k| (t - rig.anchor(k)).norm() - rig.r_mm + 0.02 * rng.normal())
            .collect();
        if t.z < 100.0 || l.iter().any(|v| *v > 2000.0) {
            continue;
        }
        let i = poses.len();
        poses.push(PoseRecord {
            id: i.to_string(),
            q_rad: q,
            measurement: Measurement::Strings(l),
            time_s: None,
            temp_c: None,
            payload_kg: None,
            split: Some(if i % 5 == 4 {
                Split::Test
            } else {
                Split::Train
            }),
        });
    }
    (
        robot,
        rig,
        Dataset {
            poses,
            n_strings: 4,
            ignored_columns: vec![],
        },
    )
}

fn benches(c: &mut Criterion) {
    let (robot, rig, data50) = load("er3a_paper_like");
    let chain = Chain::new(robot.convention, 6, 4);
    let p = Params::nominal(&robot, &rig.base_in_rig.unwrap(), &rig, 4);
    let mut jac = chain.new_jacobian();
    let q = [0.1, -0.4, 0.3, 0.8, -0.5, 1.2];
    c.bench_function("point_with_full_jacobian", |b| {
        b.iter(|| {
            chain.point_jacobian(
                black_box(&p.values),
                black_box(&q),
                OutputFrame::Rig,
                &mut jac,
            )
        })
    });

    let opts = pipeline::Options {
        identify: IdentifyOptions {
            ..IdentifyOptions::default()
        },
        physics: false,
        ..Default::default()
    };
    c.bench_function("identify_50_string_poses", |b| {
        b.iter(|| calibrate(&robot, &rig, black_box(&data50), &opts, &NoProgress).unwrap())
    });

    let (r2, rig2, d2000) = ur5_strings(2000);
    let mut g = c.benchmark_group("large");
    g.sample_size(10);
    g.bench_function("identify_2000_string_poses", |b| {
        b.iter(|| calibrate(&r2, &rig2, black_box(&d2000), &opts, &NoProgress).unwrap())
    });
    let (rg, rigg, grid) = load("real_ur10_ipa_grid");
    g.bench_function("identify_ur10_grid_11911_points", |b| {
        b.iter(|| calibrate(&rg, &rigg, black_box(&grid), &opts, &NoProgress).unwrap())
    });
    // The physics analysis alone (after the geometric fit) on 2000 string
    // poses: effect-free (every candidate tried, nothing kept) and with a
    // concealed compliance and rig step (found, refined, refitted).
    for (name, effects) in [
        (
            "physics_analysis_2000_poses_effect_free",
            serde_json::json!([]),
        ),
        (
            "physics_analysis_2000_poses_compliance_and_rig_step",
            serde_json::json!([
                {"effect": "joint_compliance", "joint": 2, "size_x_noise": 5},
                {"effect": "rig_step", "size_x_noise": 5, "at_fraction": 0.4}
            ]),
        ),
    ] {
        let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
            "robot": "er3a", "n_poses": 2000, "seed": 5, "effects": effects
        }))
        .unwrap();
        let sim = simulate::generate(&spec).unwrap();
        let po = IdentifyOptions::default();
        let session = Observations::new(&sim.robot, &sim.rig, &sim.dataset, &po).unwrap();
        let geo = geometric(&session, &po, &NoProgress).unwrap();
        g.bench_function(name, |b| {
            b.iter(|| physics::analyse(&session, black_box(&geo), &NoProgress).unwrap())
        });
    }
    g.finish();

    let report = calibrate(&robot, &rig, &data50, &opts, &NoProgress).unwrap();
    let comp = Compensator::from_report(&report).unwrap();
    let t = Target {
        target: "t".into(),
        kind: TargetKind::Joints {
            q_deg: vec![10.0, 20.0, 30.0, 40.0, 50.0, 60.0],
        },
    };
    c.bench_function("compensate_one_joint_target", |b| {
        b.iter(|| comp.compensate(black_box(&t), false))
    });
    c.bench_function("compensate_one_joint_target_with_orientation", |b| {
        b.iter(|| comp.compensate(black_box(&t), true))
    });

    // A Cartesian target: where the nominal model puts T and the flange at
    // the same joints; seeded by the closed-form IK, and by the numerical
    // seeds alone for comparison.
    let q: Vec<f64> = [10.0f64, 20.0, 30.0, 40.0, 50.0, 60.0]
        .iter()
        .map(|v| v.to_radians())
        .collect();
    let (pos, rot) = comp.nominal_pose(&q);
    let rpy = drawcal::kinematics::matrix_rpy(&rot).map(f64::to_degrees);
    let cart = |rpy_deg: Option<[f64; 3]>| Target {
        target: "c".into(),
        kind: TargetKind::Cartesian {
            xyz_mm: pos.into(),
            rpy_deg,
        },
    };
    let (with_rpy, position) = (cart(Some([rpy[0], rpy[1], rpy[2]])), cart(None));
    let mut numeric = comp.clone();
    numeric.closed_form = false;
    for (name, c_, target) in [
        (
            "compensate_one_cartesian_target_with_orientation",
            &comp,
            &with_rpy,
        ),
        (
            "compensate_one_cartesian_target_with_orientation_numeric_seeds",
            &numeric,
            &with_rpy,
        ),
        ("compensate_one_cartesian_target_position", &comp, &position),
        (
            "compensate_one_cartesian_target_position_numeric_seeds",
            &numeric,
            &position,
        ),
    ] {
        assert_eq!(c_.compensate(target, false).status, CompensationStatus::Ok);
        c.bench_function(name, |b| b.iter(|| c_.compensate(black_box(target), false)));
    }

    // Unreachable Cartesian targets: T 5 m away from the 0.72 m ER3A (beyond
    // the arm's reach ball), and T 700 or 600 mm from the shoulder with the
    // flange turned back towards the base, which would put the wrist centre
    // 830 or 730 mm out, past the 593 mm the upper arm and forearm reach.
    // At 700 mm the flange itself is beyond what joints 1-5 reach (the ball
    // with the orientation); at 600 mm no bound tells, only the solves.
    let far = Target {
        target: "far".into(),
        kind: TargetKind::Cartesian {
            xyz_mm: [5000.0, 0.0, 0.0],
            rpy_deg: None,
        },
    };
    let u = nalgebra::Vector3::new(30f64.to_radians().cos(), 30f64.to_radians().sin(), 0.0);
    let back = nalgebra::Rotation3::face_towards(&-u, &nalgebra::Vector3::z());
    let back_rpy = drawcal::kinematics::matrix_rpy(back.matrix()).map(f64::to_degrees);
    let turned_back = |r: f64| Target {
        target: "back".into(),
        kind: TargetKind::Cartesian {
            xyz_mm: (nalgebra::Vector3::new(0.0, 0.0, 330.0) + r * u).into(),
            rpy_deg: Some([back_rpy[0], back_rpy[1], back_rpy[2]]),
        },
    };
    for (name, target) in [
        ("compensate_unreachable_cartesian_target_5m_away", far),
        (
            "compensate_unreachable_cartesian_target_turned_back_700mm",
            turned_back(700.0),
        ),
        (
            "compensate_unreachable_cartesian_target_turned_back_600mm",
            turned_back(600.0),
        ),
    ] {
        assert_eq!(
            comp.compensate(&target, false).status,
            CompensationStatus::Unreachable
        );
        c.bench_function(name, |b| {
            b.iter(|| comp.compensate(black_box(&target), false))
        });
    }
}

/// Compensation with temperature-driven thermal expansion: the cached
/// compensator (at its reference temperature) against a copy moved to the
/// running temperature per request, as `POST /compensate` with `temp_c`
/// does. Filter: `cargo bench --bench engine -- thermal`.
fn thermal(c: &mut Criterion) {
    let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
        "robot": "er3a", "n_poses": 120, "seed": 777,
        "effects": [{"effect": "thermal_expansion", "size_x_noise": 10}]
    }))
    .unwrap();
    let sim = simulate::generate(&spec).unwrap();
    let report = calibrate(
        &sim.robot,
        &sim.rig,
        &sim.dataset,
        &pipeline::Options::default(),
        &NoProgress,
    )
    .unwrap();
    let comp = Compensator::from_report(&report).unwrap();
    let t_run = comp.thermal().expect("thermal accepted").reference_temp_c + 30.0;
    let t = Target {
        target: "t".into(),
        kind: TargetKind::Joints {
            q_deg: vec![10.0, -20.0, 30.0, 0.0, 40.0, 0.0],
        },
    };
    assert_eq!(comp.compensate(&t, false).status, CompensationStatus::Ok);
    c.bench_function("thermal_compensator_at_temperature", |b| {
        b.iter(|| comp.at_temperature(black_box(t_run)))
    });
    c.bench_function("thermal_compensate_one_joint_target_at_reference", |b| {
        b.iter(|| comp.compensate(black_box(&t), false))
    });
    c.bench_function("thermal_compensate_one_joint_target_at_temperature", |b| {
        b.iter(|| {
            comp.at_temperature(black_box(t_run))
                .compensate(black_box(&t), false)
        })
    });
}

criterion_group!(engine, thermal, benches);
criterion_main!(engine);
