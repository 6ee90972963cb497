//! A payload in a plan: the selection's entries (every candidate without
//! and with the payload), which poses carry it, the compliance it
//! separates, and the report's [`PayloadPlan`].

use serde::{Deserialize, Serialize};

use super::columns::Columns;
use super::{
    Candidate, MAX_PAYLOAD_KG, Made, PlanOptions, PlannedPose, PredictedParam, Tuning, plan_inner,
};
use crate::error::{Error, Result};
use crate::model::{Rig, Robot};
use crate::physics::Kind;

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

/// With a payload planned, the report's [`PayloadPlan`]: the loaded and
/// unloaded poses and the compliance with and without the payload (from
/// the plan the same options make without it).
pub(super) fn with_payload_report(
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

/// Per joint planned for compliance whose coefficient the readings see and
/// the poses determine (a 1-sigma below the coefficient's prior size: the
/// size at which it moves the readings by three times their noise): the
/// 1-sigma (with link
/// masses its only coefficient, deg/(N·m); without, its unit mass at T,
/// deg/m) and the unit.
pub(super) fn compliance_sigmas(
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
