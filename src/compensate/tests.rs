//! The module's unit tests, across its parts (a reach test compensates at
//! a temperature).

use super::*;
use crate::kinematics::rpy_matrix;
use crate::model::{Convention, Robot, Target, TargetKind};
use crate::rng::Rng;
use solve::{Model, rotation_error};
use target::display_deg;

fn robots() -> (Robot, Robot) {
    let nominal =
        Robot::from_json(include_str!("../../tests/data/er3a_paper_like/robot.json")).unwrap();
    let truth: serde_json::Value =
        serde_json::from_str(include_str!("../../tests/data/er3a_paper_like/truth.json")).unwrap();
    let true_robot: Robot = serde_json::from_value(truth["true_robot"].clone()).unwrap();
    (nominal, true_robot)
}

#[test]
fn joint_target_lands_within_a_micrometre() {
    let (nominal, cal) = robots();
    let comp = Compensator::new(&nominal, &cal).unwrap();
    for q_deg in [
        vec![10.0, 20.0, 30.0, 40.0, 50.0, 60.0],
        vec![-60.0, -10.0, 45.0, 90.0, -30.0, 10.0],
    ] {
        let t = Target {
            target: "a".into(),
            kind: TargetKind::Joints {
                q_deg: q_deg.clone(),
            },
        };
        let r = comp.compensate(&t, false);
        assert_eq!(r.status, CompensationStatus::Ok, "{r:?}");
        let q: Vec<f64> = r.q_deg.unwrap().iter().map(|v| v.to_radians()).collect();
        let q_nom: Vec<f64> = q_deg.iter().map(|v| v.to_radians()).collect();
        let want = comp.nominal_pose(&q_nom).0;
        assert!((comp.calibrated_pose(&q).0 - want).norm() < 1e-3);
        // And without compensation the true robot misses by millimetres.
        assert!((comp.calibrated_pose(&q_nom).0 - want).norm() > 0.5);
        let r = comp.compensate(&t, true);
        assert_eq!(r.status, CompensationStatus::Ok, "{r:?}");
        let q: Vec<f64> = r.q_deg.unwrap().iter().map(|v| v.to_radians()).collect();
        let (p, rot) = comp.calibrated_pose(&q);
        assert!((p - want).norm() < 1e-3);
        assert!(rotation_error(&comp.nominal_pose(&q_nom).1, &rot).norm() < 1e-6);
    }
}

#[test]
fn rotation_error_is_finite_and_exact_near_zero_and_a_half_turn() {
    let r = rpy_matrix(0.3, -0.2, 1.1);
    for angle in [
        0.0,
        1e-12,
        1e-9,
        1e-6,
        0.3,
        3.0,
        std::f64::consts::PI - 1e-9,
    ] {
        let axis = nalgebra::Unit::new_normalize(Vector3::new(0.2, -0.5, 0.8));
        let d = nalgebra::Rotation3::from_axis_angle(&axis, angle);
        let e = rotation_error(&(d.matrix() * r), &r);
        assert!(e.iter().all(|v| v.is_finite()), "{angle}: {e:?}");
        assert!(
            (e - axis.into_inner() * angle).norm() < 1e-9 * (1.0 + angle),
            "{angle}: {e:?}"
        );
    }
    // A computed product that agrees to rounding (the old acos gave NaN).
    let q = [0.3, -1.2, 1.4, -0.5, 1.1, 2.0];
    let (nominal, _) = robots();
    let comp = Compensator::new(&nominal, &nominal).unwrap();
    let a = comp.nominal_pose(&q).1;
    let b = rpy_matrix(0.0, 0.0, 1e-17) * a;
    assert!(rotation_error(&a, &b).norm() < 1e-15);
}

#[test]
fn cartesian_targets_and_failures() {
    let (nominal, cal) = robots();
    let comp = Compensator::new(&nominal, &cal).unwrap();
    let reach = comp.nominal_pose(&[0.3, 0.2, 0.4, 0.1, 0.5, 0.0]).0;
    let t = Target {
        target: "c".into(),
        kind: TargetKind::Cartesian {
            xyz_mm: reach.into(),
            rpy_deg: None,
        },
    };
    let r = comp.compensate(&t, false);
    assert_eq!(r.status, CompensationStatus::Ok, "{r:?}");
    let q: Vec<f64> = r.q_deg.unwrap().iter().map(|v| v.to_radians()).collect();
    assert!((comp.calibrated_pose(&q).0 - reach).norm() < 1e-3);
    let far = Target {
        target: "far".into(),
        kind: TargetKind::Cartesian {
            xyz_mm: [5000.0, 0.0, 0.0],
            rpy_deg: None,
        },
    };
    assert_eq!(
        comp.compensate(&far, false).status,
        CompensationStatus::Unreachable
    );
    // A calibrated joint 2 offset by +0.5 deg: a pose taught 0.2 deg
    // inside the lower limit needs 0.3 deg past it.
    let mut shifted = nominal.clone();
    shifted.joints[1].theta_offset_deg += 0.5;
    let comp = Compensator::new(&nominal, &shifted).unwrap();
    let t = Target {
        target: "lim".into(),
        kind: TargetKind::Joints {
            q_deg: vec![10.0, -109.8, 30.0, 40.0, 50.0, 60.0],
        },
    };
    let r = comp.compensate(&t, true);
    assert_eq!(r.status, CompensationStatus::JointLimit, "{r:?}");
    assert!(r.message.unwrap().contains("joint 2"));
    assert!(r.q_deg.is_none());
}

#[test]
fn joint_targets_past_the_limits_say_so() {
    let (nominal, _) = robots();
    let joints = |q1: f64, q6: f64| Target {
        target: "t".into(),
        kind: TargetKind::Joints {
            q_deg: vec![q1, -30.0, 30.0, 40.0, 50.0, q6],
        },
    };
    // Joint 6 turns +-360 deg; a calibrated joint 6 whose zero is 0.5
    // deg off needs 360.5 deg for a target taught at the limit, and the same
    // angle a turn away is within the limits: said, not taken.
    let mut cal = nominal.clone();
    cal.joints[5].q_min_deg = -360.0;
    cal.joints[5].q_max_deg = 360.0;
    let mut nom = nominal.clone();
    nom.joints[5].q_min_deg = -360.0;
    nom.joints[5].q_max_deg = 360.0;
    cal.joints[5].theta_offset_deg -= 0.5;
    let comp = Compensator::new(&nom, &cal).unwrap();
    let r = comp.compensate(&joints(10.0, 360.0), true);
    assert_eq!(r.status, CompensationStatus::JointLimit, "{r:?}");
    let msg = r.message.unwrap();
    assert!(
        msg.contains("joint 6") && msg.contains("[-360, 360] deg"),
        "{msg}"
    );
    assert!(
        msg.contains("a turn away, 0.5000 deg, is within them"),
        "{msg}"
    );
    // Limits print as robot.json gave them, not as the round trip
    // through radians leaves them.
    assert_ne!(120f64.to_radians().to_degrees(), 120.0);
    assert_eq!(display_deg(120f64.to_radians()), 120.0);
    // Absurd angles: refused at once as past the limits, whatever the
    // trigonometry makes of them.
    for q1 in [1e16, -1e16, 600.0] {
        let r = comp.compensate(&joints(q1, 0.0), false);
        assert_eq!(r.status, CompensationStatus::JointLimit, "{q1}: {r:?}");
        assert_eq!(r.iterations, 0);
        assert!(r.message.unwrap().contains("joint 1's target"));
    }
}

/// ER3A-like arms with every parameter random, in both conventions.
fn random_arms(rng: &mut Rng) -> Vec<Robot> {
    let (er3a, _) = robots();
    let mut arms = vec![];
    for convention in [Convention::Dh, Convention::Mdh] {
        for _ in 0..20 {
            let mut r = er3a.clone();
            r.convention = convention;
            for j in &mut r.joints {
                j.a_mm = rng.range(-400.0, 400.0);
                j.d_mm = rng.range(-400.0, 400.0);
                j.alpha_deg = rng.range(-180.0, 180.0);
                j.theta_offset_deg = rng.range(-180.0, 180.0);
                j.beta_deg = rng.range(-30.0, 30.0);
            }
            r.tool_point_mm = [0; 3].map(|_| rng.range(-150.0, 150.0));
            arms.push(r);
        }
    }
    arms
}

#[test]
fn the_reach_ball_holds_t_for_any_joints() {
    let mut rng = Rng::new(11);
    let (er3a, er3a_true) = robots();
    let mut arms = random_arms(&mut rng);
    arms.extend([er3a, er3a_true]);
    for robot in &arms {
        let comp = Compensator::new(robot, robot).unwrap();
        let reach = *comp.reach_calibrated();
        for _ in 0..2000 {
            let q: Vec<f64> = (0..6)
                .map(|_| rng.range(-std::f64::consts::PI, std::f64::consts::PI))
                .collect();
            let (t, r) = comp.calibrated_pose(&q);
            assert!(reach.beyond(&t) < 0.0, "{robot:?} {q:?}");
            // With the flange orientation: the start of the last
            // segment is on the last joint's axis, and within reach of
            // the others.
            let (beyond, start) = reach.beyond_pose(&t, &r, 0.0);
            assert!(beyond < 0.0, "{robot:?} {q:?}");
            let axes = comp
                .chain
                .joint_axes(&comp.calibrated.values, &q, OutputFrame::Base);
            let (axis, o) = axes[5];
            assert!((start - o).cross(&axis.normalize()).norm() < 1e-9);
            // And every joint axis is within `radius` of T (the bound
            // on how fast T moves as a joint turns).
            for (axis, o) in comp
                .chain
                .joint_axes(&comp.calibrated.values, &q, OutputFrame::Base)
            {
                let arm = (t - o).cross(&axis.normalize()).norm();
                assert!(arm <= reach.radius * (1.0 + 1e-12), "{arm} {reach:?}");
            }
        }
    }
}

#[test]
fn beyond_the_reach_ball_is_unreachable_at_once_and_just_inside_is_solved() {
    let (nominal, cal) = robots();
    let comp = Compensator::new(&nominal, &cal).unwrap();
    let reach = *comp.reach_calibrated();
    // The nominal ER3A stretches out to the whole radius: 275 mm upper
    // arm, the 60 x 312 mm forearm, 70 + 60 mm to T.
    assert!(
        (comp.reach_nominal.radius - 722.72).abs() < 0.01,
        "{reach:?}"
    );
    let u = Vector3::new(-0.6, 0.0, 0.8);
    let at = |r: f64| Target {
        target: "r".into(),
        kind: TargetKind::Cartesian {
            xyz_mm: (reach.centre + r * u).into(),
            rpy_deg: None,
        },
    };
    // (The true ER3A's 2 mm joint-1 offset turns only about the
    // vertical, so it cannot all point up this slanted direction.)
    // Solved: the joints put T there, though stretching the elbow out
    // takes joint 3 past its limit (so the status says that).
    let inside = comp.compensate(&at(reach.radius - 3.0), false);
    assert_eq!(inside.status, CompensationStatus::JointLimit, "{inside:?}");
    assert!(inside.message.unwrap().contains("joint 3"));
    for r in [reach.radius + 0.01, 5000.0] {
        let out = comp.compensate(&at(r), false);
        assert_eq!(out.status, CompensationStatus::Unreachable);
        assert_eq!(out.iterations, 0);
        assert!(out.message.unwrap().contains("beyond the 72"));
    }
    // The ball follows the temperature: lengths 10 % longer.
    let mut warm = comp.clone();
    warm.thermal = Some(Arc::new(Thermal {
        info: ThermalInfo {
            coef_per_k: 1e-3,
            reference_temp_c: 20.0,
        },
        lengths: crate::physics::effects::nominal_lengths(&nominal),
        reference_values: comp.calibrated.values.clone(),
    }));
    let warm = warm.at_temperature(120.0);
    let grown = *warm.reach_calibrated();
    let want = Reach::of(&warm.chain, &warm.calibrated.values);
    assert_eq!((grown.centre, grown.radius), (want.centre, want.radius));
    assert!(
        (grown.radius / reach.radius - 1.1).abs() < 0.01,
        "{grown:?}"
    );
    assert_eq!(
        warm.compensate(&at(reach.radius + 1.0), false).status,
        CompensationStatus::Ok
    );
}

#[test]
fn a_solve_that_cannot_converge_gives_up_early() {
    let (nominal, cal) = robots();
    let comp = Compensator::new(&nominal, &cal).unwrap();
    let home = comp.home();
    let far = Vector3::new(5000.0, 0.0, 0.0);
    let back = rpy_matrix(0.3, 2.5, 0.2);
    for (model, rot) in [
        (Model::Calibrated, None),
        (Model::Nominal, None),
        (Model::Calibrated, Some(&back)),
    ] {
        let Err(failed) = comp.solve_on(model, &far, rot, &home, f64::INFINITY) else {
            panic!("converged on a target 5 m away");
        };
        assert!(failed.iterations < 20, "{}", failed.iterations);
    }
    // The last step is never taken: the budget, not one more.
    let mut c = comp.clone();
    c.max_iterations = 3;
    let Err(failed) = c.solve_on(Model::Calibrated, &far, None, &home, f64::INFINITY) else {
        panic!()
    };
    assert!(failed.iterations <= 3);
    // A target within reach converges from home as before.
    let q = [0.3, 0.2, 0.4, 0.1, 0.5, 0.0];
    let (t, r) = comp.nominal_pose(&q);
    let sol = comp.solve(&t, Some(&r), &q, f64::INFINITY).ok().unwrap();
    assert!(sol.residual_mm < 1e-3);
}

/// The singular-pose test from the eigenvalues of `j jᵀ` says what the
/// SVD of `j` said (smallest singular value under 2 % of the largest), on
/// random task Jacobians of both sizes, on each side of the threshold and
/// close to it, and on rank-deficient ones.
#[test]
fn the_singular_pose_test_agrees_with_the_svd() {
    use nalgebra::DMatrix;
    let mut rng = Rng::new(21);
    let mut near = 0;
    for m in [3, 6] {
        for _ in 0..2000 {
            let n = if rng.range(0.0, 1.0) < 0.8 { 6 } else { 7 };
            // j = U diag(s) Vᵀ with chosen singular values: a random
            // matrix's QR gives the orthonormal factors.
            let u = DMatrix::from_fn(m, m, |_, _| rng.normal()).qr().q();
            let v = DMatrix::from_fn(n, m, |_, _| rng.normal()).qr().q();
            let scale = 10f64.powf(rng.range(-1.0, 4.0));
            let mut s: Vec<f64> = (0..m).map(|_| scale * rng.range(0.05, 1.0)).collect();
            s[0] = scale;
            s[m - 1] = scale
                * match rng.range(0.0, 1.0) {
                    x if x < 0.4 => 0.02 * (1.0 + rng.range(-1e-6, 1e-6)),
                    x if x < 0.5 => 0.0,
                    _ => rng.range(0.0, 0.1),
                };
            let j = &u * DMatrix::from_diagonal(&nalgebra::DVector::from_vec(s)) * v.transpose();
            let sv = j.clone().singular_values();
            let by_svd = !(sv.min() > 0.02 * sv.max());
            near += usize::from((sv.min() / sv.max() / 0.02 - 1.0).abs() < 1e-5);
            assert_eq!(solve::singular_task_jacobian(&j), by_svd, "{j}");
        }
    }
    assert!(near > 1000, "only {near} within 1e-5 of the threshold");
    // Fewer joints than the task has rows: never singular for it.
    assert!(!solve::singular_task_jacobian(&DMatrix::zeros(3, 2)));
    // Non-finite: singular, and answered (not left to the eigenvalue
    // iterations).
    for bad in [f64::NAN, f64::INFINITY] {
        let mut j = DMatrix::identity(6, 6);
        j[(2, 3)] = bad;
        assert!(solve::singular_task_jacobian(&j));
        let mut j = DMatrix::identity(3, 6);
        j[(0, 5)] = bad;
        assert!(solve::singular_task_jacobian(&j));
    }
}
