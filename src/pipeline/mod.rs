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
use crate::report::{PhysicsRun, Report};

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
}

impl Default for Options {
    fn default() -> Self {
        Options {
            identify: IdentifyOptions::default(),
            physics: true,
            force: false,
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
    assemble::report(
        &run.obs,
        &run.geo,
        &opts.identify,
        run.physics,
        run.warnings,
    )
}

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
        obs.set_anchors(r.calibrated())?;
    }
    warnings.extend(identify::few_poses_warning(&obs, &geo, &opts.identify));
    let physics = physics_step(&obs, &geo, opts, progress)?;
    Ok(Run {
        obs,
        geo,
        physics,
        warnings,
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
    Ok(PhysicsOutcome {
        run: PhysicsRun::Ran,
        analysis: Some(physics::analyse(obs, geo, progress)?),
        why_not: None,
    })
}
