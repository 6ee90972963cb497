//! A robot mount that tilts under the arm's gravity moment (`base_tilt`),
//! concealed in simulated recordings and analysed blind. It is nearly the
//! shape of joint 2's compliance (the moment about the base is, but for the
//! wrist offsets and link 1, joint 2's gravity torque); the two differ by
//! the tilt's lever from the base origin rather than from joint 2's axis.
//! Each must be named as itself, with its size, and compensation must
//! apply the tilt.

use nalgebra::Vector3;

use drawcal::compensate::Compensator;
use drawcal::model::{BasePose, Split, TargetKind};
use drawcal::physics::simulate;

fn simulate(seed: u64, effect: serde_json::Value) -> simulate::Simulated {
    let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
        "robot": "er3a", "n_poses": 150, "seed": seed, "effects": [effect]
    }))
    .unwrap();
    simulate::generate(&spec).unwrap()
}

#[test]
fn a_tilting_base_and_joint_2_compliance_are_each_named_as_themselves() {
    for seed in [3, 4] {
        let tilt = simulate(
            seed,
            serde_json::json!({"effect": "base_tilt", "size_x_noise": 4}),
        );
        let r = crate::common::identify_default_sim(&tilt);
        assert_eq!(
            crate::common::named(&r),
            [("base_tilt".to_string(), None)],
            "seed {seed}"
        );
        crate::common::assert_size_within_3_sigma(&tilt, &r.findings[0], &format!("seed {seed}"));

        let compliance = simulate(
            seed,
            serde_json::json!({"effect": "joint_compliance", "joint": 2, "size_x_noise": 4}),
        );
        assert_eq!(
            crate::common::named(&crate::common::identify_default_sim(&compliance)),
            [("joint_compliance".to_string(), Some(2))],
            "seed {seed}"
        );
    }
}

#[test]
fn compensation_applies_a_tilting_base() {
    let sim = simulate(
        5,
        serde_json::json!({"effect": "base_tilt", "size_x_noise": 6}),
    );
    let report = crate::common::identify_default_sim(&sim);
    assert_eq!(
        crate::common::named(&report),
        [("base_tilt".to_string(), None)]
    );
    // The truth as a report: the true robot, base and tilt, so that its
    // compensator's calibrated pose is where the real robot puts T.
    let mut truth = report.clone();
    truth.calibrated_robot = serde_json::from_value(sim.truth["true_robot"].clone()).unwrap();
    truth.base_in_rig = serde_json::from_value(sim.truth["base_in_rig"].clone()).unwrap();
    if let Some(drawcal::report::FindingModel::Effect(p)) = &mut truth.findings[0].parameters {
        p.model.coef = sim.effects[0].coef.clone();
    }
    let real = Compensator::from_report(&truth).unwrap();
    let frame = |b: &BasePose| {
        let [r, p, y] = b.rpy_deg.map(f64::to_radians);
        (
            drawcal::kinematics::rpy_matrix(r, p, y),
            Vector3::from(b.xyz_mm),
        )
    };
    let (rot_true, t_true) = frame(&truth.base_in_rig);
    let (rot, t_cal) = frame(&report.base_in_rig);
    let comp = Compensator::from_report(&report).unwrap();
    let mut without = report.clone();
    without.findings.clear();
    let comp_without = Compensator::from_report(&without).unwrap();
    let (mut with_sq, mut without_sq, mut n) = (0.0, 0.0, 0.0);
    for pose in sim
        .dataset
        .poses
        .iter()
        .filter(|p| p.split == Some(Split::Test))
    {
        // A joint target: T where the nominal model puts the taught joints.
        let target = drawcal::model::Target {
            target: pose.id.clone(),
            kind: TargetKind::Joints {
                q_deg: pose.q_rad.iter().map(|v| v.to_degrees()).collect(),
            },
        };
        let wanted = rot * comp.nominal_pose(&pose.q_rad).0 + t_cal;
        // A target the compensation refuses (a joint at its limit) is
        // skipped for both.
        let miss = |c: &Compensator| {
            let q: Vec<f64> = c
                .compensate(&target, false)
                .q_deg?
                .iter()
                .map(|v| v.to_radians())
                .collect();
            Some((rot_true * real.calibrated_pose(&q).0 + t_true - wanted).norm())
        };
        let (Some(with), Some(without)) = (miss(&comp), miss(&comp_without)) else {
            continue;
        };
        with_sq += with.powi(2);
        without_sq += without.powi(2);
        n += 1.0;
    }
    assert!(n >= 20.0, "{n} targets compensated");
    let (with_rms, without_rms) = ((with_sq / n).sqrt(), (without_sq / n).sqrt());
    eprintln!("compensated: {with_rms:.4} mm with the tilt, {without_rms:.4} mm without");
    assert!(
        with_rms < 0.5 * without_rms,
        "compensated targets land {with_rms:.4} mm RMS from the truth with the tilt, {without_rms:.4} mm without"
    );
}
