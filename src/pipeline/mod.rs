//! The calibration pipeline: recorded poses in, a [`Report`] out.
//!
//! [`calibrate`] runs the steps in order; each lives in its own module and
//! knows nothing of the steps after it:
//!
//! 1. prepare ([`Observations::new`]): check shapes, split train and test,
//!    locate T at every pose;
//! 2. geometric identification ([`identify::geometric()`]): base and tool,
//!    then every identifiable parameter;
//! 3. physics analysis ([`physics::analyse()`]), unless turned off, the
//!    paper's method was asked for, or the geometry misses by more than
//!    [`PHYSICS_MAX_GEOMETRIC_RMS_MM`] ([`physics_step`]);
//! 4. assemble the report ([`assemble`]).
//!
//! [`evaluate`] is the blind-evaluation harness beside it: simulated
//! recordings with concealed effects, run through the same steps, scored
//! against the truth.

pub mod assemble;
pub mod evaluate;

use crate::error::{Error, Result};
use crate::identify::warnings::InputCheck;
use crate::identify::{self, Geometric, IdentifyOptions, Method, Observations, Progress, warnings};
use crate::model::{Dataset, Rig, Robot};
use crate::physics::{self, Analysis};
use crate::plan;
use crate::report::verdict::Verdict;
use crate::report::{ExtraPoses, FixedReason, PhysicsRun, Report};

/// Options of a whole calibration.
#[derive(Debug, Clone)]
pub struct Options {
    /// The geometric identification's options (method, split, holds...).
    pub identify: IdentifyOptions,
    /// Run the physics analysis after the geometric identification.
    pub physics: bool,
    /// Calibrate even from poses whose joint angles look like radians
    /// (refused otherwise, since the result would move a robot by a model
    /// fitted to the wrong angles: [`InputCheck::in_radians`]).
    pub force: bool,
    /// Hold half of the held-out poses back from the physics analysis
    /// ([`Observations::gate_half`]): its held-out gates and confirmations
    /// read the other half only, and the report's `stats.confirmation`
    /// (and `per_pose[].confirmation`) measure the final model on poses no
    /// decision saw. `stats.test` stays over every held-out pose.
    pub confirm_half: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            identify: IdentifyOptions::default(),
            physics: true,
            force: false,
            confirm_half: false,
        }
    }
}

impl From<IdentifyOptions> for Options {
    /// These identification options, with the physics analysis on.
    fn from(identify: IdentifyOptions) -> Self {
        Options {
            identify,
            ..Options::default()
        }
    }
}

/// Train RMS (mm) after the geometric calibration beyond which the physics
/// analysis is not run: physical effects are fractions of a millimetre, and
/// a calibrated arm that misses by more than this is a wrong model or wrong
/// data (angles in radians, another robot, a swapped string), not physics.
pub const PHYSICS_MAX_GEOMETRIC_RMS_MM: f64 = 10.0;

/// Run the whole calibration and build the report.
pub fn calibrate(
    robot: &Robot,
    rig: &Rig,
    data: &Dataset,
    opts: &Options,
    progress: &dyn Progress,
) -> Result<Report> {
    let run = run(robot, rig, data, opts, progress)?;
    let mut report =
        assemble::report(&run.obs, &run.geo, &run.identify, run.physics, run.warnings)?;
    report.extra_poses = extra_poses(&run.obs, &report);
    report.verdict = Some(Verdict::of(&report));
    Ok(report)
}

/// The poses that would determine what these poses left undetermined (the
/// parameters held at nominal, neither by request nor by the free set,
/// which the verdict treats apart: aliases of these poses may be separable
/// by others), and which of those they called undetermined no pose would
/// separate. A rig the planner cannot
/// draw for gives none: this is advice, never a reason to fail a
/// calibration.
fn extra_poses(obs: &Observations, report: &Report) -> Option<ExtraPoses> {
    let wanted: Vec<String> = report
        .identifiability
        .fixed
        .iter()
        .filter(|f| !matches!(f.reason, FixedReason::Requested | FixedReason::FreeSet))
        .map(|f| f.name.clone())
        .collect();
    if wanted.is_empty() {
        return None;
    }
    let recorded: Vec<Vec<f64>> = obs
        .train
        .iter()
        .map(|&i| {
            obs.data.poses[i]
                .q_rad
                .iter()
                .map(|q| q.to_degrees())
                .collect()
        })
        .collect();
    let free: Vec<String> = report.parameters.iter().map(|p| p.name.clone()).collect();
    let mut x = plan::extend(
        obs.robot,
        obs.rig,
        &recorded,
        &free,
        &wanted,
        report.string_sigma_mm,
        EXTRA_POSES_SEED,
    )
    .ok()
    .flatten()?;
    // Aliases the session named as such stay in `identifiability.fixed`
    // alone: inseparable is news only for what it called undetermined.
    x.inseparable.retain(|i| {
        report
            .identifiability
            .fixed
            .iter()
            .any(|f| f.name == i.name && f.reason != FixedReason::Aliased)
    });
    (!x.poses.is_empty() || !x.inseparable.is_empty()).then_some(x)
}

/// Seed of the extra poses' draws: a report is reproducible.
const EXTRA_POSES_SEED: u64 = 2024;

/// Steps 1-3, whose results the report is assembled from: for callers
/// that look inside (the evaluation harness, tests).
pub struct Run<'a> {
    /// The prepared recordings.
    pub obs: Observations<'a>,
    /// The geometric fit.
    pub geo: Geometric,
    /// The physics step.
    pub physics: PhysicsOutcome,
    /// Warnings about the input.
    pub warnings: Vec<String>,
    /// The identification options the run used: those asked, with
    /// `rig_anchors` turned on when the recording showed a constant anchor
    /// error ([`propose_rig_anchors`]).
    pub identify: IdentifyOptions,
}

/// Steps 1-3 of the pipeline (see [`calibrate`]).
pub fn run<'a>(
    robot: &'a Robot,
    rig: &'a Rig,
    data: &'a Dataset,
    opts: &Options,
    progress: &dyn Progress,
) -> Result<Run<'a>> {
    let mut obs = Observations::new(robot, rig, data, &opts.identify)?;
    let checked = warnings::check_input(&obs);
    if let (Some(evidence), false) = (&checked.in_radians, opts.force) {
        return Err(Error::field("poses", InputCheck::refusal(evidence)));
    }
    let mut warnings = checked.warnings;
    let geo = identify::geometric(&obs, &opts.identify, progress)?;
    // With the anchors identified, T is located with them from here on:
    // the robot's part of the fit holds for those points, and every figure
    // after (the physics analysis, the held-out errors) is of them.
    if let Some(r) = &geo.rig {
        let l = obs.chain.layout;
        let offsets = geo.after.values[l.string_offset(0)..l.r()].to_vec();
        obs.set_anchors(r.calibrated(), &offsets)?;
    }
    warnings.extend(identify::few_poses_warning(&obs, &geo, &opts.identify));
    let physics = physics_step(&obs, &geo, opts, progress)?;
    if let Some(advice) = &physics.advice {
        // Modelled like any effect the held-out readings support: the
        // calibration is made again with the anchors identified, and says
        // so (it cannot propose the rig again: the anchors are free).
        let mut with_rig = opts.clone();
        with_rig.identify.rig_anchors = true;
        let mut again = run(robot, rig, data, &with_rig, progress)?;
        again.warnings.insert(
            0,
            format!(
                "{advice}: the anchors were identified with the robot (as --rig-anchors, \
                 a job's rig_anchors, asks), and this report is that calibration; put its \
                 calibrated_rig in rig.json for the next session"
            ),
        );
        return Ok(again);
    }
    Ok(Run {
        obs,
        geo,
        physics,
        warnings,
        identify: opts.identify.clone(),
    })
}

/// What the physics step did: whether it ran, and its analysis when it
/// did or why not when it did not.
pub struct PhysicsOutcome {
    /// Whether the analysis ran.
    pub run: PhysicsRun,
    /// The analysis (when it ran).
    pub analysis: Option<Analysis>,
    /// Why it did not run (beginning with [`PhysicsRun::NOTE_PREFIX`]).
    pub why_not: Option<String>,
    /// The held-out poses it never read ([`Options::confirm_half`]), in
    /// session order; empty when it read them all or did not run.
    pub confirmation: Vec<usize>,
    /// What to do instead of trusting the analysis, when its findings were
    /// set aside ([`propose_rig_anchors`]): a warning of the report.
    pub advice: Option<String>,
}

impl PhysicsOutcome {
    /// The report's `physics_notes`: the analysis's own, or why it did not
    /// run.
    pub fn notes(&self) -> Vec<String> {
        match &self.analysis {
            Some(a) => a.notes.clone(),
            None => self.why_not.iter().cloned().collect(),
        }
    }
}

/// Step 3: the physics analysis on top of the geometric fit, when it can
/// mean something.
pub fn physics_step(
    obs: &Observations,
    geo: &Geometric,
    opts: &Options,
    progress: &dyn Progress,
) -> Result<PhysicsOutcome> {
    let not_run = |run, why: String| PhysicsOutcome {
        run,
        analysis: None,
        why_not: Some(format!("{}{why}", PhysicsRun::NOTE_PREFIX)),
        advice: None,
        confirmation: Vec::new(),
    };
    if !opts.physics {
        return Ok(not_run(PhysicsRun::Off, " (physics off)".into()));
    }
    if opts.identify.method == Method::Paper {
        return Ok(not_run(
            PhysicsRun::PaperMethod,
            " (method paper: the analysis builds on the Levenberg-Marquardt fit; run --method lm)"
                .into(),
        ));
    }
    let train_rms_mm = crate::stats::rms_norm(&obs.errors(&geo.after.values, &obs.train));
    // NaN counts as broken.
    if !(train_rms_mm <= PHYSICS_MAX_GEOMETRIC_RMS_MM) {
        return Ok(not_run(
            PhysicsRun::GeometryMisses,
            format!(
                ": the calibrated geometric model still misses the train poses by {train_rms_mm:.1} mm RMS (more than {PHYSICS_MAX_GEOMETRIC_RMS_MM} mm), so it does not describe these recordings and any effect fitted on top would fit a broken model; check the units (degrees, mm), the robot model and the rig first"
            ),
        ));
    }
    progress.update("physics analysis", 0.0);
    // Every decision below that reads held-out poses reads the gate half.
    let gate = opts.confirm_half.then(|| obs.gate_half()).flatten();
    let obs = gate.as_ref().unwrap_or(obs);
    let mut analysis = physics::analyse(obs, geo, progress)?;
    let advice = if opts.identify.rig_anchors {
        None
    } else {
        propose_rig_anchors(obs, geo, &mut analysis)
    };
    Ok(PhysicsOutcome {
        run: PhysicsRun::Ran,
        analysis: Some(analysis),
        why_not: None,
        advice,
        confirmation: obs.confirmation.clone(),
    })
}

/// The analysis's final held-out RMS, over what an exact model would show,
/// beyond which a constant anchor error is looked for: below it the
/// analysis has explained the recording and nothing is tried.
pub const RIG_PROBE_ABOVE_EXPECTED: f64 = 1.3;

/// A constant anchor error explains the recording when, with the anchors
/// fitted, the held-out RMS is within this factor of what an exact model
/// would show...
pub const RIG_PROBE_EXPLAINS: f64 = 1.3;

/// ...and at most this fraction of the analysis's own final held-out RMS.
pub const RIG_PROBE_GAIN: f64 = 0.8;

/// When the strings disagree the way a constant error of rig.json's anchors
/// explains, and the analysis did not explain them, set its findings aside
/// and say why (then [`run`] calibrates again with the anchors free): a wrong rig shows as string
/// offsets, anchor steps and rig moves that describe no part that moved
/// (misnaming is the worst failure of a diagnosis), and the geometry fitted
/// around a wrong rig is no calibration to use either. Returns the advice.
///
/// Tried only on string rigs of four or more (where the anchors are
/// identifiable) when the analysis found something or ended well above
/// what an exact model would show ([`RIG_PROBE_ABOVE_EXPECTED`]); it then
/// fires only when the geometric fit with the anchors free explains
/// essentially everything (its held-out RMS within [`RIG_PROBE_EXPLAINS`]
/// of what an exact model shows at the residual scale it leaves) and
/// clearly beats the analysis ([`RIG_PROBE_GAIN`]). A catalogue effect the
/// analysis named reaches the noise already, so it is not displaced, and
/// an effect-free session does not get this far. Not proven: an effect
/// outside the catalogue that a constant anchor error largely mimics could
/// be proposed as one; the re-run's report shows whether the anchors
/// explain it.
pub fn propose_rig_anchors(
    obs: &Observations,
    geo: &Geometric,
    analysis: &mut Analysis,
) -> Option<String> {
    if obs.anchors.len() < identify::rig::MIN_STRINGS || analysis.test_errors.is_empty() {
        return None;
    }
    let expected_with = |sigma: f64| {
        obs.expected_test_rms(
            &geo.after.values,
            &geo.selection.free,
            &geo.result.jtj,
            Some(sigma),
        )
    };
    let ended = crate::stats::rms_norm(&analysis.test_errors);
    // The strings' redundancy includes the disagreement a wrong rig makes,
    // so the noise it gives is no reference here: anything found, or an
    // end above even that, is reason to look.
    let sigma = obs.string_sigma().unwrap_or(geo.sigma);
    let above = expected_with(sigma).is_some_and(|e| ended > RIG_PROBE_ABOVE_EXPECTED * e);
    if analysis.findings.is_empty() && !above {
        return None;
    }
    let probe = identify::rig::probe(obs, &geo.after.values, &geo.selection.free)?;
    let p = probe.test_rms_mm;
    // With the anchors fitted, what an exact model would show at the
    // residual scale that fit leaves.
    let expected = expected_with(probe.sigma_mm)?;
    if !(p <= RIG_PROBE_EXPLAINS * expected && p <= RIG_PROBE_GAIN * ended) {
        return None;
    }
    let names: Vec<String> = analysis
        .findings
        .iter()
        .map(|f| match f.sensor {
            Some(k) => format!("{} (sensor {k})", f.effect),
            None => f.effect.clone(),
        })
        .collect();
    let advice = format!(
        "the strings disagree the way a constant error of rig.json's anchors explains: with the \
         anchors fitted the held-out RMS would be {p:.4} mm (an exact model: about \
         {expected:.4} mm) against {ended:.4} mm here, the largest correction {:.2} mm at \
         anchor {}",
        probe.largest_mm,
        obs.rig.sensor_name(probe.largest_anchor)
    );
    if !names.is_empty() {
        analysis.notes.push(format!(
            "set aside, as a constant anchor error explains the recording better: {}",
            names.join(", ")
        ));
    }
    analysis.notes.push(advice.clone());
    // The geometric model stands, without the findings a wrong rig made.
    let all: Vec<usize> = obs.test.clone();
    analysis.test_errors = obs.errors(&geo.after.values, &all);
    analysis.findings.clear();
    analysis.effects.clear();
    analysis.final_params = geo.after.clone();
    analysis.final_sigmas = None;
    Some(advice)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::NoProgress;
    use crate::model::{Measurement, Split};
    use crate::physics::simulate;
    use crate::report::Report;

    fn session() -> simulate::Simulated {
        let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
            "robot": "er3a", "n_poses": 150, "seed": 3,
            "effects": [{"effect": "joint_compliance", "joint": 2, "size_x_noise": 5}]
        }))
        .unwrap();
        simulate::generate(&spec).unwrap()
    }

    fn calibrate_with(sim: &simulate::Simulated, data: &Dataset, confirm_half: bool) -> Report {
        let opts = Options {
            confirm_half,
            ..Options::default()
        };
        calibrate(&sim.robot, &sim.rig, data, &opts, &NoProgress).unwrap()
    }

    /// The confirmation half is every other held-out pose, marked in
    /// `per_pose` and measured in `stats.confirmation`; and no decision of
    /// the analysis reads it: readings moved there change the figures
    /// measured there, never what was found nor the model.
    #[test]
    fn the_confirmation_half_is_reported_and_read_by_no_decision() {
        let sim = session();
        let report = calibrate_with(&sim, &sim.dataset, true);
        assert!(!report.findings.is_empty(), "the compliance is found");
        let test: Vec<usize> = (0..report.per_pose.len())
            .filter(|&i| report.per_pose[i].split == Split::Test)
            .collect();
        let marked: Vec<usize> = (0..report.per_pose.len())
            .filter(|&i| report.per_pose[i].confirmation)
            .collect();
        let expected: Vec<usize> = test.iter().skip(1).step_by(2).copied().collect();
        assert_eq!(marked, expected);
        let c = report.stats.confirmation.expect("halved");
        assert_eq!(c.n, marked.len());
        assert_eq!(report.stats.test.n, test.len());

        // Move every confirmation pose's readings by 0.3 mm.
        let mut moved = sim.dataset.clone();
        for &i in &marked {
            if let Measurement::Strings(l) = &mut moved.poses[i].measurement {
                l.iter_mut().for_each(|v| *v += 0.3);
            }
        }
        let again = calibrate_with(&sim, &moved, true);
        let names =
            |r: &Report| -> Vec<String> { r.findings.iter().map(|f| f.effect.clone()).collect() };
        assert_eq!(names(&again), names(&report));
        assert_eq!(again.parameters, report.parameters);
        assert_eq!(again.stats.train, report.stats.train);
        let c2 = again.stats.confirmation.unwrap();
        assert!(c2.after.rms_mm > c.after.rms_mm + 0.05, "{c2:?} vs {c:?}");

        // Off: nothing set aside.
        let off = calibrate_with(&sim, &sim.dataset, false);
        assert!(off.stats.confirmation.is_none());
        assert!(off.per_pose.iter().all(|p| !p.confirmation));
        assert_eq!(off.stats.test.n, report.stats.test.n);
    }
}
