//! Shared helpers for the integration tests: load a dataset copied under
//! tests/data.
#![allow(dead_code)]

use std::path::PathBuf;

use drawcal::model::{Dataset, Rig, Robot};

/// `drawcal identify` with the default options on a loaded dataset.
pub fn identify_default(robot: &Robot, rig: &Rig, data: &Dataset) -> drawcal::report::Report {
    use drawcal::identify::NoProgress;
    drawcal::pipeline::calibrate(robot, rig, data, &Default::default(), &NoProgress).unwrap()
}

/// `drawcal identify` with the default options on a simulated session.
pub fn identify_default_sim(
    sim: &drawcal::physics::simulate::Simulated,
) -> drawcal::report::Report {
    identify_default(&sim.robot, &sim.rig, &sim.dataset)
}

/// Each finding of a report as (effect, joint): a joint effect's joint or
/// a bending link's root joint (1-based), none elsewhere.
pub fn named(r: &drawcal::report::Report) -> Vec<(String, Option<usize>)> {
    r.findings
        .iter()
        .map(|f| (f.effect.clone(), f.joint))
        .collect()
}

/// The effect context of a simulated session at the nominal geometry, as
/// the analysis builds it: what a simulated effect's truth is measured in.
pub fn sim_context(sim: &drawcal::physics::simulate::Simulated) -> drawcal::physics::Context {
    drawcal::physics::analyse::effect_context(
        &drawcal::identify::Observations::new(
            &sim.robot,
            &sim.rig,
            &sim.dataset,
            &Default::default(),
        )
        .unwrap(),
        &drawcal::kinematics::Params::of_robot(&sim.robot),
    )
}

/// A finding's size is the simulated effect's (`sim.effects[0]`), in the
/// same unit, within three of its sigma; `what` names the case.
pub fn assert_size_within_3_sigma(
    sim: &drawcal::physics::simulate::Simulated,
    f: &drawcal::report::Finding,
    what: &str,
) {
    let (truth, unit) =
        drawcal::physics::simulate::report_magnitude(&sim.effects[0], &sim_context(sim));
    assert_eq!(f.unit, unit);
    assert!(
        (f.magnitude - truth).abs() < 3.0 * f.sigma,
        "{what}: {} ± {} {unit}, truth {truth}",
        f.magnitude,
        f.sigma
    );
}

/// How well a calibration's compensator follows the shift of T that a
/// simulated load effect (a base tilt, a bending link, a compliant tool)
/// put into the recording: over the held-out poses, each at its own
/// payload, the RMS (mm) of the calibrated pose's shift by the report's
/// findings less the true shift, and the RMS of the true shift.
pub fn load_shift_followed(
    sim: &drawcal::physics::simulate::Simulated,
    report: &drawcal::report::Report,
) -> (f64, f64) {
    use drawcal::compensate::Compensator;
    let comp = Compensator::from_report(report).unwrap();
    let mut without = report.clone();
    without.findings.clear();
    let comp_without = Compensator::from_report(&without).unwrap();
    let ctx = sim_context(sim);
    // The context's frame: the nominal base's rotation in the rig.
    let rig_to_base = drawcal::kinematics::Params::of_robot(&sim.robot)
        .base_rt()
        .0
        .transpose();
    let mut buf = drawcal::physics::effects::Basis::default();
    let (mut with_sq, mut without_sq, mut n) = (0.0, 0.0, 0.0);
    for (i, pose) in sim.dataset.poses.iter().enumerate() {
        if pose.split != Some(drawcal::model::Split::Test) {
            continue;
        }
        let truth = rig_to_base * ctx.apply(&sim.effects, i, &mut buf).dp;
        let at = comp.with_payload_kg(pose.payload_kg.unwrap_or(0.0));
        let shift = at.calibrated_pose(&pose.q_rad).0 - comp_without.calibrated_pose(&pose.q_rad).0;
        with_sq += (shift - truth).norm_squared();
        without_sq += truth.norm_squared();
        n += 1.0;
    }
    ((with_sq / n).sqrt(), (without_sq / n).sqrt())
}

/// The geometric fit and the physics analysis with the default options, as
/// `drawcal identify` runs them: the analysis and the held-out 3-D RMS of
/// its final model (mm).
pub fn analyse_blind(
    robot: &Robot,
    rig: &Rig,
    data: &Dataset,
) -> (drawcal::physics::Analysis, f64) {
    use drawcal::identify::NoProgress;
    let run = drawcal::pipeline::run(robot, rig, data, &Default::default(), &NoProgress).unwrap();
    let a = run.physics.analysis.expect("the physics analysis ran");
    let rms = drawcal::stats::rms_norm(&a.test_errors);
    (a, rms)
}

pub fn dir(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

pub fn load(name: &str) -> (Robot, Rig, Dataset) {
    let d = dir(name);
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

pub fn truth(name: &str) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir(name).join("truth.json")).unwrap()).unwrap()
}

/// truth.json's `true_points_mm`, in pose order.
pub fn true_points(truth: &serde_json::Value) -> Vec<nalgebra::Vector3<f64>> {
    truth["true_points_mm"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| nalgebra::Vector3::from_iterator((0..3).map(|c| p[c].as_f64().unwrap())))
        .collect()
}

/// The truth expressed in the parametrisation `rep` identified: the
/// geometric model fitted to exact, noise-free string readings of the true
/// points at the same poses, with the parameters `rep` held at nominal
/// held too. This maps the aliased parameters (d2+d3 along parallel axes,
/// joint 6 and the tool point, joint 1 and the base, the wrist pairs the
/// data did not separate) the way the calibration does.
pub fn mapped_truth(
    robot: &Robot,
    rig: &Rig,
    data: &Dataset,
    true_points: &[nalgebra::Vector3<f64>],
    rep: &drawcal::report::Report,
) -> drawcal::report::Report {
    use drawcal::identify::{IdentifyOptions, NoProgress};
    use drawcal::model::Measurement;
    use drawcal::pipeline;
    let mut exact = data.clone();
    for (pose, t) in exact.poses.iter_mut().zip(true_points) {
        pose.measurement = Measurement::Strings(
            (0..rig.n_strings())
                .map(|k| (t - rig.anchor(k)).norm() - rig.r_mm)
                .collect(),
        );
    }
    let opts = pipeline::Options {
        identify: IdentifyOptions {
            hold: rep.fixed.clone(),
            ..IdentifyOptions::default()
        },
        physics: false,
        ..Default::default()
    };
    pipeline::calibrate(robot, rig, &exact, &opts, &NoProgress).unwrap()
}

/// Proptest settings for the fuzz tests: `n` cases (a few seconds in CI),
/// or `PROPTEST_CASES` for a long campaign; no failure files written.
pub fn proptest_cases(n: u32) -> proptest::prelude::ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(n);
    proptest::prelude::ProptestConfig {
        cases,
        failure_persistence: None,
        ..proptest::prelude::ProptestConfig::default()
    }
}

/// A CSV text with the named columns removed (a recording made without
/// them), every other column and row unchanged.
pub fn drop_columns(csv: &str, names: &[&str]) -> String {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| !names.contains(&header[i]))
        .collect();
    let pick = |l: &str| {
        let cells: Vec<&str> = l.split(',').collect();
        keep.iter()
            .map(|&i| cells.get(i).copied().unwrap_or(""))
            .collect::<Vec<_>>()
            .join(",")
    };
    std::iter::once(pick(&header.join(",")))
        .chain(lines.map(pick))
        .collect::<Vec<_>>()
        .join("\n")
}

/// A poses.csv text with the joint angles (`q*_deg`) of the given data
/// rows (0-based; every row when `None`) rewritten in radians: input that
/// parses but looks wrong.
pub fn q_columns_in_radians(csv: &str, rows: Option<&[usize]>) -> String {
    let mut lines = csv.lines();
    let header = lines.next().unwrap_or("");
    let q: Vec<bool> = header
        .split(',')
        .map(|h| h.starts_with('q') && h.ends_with("_deg"))
        .collect();
    let mut out = vec![header.to_string()];
    for (r, line) in lines.enumerate() {
        if rows.is_some_and(|rows| !rows.contains(&r)) {
            out.push(line.to_string());
            continue;
        }
        let cells: Vec<String> = line
            .split(',')
            .zip(&q)
            .map(|(c, &q)| {
                if q {
                    format!("{:.6}", c.parse::<f64>().unwrap().to_radians())
                } else {
                    c.to_string()
                }
            })
            .collect();
        out.push(cells.join(","));
    }
    out.join("\n") + "\n"
}

/// A finding's `parameters` as the report's JSON has them (what clients
/// read).
pub fn params(f: &drawcal::report::Finding) -> serde_json::Value {
    serde_json::to_value(&f.parameters).unwrap()
}

/// The pipeline without the physics analysis (the geometric calibration
/// and its report), with these identification options.
pub fn calibrate_geometric(
    robot: &Robot,
    rig: &Rig,
    data: &Dataset,
    opts: &drawcal::identify::IdentifyOptions,
    progress: &dyn drawcal::identify::Progress,
) -> drawcal::Result<drawcal::report::Report> {
    let opts = drawcal::pipeline::Options {
        identify: opts.clone(),
        physics: false,
        ..Default::default()
    };
    drawcal::pipeline::calibrate(robot, rig, data, &opts, progress)
}

/// The first data-driven correction `report` kept (panics with the
/// findings when there is none).
pub fn data_driven_correction(report: &drawcal::report::Report) -> drawcal::physics::Kind {
    report
        .findings
        .iter()
        .find_map(|f| f.effect_model().filter(|m| m.kind.is_data_driven()))
        .map(|m| m.kind.clone())
        .unwrap_or_else(|| panic!("no data-driven correction: {:#?}", report.findings))
}

/// What the first data-driven correction of `report` corrects and what
/// drives it: `(target, target_index, driver, driver_index)`.
pub fn correction_slot(
    report: &drawcal::report::Report,
) -> (
    drawcal::physics::effects::CorrectionTarget,
    Option<usize>,
    drawcal::physics::effects::CorrectionDriver,
    Option<usize>,
) {
    let drawcal::physics::Kind::DataDriven {
        target,
        target_index,
        driver,
        driver_index,
        ..
    } = data_driven_correction(report)
    else {
        unreachable!("data_driven_correction returns a data-driven kind")
    };
    (target, target_index, driver, driver_index)
}

/// The finding of `report`'s data-driven correction of `target` by
/// `driver` (the first such), or a panic listing the findings.
pub fn correction_finding(
    report: &drawcal::report::Report,
    target: drawcal::physics::effects::CorrectionTarget,
    driver: drawcal::physics::effects::CorrectionDriver,
) -> &drawcal::report::Finding {
    report
        .findings
        .iter()
        .find(|f| {
            f.effect_model().is_some_and(|m| {
                matches!(
                    m.kind,
                    drawcal::physics::Kind::DataDriven { target: t, driver: d, .. }
                        if t == target && d == driver
                )
            })
        })
        .unwrap_or_else(|| panic!("no {target:?} by {driver:?}: {:#?}", report.findings))
}

/// The twin (the same session without the error) finds nothing, and
/// `report`'s held-out RMS comes within `factor` times the twin's.
pub fn near_the_twin(
    report: &drawcal::report::Report,
    twin: &drawcal::report::Report,
    factor: f64,
) {
    assert!(twin.findings.is_empty(), "{:#?}", twin.findings);
    let (with, without) = (report.stats.test.after.rms_mm, twin.stats.test.after.rms_mm);
    assert!(
        with < factor * without,
        "held out {with} mm against {without} mm without the error"
    );
}

/// Every finding of `report` is `unexplained` or `data_driven`: no
/// catalogue name was forced.
pub fn nothing_named(report: &drawcal::report::Report) {
    let names: Vec<&str> = report.findings.iter().map(|f| f.effect.as_str()).collect();
    assert!(
        names
            .iter()
            .all(|n| matches!(*n, "unexplained" | "data_driven")),
        "a catalogue name was forced: {names:?}"
    );
}

/// The first place of `report`'s unexplained findings that `wanted`
/// accepts (panics with every place when none does).
pub fn place_where(
    report: &drawcal::report::Report,
    wanted: impl Fn(&drawcal::report::Place) -> bool,
) -> &drawcal::report::Place {
    let mut places = report
        .findings
        .iter()
        .filter_map(|f| f.unexplained())
        .flat_map(|u| u.places.iter());
    places
        .find(|p| wanted(p))
        .unwrap_or_else(|| panic!("no such place among {:#?}", report.findings))
}

/// A recording of the cross-checks with physics outside the catalogue
/// (`tests/data/<dir>`, its effect-free twin in `<dir>/twin`), analysed
/// with the defaults: nothing is named, some unexplained place is one
/// `wanted` accepts, and the held-out RMS comes within `factor` of the
/// twin's. The report, and the recording's robot and data, for the
/// case's own checks.
pub fn unnamed_near_the_twin(
    dir: &str,
    wanted: impl Fn(&drawcal::report::Place) -> bool,
    factor: f64,
) -> (drawcal::report::Report, Robot, Dataset) {
    let (robot, rig, data) = load(dir);
    let report = identify_default(&robot, &rig, &data);
    nothing_named(&report);
    place_where(&report, wanted);
    let (twin_robot, twin_rig, twin) = load(&format!("{dir}/twin"));
    near_the_twin(
        &report,
        &identify_default(&twin_robot, &twin_rig, &twin),
        factor,
    );
    (report, robot, data)
}

/// A recording whose remainder no catalogue effect explains (`tests/data/<dir>`),
/// analysed with the defaults: nothing is named, some unexplained place is
/// one `wanted` accepts, the first data-driven correction kept has `slot`
/// (`(target, target_index, driver, driver_index)`) and takes the held-out
/// RMS below `factor` times what it was. The report and the correction's
/// finding, for the case's own checks.
pub fn corrected_unnamed(
    dir: &str,
    wanted: impl Fn(&drawcal::report::Place) -> bool,
    slot: (
        drawcal::physics::effects::CorrectionTarget,
        Option<usize>,
        drawcal::physics::effects::CorrectionDriver,
        Option<usize>,
    ),
    factor: f64,
) -> (drawcal::report::Report, drawcal::report::Finding) {
    let (robot, rig, data) = load(dir);
    let report = identify_default(&robot, &rig, &data);
    nothing_named(&report);
    let place = place_where(&report, wanted);
    assert!(place.z > place.threshold, "{place:?}");
    assert_eq!(correction_slot(&report), slot);
    let d = report
        .findings
        .iter()
        .find(|f| f.effect == "data_driven")
        .cloned()
        .expect("correction_slot found one");
    assert!(
        d.test_rms_after_mm < factor * d.test_rms_before_mm,
        "{} -> {}",
        d.test_rms_before_mm,
        d.test_rms_after_mm
    );
    (report, d)
}
