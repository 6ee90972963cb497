//! Planning a calibration session: which poses to record, in which order,
//! and what they will determine (`drawcal plan`, `POST /plans`).
//!
//! 1. Candidates ([`candidates`]): random joint poses inside the limits
//!    that the rig measures well (every string in range, off the anchors'
//!    plane, well spread at T, clear of the arm) and that keep the arm
//!    above the floor, out of the keep-out boxes and away from
//!    singularities.
//! 2. Selection ([`design`]): the `n` poses minimising the expected
//!    squared error of the calibrated model's T at random valid poses
//!    (I-optimal), over the parameters the identification frees and any
//!    effects asked for, greedily and then by exchanges.
//! 3. Order ([`tour`]): a short tour from home.
//! 4. The report: predicted 1-sigma per parameter, predicted held-out RMS
//!    (and the same for random poses), the parameters the rig and the
//!    poses cannot determine and why, and the prediction over N.
//!
//! The predictions are linear least squares with the noise given: they
//! hold for the geometric model and the effects planned for, not for
//! physics nobody modelled.

use std::collections::BTreeMap;

use nalgebra::{DMatrix, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::identify::{IdentifyOptions, geometric::candidates as free_candidates, identifiability};
use crate::kinematics::JointParam;
use crate::kinematics::chain::OutputFrame;
use crate::model::{Rig, Robot};
use crate::physics::Kind;
use crate::physics::effects::{Basis, Context, PoseInput, approach_directions};
use crate::report::FixedParam;
use crate::rng::Rng;

mod backlash;
pub mod candidates;
pub mod design;
pub mod extend;
pub mod tour;

pub use candidates::{Candidate, KeepOut, Rejection, Scene, Workspace};
pub use extend::extend;

use backlash::BacklashDesign;

/// The report's format tag.
pub const PLAN_FORMAT: &str = "drawcal plan v1";

/// Effects a plan can be made for.
pub const PLANNABLE_EFFECTS: &[&str] = &[
    "joint_compliance",
    "backlash",
    "joint_scale",
    "sensor_scale",
    "cable_sag",
];

/// What to plan.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanOptions {
    /// Poses to choose for the identification.
    pub n_poses: usize,
    /// Random valid poses added and marked `test`, to measure the held-out
    /// RMS; default `max(5, n_poses / 4)`.
    #[serde(default)]
    pub n_check: Option<usize>,
    /// Where poses may go.
    #[serde(default)]
    pub workspace: Workspace,
    /// Effects the poses must also determine ([`PLANNABLE_EFFECTS`]).
    #[serde(default)]
    pub effects: Vec<String>,
    /// Candidate poses drawn (valid ones).
    #[serde(default = "default_candidates")]
    pub candidates: usize,
    /// Seed of the draws.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Noise of one string reading (mm), or of each coordinate of a
    /// measured point; default 0.02 mm (strings, plus the resolution's
    /// quantisation) or 0.03 mm (a point instrument).
    #[serde(default)]
    pub noise_mm: Option<f64>,
    /// Where the tour starts (deg); default every joint at 0, inside its
    /// limits.
    #[serde(default)]
    pub home_deg: Option<Vec<f64>>,
    /// A payload (kg at T) the poses may carry, with `joint_compliance`
    /// among the effects: the selection chooses which poses carry it, and
    /// the tour visits the unloaded ones first, so that it is mounted once.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload_kg: Option<f64>,
}

/// Heaviest payload a plan takes (kg), as `/compensate` does.
pub const MAX_PAYLOAD_KG: f64 = 5000.0;

fn default_candidates() -> usize {
    10_000
}
fn default_seed() -> u64 {
    1
}

impl PlanOptions {
    /// Options for `n_poses` with every default.
    pub fn new(n_poses: usize) -> Self {
        PlanOptions {
            n_poses,
            n_check: None,
            workspace: Workspace::default(),
            effects: vec![],
            candidates: default_candidates(),
            seed: default_seed(),
            noise_mm: None,
            home_deg: None,
            payload_kg: None,
        }
    }
}

/// One pose of the plan, in visiting order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlannedPose {
    /// Id (`p01`..., `c01`... for check poses).
    pub id: String,
    /// Nominal joint targets (deg).
    pub q_deg: Vec<f64>,
    /// `train` (chosen for the identification) or `test` (a check pose).
    pub split: String,
    /// Payload at T (kg) when the plan plans one: 0 or the payload.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload_kg: Option<f64>,
}

/// A parameter's predicted uncertainty.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PredictedParam {
    /// Report name (`j2.theta`, `base.x`, `tool.z`, or an effect's).
    pub name: String,
    /// Predicted 1-sigma in `unit`.
    pub sigma: f64,
    /// `mm`, `deg` or the effect's coefficient unit.
    pub unit: String,
}

/// The prediction for a number of poses.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PredictionAtN {
    /// Poses.
    pub n_poses: usize,
    /// RMS error of the calibrated model's T at random valid poses (mm).
    pub model_rms_mm: f64,
    /// Predicted held-out RMS: the model's error and the located point's
    /// noise together (mm).
    pub holdout_rms_mm: f64,
}

/// Approach directions of a joint over the tour (for backlash).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ApproachBalance {
    /// Joint (1-based).
    pub joint: usize,
    /// Poses reached with the joint moving up.
    pub from_below: usize,
    /// Poses reached moving down.
    pub from_above: usize,
}

/// What the plan predicts and why.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PlanReport {
    /// [`PLAN_FORMAT`].
    pub format: String,
    /// Robot name.
    pub robot: String,
    /// Poses chosen for the identification.
    pub n_poses: usize,
    /// Check poses (split `test`).
    pub n_check: usize,
    /// The selection criterion, in words.
    pub criterion: String,
    /// Noise assumed per reading (mm).
    pub noise_mm: f64,
    /// Candidates drawn, kept, and why the others were not.
    pub candidates_drawn: usize,
    /// Valid candidates the poses were chosen from.
    pub candidates_kept: usize,
    /// Drawn poses refused, by reason.
    pub rejected: BTreeMap<Rejection, usize>,
    /// Predicted 1-sigma of each parameter the poses determine.
    pub parameters: Vec<PredictedParam>,
    /// Parameters neither this rig nor any poses can separate, held at
    /// nominal by the identification, with what they move T like.
    pub undetermined: Vec<FixedParam>,
    /// The chosen poses' prediction.
    pub predicted: PredictionAtN,
    /// The same number of random valid poses (mean of five draws).
    pub random: PredictionAtN,
    /// RMS of the located point's noise at random valid poses (mm).
    pub point_noise_rms_mm: f64,
    /// The prediction as N changes (the greedy selection's nested sets).
    pub by_n: Vec<PredictionAtN>,
    /// Effects planned for.
    pub effects: Vec<String>,
    /// Approach directions per joint when backlash is planned for.
    pub approach: Vec<ApproachBalance>,
    /// The tour's total slowest-joint travel (deg).
    pub tour_travel_deg: f64,
    /// Exchanges made after the greedy selection.
    pub exchanges: usize,
    /// What the user should know.
    pub notes: Vec<String>,
    /// The dead bands, when backlash is planned for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backlash: Option<BacklashTour>,
    /// The payload's plan, when one is planned.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload: Option<PayloadPlan>,
}

/// A joint's dead band as the plan predicts it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BacklashSigma {
    /// Joint (1-based).
    pub joint: usize,
    /// Predicted 1-sigma of half the dead band (deg) with the tour
    /// planned; `None` when it is not determined: the joint's angle does
    /// not move the readings, or every pose is approached from one side
    /// (the dead band is then a joint offset).
    pub sigma_deg: Option<f64>,
    /// The same with the shortest tour.
    pub sigma_shortest_deg: Option<f64>,
    /// Correlation over the train poses of the joint's approach direction
    /// with its angle (near ±1 the dead band looks like an error growing
    /// with the angle).
    pub direction_angle_correlation: f64,
}

/// The tour ordered for backlash.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BacklashTour {
    /// The travel allowed, as a multiple of the shortest tour's.
    pub travel_bound: f64,
    /// The shortest tour's travel (deg).
    pub shortest_travel_deg: f64,
    /// Per joint.
    pub joints: Vec<BacklashSigma>,
}

/// A joint's compliance with and without the payload.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ComplianceSigma {
    /// Joint (1-based).
    pub joint: usize,
    /// Predicted 1-sigma with this plan (the payload carried where it
    /// chose).
    pub sigma_with_payload: f64,
    /// Predicted 1-sigma of the plan the same options make without a
    /// payload.
    pub sigma_without_payload: f64,
    /// `deg/(N·m)` with link masses; without them the coefficient of a
    /// unit mass at T, `deg/m`.
    pub unit: String,
}

/// Which poses carry the payload.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PayloadPlan {
    /// The payload (kg at T).
    pub payload_kg: f64,
    /// Chosen poses carrying it.
    pub loaded_poses: usize,
    /// Chosen poses without it.
    pub unloaded_poses: usize,
    /// Times the payload is mounted or taken off during the tour (the
    /// unloaded poses first: once when both groups have poses; none when
    /// the selection put every pose in one group, which is then carried
    /// from the start).
    pub payload_changes: usize,
    /// Per joint: the compliance's 1-sigma with and without the payload.
    pub compliance: Vec<ComplianceSigma>,
}

/// A plan: the poses in visiting order and the report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Plan {
    /// Poses, in visiting order.
    pub poses: Vec<PlannedPose>,
    /// What they predict.
    pub report: PlanReport,
}

impl Plan {
    /// targets.csv of the plan: `target,q1_deg..qn_deg[,payload_kg],split`
    /// (the payload and split columns are drawcal's additions: `drawcal
    /// simulate --targets` and the recording's poses.csv carry them over;
    /// the payload column only when the plan plans one).
    pub fn targets_csv(&self) -> String {
        if self.poses.iter().any(|p| p.payload_kg.is_some()) {
            return crate::model::targets::joint_targets_payload_csv(self.poses.iter().map(|p| {
                (
                    p.id.as_str(),
                    p.q_deg.as_slice(),
                    p.payload_kg.unwrap_or(0.0),
                    p.split.as_str(),
                )
            }));
        }
        crate::model::targets::joint_targets_csv(
            self.poses
                .iter()
                .map(|p| (p.id.as_str(), p.q_deg.as_slice(), p.split.as_str())),
        )
    }
}

/// Valid random poses drawn before giving up on finding enough, per pose
/// asked for.
const DRAWS_PER_CANDIDATE: usize = 50;
/// Random valid poses the prediction is averaged over.
const PREDICTION_POSES: usize = 400;
/// Exchange passes after the greedy selection.
const EXCHANGE_PASSES: usize = 3;

/// The columns the design determines: parameters of the identification
/// and effect coefficients.
struct Columns {
    /// Parameter indices, identification priority order.
    params: Vec<usize>,
    /// Prior size of each parameter (mm or rad).
    param_scale: Vec<f64>,
    /// Effects (kind, name) with their coefficient count.
    effects: Vec<(Kind, String)>,
    /// Prior size of each effect coefficient (its unit).
    effect_scale: Vec<f64>,
    /// What no pose of this rig can separate: the identification's
    /// structural selection over the whole pool, held at nominal.
    aliased: Vec<FixedParam>,
}

impl Columns {
    fn len(&self) -> usize {
        self.params.len() + self.effect_scale.len()
    }
}

/// Most keep-out boxes a plan takes.
pub const MAX_KEEP_OUT: usize = 100;

/// Check a plan's options against the robot and the rig without planning
/// (cheap: no poses drawn), so that a service can refuse a bad request
/// before queueing it. [`plan`] runs the same check first.
pub fn check(robot: &Robot, rig: &Rig, opts: &PlanOptions) -> Result<()> {
    check_options(robot, opts)?;
    Scene::new(robot, rig, &opts.workspace).map(|_| ())
}

/// How the selection is made, beyond what a user asks: the defaults are
/// drawcal's; the others are there to be measured against them
/// (tests/engine/plan.rs).
#[derive(Debug, Clone, PartialEq)]
pub struct Tuning {
    /// What the selection minimises.
    pub criterion: design::Criterion,
    /// Exchange passes after the greedy selection.
    pub exchange_passes: usize,
}

impl Default for Tuning {
    fn default() -> Self {
        Tuning {
            criterion: design::Criterion::IOptimal,
            exchange_passes: EXCHANGE_PASSES,
        }
    }
}

/// Plan a session for `robot` on `rig`.
pub fn plan(robot: &Robot, rig: &Rig, opts: &PlanOptions) -> Result<Plan> {
    plan_tuned(robot, rig, opts, &Tuning::default())
}

/// [`plan`] with the selection made as `tuning` says.
pub fn plan_tuned(robot: &Robot, rig: &Rig, opts: &PlanOptions, tuning: &Tuning) -> Result<Plan> {
    let made = plan_inner(robot, rig, opts, tuning, false)?;
    Ok(with_payload_report(robot, rig, opts, tuning, made)?.plan)
}

/// How well any `n_poses` of a plan's candidates could do, in the plan's
/// linear model: the best design with weights over the candidates (which
/// no set of `n_poses` poses can beat), for comparison with the plan's own
/// prediction ([`PlanReport::predicted`]).
#[derive(Debug, Clone, Copy)]
pub struct DesignBound {
    /// Model RMS (mm) of the best weighted design found, at `n_poses`.
    pub weighted_model_rms_mm: f64,
    /// A lower bound on the model RMS (mm) of any `n_poses` of the
    /// candidates (from the weighted design's optimality gap).
    pub lower_model_rms_mm: f64,
}

/// [`plan_tuned`] and the [`DesignBound`] of its candidates (seconds to
/// minutes more: a diagnosis, not part of planning).
pub fn plan_with_bound(
    robot: &Robot,
    rig: &Rig,
    opts: &PlanOptions,
    tuning: &Tuning,
) -> Result<(Plan, DesignBound)> {
    let made = plan_inner(robot, rig, opts, tuning, true)?;
    let made = with_payload_report(robot, rig, opts, tuning, made)?;
    Ok((made.plan, made.bound.expect("asked for")))
}

/// With a payload planned, the report's [`PayloadPlan`]: the loaded and
/// unloaded poses and the compliance with and without the payload (from
/// the plan the same options make without it).
fn with_payload_report(
    robot: &Robot,
    rig: &Rig,
    opts: &PlanOptions,
    tuning: &Tuning,
    mut made: Made,
) -> Result<Made> {
    let Some(payload_kg) = opts.payload_kg else {
        return Ok(made);
    };
    let without = plan_inner(
        robot,
        rig,
        &PlanOptions {
            payload_kg: None,
            ..opts.clone()
        },
        tuning,
        false,
    )?;
    let compliance = made
        .compliance
        .iter()
        .filter_map(|&(j, with, unit)| {
            let &(_, w, _) = without.compliance.iter().find(|c| c.0 == j)?;
            Some(ComplianceSigma {
                joint: j + 1,
                sigma_with_payload: with,
                sigma_without_payload: w,
                unit: unit.into(),
            })
        })
        .collect();
    let train: Vec<&PlannedPose> = made
        .plan
        .poses
        .iter()
        .filter(|p| p.split == "train")
        .collect();
    let loaded = train.iter().filter(|p| p.payload_kg > Some(0.0)).count();
    let changes = made
        .plan
        .poses
        .windows(2)
        .filter(|w| w[0].payload_kg != w[1].payload_kg)
        .count();
    let r = &mut made.plan.report;
    r.notes.push(payload_note(
        payload_kg,
        loaded,
        train.len() - loaded,
        changes,
    ));
    r.payload = Some(PayloadPlan {
        payload_kg,
        loaded_poses: loaded,
        unloaded_poses: train.len() - loaded,
        payload_changes: changes,
        compliance,
    });
    Ok(made)
}

/// The payload plan in words.
fn payload_note(payload_kg: f64, loaded: usize, unloaded: usize, changes: usize) -> String {
    match (loaded, unloaded) {
        (0, _) => format!(
            "no pose carries the {payload_kg} kg payload: the selection found it adds nothing the robot's own weight does not"
        ),
        (_, 0) => format!(
            "every pose carries the {payload_kg} kg payload: mount it before the first pose"
        ),
        _ => format!(
            "{unloaded} chosen poses without the payload, then {loaded} with the {payload_kg} kg payload at T: the payload changes {changes} time(s), where targets.csv's payload_kg does"
        ),
    }
}

/// What [`plan_inner`] makes: the plan, the bound when asked, and each
/// joint's compliance 1-sigma (deg per the coefficient's unit, the unit).
struct Made {
    plan: Plan,
    bound: Option<DesignBound>,
    compliance: Vec<(usize, f64, &'static str)>,
}

fn plan_inner(
    robot: &Robot,
    rig: &Rig,
    opts: &PlanOptions,
    tuning: &Tuning,
    with_bound: bool,
) -> Result<Made> {
    check_options(robot, opts)?;
    let scene = Scene::new(robot, rig, &opts.workspace)?;
    let noise = opts.noise_mm.unwrap_or_else(|| default_noise(rig));
    let mut rng = Rng::new(opts.seed);
    let want = opts.candidates + PREDICTION_POSES;
    let (mut pool, drawn, rejected) = scene.sample(want, want * DRAWS_PER_CANDIDATE, &mut rng);
    let n_check = opts.n_check.unwrap_or((opts.n_poses / 4).max(5));
    if pool.len() < PREDICTION_POSES + 2 * (opts.n_poses + n_check) {
        return Err(Error::InsufficientData(format!(
            "only {} of {drawn} drawn poses are inside the joint limits, the strings' range and the workspace ({}): too few to plan {} poses; relax the floor or keep-out boxes or check base_in_rig",
            pool.len(),
            rejection_words(&rejected),
            opts.n_poses
        )));
    }
    let validation: Vec<Candidate> = pool.split_off(pool.len() - PREDICTION_POSES);
    let entries = Entries::new(pool.len(), opts.payload_kg);
    let cols = columns(&scene, &pool, &entries, opts, noise)?;
    let design_pool = design_pool(&scene, &cols, &pool, &entries, &validation, noise);
    let n_greedy = (2 * opts.n_poses).min(entries.len() - n_check);
    let sel = design::select_by(
        &design_pool,
        opts.n_poses,
        n_greedy,
        tuning.exchange_passes,
        tuning.criterion,
    );

    // Check poses: random valid poses not chosen.
    let chosen_poses: Vec<usize> = sel.chosen.iter().map(|&e| entries.cand[e]).collect();
    let mut rest: Vec<usize> = (0..pool.len())
        .filter(|i| !chosen_poses.contains(i))
        .collect();
    rng.shuffle(&mut rest);
    let home = home_pose(robot, opts);
    let visits = visits(&entries, &sel.chosen, &rest[..n_check]);
    let toured = Toured::new(
        &scene,
        &design_pool,
        &pool,
        &visits,
        &home,
        &sel.chosen,
        opts,
        noise,
    );
    let poses = toured.poses(&pool, &visits);
    let toured_q: Vec<&[f64]> = poses.iter().map(|p| p.q_deg.as_slice()).collect();
    let tour_travel_deg = tour::path_travel_deg(&home, &toured_q);

    let point_noise_rms_mm = point_noise_rms(&scene, &validation, noise);
    let (predicted, random, by_n) = predictions(
        &design_pool,
        &sel,
        opts.n_poses,
        point_noise_rms_mm,
        &mut rng,
    );
    let mut parameters =
        predicted_sigmas(&toured.covariance(&design_pool, &sel.chosen), &cols, &scene);
    let backlash = toured.report(robot.dof());
    parameters.extend(backlash_params(backlash.as_ref()));
    let compliance = compliance_sigmas(&cols, &parameters, robot.dof());
    let bound = with_bound.then(|| {
        let (phi, lower) = design::continuous_bound(&design_pool, 300);
        let n = opts.n_poses as f64;
        DesignBound {
            weighted_model_rms_mm: (phi / n).sqrt(),
            lower_model_rms_mm: (lower.max(0.0) / n).sqrt(),
        }
    });
    let approach = if opts.effects.iter().any(|e| e == "backlash") {
        approach_balance(&toured_q, &home)
    } else {
        vec![]
    };
    let notes = notes(opts, &approach, backlash.as_ref());
    let report = PlanReport {
        format: PLAN_FORMAT.into(),
        robot: robot.name.clone(),
        n_poses: opts.n_poses,
        n_check,
        criterion: format!(
            "I-optimal: the {} poses minimising the mean squared error of the calibrated model's T at {PREDICTION_POSES} random valid poses (linear least squares, {noise} mm per reading), chosen greedily from {} candidates{} then improved by exchanges",
            opts.n_poses,
            pool.len(),
            opts.payload_kg
                .map(|p| format!(", each without and with the {p} kg payload,"))
                .unwrap_or_default()
        ),
        noise_mm: noise,
        candidates_drawn: drawn,
        candidates_kept: pool.len() + validation.len(),
        rejected,
        parameters,
        undetermined: cols.aliased,
        predicted,
        random,
        point_noise_rms_mm,
        by_n,
        effects: opts.effects.clone(),
        approach,
        tour_travel_deg,
        exchanges: sel.swaps,
        notes,
        backlash,
        payload: None,
    };
    Ok(Made {
        plan: Plan { poses, report },
        bound,
        compliance,
    })
}

/// The rows the selection chooses from: every candidate unloaded and,
/// when a payload is planned, every candidate again carrying it.
struct Entries {
    /// The candidate of each entry.
    cand: Vec<usize>,
    /// Its payload: `None` when no payload is planned, else 0 or the
    /// payload (kg).
    payload: Vec<Option<f64>>,
}

impl Entries {
    fn new(n: usize, payload_kg: Option<f64>) -> Self {
        match payload_kg {
            None => Entries {
                cand: (0..n).collect(),
                payload: vec![None; n],
            },
            Some(p) => Entries {
                cand: (0..n).chain(0..n).collect(),
                payload: (0..2 * n)
                    .map(|i| Some(if i < n { 0.0 } else { p }))
                    .collect(),
            },
        }
    }

    fn len(&self) -> usize {
        self.cand.len()
    }

    /// Each entry's candidate with its payload.
    fn of<'a>(&self, pool: &'a [Candidate]) -> Vec<(&'a Candidate, Option<f64>)> {
        self.cand
            .iter()
            .zip(&self.payload)
            .map(|(&c, &p)| (&pool[c], p))
            .collect()
    }
}

/// One pose to record, before the tour orders them.
struct VisitSpec {
    /// Candidate.
    cand: usize,
    /// The design entry of a chosen pose; `None` for a check pose.
    entry: Option<usize>,
    /// Payload (kg), when payloads are planned.
    payload_kg: Option<f64>,
}

/// The chosen poses, then the check poses, these sharing the payload
/// groups in the chosen poses' proportion (the last of them loaded).
fn visits(entries: &Entries, chosen: &[usize], checks: &[usize]) -> Vec<VisitSpec> {
    let loaded = chosen
        .iter()
        .filter(|&&e| entries.payload[e].is_some_and(|p| p > 0.0))
        .count();
    let payload = entries
        .payload
        .iter()
        .flatten()
        .cloned()
        .fold(0.0, f64::max);
    let n_loaded = (checks.len() * loaded + chosen.len() / 2) / chosen.len().max(1);
    let planned = entries.payload.first().is_some_and(|p| p.is_some());
    chosen
        .iter()
        .map(|&e| VisitSpec {
            cand: entries.cand[e],
            entry: Some(e),
            payload_kg: entries.payload[e],
        })
        .chain(checks.iter().enumerate().map(|(k, &c)| VisitSpec {
            cand: c,
            entry: None,
            payload_kg: planned.then(|| {
                if k + n_loaded >= checks.len() {
                    payload
                } else {
                    0.0
                }
            }),
        }))
        .collect()
}

/// Travel a tour ordered for backlash may take, over the shortest tour's:
/// a session's time is mostly the dwell at each pose (settling and
/// measuring, 20 s in the simulator's session against about 4 s of moving
/// at its 30 deg/s on the ER3A's planned tour), so a fifth more travel
/// costs about 3 % of it.
pub const BACKLASH_TRAVEL_BOUND: f64 = 1.2;
/// Moves the backlash tour's local search tries, at most, for a tour of
/// 40 poses or fewer (about ten passes over every move of a 40-pose
/// tour); a longer tour gets proportionally fewer, each move costing in
/// proportion to its length.
const BACKLASH_SEARCH_BUDGET: usize = 20_000;

/// The visiting order and, with backlash, its dead bands' design.
struct Toured {
    /// Visits (indices into the plan's visits) in order.
    order: Vec<usize>,
    /// The shortest tour, when backlash reordered it.
    shortest: Vec<usize>,
    /// The dead bands' design, when backlash is planned for.
    backlash: Option<BacklashDesign>,
    /// Travel of the shortest tour (deg).
    shortest_travel_deg: f64,
    /// Angles of each visit (rad) and whether it is fitted.
    q_rad: Vec<(Vec<f64>, bool)>,
}

impl Toured {
    /// Order the visits: a short tour from `home`, one payload group after
    /// the other (unloaded first), reordered within
    /// [`BACKLASH_TRAVEL_BOUND`] for the dead bands when backlash is
    /// planned for.
    #[allow(clippy::too_many_arguments)]
    fn new(
        scene: &Scene,
        dpool: &design::Pool,
        pool: &[Candidate],
        visits: &[VisitSpec],
        home: &[f64],
        chosen: &[usize],
        opts: &PlanOptions,
        noise: f64,
    ) -> Self {
        let refs: Vec<&[f64]> = visits
            .iter()
            .map(|v| pool[v.cand].q_deg.as_slice())
            .collect();
        let group: Vec<usize> = visits
            .iter()
            .map(|v| usize::from(v.payload_kg.is_some_and(|p| p > 0.0)))
            .collect();
        let shortest = grouped_tour(home, &refs, &group);
        let travel = |o: &[usize]| {
            tour::path_travel_deg(home, &o.iter().map(|&k| refs[k]).collect::<Vec<_>>())
        };
        let shortest_travel_deg = travel(&shortest);
        let q_rad = visits
            .iter()
            .map(|v| (pool[v.cand].q_rad.clone(), v.entry.is_some()))
            .collect();
        let backlash = opts
            .effects
            .iter()
            .any(|e| e == "backlash")
            .then(|| backlash_design(scene, dpool, pool, visits, chosen, noise))
            .flatten();
        let order = match &backlash {
            Some(b) => tour::improve(
                home,
                &refs,
                shortest.clone(),
                &group,
                BACKLASH_TRAVEL_BOUND * shortest_travel_deg,
                BACKLASH_SEARCH_BUDGET * 40 / refs.len().max(40),
                &mut |o| b.cost(o),
            ),
            None => shortest.clone(),
        };
        Toured {
            order,
            shortest,
            backlash,
            shortest_travel_deg,
            q_rad,
        }
    }

    /// The poses in visiting order with their ids (`p01`..., `c01`...).
    fn poses(&self, pool: &[Candidate], visits: &[VisitSpec]) -> Vec<PlannedPose> {
        let (mut n_train, mut n_test) = (0, 0);
        self.order
            .iter()
            .map(|&k| {
                let v = &visits[k];
                let check = v.entry.is_none();
                let id = if check {
                    n_test += 1;
                    format!("c{n_test:02}")
                } else {
                    n_train += 1;
                    format!("p{n_train:02}")
                };
                PlannedPose {
                    id,
                    q_deg: pool[v.cand].q_deg.clone(),
                    split: if check { "test" } else { "train" }.into(),
                    payload_kg: v.payload_kg,
                }
            })
            .collect()
    }

    /// Covariance of the design's columns over the chosen entries (rows in
    /// noise units), the dead bands fitted beside them when planned for.
    fn covariance(&self, dpool: &design::Pool, chosen: &[usize]) -> Option<DMatrix<f64>> {
        let a = information(dpool, chosen);
        let Some(b) = &self.backlash else {
            return a.try_inverse();
        };
        let (bb, cc) = b.blocks(&self.order);
        let (p, k) = (a.nrows(), cc.nrows());
        let mut full = DMatrix::zeros(p + k, p + k);
        full.view_mut((0, 0), (p, p)).copy_from(&a);
        full.view_mut((0, p), (p, k)).copy_from(&bb);
        full.view_mut((p, 0), (k, p)).copy_from(&bb.transpose());
        full.view_mut((p, p), (k, k)).copy_from(&cc);
        full.try_inverse()
            .map(|inv| inv.view((0, 0), (p, p)).into_owned())
    }

    /// The dead bands' report, when backlash is planned for.
    fn report(&self, n: usize) -> Option<BacklashTour> {
        let b = self.backlash.as_ref()?;
        let sd = |v: Option<f64>| v.filter(|v| v.is_finite()).map(|v| v.sqrt().to_degrees());
        let now = b.variances(&self.order);
        let before = b.variances(&self.shortest);
        let train: Vec<&(Vec<f64>, bool)> = self.order.iter().map(|&k| &self.q_rad[k]).collect();
        let qs: Vec<&[f64]> = train.iter().map(|(q, _)| q.as_slice()).collect();
        let dirs = approach_directions(&qs);
        let joints = (0..n)
            .map(|j| {
                let (q, d): (Vec<f64>, Vec<f64>) = train
                    .iter()
                    .zip(&dirs)
                    .filter(|((_, fitted), _)| *fitted)
                    .map(|((q, _), d)| (q[j], d[j]))
                    .unzip();
                BacklashSigma {
                    joint: j + 1,
                    sigma_deg: sd(now[j]),
                    sigma_shortest_deg: sd(before[j]),
                    direction_angle_correlation: backlash::direction_angle_correlation(&q, &d),
                }
            })
            .collect();
        Some(BacklashTour {
            travel_bound: BACKLASH_TRAVEL_BOUND,
            shortest_travel_deg: self.shortest_travel_deg,
            joints,
        })
    }
}

/// A short tour of `refs` from `home` visiting group 0 first, then group
/// 1 from where group 0 ended. With one group: [`tour::order`] itself.
fn grouped_tour(home: &[f64], refs: &[&[f64]], group: &[usize]) -> Vec<usize> {
    let mut out: Vec<usize> = Vec::with_capacity(refs.len());
    for g in 0..=1 {
        let idx: Vec<usize> = (0..refs.len()).filter(|&k| group[k] == g).collect();
        if idx.is_empty() {
            continue;
        }
        let start = out.last().map_or(home, |&k| refs[k]);
        let sub: Vec<&[f64]> = idx.iter().map(|&k| refs[k]).collect();
        out.extend(tour::order(start, &sub).into_iter().map(|k| idx[k]));
    }
    out
}

/// The dead bands' design of the visits: the chosen entries' rows, and per
/// joint how the readings change with its angle (scaled by
/// [`backlash::BACKLASH_SCALE_RAD`], in noise units).
fn backlash_design(
    scene: &Scene,
    dpool: &design::Pool,
    pool: &[Candidate],
    visits: &[VisitSpec],
    chosen: &[usize],
    noise: f64,
) -> Option<BacklashDesign> {
    let n = scene.robot.dof();
    let l = scene.chain.layout;
    let mut jac = scene.chain.new_jacobian();
    let list: Vec<backlash::Visit> = visits
        .iter()
        .map(|v| {
            let c = &pool[v.cand];
            let fitted = v.entry.map(|e| {
                scene.chain.point_jacobian(
                    &scene.nominal.values,
                    &c.q_rad,
                    OutputFrame::Rig,
                    &mut jac,
                );
                let dirs = reading_directions(scene, &c.t_rig);
                let per_joint = (0..n)
                    .map(|j| {
                        let dt = jac.d_params[l.joint(j, JointParam::Theta)];
                        dirs.iter()
                            .map(|u| u.dot(&dt) * backlash::BACKLASH_SCALE_RAD / noise)
                            .collect()
                    })
                    .collect();
                (dpool.rows[e].clone(), per_joint)
            });
            backlash::Visit {
                q_rad: c.q_rad.clone(),
                fitted,
            }
        })
        .collect();
    BacklashDesign::new(&information(dpool, chosen), &list, n)
}

/// The dead bands as predicted parameters (`j2.backlash`, deg).
fn backlash_params(b: Option<&BacklashTour>) -> Vec<PredictedParam> {
    b.into_iter()
        .flat_map(|b| &b.joints)
        .filter_map(|j| {
            Some(PredictedParam {
                name: format!("j{}.backlash", j.joint),
                sigma: j.sigma_deg?,
                unit: "deg".into(),
            })
        })
        .collect()
}

/// Per joint planned for compliance whose coefficient the readings see and
/// the poses determine (a 1-sigma below the coefficient's prior size: the
/// size at which it moves the readings by three times their noise): the
/// 1-sigma (with link
/// masses its only coefficient, deg/(N·m); without, its unit mass at T,
/// deg/m) and the unit.
fn compliance_sigmas(
    cols: &Columns,
    params: &[PredictedParam],
    n: usize,
) -> Vec<(usize, f64, &'static str)> {
    let mut k0 = 0;
    let mut out = Vec::new();
    for (kind, name) in &cols.effects {
        let first = k0;
        k0 += kind.n_coef();
        let Kind::JointCompliance {
            joint_index,
            regressors,
        } = kind
        else {
            continue;
        };
        let (c, wanted, unit) = if regressors.is_empty() {
            (0, name.clone(), "deg/(N·m)")
        } else {
            let Some(c) = regressors.iter().position(|&r| r == n) else {
                continue;
            };
            (c, format!("{name}[{c}]"), "deg/m (a unit mass at T)")
        };
        // A coefficient that must reach a radian per unit before the
        // readings notice it (a wrist joint whose turn does not move T) is
        // one they do not see.
        let prior = cols.effect_scale[first + c];
        let seen = |p: &&PredictedParam| p.sigma > 0.0 && p.sigma < prior && prior < 1.0;
        if let Some(p) = params.iter().find(|p| p.name == wanted).filter(seen) {
            out.push((*joint_index, p.sigma.to_degrees(), unit));
        }
    }
    out
}

/// What least squares will give (without the prior): the chosen poses,
/// the same number of random ones (mean square of five draws) and the
/// greedy selection's nested sets from N/2 to 2N.
fn predictions(
    pool: &design::Pool,
    sel: &design::Selection,
    n: usize,
    point_noise_rms_mm: f64,
    rng: &mut Rng,
) -> (PredictionAtN, PredictionAtN, Vec<PredictionAtN>) {
    let at = |set: &[usize]| prediction(pool, set, point_noise_rms_mm);
    let predicted = at(&sel.chosen);
    let mut random_model = 0.0;
    for _ in 0..5 {
        let mut idx: Vec<usize> = (0..pool.rows.len()).collect();
        rng.shuffle(&mut idx);
        random_model += at(&idx[..n]).model_rms_mm.powi(2) / 5.0;
    }
    let random = PredictionAtN {
        n_poses: n,
        model_rms_mm: random_model.sqrt(),
        holdout_rms_mm: (random_model + point_noise_rms_mm.powi(2)).sqrt(),
    };
    let mut by_n: Vec<PredictionAtN> = curve_sizes(n, sel.greedy_order.len())
        .into_iter()
        .filter(|&k| k != n)
        .map(|k| at(&sel.greedy_order[..k]))
        .filter(|p| p.model_rms_mm.is_finite())
        .collect();
    by_n.push(predicted.clone());
    by_n.sort_by_key(|p| p.n_poses);
    (predicted, random, by_n)
}

/// What the user should know about the effects planned for.
fn notes(
    opts: &PlanOptions,
    approach: &[ApproachBalance],
    backlash: Option<&BacklashTour>,
) -> Vec<String> {
    let mut notes = Vec::new();
    if opts.effects.iter().any(|e| e == "joint_compliance") && opts.payload_kg.is_none() {
        notes.push("compliance is planned with the robot's own link masses; a payload changed part-way (payload_kg) separates it further".into());
    }
    if let Some(b) = approach
        .iter()
        .find(|b| b.from_below.min(b.from_above) * 3 < b.from_below.max(b.from_above))
    {
        notes.push(format!(
            "joint {} is approached {} times from below and {} from above: backlash is best seen with both directions in similar numbers",
            b.joint, b.from_below, b.from_above
        ));
    }
    notes.extend(backlash.map(backlash_note));
    notes
}

/// The backlash tour in words: how far it went beyond the shortest, and
/// the joints whose dead band the readings cannot see.
fn backlash_note(b: &BacklashTour) -> String {
    let unseen: Vec<String> = b
        .joints
        .iter()
        .filter(|j| j.sigma_deg.is_none())
        .map(|j| j.joint.to_string())
        .collect();
    let mut s = format!(
        "the tour is ordered for the approach directions backlash needs, within {}x the shortest tour's travel ({:.0} deg); no via-points: poses.csv's row order is what tells identify the direction",
        b.travel_bound, b.shortest_travel_deg
    );
    if !unseen.is_empty() {
        s += &format!(
            "; the dead band of joint(s) {} does not move the measured point, so no order determines it",
            unseen.join(", ")
        );
    }
    s
}

fn check_options(robot: &Robot, opts: &PlanOptions) -> Result<()> {
    if opts.n_poses < 3 || opts.n_poses > 2000 {
        return Err(Error::field(
            "n_poses",
            format!("{}: between 3 and 2000", opts.n_poses),
        ));
    }
    if !(100..=200_000).contains(&opts.candidates) {
        return Err(Error::field(
            "candidates",
            format!("{}: between 100 and 200000", opts.candidates),
        ));
    }
    if opts.candidates < 4 * opts.n_poses {
        return Err(Error::field(
            "candidates",
            format!(
                "{}: at least four per pose planned ({})",
                opts.candidates,
                4 * opts.n_poses
            ),
        ));
    }
    if let Some(c) = opts.n_check {
        if c > opts.n_poses {
            return Err(Error::field("n_check", format!("{c}: at most n_poses")));
        }
    }
    if let Some(s) = opts.noise_mm {
        if !(s.is_finite() && s > 0.0 && s < 100.0) {
            return Err(Error::field(
                "noise_mm",
                format!("{s}: a positive number of mm"),
            ));
        }
    }
    if let Some(h) = &opts.home_deg {
        if h.len() != robot.dof() {
            return Err(Error::field(
                "home_deg",
                format!("{} angles for a robot with {} joints", h.len(), robot.dof()),
            ));
        }
    }
    check_payload(opts)?;
    for (i, e) in opts.effects.iter().enumerate() {
        if !PLANNABLE_EFFECTS.contains(&e.as_str()) {
            return Err(Error::field(
                "effects",
                format!(
                    "'{e}' cannot be planned for: one of {} (time and temperature effects depend on the session, not on the poses)",
                    PLANNABLE_EFFECTS.join(", ")
                ),
            ));
        }
        if opts.effects[..i].contains(e) {
            return Err(Error::field("effects", format!("'{e}' given twice")));
        }
    }
    let w = &opts.workspace;
    if w.keep_out.len() > MAX_KEEP_OUT {
        return Err(Error::field(
            "workspace.keep_out",
            format!("{} boxes: at most {MAX_KEEP_OUT}", w.keep_out.len()),
        ));
    }
    for (name, v) in [
        ("min_string_mm", w.min_string_mm),
        ("range_margin_mm", w.range_margin_mm),
        ("anchor_plane_clearance_mm", w.anchor_plane_clearance_mm),
        ("string_clearance_mm", w.string_clearance_mm),
    ] {
        if !(0.0..=100_000.0).contains(&v) {
            return Err(Error::field(
                format!("workspace.{name}"),
                format!("{v}: between 0 and 100000 mm"),
            ));
        }
    }
    if let Some(z) = w.floor_z_mm {
        if !z.is_finite() {
            return Err(Error::field("workspace.floor_z_mm", "not a finite number"));
        }
    }
    Ok(())
}

/// A payload is a positive number of kg up to [`MAX_PAYLOAD_KG`], planned
/// for a joint compliance.
fn check_payload(opts: &PlanOptions) -> Result<()> {
    let Some(p) = opts.payload_kg else {
        return Ok(());
    };
    if !(p.is_finite() && p > 0.0 && p <= MAX_PAYLOAD_KG) {
        return Err(Error::field(
            "payload_kg",
            format!("{p}: more than 0 and at most {MAX_PAYLOAD_KG} kg"),
        ));
    }
    if !opts.effects.iter().any(|e| e == "joint_compliance") {
        return Err(Error::field(
            "payload_kg",
            "a payload is planned for a joint compliance (which poses carry it, so that its gravity torque separates the compliance from the geometry): add joint_compliance to the effects, or leave payload_kg out",
        ));
    }
    Ok(())
}

fn default_noise(rig: &Rig) -> f64 {
    if rig.n_strings() == 0 {
        return 0.03;
    }
    let res = rig.sensor.and_then(|s| s.resolution_mm).unwrap_or(0.0);
    (0.02f64.powi(2) + res * res / 12.0).sqrt()
}

fn home_pose(robot: &Robot, opts: &PlanOptions) -> Vec<f64> {
    match &opts.home_deg {
        Some(h) => h.clone(),
        None => robot
            .joints
            .iter()
            .map(|j| 0.0f64.clamp(j.q_min_deg, j.q_max_deg))
            .collect(),
    }
}

fn rejection_words(rejected: &BTreeMap<Rejection, usize>) -> String {
    let words: Vec<String> = rejected
        .iter()
        .map(|(r, n)| {
            format!(
                "{n} {}",
                serde_json::to_value(r)
                    .ok()
                    .and_then(|v| v.as_str().map(String::from))
                    .unwrap_or_default()
            )
        })
        .collect();
    if words.is_empty() {
        "none refused".into()
    } else {
        format!("refused: {}", words.join(", "))
    }
}

/// The parameters the identification frees that the pool can determine,
/// with their prior sizes, and the effects' coefficients.
fn columns(
    scene: &Scene,
    pool: &[Candidate],
    entries: &Entries,
    opts: &PlanOptions,
    noise: f64,
) -> Result<Columns> {
    let l = scene.chain.layout;
    let cand = free_candidates(l, &IdentifyOptions::default());
    let jtj = normal_matrix(scene, pool, &cand);
    let sel = identifiability::select(&jtj, &cand, &l, identifiability::DEFAULT_TOLERANCE);
    let param_scale = sel.free.iter().map(|&i| prior_size(l, i)).collect();
    let design = entries.of(pool);
    let ctx = effect_context(scene, &design);
    let mut effects = Vec::new();
    let n = scene.robot.dof();
    for e in &opts.effects {
        match e.as_str() {
            "joint_compliance" => {
                for j in 0..n {
                    let regressors = if ctx.has_masses {
                        vec![]
                    } else {
                        ctx.compliance_regressors(j, &(0..design.len()).collect::<Vec<_>>())
                    };
                    effects.push((
                        Kind::JointCompliance {
                            joint_index: j,
                            regressors,
                        },
                        format!("j{}.compliance", j + 1),
                    ));
                }
            }
            "joint_scale" => {
                effects.extend((0..n).map(|j| {
                    (
                        Kind::JointScale { joint_index: j },
                        format!("j{}.scale", j + 1),
                    )
                }));
            }
            "sensor_scale" => effects.extend((0..l.n_strings).map(|k| {
                (
                    Kind::SensorScale { sensor_index: k },
                    format!("{}.scale", scene.rig.sensor_name(k)),
                )
            })),
            "cable_sag" => effects.push((Kind::CableSag, "cable_sag".into())),
            _ => {} // backlash: a matter of the tour's approach directions
        }
    }
    let mut cols = Columns {
        params: sel.free,
        aliased: sel.fixed,
        param_scale,
        effects,
        effect_scale: vec![],
    };
    // An effect coefficient's prior: the size at which it moves the
    // readings by three times their noise (RMS over the candidates).
    let mut buf = Basis::default();
    let mut scales = Vec::new();
    for (kind, _) in &cols.effects {
        let nc = kind.n_coef();
        let mut sq = vec![0.0; nc];
        for (i, (c, _)) in design.iter().enumerate() {
            let rows = effect_rows(scene, &ctx, kind, i, c, &mut buf);
            let per = rows.len() / nc;
            for (k, r) in rows.iter().enumerate() {
                sq[k / per] += r * r;
            }
        }
        let rows_per = (scene.rig.n_strings().max(3) * design.len()) as f64;
        for s in sq {
            let rms = (s / rows_per).sqrt();
            scales.push(if rms > 0.0 { 3.0 * noise / rms } else { 0.0 });
        }
    }
    cols.effect_scale = scales;
    Ok(cols)
}

/// Prior size of parameter `i`: a manufacturing tolerance (the
/// simulator's deviations: 0.5 mm, 0.1 deg; the base 2 mm, 0.5 deg).
fn prior_size(l: crate::kinematics::Layout, i: usize) -> f64 {
    let b = l.base();
    if (b..b + 3).contains(&i) {
        2.0
    } else if (b + 3..b + 6).contains(&i) {
        0.5f64.to_radians()
    } else if l.is_angle(i) {
        0.1f64.to_radians()
    } else {
        0.5
    }
}

/// Normal matrix of the readings over `pool` for parameters `cand`
/// (natural units).
fn normal_matrix(scene: &Scene, pool: &[Candidate], cand: &[usize]) -> DMatrix<f64> {
    let p = cand.len();
    let mut jtj = DMatrix::zeros(p, p);
    let mut jac = scene.chain.new_jacobian();
    let mut row = vec![0.0; p];
    for c in pool {
        scene
            .chain
            .point_jacobian(&scene.nominal.values, &c.q_rad, OutputFrame::Rig, &mut jac);
        for dir in reading_directions(scene, &c.t_rig) {
            for (k, &i) in cand.iter().enumerate() {
                row[k] = dir.dot(&jac.d_params[i]);
            }
            for a in 0..p {
                for b in 0..p {
                    jtj[(a, b)] += row[a] * row[b];
                }
            }
        }
    }
    jtj
}

/// The direction each reading measures T along: the strings' unit
/// vectors, or the three axes for a point instrument.
fn reading_directions(scene: &Scene, t: &Vector3<f64>) -> Vec<Vector3<f64>> {
    if scene.anchors().is_empty() {
        vec![Vector3::x(), Vector3::y(), Vector3::z()]
    } else {
        scene
            .anchors()
            .iter()
            .map(|a| (t - a).normalize())
            .collect()
    }
}

/// The effects' context of candidates with their payloads (kg at T).
fn effect_context(scene: &Scene, poses: &[(&Candidate, Option<f64>)]) -> Context {
    let inputs: Vec<PoseInput> = poses
        .iter()
        .map(|(c, payload_kg)| PoseInput {
            q_rad: &c.q_rad,
            time_s: None,
            temp_c: None,
            payload_kg: *payload_kg,
            point_rig: c.t_rig,
        })
        .collect();
    let (r, _) = scene.nominal.base_rt();
    Context::new(
        scene.robot,
        scene.anchors().to_vec(),
        scene.rig.r_mm,
        &r,
        &inputs,
    )
}

/// An effect's reading rows at candidate `i` (per coefficient, per
/// reading, coefficient-major): the joint changes through T, plus the
/// readings' own change.
fn effect_rows(
    scene: &Scene,
    ctx: &Context,
    kind: &Kind,
    i: usize,
    c: &Candidate,
    buf: &mut Basis,
) -> Vec<f64> {
    let (dt, dl) = effect_displacement(scene, ctx, kind, i, c, buf);
    let dirs = reading_directions(scene, &c.t_rig);
    let nc = kind.n_coef();
    let mut out = Vec::with_capacity(nc * dirs.len());
    for (k, d) in dt.iter().enumerate() {
        for (s, u) in dirs.iter().enumerate() {
            out.push(
                u.dot(d)
                    + dl.get(k * scene.anchors().len() + s)
                        .copied()
                        .unwrap_or(0.0),
            );
        }
    }
    out
}

/// Per coefficient: T's displacement (rig frame, mm) and the readings'
/// change (mm, `n_coef × m`).
fn effect_displacement(
    scene: &Scene,
    ctx: &Context,
    kind: &Kind,
    i: usize,
    c: &Candidate,
    buf: &mut Basis,
) -> (Vec<Vector3<f64>>, Vec<f64>) {
    ctx.basis(kind, i, buf);
    let n = scene.robot.dof();
    let l = scene.chain.layout;
    let mut jac = scene.chain.new_jacobian();
    scene
        .chain
        .point_jacobian(&scene.nominal.values, &c.q_rad, OutputFrame::Rig, &mut jac);
    let nc = kind.n_coef();
    let dt = (0..nc)
        .map(|k| {
            (0..n).fold(Vector3::zeros(), |acc, j| {
                acc + jac.d_params[l.joint(j, JointParam::Theta)] * buf.dq[k * n + j]
            }) + Vector3::new(buf.dp[k * 3], buf.dp[k * 3 + 1], buf.dp[k * 3 + 2])
        })
        .collect();
    (dt, buf.dl.clone())
}

/// The design pool: each entry's readings over the columns, scaled by the
/// priors and divided by the noise, and the prediction weight from the
/// validation poses (with a payload planned, each taken unloaded and
/// loaded: compensation may be asked for either).
fn design_pool(
    scene: &Scene,
    cols: &Columns,
    pool: &[Candidate],
    entries: &Entries,
    validation: &[Candidate],
    noise: f64,
) -> design::Pool {
    let m = scene.anchors().len().max(3);
    let rows = design_rows(scene, cols, &entries.of(pool), noise);
    let loads: Vec<Option<f64>> = match entries.payload.last() {
        Some(Some(p)) => vec![Some(0.0), Some(*p)],
        _ => vec![None],
    };
    let mut w = DMatrix::zeros(cols.len(), cols.len());
    for load in &loads {
        let v: Vec<(&Candidate, Option<f64>)> = validation.iter().map(|c| (c, *load)).collect();
        w += prediction_weight(scene, cols, &v);
    }
    w /= (validation.len() * loads.len()) as f64;
    design::Pool {
        m,
        p: cols.len(),
        rows,
        w,
    }
}

/// Each entry's `m × p` rows (row-major), scaled by the priors, in noise
/// units.
fn design_rows(
    scene: &Scene,
    cols: &Columns,
    entries: &[(&Candidate, Option<f64>)],
    noise: f64,
) -> Vec<Vec<f64>> {
    let p = cols.len();
    let m = scene.anchors().len().max(3);
    let mut jac = scene.chain.new_jacobian();
    let mut buf = Basis::default();
    let ctx = effect_context(scene, entries);
    entries
        .iter()
        .enumerate()
        .map(|(i, (c, _))| {
            scene
                .chain
                .point_jacobian(&scene.nominal.values, &c.q_rad, OutputFrame::Rig, &mut jac);
            let dirs = reading_directions(scene, &c.t_rig);
            let mut r = vec![0.0; m * p];
            for (s, u) in dirs.iter().enumerate() {
                for (k, (&pi, sc)) in cols.params.iter().zip(&cols.param_scale).enumerate() {
                    r[s * p + k] = u.dot(&jac.d_params[pi]) * sc / noise;
                }
            }
            let mut k0 = cols.params.len();
            for (kind, _) in &cols.effects {
                let er = effect_rows(scene, &ctx, kind, i, c, &mut buf);
                let nc = kind.n_coef();
                for k in 0..nc {
                    for s in 0..m {
                        r[s * p + k0 + k] =
                            er[k * m + s] * cols.effect_scale[k0 - cols.params.len() + k] / noise;
                    }
                }
                k0 += nc;
            }
            r
        })
        .collect()
}

/// The sum over `poses` of `J_Tᵀ J_T`, scaled like the rows (no noise).
fn prediction_weight(
    scene: &Scene,
    cols: &Columns,
    poses: &[(&Candidate, Option<f64>)],
) -> DMatrix<f64> {
    let p = cols.len();
    let mut jac = scene.chain.new_jacobian();
    let mut buf = Basis::default();
    let vctx = effect_context(scene, poses);
    let mut w = DMatrix::zeros(p, p);
    for (i, (c, _)) in poses.iter().enumerate() {
        scene
            .chain
            .point_jacobian(&scene.nominal.values, &c.q_rad, OutputFrame::Rig, &mut jac);
        let mut jt = DMatrix::zeros(3, p);
        for (k, (&pi, sc)) in cols.params.iter().zip(&cols.param_scale).enumerate() {
            for a in 0..3 {
                jt[(a, k)] = jac.d_params[pi][a] * sc;
            }
        }
        let mut k0 = cols.params.len();
        for (kind, _) in &cols.effects {
            let (dt, _) = effect_displacement(scene, &vctx, kind, i, c, &mut buf);
            for (k, d) in dt.iter().enumerate() {
                for a in 0..3 {
                    jt[(a, k0 + k)] = d[a] * cols.effect_scale[k0 - cols.params.len() + k];
                }
            }
            k0 += dt.len();
        }
        w += jt.transpose() * jt;
    }
    w
}

/// Information of a set without the prior (what least squares gives);
/// a column no pose of the set determines keeps its prior.
fn information(pool: &design::Pool, set: &[usize]) -> DMatrix<f64> {
    let mut mm = DMatrix::zeros(pool.p, pool.p);
    for &i in set {
        let j = DMatrix::from_row_slice(pool.m, pool.p, &pool.rows[i]);
        mm += j.transpose() * j;
    }
    for c in 0..pool.p {
        if mm[(c, c)] < 1e-9 {
            mm[(c, c)] = 1.0;
        }
    }
    mm
}

fn prediction(pool: &design::Pool, set: &[usize], point_noise_rms_mm: f64) -> PredictionAtN {
    let model = information(pool, set)
        .try_inverse()
        .map_or(f64::INFINITY, |inv| (&pool.w * inv).trace().max(0.0));
    PredictionAtN {
        n_poses: set.len(),
        model_rms_mm: model.sqrt(),
        holdout_rms_mm: (model + point_noise_rms_mm.powi(2)).sqrt(),
    }
}

/// Each column's 1-sigma from the covariance `inv` (rows in noise units:
/// the information's inverse), in the parameters' units.
fn predicted_sigmas(
    inv: &Option<DMatrix<f64>>,
    cols: &Columns,
    scene: &Scene,
) -> Vec<PredictedParam> {
    let Some(inv) = inv else {
        return vec![];
    };
    let l = scene.chain.layout;
    let mut out: Vec<PredictedParam> = cols
        .params
        .iter()
        .zip(&cols.param_scale)
        .enumerate()
        .map(|(k, (&i, sc))| {
            let s = inv[(k, k)].max(0.0).sqrt() * sc;
            let angle = l.is_angle(i);
            PredictedParam {
                name: l.name(i),
                sigma: if angle { s.to_degrees() } else { s },
                unit: if angle { "deg" } else { "mm" }.into(),
            }
        })
        .collect();
    let mut k = cols.params.len();
    for (kind, name) in &cols.effects {
        for c in 0..kind.n_coef() {
            out.push(PredictedParam {
                name: if kind.n_coef() > 1 {
                    format!("{name}[{c}]")
                } else {
                    name.clone()
                },
                sigma: inv[(k, k)].max(0.0).sqrt() * cols.effect_scale[k - cols.params.len()],
                unit: "coefficient (rad per N·m, per unit)".into(),
            });
            k += 1;
        }
    }
    out
}

fn point_noise_rms(scene: &Scene, poses: &[Candidate], noise: f64) -> f64 {
    let m = scene.anchors().len();
    if m == 0 {
        return noise * 3f64.sqrt();
    }
    let mean: f64 = poses
        .iter()
        .map(|c| {
            let g = DMatrix::from_fn(m, 3, |k, a| (c.t_rig - scene.anchors()[k]).normalize()[a]);
            (g.transpose() * g)
                .try_inverse()
                .map_or(0.0, |inv| inv.trace())
        })
        .sum::<f64>()
        / poses.len() as f64;
    noise * mean.sqrt()
}

fn curve_sizes(n: usize, max: usize) -> Vec<usize> {
    let mut v: Vec<usize> = [0.5, 0.67, 1.0, 1.33, 1.67, 2.0]
        .iter()
        .map(|f| ((n as f64) * f).round() as usize)
        .filter(|&k| k >= 3 && k <= max)
        .collect();
    v.dedup();
    v
}

fn approach_balance(toured: &[&[f64]], home: &[f64]) -> Vec<ApproachBalance> {
    let mut path: Vec<&[f64]> = vec![home];
    path.extend_from_slice(toured);
    let dirs = approach_directions(&path);
    (0..home.len())
        .map(|j| ApproachBalance {
            joint: j + 1,
            from_below: dirs[1..].iter().filter(|d| d[j] > 0.0).count(),
            from_above: dirs[1..].iter().filter(|d| d[j] < 0.0).count(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Poses sweeping joint 1 of the ER3A in 8 deg steps, the other joints
    /// within ±2 deg of one valid pose: the shortest tour walks joint 1
    /// one way, where its dead band is an offset.
    fn sweep(scene: &Scene) -> Vec<Candidate> {
        let mut rng = Rng::new(3);
        let (pool, _, _) = scene.sample(50, 50_000, &mut rng);
        let mut jac = scene.chain.new_jacobian();
        let centre = pool
            .iter()
            .max_by_key(|c| {
                (-12..=12)
                    .filter(|k| {
                        let mut q = c.q_deg.clone();
                        q[0] += 8.0 * *k as f64;
                        q[0].abs() < 168.0 && scene.check(q, &mut jac).is_ok()
                    })
                    .count()
            })
            .unwrap()
            .clone();
        (-12..=12)
            .filter_map(|k| {
                let mut q = centre.q_deg.clone();
                q[0] += 8.0 * k as f64;
                for v in q.iter_mut().skip(1) {
                    *v = ((*v + rng.range(-2.0, 2.0)) * 1e4).round() / 1e4;
                }
                let inside = q
                    .iter()
                    .zip(&scene.robot.joints)
                    .all(|(v, j)| *v >= j.q_min_deg && *v <= j.q_max_deg);
                inside.then(|| scene.check(q, &mut jac).ok()).flatten()
            })
            .collect()
    }

    #[test]
    fn a_tour_sweeping_a_joint_one_way_is_reordered_to_see_its_dead_band() {
        let (robot, rig, _) = crate::physics::simulate::preset("er3a").unwrap();
        let ws = Workspace::default();
        let scene = Scene::new(&robot, &rig, &ws).unwrap();
        let poses = sweep(&scene);
        assert!(poses.len() >= 12, "{} poses", poses.len());
        let mut opts = PlanOptions::new(poses.len());
        opts.effects = vec!["backlash".into()];
        let noise = default_noise(&rig);
        let entries = Entries::new(poses.len(), None);
        let cols = columns(&scene, &poses, &entries, &opts, noise).unwrap();
        let dpool = design_pool(&scene, &cols, &poses, &entries, &poses, noise);
        let chosen: Vec<usize> = (0..poses.len()).collect();
        let v = visits(&entries, &chosen, &[]);
        let home = home_pose(&robot, &opts);
        let toured = Toured::new(&scene, &dpool, &poses, &v, &home, &chosen, &opts, noise);
        let q1 = |o: &[usize]| -> Vec<f64> { o.iter().map(|&k| poses[k].q_deg[0]).collect() };
        let ups = |q: &[f64]| q.windows(2).filter(|w| w[1] > w[0]).count();
        let (before, after) = (q1(&toured.shortest), q1(&toured.order));
        let n = before.len() - 1;
        // The shortest tour sweeps joint 1 one way.
        assert!(ups(&before) == 0 || ups(&before) == n, "{before:?}");
        // The tour planned approaches it from both sides within the travel
        // bound (a one-way sweep of small steps can only be partly
        // balanced: each step back costs twice its size).
        let up = ups(&after);
        assert!(6 * up.min(n - up) >= n, "{up} of {n} up: {after:?}");
        let refs =
            |o: &[usize]| -> Vec<&[f64]> { o.iter().map(|&k| poses[k].q_deg.as_slice()).collect() };
        let travel = tour::path_travel_deg(&home, &refs(&toured.order));
        assert!(travel <= BACKLASH_TRAVEL_BOUND * toured.shortest_travel_deg + 1e-9);
        // And its predicted sigma falls.
        let r = toured.report(robot.dof()).unwrap();
        let j1 = &r.joints[0];
        let s = j1.sigma_deg.unwrap();
        assert!(
            j1.sigma_shortest_deg.is_none_or(|s0| s < 0.5 * s0),
            "joint 1: {s} deg against {:?} deg with the shortest tour",
            j1.sigma_shortest_deg
        );
    }
}
