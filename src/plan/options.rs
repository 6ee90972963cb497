//! What a plan is asked for: its options, their defaults and limits, and
//! their checks against the robot.

use serde::{Deserialize, Serialize};

use super::Workspace;
use super::payload::check_payload;
use crate::error::{Error, Result};
use crate::model::{Rig, Robot};

/// Effects a plan can be made for.
pub const PLANNABLE_EFFECTS: &[&str] = &[
    "joint_compliance",
    "backlash",
    "joint_scale",
    "sensor_scale",
    "cable_sag",
    "base_tilt",
    "link_bending",
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

/// Most keep-out boxes a plan takes.
pub const MAX_KEEP_OUT: usize = 100;

pub(super) fn check_options(robot: &Robot, opts: &PlanOptions) -> Result<()> {
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
    if let Some(e) = opts
        .effects
        .iter()
        .find(|e| matches!(e.as_str(), "base_tilt" | "link_bending"))
    {
        if !super::payload::has_masses(robot) {
            return Err(Error::field(
                "effects",
                format!(
                    "'{e}' is driven by the weight of the links, and robot.json has no link masses"
                ),
            ));
        }
    }
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

pub(super) fn default_noise(rig: &Rig) -> f64 {
    if rig.n_strings() == 0 {
        return 0.03;
    }
    let res = rig.sensor.and_then(|s| s.resolution_mm).unwrap_or(0.0);
    (0.02f64.powi(2) + res * res / 12.0).sqrt()
}

pub(super) fn home_pose(robot: &Robot, opts: &PlanOptions) -> Vec<f64> {
    match &opts.home_deg {
        Some(h) => h.clone(),
        None => robot
            .joints
            .iter()
            .map(|j| 0.0f64.clamp(j.q_min_deg, j.q_max_deg))
            .collect(),
    }
}
