//! Every effect's analytic derivative (through the augmented problem's
//! Jacobian rows) against central finite differences of the residuals.

use drawcal::identify::{IdentifyOptions, Observations};
use drawcal::kinematics::Params;
use drawcal::model::{Dataset, Rig, Robot};
use drawcal::physics::effects::{Kind, ThermalDriver};
use drawcal::physics::problem::EffectProblem;
use drawcal::physics::{EffectModel, effect_context};

fn load(dir: &str) -> (Robot, Rig, Dataset) {
    let robot =
        Robot::from_json(&std::fs::read_to_string(format!("{dir}/robot.json")).unwrap()).unwrap();
    let rig = Rig::from_json(&std::fs::read_to_string(format!("{dir}/rig.json")).unwrap()).unwrap();
    let data = Dataset::from_csv(
        std::fs::File::open(format!("{dir}/poses.csv")).unwrap(),
        &robot,
        &rig,
    )
    .unwrap();
    (robot, rig, data)
}

fn residuals(p: &EffectProblem, x: &[f64]) -> Vec<f64> {
    let mut r = Vec::new();
    p.rows(x, |_, v, _| r.push(v));
    r
}

fn check(dir: &str, kinds: Vec<(Kind, Vec<f64>)>) {
    let (robot, rig, data) = load(dir);
    let opts = IdentifyOptions::default();
    let s = Observations::new(&robot, &rig, &data, &opts).unwrap();
    let base = rig.base_in_rig.unwrap();
    let p0 = Params::nominal(&robot, &base, &rig, data.n_strings);
    let ctx = effect_context(&s, &p0);
    let effects: Vec<EffectModel> = kinds
        .into_iter()
        .map(|(kind, coef)| EffectModel { kind, coef })
        .collect();
    let l = p0.layout;
    // Free: a few geometric parameters of each kind, plus every coefficient.
    let mut free = vec![
        l.joint(1, drawcal::kinematics::JointParam::Theta),
        l.joint(2, drawcal::kinematics::JointParam::A),
        l.base() + 1,
        l.base() + 4,
        l.tool() + 2,
    ];
    if l.n_strings > 0 {
        free.push(l.string_offset(0));
        free.push(l.r());
    }
    let problem = EffectProblem {
        chain: s.chain,
        ctx: &ctx,
        data: &data,
        poses: (0..data.poses.len().min(25)).collect(),
        full: p0.values.clone(),
        free,
        effects,
    };
    let x = problem.x0();
    let mut rows: Vec<Vec<f64>> = Vec::new();
    problem.rows(&x, |_, _, row| rows.push(row.to_vec()));
    for c in 0..x.len() {
        // A step that moves the residuals by about a micrometre: small
        // enough for the curvature, large against rounding.
        let slope = rows
            .iter()
            .map(|r| r[c].abs())
            .fold(0.0, f64::max)
            .max(1e-12);
        let h = 1e-3 / slope;
        let mut xp = x.clone();
        xp[c] += h;
        let mut xm = x.clone();
        xm[c] -= h;
        let rp = residuals(&problem, &xp);
        let rm = residuals(&problem, &xm);
        for (i, row) in rows.iter().enumerate() {
            let fd = (rp[i] - rm[i]) / (2.0 * h);
            let scale = 1.0 + fd.abs().max(row[c].abs());
            assert!(
                (fd - row[c]).abs() < 2e-5 * scale,
                "{dir}: column {c} row {i}: analytic {} finite difference {fd}",
                row[c]
            );
        }
    }
}

#[test]
fn string_effects_match_finite_differences() {
    // er3a has link masses: one compliance coefficient.
    check(
        "tests/data/er3a_compliance_j2",
        vec![
            (
                Kind::JointCompliance {
                    joint_index: 1,
                    regressors: vec![],
                },
                vec![4e-5],
            ),
            (Kind::Backlash { joint_index: 2 }, vec![2e-4, -1e-4]),
            (
                Kind::JointPeriodic {
                    joint_index: 3,
                    harmonic: 1,
                },
                vec![1e-4, -2e-4],
            ),
            (
                Kind::JointPeriodic {
                    joint_index: 0,
                    harmonic: 2,
                },
                vec![3e-4, 1e-4],
            ),
            (
                Kind::ThermalExpansion {
                    driver: ThermalDriver::Temperature,
                    tau_h: None,
                },
                vec![2e-5],
            ),
            (Kind::JointScale { joint_index: 2 }, vec![3e-4]),
            (Kind::SensorScale { sensor_index: 1 }, vec![1e-4]),
            (Kind::SensorOffset { sensor_index: 2 }, vec![0.1]),
            (Kind::SensorDrift { sensor_index: 0 }, vec![0.2]),
            (Kind::CableSag, vec![0.05]),
            (
                Kind::AnchorStep {
                    sensor_index: 3,
                    t0_s: 600.0,
                },
                vec![0.3, -0.2, 0.1],
            ),
            (
                Kind::RigStep { t0_s: 300.0 },
                vec![0.2, -0.1, 0.3, 0.05, -0.04, 0.02],
            ),
            (Kind::RigDrift, vec![0.1, 0.2, -0.1, 0.03, 0.01, -0.02]),
        ],
    );
}

#[test]
fn point_data_and_mass_free_compliance_match_finite_differences() {
    // The UR10 has no link masses: unit-mass regressors.
    check(
        "tests/data/real_ur10_ipa_random",
        vec![
            (
                Kind::JointCompliance {
                    joint_index: 1,
                    regressors: vec![2, 4, 6],
                },
                vec![1e-4, -5e-5, 2e-5],
            ),
            (
                Kind::JointPeriodic {
                    joint_index: 2,
                    harmonic: 1,
                },
                vec![1e-4, -2e-4],
            ),
            (
                // A warm-up that settles (the driver of a session
                // without temperature): the basis is the settling curve.
                Kind::ThermalExpansion {
                    driver: ThermalDriver::Time,
                    tau_h: Some(0.5),
                },
                vec![2e-5],
            ),
            (Kind::Backlash { joint_index: 0 }, vec![1e-4, 3e-4]),
            (
                Kind::RigStep { t0_s: 10.5 },
                vec![0.2, -0.1, 0.3, 0.05, -0.04, 0.02],
            ),
            (Kind::RigDrift, vec![0.1, 0.2, -0.1, 0.03, 0.01, -0.02]),
        ],
    );
}

#[test]
fn compliance_uses_the_gravity_torque_sign_of_the_reference() {
    // The reference simulator's compliance deflects joint 2 by +c·τ; the
    // shared dataset's fitted coefficient must come out positive and near
    // truth (checked loosely here; the analysis test checks 3 sigma).
    let (robot, rig, data) = load("tests/data/er3a_compliance_j2");
    let opts = IdentifyOptions::default();
    let s = Observations::new(&robot, &rig, &data, &opts).unwrap();
    let g = drawcal::identify::geometric(&s, &opts, &drawcal::identify::NoProgress).unwrap();
    let a = drawcal::physics::analyse(&s, &g, &drawcal::identify::NoProgress).unwrap();
    let f = &a.findings[0];
    assert_eq!(f.effect, "joint_compliance");
    assert!(f.magnitude > 0.0);
}
