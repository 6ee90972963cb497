//! A payload in a plan: the selection's entries (every candidate without
//! and with the payload), which poses carry it, the compliance it
//! separates, and the report's [`PayloadPlan`].

use serde::{Deserialize, Serialize};

use super::columns::{Columns, design_pool_in, effect_columns, predicted_sigmas};
use super::{
    Candidate, Drawn, MAX_PAYLOAD_KG, Plan, PlanOptions, PlannedPose, PredictedParam, Tuning,
    choose,
};
use crate::error::{Error, Result};
use crate::model::Robot;
use crate::physics::Kind;
use crate::rng::Rng;

/// A joint's compliance with and without the payload.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ComplianceSigma {
    /// Joint (1-based).
    pub joint: usize,
    /// Predicted 1-sigma with this plan (the payload carried where it
    /// chose). With link masses, of the joint's one compliance
    /// coefficient; without them, of the payload's coefficient divided by
    /// g: the payload's gravity torque is then the only one known, and its
    /// coefficient is the compliance times g.
    pub sigma_with_payload: f64,
    /// Predicted 1-sigma of the plan the same options make without a
    /// payload; `None` (`null`) where that plan does not determine the
    /// compliance: always for a robot without link masses, where only the
    /// compliance times the links' unknown masses can be fitted without a
    /// payload.
    pub sigma_without_payload: Option<f64>,
    /// `deg/(N·m)`.
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

/// The rows the selection chooses from: every candidate unloaded and,
/// when a payload is planned, every candidate again carrying it.
pub(super) struct Entries {
    /// The candidate of each entry.
    pub(super) cand: Vec<usize>,
    /// Its payload: `None` when no payload is planned, else 0 or the
    /// payload (kg).
    pub(super) payload: Vec<Option<f64>>,
}

impl Entries {
    pub(super) fn new(n: usize, payload_kg: Option<f64>) -> Self {
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

    pub(super) fn len(&self) -> usize {
        self.cand.len()
    }

    /// Each entry's candidate with its payload.
    pub(super) fn of<'a>(&self, pool: &'a [Candidate]) -> Vec<(&'a Candidate, Option<f64>)> {
        self.cand
            .iter()
            .zip(&self.payload)
            .map(|(&c, &p)| (&pool[c], p))
            .collect()
    }
}

/// The compliance 1-sigma per joint (deg/(N·m)) of the plan the same
/// options make without the payload (what [`add_payload_report`] sets
/// beside the plan's own), made from the payload plan's draws: the same candidates
/// and prediction poses, the same parameters freed, and the draws'
/// random state `after_draws` for its check poses. The candidates
/// unloaded are the payload plan's first entries, so their effect context
/// is `drawn.ctx`'s first poses. It is the plan `plan` makes without
/// `payload_kg`, but for its curve over N (the greedy steps past N, which
/// change none of its poses, are not taken) and its report.
pub(super) fn compliance_without_payload(
    drawn: &Drawn,
    opts: &PlanOptions,
    tuning: &Tuning,
    mut after_draws: Rng,
) -> Vec<(usize, f64)> {
    let opts = PlanOptions {
        payload_kg: None,
        ..opts.clone()
    };
    let scene = drawn.scene;
    let entries = Entries::new(drawn.pool.len(), None);
    let design = entries.of(drawn.pool);
    let cols = effect_columns(scene, drawn.free, drawn.ctx, &design, &opts, drawn.noise);
    let dpool = design_pool_in(
        scene,
        &cols,
        drawn.ctx,
        &design,
        &entries,
        drawn.validation,
        drawn.noise,
    );
    let chosen = choose(
        scene,
        &dpool,
        drawn.pool,
        &entries,
        &opts,
        tuning,
        opts.n_poses,
        drawn.n_check,
        &mut after_draws,
        drawn.noise,
    );
    let params = predicted_sigmas(
        &chosen.toured.covariance(&dpool, &chosen.sel.chosen),
        &cols,
        scene,
    );
    compliance_sigmas(&cols, &params, scene.robot)
}

/// The report's [`PayloadPlan`] and its notes: the loaded and unloaded
/// poses of `plan`, and per joint its compliance 1-sigma (`with`,
/// deg/(N·m)) beside the plan's without the payload (`without`; `None`
/// when no plan without a payload determines it, for a robot without link
/// masses).
pub(super) fn add_payload_report(
    plan: &mut Plan,
    robot: &Robot,
    payload_kg: f64,
    with: &[(usize, f64)],
    without: Option<&[(usize, f64)]>,
) {
    let compliance = with
        .iter()
        .map(|&(j, with)| ComplianceSigma {
            joint: j + 1,
            sigma_with_payload: with,
            sigma_without_payload: without
                .and_then(|w| w.iter().find(|c| c.0 == j))
                .map(|c| c.1),
            unit: COMPLIANCE_UNIT.into(),
        })
        .collect();
    let train: Vec<&PlannedPose> = plan.poses.iter().filter(|p| p.split == "train").collect();
    let loaded = train.iter().filter(|p| p.payload_kg > Some(0.0)).count();
    let changes = plan
        .poses
        .windows(2)
        .filter(|w| w[0].payload_kg != w[1].payload_kg)
        .count();
    let r = &mut plan.report;
    r.notes.push(payload_note(
        payload_kg,
        loaded,
        train.len() - loaded,
        changes,
    ));
    let seen: Vec<usize> = with.iter().map(|c| c.0).collect();
    let unseen: Vec<String> = (0..robot.dof())
        .filter(|j| !seen.contains(j))
        .map(|j| (j + 1).to_string())
        .collect();
    if !has_masses(robot) {
        r.notes.push(format!(
            "robot.json has no link masses: {}; the arm's own weight enters as lumped terms (the compliance times the links' unknown masses), which no plan without a payload separates from the compliance",
            if seen.is_empty() {
                "no joint's compliance is determined, which takes poses both with and without the payload whose torque on the joint differs".to_string()
            } else {
                format!(
                    "the compliance of joint(s) {} (deg/(N·m)) is determined by the payload alone, from the poses with it against those without",
                    seen.iter().map(|j| (j + 1).to_string()).collect::<Vec<_>>().join(", ")
                )
            }
        ));
    }
    if !unseen.is_empty() && !seen.is_empty() {
        r.notes.push(format!(
            "the compliance of joint(s) {} is not determined: the gravity torques on it are nil or too small over these poses, or its turn does not move the measured point",
            unseen.join(", ")
        ));
    }
    r.payload = Some(PayloadPlan {
        payload_kg,
        loaded_poses: loaded,
        unloaded_poses: train.len() - loaded,
        payload_changes: changes,
        compliance,
    });
}

/// The unit of a compliance's 1-sigma in a plan's payload report.
const COMPLIANCE_UNIT: &str = "deg/(N·m)";

/// True when `robot` has a mass for every link (the gravity torques are
/// then known, and a compliance has one coefficient).
pub(super) fn has_masses(robot: &Robot) -> bool {
    robot.links.as_ref().is_some_and(|l| l.len() == robot.dof())
}

/// The size of gravity for `robot` (m/s²: its `gravity_in_base`, or
/// 9.81).
fn gravity(robot: &Robot) -> f64 {
    robot
        .gravity_in_base
        .map_or(9.81, |g| (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt())
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

/// Per joint planned for compliance whose compliance the readings see and
/// the poses determine (a 1-sigma below the coefficient's prior size: the
/// size at which it moves the readings by three times their noise): the
/// 1-sigma of its compliance (deg/(N·m)). With link masses that is its one
/// coefficient's. Without them the payload's gravity torque at T is the
/// only one known, and its coefficient is the compliance times g: its
/// 1-sigma over g; a joint without that coefficient (no payload planned,
/// or the payload's torque on it nil or following the tool's) is not
/// listed.
pub(super) fn compliance_sigmas(
    cols: &Columns,
    params: &[PredictedParam],
    robot: &Robot,
) -> Vec<(usize, f64)> {
    let payload_regressor = robot.dof() + 1;
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
        let (c, per) = if regressors.is_empty() {
            (0, 1.0)
        } else {
            let Some(c) = regressors.iter().position(|&r| r == payload_regressor) else {
                continue;
            };
            (c, gravity(robot))
        };
        // As `predicted_sigmas` names the coefficients.
        let wanted = if kind.n_coef() > 1 {
            format!("{name}[{c}]")
        } else {
            name.clone()
        };
        // A coefficient that must reach a radian per unit before the
        // readings notice it (a wrist joint whose turn does not move T) is
        // one they do not see.
        let prior = cols.effect_scale[first + c];
        let seen = |p: &&PredictedParam| p.sigma > 0.0 && p.sigma < prior && prior < 1.0;
        if let Some(p) = params.iter().find(|p| p.name == wanted).filter(seen) {
            out.push((*joint_index, p.sigma.to_degrees() / per));
        }
    }
    out
}

/// A payload is a positive number of kg up to [`MAX_PAYLOAD_KG`], planned
/// for a joint compliance.
pub(super) fn check_payload(opts: &PlanOptions) -> Result<()> {
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
