//! Compensation with the physics the analysis found, checked against the
//! simulator's truth: on a dataset with a compliant joint, joint targets
//! compensated with the calibration (geometry + accepted compliance) put
//! the true T much nearer the target than a geometric-only calibration.

use crate::common;
use drawcal::compensate::Compensator;
use drawcal::identify::{IdentifyOptions, NoProgress};
use drawcal::kinematics::Params;
use drawcal::kinematics::chain::{Chain, OutputFrame};
use drawcal::kinematics::rpy_matrix;
use drawcal::model::{BasePose, Robot, Target, TargetKind};
use drawcal::physics::effects::{Basis, Context, PoseInput};
use drawcal::physics::simulate::{self, Spec};
use drawcal::pipeline::{self, calibrate};
use nalgebra::{Matrix3, Vector3};

fn base_rt(b: &BasePose) -> (Matrix3<f64>, Vector3<f64>) {
    (
        rpy_matrix(
            b.rpy_deg[0].to_radians(),
            b.rpy_deg[1].to_radians(),
            b.rpy_deg[2].to_radians(),
        ),
        Vector3::from(b.xyz_mm),
    )
}

/// T of `robot` at `q` in its own base frame (tool point included).
fn point(robot: &Robot, q: &[f64]) -> Vector3<f64> {
    let p = Params::of_robot(robot);
    Chain::new(robot.convention, robot.dof(), 0)
        .point(&p.values, q, OutputFrame::Base)
        .1
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// A session simulated from `spec` and calibrated with the physics, which
/// must have named `effect` on `joint`.
struct Calibrated {
    sim: simulate::Simulated,
    report: drawcal::report::Report,
    true_robot: Robot,
    /// The true base in the rig: rotation and translation.
    rt: Matrix3<f64>,
    tt: Vector3<f64>,
}

impl Calibrated {
    /// Where the real robot puts T (rig frame) when commanded `q` carrying
    /// `payload_kg`: the true geometry at the angles the true (single-pose)
    /// effects deflect it to.
    fn true_point(&self, q: &[f64], payload_kg: Option<f64>) -> Vector3<f64> {
        let ctx = Context::new(
            &self.sim.robot,
            vec![],
            0.0,
            &Matrix3::identity(),
            &[PoseInput {
                q_rad: q,
                time_s: None,
                temp_c: None,
                payload_kg,
                point_rig: Vector3::zeros(),
            }],
        );
        let mut buf = Basis::default();
        let dq = ctx.apply(&self.sim.effects, 0, &mut buf).dq;
        let qe: Vec<f64> = q.iter().zip(&dq).map(|(a, b)| a + b).collect();
        self.rt * point(&self.true_robot, &qe) + self.tt
    }
}

fn calibrated(spec: serde_json::Value, effect: &str, joint: Option<usize>) -> Calibrated {
    let spec: Spec = serde_json::from_value(spec).unwrap();
    let sim = simulate::generate(&spec).unwrap();
    let true_robot: Robot = serde_json::from_value(sim.truth["true_robot"].clone()).unwrap();
    let true_base: BasePose = serde_json::from_value(sim.truth["base_in_rig"].clone()).unwrap();
    let (rt, tt) = base_rt(&true_base);
    let report = calibrate(
        &sim.robot,
        &sim.rig,
        &sim.dataset,
        &pipeline::Options::default(),
        &NoProgress,
    )
    .unwrap();
    assert!(
        report
            .findings
            .iter()
            .any(|f| f.effect == effect && f.joint == joint),
        "{} seed {}: {:#?}",
        spec.robot,
        spec.seed,
        report.findings
    );
    Calibrated {
        sim,
        report,
        true_robot,
        rt,
        tt,
    }
}

#[test]
fn compensation_with_compliance_beats_geometry_only() {
    check_joint_effect_compensation("er3a", 4242, "joint_compliance", 2);
}

#[test]
fn compensation_with_a_joint_scale_error_beats_geometry_only() {
    check_joint_effect_compensation("ur5", 4243, "joint_scale", 2);
}

/// A pose-dependent joint effect about ten times the point noise, on
/// `joint`: compensation with the accepted effect puts the true T on the
/// target far better than geometry alone.
fn check_joint_effect_compensation(robot: &str, seed: u64, effect: &str, joint: usize) {
    let cal = calibrated(
        serde_json::json!({
            "robot": robot,
            "n_poses": 120,
            "seed": seed,
            "effects": [{"effect": effect, "joint": joint, "size_x_noise": 10}]
        }),
        effect,
        Some(joint),
    );
    let (sim, with) = (&cal.sim, &cal.report);
    let without = calibrate(
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
    assert!(without.findings.is_empty());

    // Where the real robot puts T (rig frame) when commanded `q`: the true
    // geometry at the angles the true effect deflects it to.
    let true_t = |q: &[f64]| cal.true_point(q, None);

    // Targets: nominal joint poses across the workspace (the dataset's test
    // poses). Each calibration states the target in its own base frame: the
    // error is the true T against the nominal point placed by that base.
    let targets: Vec<Vec<f64>> = sim
        .dataset
        .poses
        .iter()
        .enumerate()
        .filter(|(i, _)| i % 3 == 0)
        .map(|(_, p)| p.q_rad.clone())
        .collect();
    let errors = |report: &drawcal::report::Report| -> (Vec<f64>, Vec<f64>) {
        let comp = Compensator::from_report(report).unwrap();
        let (rb, tb) = base_rt(&report.base_in_rig);
        let (mut compensated, mut raw) = (vec![], vec![]);
        for (k, q) in targets.iter().enumerate() {
            let goal = rb * point(&sim.robot, q) + tb;
            let target = Target {
                target: format!("t{k}"),
                kind: TargetKind::Joints {
                    q_deg: q.iter().map(|v| v.to_degrees()).collect(),
                },
            };
            let c = comp.compensate(&target, false);
            let qc: Vec<f64> = c
                .q_deg
                .unwrap_or_else(|| panic!("target {k}: {:?}", c.message))
                .iter()
                .map(|v| v.to_radians())
                .collect();
            compensated.push((true_t(&qc) - goal).norm());
            raw.push((true_t(q) - goal).norm());
        }
        (compensated, raw)
    };
    let (phys, raw) = errors(&with);
    let (geo, _) = errors(&without);
    let (r_phys, r_geo, r_raw) = (rms(&phys), rms(&geo), rms(&raw));
    let msg = format!(
        "true T to target RMS over {} targets: uncompensated {r_raw:.4} mm, geometric-only {r_geo:.4} mm, with physics {r_phys:.4} mm",
        targets.len()
    );
    eprintln!("{msg}");
    // The effect is about ten times the point noise: geometry alone cannot
    // model a pose-dependent deflection, the accepted effect can.
    assert!(r_geo < r_raw, "{msg}");
    assert!(r_phys < 0.5 * r_geo, "{msg}");
    // With the effect modelled, what remains is estimation noise of the
    // calibration (well under the point noise of one measurement).
    assert!(r_phys < sim.point_noise_mm, "{msg}");
}

/// Thermal expansion driven by the temperature: the calibration holds at
/// the session's reference temperature; compensating at the temperature the
/// robot runs at puts the true T (true geometry grown by its true thermal
/// coefficient) far nearer the target than compensating at the reference.
#[test]
fn compensation_at_the_running_temperature_beats_the_reference() {
    let Calibrated {
        sim,
        report,
        true_robot,
        rt,
        tt,
    } = calibrated(
        serde_json::json!({
            "robot": "er3a",
            "n_poses": 120,
            "seed": 777,
            "effects": [{"effect": "thermal_expansion", "size_x_noise": 10}]
        }),
        "thermal_expansion",
        None,
    );
    let true_k = sim.effects[0].coef[0];
    let t_ref = sim.dataset.poses[0].temp_c.unwrap();
    let finding = report
        .findings
        .iter()
        .find(|f| f.effect == "thermal_expansion")
        .unwrap();
    assert_eq!(common::params(&finding)["driver"], "temperature");
    assert_eq!(
        common::params(&finding)["reference_temp_c"].as_f64(),
        Some(t_ref)
    );

    let comp = Compensator::from_report(&report).unwrap();
    let info = comp.thermal().expect("a temperature-driven thermal effect");
    assert_eq!(info.reference_temp_c, t_ref);
    assert_eq!(comp.temperature_c(), Some(t_ref));
    assert!(
        (info.coef_per_k - true_k).abs() < 0.2 * true_k.abs(),
        "fitted {} /K, true {true_k} /K",
        info.coef_per_k
    );

    // Far outside the session's few kelvin of warm-up.
    let t_run = t_ref + 30.0;
    let warm = comp.at_temperature(t_run);
    assert_eq!(warm.temperature_c(), Some(t_run));
    // The true robot at t_run: its geometry grown by the true coefficient.
    let lengths = drawcal::physics::effects::nominal_lengths(&sim.robot);
    let mut p_run = Params::of_robot(&true_robot);
    for &(i, v) in &lengths {
        p_run.values[i] += true_k * (t_run - t_ref) * v;
    }
    let chain = Chain::new(true_robot.convention, true_robot.dof(), 0);
    let true_t = |q: &[f64]| rt * chain.point(&p_run.values, q, OutputFrame::Base).1 + tt;

    let (rb, tb) = base_rt(&report.base_in_rig);
    let (mut at_ref, mut at_run) = (vec![], vec![]);
    let mut n_targets = 0;
    for (k, p) in sim
        .dataset
        .poses
        .iter()
        .enumerate()
        .filter(|(i, _)| i % 3 == 0)
    {
        let goal = rb * point(&sim.robot, &p.q_rad) + tb;
        let target = Target {
            target: format!("t{k}"),
            kind: TargetKind::Joints {
                q_deg: p.q_rad.iter().map(|v| v.to_degrees()).collect(),
            },
        };
        // Targets at the edge of a joint limit may need a joint past it
        // at one temperature: skipped (counted below).
        let q_of = |c: drawcal::compensate::Compensated| -> Option<Vec<f64>> {
            Some(c.q_deg?.iter().map(|v| v.to_radians()).collect())
        };
        n_targets += 1;
        let (Some(q_ref), Some(q_run)) = (
            q_of(comp.compensate(&target, false)),
            q_of(warm.compensate(&target, false)),
        ) else {
            continue;
        };
        // At the reference temperature nothing changes.
        assert_eq!(
            q_of(comp.at_temperature(t_ref).compensate(&target, false)),
            Some(q_ref.clone())
        );
        at_ref.push((true_t(&q_ref) - goal).norm());
        at_run.push((true_t(&q_run) - goal).norm());
    }
    assert!(
        at_ref.len() * 10 >= n_targets * 9,
        "{} of {n_targets} compensated",
        at_ref.len()
    );
    let (r_ref, r_run) = (rms(&at_ref), rms(&at_run));
    let msg = format!(
        "true T to target RMS at {t_run:.1} C (reference {t_ref:.2} C, k {:.2} ppm/K fitted, {:.2} true) over {} targets: compensated at the reference {r_ref:.4} mm, at the running temperature {r_run:.4} mm (point noise {:.4} mm)",
        info.coef_per_k * 1e6,
        true_k * 1e6,
        at_ref.len(),
        sim.point_noise_mm
    );
    eprintln!("{msg}");
    // Measured: about 4.2 mm at the reference, 0.04 mm at the running
    // temperature (what is left is the fitted coefficient's error
    // extrapolated 30 K beyond a session that warmed up by a few).
    assert!(r_run < 0.05 * r_ref, "{msg}");
    assert!(r_ref > 1.0, "{msg}");
}

/// A compliant joint deflects under the payload's gravity torque too: a
/// session that swapped test weights (0, 12 and 4 kg, median 4) is
/// calibrated, then compensated for a robot carrying 12 kg. Given the
/// payload, the compensation puts the true T (true geometry, deflected by
/// the true compliance under 12 kg) far nearer the target than assuming the
/// session's median. With link masses (er3a: one compliance in rad/(N·m))
/// and without (ur5: unit-mass regressors, the payload's lever fitted from
/// the swaps).
fn check_payload_compensation(robot: &str, seed: u64) {
    let cal = calibrated(
        serde_json::json!({
            "robot": robot,
            "n_poses": 120,
            "seed": seed,
            "session": {"payload_kg": [0.0, 12.0, 4.0]},
            "effects": [{"effect": "joint_compliance", "joint": 2, "size_x_noise": 10}]
        }),
        "joint_compliance",
        Some(2),
    );
    let (sim, report) = (&cal.sim, &cal.report);
    let comp = Compensator::from_report(&report).unwrap();
    assert_eq!(
        comp.payload_kg(),
        Some(4.0),
        "{robot}: the session's median"
    );
    let run_kg = 12.0;
    let loaded = comp.with_payload_kg(run_kg);
    assert_eq!(loaded.payload_kg(), Some(run_kg));

    // The real robot carrying `run_kg`, commanded `q` (rig frame).
    let true_t = |q: &[f64]| cal.true_point(q, Some(run_kg));
    let (rb, tb) = base_rt(&report.base_in_rig);
    let (mut assumed, mut given) = (vec![], vec![]);
    for (k, p) in sim.dataset.poses.iter().enumerate().step_by(3) {
        let goal = rb * point(&sim.robot, &p.q_rad) + tb;
        let target = Target {
            target: format!("t{k}"),
            kind: TargetKind::Joints {
                q_deg: p.q_rad.iter().map(|v| v.to_degrees()).collect(),
            },
        };
        let q_of = |c: drawcal::compensate::Compensated| -> Option<Vec<f64>> {
            Some(c.q_deg?.iter().map(|v| v.to_radians()).collect())
        };
        let (Some(q_a), Some(q_g)) = (
            q_of(comp.compensate(&target, false)),
            q_of(loaded.compensate(&target, false)),
        ) else {
            continue;
        };
        assumed.push((true_t(&q_a) - goal).norm());
        given.push((true_t(&q_g) - goal).norm());
    }
    assert!(assumed.len() >= 30, "{robot}: {} targets", assumed.len());
    let (r_assumed, r_given) = (rms(&assumed), rms(&given));
    let msg = format!(
        "{robot}: true T to target RMS with {run_kg} kg over {} targets: compensated for the session's 4 kg {r_assumed:.4} mm, for {run_kg} kg {r_given:.4} mm (point noise {:.4} mm)",
        given.len(),
        sim.point_noise_mm
    );
    eprintln!("{msg}");
    assert!(r_given < 0.5 * r_assumed, "{msg}");
    assert!(r_given < sim.point_noise_mm, "{msg}");
}

#[test]
fn compensation_with_the_running_payload_beats_the_session_median() {
    check_payload_compensation("er3a", 5);
    check_payload_compensation("ur5", 6);
}

/// Without a compliance the payload changes nothing, and says so.
#[test]
fn payload_does_not_matter_without_a_compliance() {
    let (robot, rig, data) = {
        let spec: Spec = serde_json::from_value(serde_json::json!({
            "robot": "ur5", "n_poses": 60, "seed": 11, "effects": []
        }))
        .unwrap();
        let sim = simulate::generate(&spec).unwrap();
        (sim.robot, sim.rig, sim.dataset)
    };
    let report = calibrate(
        &robot,
        &rig,
        &data,
        &pipeline::Options::default(),
        &NoProgress,
    )
    .unwrap();
    assert!(report.findings.is_empty(), "{:#?}", report.findings);
    let comp = Compensator::from_report(&report).unwrap();
    assert_eq!(comp.payload_kg(), None);
    let target = Target {
        target: "t".into(),
        kind: TargetKind::Joints {
            q_deg: vec![10.0, -60.0, 70.0, -20.0, 80.0, 15.0],
        },
    };
    assert_eq!(
        comp.with_payload_kg(50.0).compensate(&target, false),
        comp.compensate(&target, false)
    );
}

/// Backlash: where a joint stops depends on the side it arrives from. A
/// program visits its targets in order, so `compensate_in_order` takes
/// each joint's approach from the move out of the previous target; the
/// default assumes every joint arrives in +q. Against the simulator's
/// truth (the true backlash, with the approach of the commanded sequence),
/// over poses visited in the recording's order, the first left out (its
/// approach from home is not in the list).
#[test]
fn compensation_in_visiting_order_follows_the_backlash() {
    let Calibrated {
        sim,
        report,
        true_robot,
        rt,
        tt,
    } = calibrated(
        serde_json::json!({
            "robot": "er3a",
            "n_poses": 150,
            "seed": 31,
            "effects": [{"effect": "backlash", "joint": 2, "size_x_noise": 10}]
        }),
        "backlash",
        Some(2),
    );
    let comp = Compensator::from_report(&report).unwrap();
    assert!(comp.has_backlash());
    let (rb, tb) = base_rt(&report.base_in_rig);
    let poses: Vec<&[f64]> = sim
        .dataset
        .poses
        .iter()
        .take(60)
        .map(|p| p.q_rad.as_slice())
        .collect();
    let targets: Vec<Target> = poses
        .iter()
        .enumerate()
        .map(|(k, q)| Target {
            target: format!("t{k}"),
            kind: TargetKind::Joints {
                q_deg: q.iter().map(|v| v.to_degrees()).collect(),
            },
        })
        .collect();
    // The true T of a commanded sequence: each joint deflected by the true
    // backlash for the direction the sequence moves it in.
    let errors = |rows: &[drawcal::compensate::Compensated]| -> Vec<f64> {
        let qs: Vec<Vec<f64>> = rows
            .iter()
            .map(|r| {
                r.q_deg
                    .as_ref()
                    .unwrap_or_else(|| panic!("{:?}", r.message))
                    .iter()
                    .map(|v| v.to_radians())
                    .collect()
            })
            .collect();
        let inputs: Vec<PoseInput> = qs
            .iter()
            .map(|q| PoseInput {
                q_rad: q,
                time_s: None,
                temp_c: None,
                payload_kg: None,
                point_rig: Vector3::zeros(),
            })
            .collect();
        let ctx = Context::new(&sim.robot, vec![], 0.0, &Matrix3::identity(), &inputs);
        let mut buf = Basis::default();
        (1..qs.len())
            .map(|i| {
                let dq = ctx.apply(&sim.effects, i, &mut buf).dq;
                let qe: Vec<f64> = qs[i].iter().zip(&dq).map(|(a, b)| a + b).collect();
                let goal = rb * point(&sim.robot, poses[i]) + tb;
                (rt * point(&true_robot, &qe) + tt - goal).norm()
            })
            .collect()
    };
    let positive = rms(&errors(&drawcal::compensate::compensate_all(
        &comp, &targets, false,
    )));
    let in_order = rms(&errors(&drawcal::compensate::compensate_in_order(
        &comp, &targets, false,
    )));
    let msg = format!(
        "true T to target RMS over {} targets visited in order: assuming +q approach {positive:.4} mm, approach from the previous target {in_order:.4} mm (point noise {:.4} mm)",
        targets.len() - 1,
        sim.point_noise_mm
    );
    eprintln!("{msg}");
    assert!(in_order < 0.5 * positive, "{msg}");
    assert!(in_order < sim.point_noise_mm, "{msg}");
}
