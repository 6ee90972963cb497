//! Acceptance tests of the calibration engine on the shared datasets (copied
//! under tests/data): accuracy against truth.json, the noise floor, the
//! identifiable parameters, and the real recordings.

use crate::common;

use drawcal::identify::{IdentifyOptions, Method, NoProgress};
use drawcal::kinematics::Params;
use drawcal::kinematics::chain::{Chain, OutputFrame};
use drawcal::model::{Dataset, Measurement};
use drawcal::report::Report;
use nalgebra::Vector3;

fn geometric_only() -> IdentifyOptions {
    IdentifyOptions::default()
}

fn true_points(name: &str) -> Vec<Vector3<f64>> {
    common::true_points(&common::truth(name))
}

/// RMS distance between the calibrated model's T and the true T over the
/// held-out poses.
fn model_vs_truth_mm(name: &str, rep: &Report, data: &Dataset, n_strings: usize) -> f64 {
    let truth = true_points(name);
    let p = Params::nominal(
        &rep.calibrated_robot,
        &rep.base_in_rig,
        &common::load(name).1,
        n_strings,
    );
    let chain = Chain::new(
        rep.calibrated_robot.convention,
        rep.calibrated_robot.dof(),
        n_strings,
    );
    let mut ss = 0.0;
    let mut n = 0;
    for (i, pose) in data.poses.iter().enumerate() {
        if rep.held_out.contains(&pose.id) {
            let (_, t) = chain.point(&p.values, &pose.q_rad, OutputFrame::Rig);
            ss += (t - truth[i]).norm_squared();
            n += 1;
        }
    }
    (ss / n as f64).sqrt()
}

fn check_simulated(name: &str) {
    let (robot, rig, data) = common::load(name);
    let rep =
        common::calibrate_geometric(&robot, &rig, &data, &geometric_only(), &NoProgress).unwrap();
    let truth = common::truth(name);
    let point_noise = truth["point_noise_mm"].as_f64().unwrap();
    let floor = rep.noise_floor_mm.unwrap();
    let after = rep.stats.test.after.rms_mm;
    // Our floor is estimated from the strings' redundancy; it must agree
    // with the simulator's point noise to within its sampling error.
    assert!(
        (floor / point_noise - 1.0).abs() < 0.25,
        "{name}: floor {floor} vs simulated point noise {point_noise}"
    );
    // Held-out accuracy within 1.2x the noise floor as the simulator
    // measured it (against our estimate of it, see docs/CLI.md's honest
    // limits on er3a_paper_like: its string sigma came out 12 % low).
    assert!(
        after < 1.2 * point_noise,
        "{name}: test RMS {after} vs point noise {point_noise}"
    );
    assert!(
        rep.stats.test.before.rms_mm > 20.0 * after,
        "{name}: calibration must remove most of the error"
    );
    let vs_truth = model_vs_truth_mm(name, &rep, &data, rig.n_strings());
    eprintln!(
        "{name}: calibrated model {vs_truth:.4} mm RMS from the true points (held-out poses)"
    );
    assert!(
        vs_truth < 0.03,
        "{name}: calibrated model {vs_truth} mm RMS from the true points"
    );
    // Identifiable parameters within 3 sigma of the mapped truth.
    let mapped = common::mapped_truth(&robot, &rig, &data, &true_points(name), &rep);
    assert!(
        mapped.stats.train.after.rms_mm < 2e-3,
        "{name}: the model must represent the truth exactly"
    );
    for p in &rep.parameters {
        let t = mapped
            .parameters
            .iter()
            .find(|q| q.name == p.name)
            .unwrap_or_else(|| panic!("{name}: {} not identified on exact data", p.name));
        let z = (p.value - t.value) / p.sigma;
        assert!(
            z.abs() < 3.0,
            "{name}: {} = {} ± {} but truth maps to {} ({z:.1} sigma)",
            p.name,
            p.value,
            p.sigma,
            t.value
        );
    }
    // Aliases named as a calibration engineer expects.
    assert!(
        rep.fixed.contains(&"j3.d".to_string()),
        "{name}: d3 aliases d2 along parallel axes: {:?}",
        rep.fixed
    );
    assert!(
        rep.fixed.contains(&"j6.d".to_string()),
        "{name}: d6 aliases the tool point: {:?}",
        rep.fixed
    );
    // The paper's method is reported beside, and is worse.
    let paper = rep.paper_stats.expect("paper comparison");
    assert!(paper.test.after.rms_mm > after);
}

#[test]
fn er3a_paper_like_reaches_the_noise_floor_and_the_truth() {
    check_simulated("er3a_paper_like");
}

#[test]
fn ur5_geometric_reaches_the_noise_floor_and_the_truth() {
    check_simulated("ur5_geometric");
    let (robot, rig, data) = common::load("ur5_geometric");
    let rep =
        common::calibrate_geometric(&robot, &rig, &data, &geometric_only(), &NoProgress).unwrap();
    assert!(rep.stats.test.after.rms_mm < 1.2 * rep.noise_floor_mm.unwrap());
}

#[test]
fn paper_method_runs_as_published() {
    let (robot, rig, data) = common::load("er3a_paper_like");
    let opts = IdentifyOptions {
        method: Method::Paper,
        ..geometric_only()
    };
    let rep = common::calibrate_geometric(&robot, &rig, &data, &opts, &NoProgress).unwrap();
    assert_eq!(rep.method, "paper");
    // One linear step removes much of the error but stops far from the floor.
    assert!(rep.stats.test.after.rms_mm < 0.6 * rep.stats.test.before.rms_mm);
    assert!(rep.stats.test.after.rms_mm > 5.0 * rep.noise_floor_mm.unwrap());
    // Its pseudo-inverse splits d2 and d3 equally, as in the paper's Table 2.
    let d2 = rep.deviations[1].d_mm;
    let d3 = rep.deviations[2].d_mm;
    assert!((d2 - d3).abs() < 1e-6, "d2 {d2} d3 {d3}");
}

#[test]
fn real_ur10_random_tracker_data() {
    let (robot, rig, data) = common::load("real_ur10_ipa_random");
    let rep =
        common::calibrate_geometric(&robot, &rig, &data, &geometric_only(), &NoProgress).unwrap();
    assert_eq!(rep.split_source, "file");
    assert!(
        rep.noise_floor_mm.is_none(),
        "point data has no redundancy to estimate a floor from"
    );
    let before = rep.stats.test.before.rms_mm;
    let after = rep.stats.test.after.rms_mm;
    // SOURCE.md's independent check: 0.993 -> 0.493 mm.
    assert!(before > 0.95 && before < 1.05, "{before}");
    assert!(after < 0.495, "{after}");
    // The measured point sits ~16 mm nearer the flange than the planning TCP.
    assert!(
        (rep.tool_point_mm[2] - 92.8).abs() < 1.0,
        "{:?}",
        rep.tool_point_mm
    );
}

#[test]
fn real_positioner_two_axes_camera() {
    let (robot, rig, data) = common::load("real_positioner2ax_rosi");
    let rep =
        common::calibrate_geometric(&robot, &rig, &data, &geometric_only(), &NoProgress).unwrap();
    assert!(
        rep.stats.test.after.rms_mm <= 0.42,
        "{}",
        rep.stats.test.after.rms_mm
    );
    assert!(rep.stats.test.after.rms_mm < rep.stats.test.before.rms_mm);
}

#[test]
fn real_ur10_grid_calibrates_in_full() {
    let (robot, rig, data) = common::load("real_ur10_ipa_grid");
    assert_eq!(data.poses.len(), 11911);
    let rep =
        common::calibrate_geometric(&robot, &rig, &data, &geometric_only(), &NoProgress).unwrap();
    assert_eq!(rep.stats.train.n + rep.stats.test.n, 11911);
    // SOURCE.md: 0.841 mm before, 0.441 mm after (independent check).
    assert!(rep.stats.test.before.rms_mm < 0.9);
    assert!(
        rep.stats.test.after.rms_mm < 0.46,
        "{}",
        rep.stats.test.after.rms_mm
    );
}

#[test]
fn chosen_split_is_reported_and_reproducible() {
    let (robot, rig, mut data) = common::load("ur5_geometric");
    for p in &mut data.poses {
        p.split = None;
    }
    let a =
        common::calibrate_geometric(&robot, &rig, &data, &geometric_only(), &NoProgress).unwrap();
    let b =
        common::calibrate_geometric(&robot, &rig, &data, &geometric_only(), &NoProgress).unwrap();
    assert_eq!(a.held_out, b.held_out);
    assert_eq!(a.held_out.len(), 24); // 30% of 80
    assert!(a.split_source.starts_with("chosen"));
}

#[test]
fn real_ur10_random_with_physics_reaches_the_goal() {
    let (robot, rig, data) = common::load("real_ur10_ipa_random");
    let rep = common::identify_default(&robot, &rig, &data);
    // The geometric model leaves 0.493 mm; the accepted effects must bring
    // the held-out RMS to the 0.49 mm goal, and every accepted effect must
    // have improved the held-out error.
    assert!(
        rep.stats.test.after.rms_mm <= 0.49,
        "{}",
        rep.stats.test.after.rms_mm
    );
    for f in rep.findings.iter().filter(|f| f.effect != "unexplained") {
        assert!(f.test_rms_after_mm < f.test_rms_before_mm, "{f:?}");
    }
}

#[test]
fn per_pose_string_residuals_include_the_accepted_effects() {
    let (robot, rig, data) = common::load("er3a_compliance_j2");
    let rep = common::identify_default(&robot, &rig, &data);
    assert!(
        rep.findings
            .iter()
            .any(|f| f.effect == "joint_compliance" && f.joint == Some(2)),
        "{:?}",
        rep.findings
    );
    let all: Vec<f64> = rep
        .per_pose
        .iter()
        .flat_map(|p| p.strings_mm.clone().unwrap())
        .collect();
    let rms = (all.iter().map(|v| v * v).sum::<f64>() / all.len() as f64).sqrt();
    // The final model (geometry + compliance) leaves string noise only.
    assert!(
        rms < 1.5 * rep.string_sigma_mm.unwrap(),
        "string residual RMS {rms}"
    );
}

#[test]
fn uncertainties_come_from_the_final_model_with_its_effects() {
    // With the compliance left out the geometric fit's residual is about 4x
    // the string noise, and so are its sigmas; the final model (geometry +
    // compliance) must report the sigmas of its own, much tighter, fit.
    let (robot, rig, data) = common::load("er3a_compliance_j2");
    let geo =
        common::calibrate_geometric(&robot, &rig, &data, &geometric_only(), &NoProgress).unwrap();
    let fin = common::identify_default(&robot, &rig, &data);
    assert!(!fin.findings.is_empty());
    let mut ratios: Vec<f64> = fin
        .parameters
        .iter()
        .filter_map(|p| {
            let g = geo.parameters.iter().find(|q| q.name == p.name)?;
            assert!(p.sigma.is_finite() && p.sigma > 0.0, "{}", p.name);
            Some(p.sigma / g.sigma)
        })
        .collect();
    assert!(ratios.len() > 10);
    ratios.sort_by(|a, b| a.total_cmp(b));
    let median = ratios[ratios.len() / 2];
    assert!(median < 0.5, "median sigma ratio final/geometric {median}");
}

/// The figures docs/CLI.md's "Honest limits" quotes for er3a_paper_like,
/// measured against truth.json: the realised string noise (readings minus
/// the true distances) is 0.0207 mm where the strings' redundancy
/// estimates 0.0183 mm, and the held-out poses' located points lie
/// 0.0359 mm from the truth, so the held-out 0.0424 mm is 1.18x their own
/// noise.
#[test]
fn er3a_paper_like_noise_as_the_readme_quotes_it() {
    let name = "er3a_paper_like";
    let (robot, rig, data) = common::load(name);
    let truth = true_points(name);
    let anchors: Vec<Vector3<f64>> = (0..rig.n_strings()).map(|k| rig.anchor(k)).collect();
    let rep =
        common::calibrate_geometric(&robot, &rig, &data, &geometric_only(), &NoProgress).unwrap();
    let (mut string_ss, mut n_strings, mut located_ss, mut n_test) = (0.0, 0, 0.0, 0);
    for (pose, t) in data.poses.iter().zip(&truth) {
        let Measurement::Strings(l) = &pose.measurement else {
            panic!("strings expected")
        };
        for (a, li) in anchors.iter().zip(l) {
            string_ss += (li - ((t - a).norm() - rig.r_mm)).powi(2);
            n_strings += 1;
        }
        if rep.held_out.contains(&pose.id) {
            let d: Vec<f64> = l.iter().map(|li| li + rig.r_mm).collect();
            let p = drawcal::measure::locate(&anchors, &d, None).unwrap().point;
            located_ss += (p - t).norm_squared();
            n_test += 1;
        }
    }
    let realised = (string_ss / n_strings as f64).sqrt();
    let located = (located_ss / n_test as f64).sqrt();
    let held_out = rep.stats.test.after.rms_mm;
    assert!((realised - 0.0207).abs() < 5e-5, "{realised}");
    assert!((rep.string_sigma_mm.unwrap() - 0.0183).abs() < 5e-5);
    assert!((located - 0.0359).abs() < 5e-5, "{located}");
    assert!(
        (held_out / located - 1.18).abs() < 0.005,
        "{held_out} / {located}"
    );
}

/// Why each parameter is held, and holds by request: the wrist pair these
/// data do not determine (the tool point sits 0.8 mm off the joint-6 axis)
/// is held as undetermined, not as aliased; `undetermined_z: 0` keeps it
/// free; `hold` holds joint parameters by name and refuses the rest.
#[test]
fn held_parameters_say_why() {
    use drawcal::report::FixedReason;
    let (robot, rig, data) = common::load("er3a_paper_like");
    let run = |opts: IdentifyOptions| {
        common::calibrate_geometric(&robot, &rig, &data, &opts, &NoProgress)
    };
    let reason = |rep: &Report, name: &str| {
        rep.identifiability
            .fixed
            .iter()
            .find(|f| f.name == name)
            .map(|f| f.reason)
    };
    let rep = run(geometric_only()).unwrap();
    assert_eq!(reason(&rep, "j3.d"), Some(FixedReason::Aliased));
    assert_eq!(reason(&rep, "j5.a"), Some(FixedReason::Undetermined));
    assert_eq!(reason(&rep, "j5.d"), Some(FixedReason::Undetermined));
    let id = &rep.identifiability;
    assert_eq!(id.n_identified + id.fixed.len(), id.n_candidates);

    let free = run(IdentifyOptions {
        undetermined_z: 0.0,
        ..geometric_only()
    })
    .unwrap();
    assert!(
        free.identifiability
            .fixed
            .iter()
            .all(|f| f.reason == FixedReason::Aliased)
    );
    assert!(free.parameters.iter().any(|p| p.name == "j5.a"));

    let held = run(IdentifyOptions {
        hold: vec!["j2.a".into(), "j2.a".into()],
        ..geometric_only()
    })
    .unwrap();
    assert_eq!(reason(&held, "j2.a"), Some(FixedReason::Requested));
    assert!(held.parameters.iter().all(|p| p.name != "j2.a"));
    assert_eq!(held.fixed.iter().filter(|f| *f == "j2.a").count(), 1);
    let id = &held.identifiability;
    assert_eq!(id.n_identified + id.fixed.len(), id.n_candidates);
    let a = held.calibrated_robot.joints[1].a_mm;
    assert_eq!(a, robot.joints[1].a_mm, "held at nominal");

    for (hold, method, says) in [
        ("j9.a", Method::Lm, "not a joint parameter"),
        ("base.x", Method::Lm, "fitted in every calibration"),
        ("j2.a", Method::Paper, "paper"),
    ] {
        let err = run(IdentifyOptions {
            hold: vec![hold.into()],
            method,
            ..geometric_only()
        })
        .unwrap_err()
        .to_string();
        assert!(err.contains("hold") && err.contains(says), "{hold}: {err}");
    }
}
