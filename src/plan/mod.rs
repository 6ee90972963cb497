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
//!
//! This file holds the entry points and the steps in order; beside it:
//! `options.rs` (the options and their checks), `report.rs` (the plan and
//! its report as serialised), `columns.rs` (the design's columns, each
//! candidate's rows and the linear predictions), `visits.rs` (the poses to
//! record and their visiting order), `backlash.rs` (the dead bands a
//! visiting order determines) and `payload.rs` (which poses carry a
//! payload, and the compliance it separates).

use std::collections::BTreeMap;

use crate::error::{Error, Result};
use crate::model::{Rig, Robot};
use crate::physics::effects::approach_directions;
use crate::rng::Rng;

mod backlash;
pub mod candidates;
mod columns;
pub mod design;
pub mod extend;
mod options;
mod payload;
mod report;
pub mod tour;
mod visits;

pub use backlash::{BACKLASH_TRAVEL_BOUND, BacklashSigma, BacklashTour};
pub use candidates::{Candidate, KeepOut, Rejection, Scene, Workspace};
pub use extend::extend;
pub use options::{MAX_KEEP_OUT, MAX_PAYLOAD_KG, PLANNABLE_EFFECTS, PlanOptions};
pub use payload::{ComplianceSigma, PayloadPlan};
pub use report::{
    ApproachBalance, PLAN_FORMAT, Plan, PlanReport, PlannedPose, PredictedParam, PredictionAtN,
};

use crate::physics::effects::Context;
use backlash::{backlash_note, backlash_params};
use columns::{
    FreeParams, design_pool_in, effect_columns, effect_context, free_params, point_noise_rms,
    predicted_sigmas, prediction,
};
use options::{check_options, default_noise, home_pose};
use payload::{
    Entries, add_payload_report, compliance_sigmas, compliance_without_payload, has_masses,
};
use visits::{Toured, VisitSpec, visits};

/// Valid random poses drawn before giving up on finding enough, per pose
/// asked for.
const DRAWS_PER_CANDIDATE: usize = 50;

/// Random valid poses the prediction is averaged over.
const PREDICTION_POSES: usize = 400;

/// Exchange passes after the greedy selection.
const EXCHANGE_PASSES: usize = 3;

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
    Ok(plan_inner(robot, rig, opts, tuning, false)?.plan)
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
    Ok((made.plan, made.bound.expect("asked for")))
}

/// What [`plan_inner`] makes: the plan and the bound when asked.
struct Made {
    plan: Plan,
    bound: Option<DesignBound>,
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
    // A payload plan reports the plan the same options make without the
    // payload beside its own: it starts from the same draws.
    let after_draws = rng.clone();
    let entries = Entries::new(pool.len(), opts.payload_kg);
    let design = entries.of(&pool);
    let ctx = effect_context(&scene, &design);
    let free = free_params(&scene, &pool);
    let cols = effect_columns(&scene, &free, &ctx, &design, opts, noise);
    let design_pool = design_pool_in(&scene, &cols, &ctx, &design, &entries, &validation, noise);
    let n_greedy = (2 * opts.n_poses).min(entries.len() - n_check);
    let Chosen {
        sel,
        visits,
        toured,
    } = choose(
        &scene,
        &design_pool,
        &pool,
        &entries,
        opts,
        tuning,
        n_greedy,
        n_check,
        &mut rng,
        noise,
    );
    let home = home_pose(robot, opts);
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
    let compliance = compliance_sigmas(&cols, &parameters, robot);
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
    let mut notes = notes(robot, opts, &approach, backlash.as_ref());
    notes.extend(undetermined_note(&predicted, &by_n));
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
    let mut plan = Plan { poses, report };
    if let Some(payload_kg) = opts.payload_kg {
        // Without link masses no plan without a payload determines a
        // compliance: there is nothing to set beside this one's.
        let without = has_masses(robot).then(|| {
            compliance_without_payload(
                &Drawn {
                    scene: &scene,
                    pool: &pool,
                    validation: &validation,
                    free: &free,
                    ctx: &ctx,
                    n_check,
                    noise,
                },
                opts,
                tuning,
                after_draws,
            )
        });
        add_payload_report(
            &mut plan,
            robot,
            payload_kg,
            &compliance,
            without.as_deref(),
        );
    }
    Ok(Made { plan, bound })
}

/// What every design of a plan is built from: the scene, the candidates
/// drawn and the prediction poses, the parameters the identification
/// frees over them, and the effects' context of the plan's entries (the
/// candidates unloaded first: a design without the payload takes the
/// first poses).
struct Drawn<'a> {
    scene: &'a Scene<'a>,
    pool: &'a [Candidate],
    validation: &'a [Candidate],
    free: &'a FreeParams,
    ctx: &'a Context,
    n_check: usize,
    noise: f64,
}

/// A design's choice: the selection, the poses to record (the chosen,
/// then check poses drawn from the candidates not chosen) and their
/// visiting order.
struct Chosen {
    sel: design::Selection,
    visits: Vec<VisitSpec>,
    toured: Toured,
}

/// Select `opts.n_poses` of `dpool`'s entries (greedily up to `n_greedy`,
/// then by exchanges), draw the check poses with `rng` and order the
/// visits.
#[allow(clippy::too_many_arguments)]
fn choose(
    scene: &Scene,
    dpool: &design::Pool,
    pool: &[Candidate],
    entries: &Entries,
    opts: &PlanOptions,
    tuning: &Tuning,
    n_greedy: usize,
    n_check: usize,
    rng: &mut Rng,
    noise: f64,
) -> Chosen {
    let sel = design::select_by(
        dpool,
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
    let home = home_pose(scene.robot, opts);
    let visits = visits(entries, &sel.chosen, &rest[..n_check]);
    let toured = Toured::new(scene, dpool, pool, &visits, &home, &sel.chosen, opts, noise);
    Chosen {
        sel,
        visits,
        toured,
    }
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
    robot: &Robot,
    opts: &PlanOptions,
    approach: &[ApproachBalance],
    backlash: Option<&BacklashTour>,
) -> Vec<String> {
    let mut notes = Vec::new();
    if opts.effects.iter().any(|e| e == "joint_compliance") && opts.payload_kg.is_none() {
        notes.push(if has_masses(robot) {
            "compliance is planned with the robot's own link masses; a payload changed part-way (payload_kg) separates it further".into()
        } else {
            "robot.json has no link masses: without a payload the compliance is planned as lumped terms (the compliance times the links' unknown masses), which predict the deflection under the arm's own weight but do not determine the compliance itself; a payload changed part-way (payload_kg) determines it".into()
        });
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

/// Where the chosen poses do not determine every parameter, say so and
/// which N of the curve does: the predictions for N are then `null`.
fn undetermined_note(predicted: &PredictionAtN, by_n: &[PredictionAtN]) -> Option<String> {
    if predicted.is_determined() {
        return None;
    }
    let enough = by_n
        .iter()
        .find(|p| p.is_determined() && p.n_poses > predicted.n_poses)
        .map_or("more poses are needed".to_string(), |p| {
            format!("{} poses do", p.n_poses)
        });
    Some(format!(
        "{} poses do not determine every parameter this rig can determine (their readings' information is singular), so their predictions are null; {enough}",
        predicted.n_poses
    ))
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
