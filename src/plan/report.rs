//! The plan and its report as they are serialised (the plan's JSON and
//! targets.csv); the backlash and payload parts of the report are with
//! their planning, in `backlash` and `payload`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::{BacklashTour, PayloadPlan, Rejection};
use crate::report::FixedParam;

/// The report's format tag.
pub const PLAN_FORMAT: &str = "drawcal plan v1";

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

/// The prediction for a number of poses. Both figures are infinite where
/// the poses do not determine every parameter (JSON has no infinity:
/// serde_json writes `null`, read back as infinite).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PredictionAtN {
    /// Poses.
    pub n_poses: usize,
    /// RMS error of the calibrated model's T at random valid poses (mm).
    #[serde(deserialize_with = "infinite_if_null")]
    pub model_rms_mm: f64,
    /// Predicted held-out RMS: the model's error and the located point's
    /// noise together (mm).
    #[serde(deserialize_with = "infinite_if_null")]
    pub holdout_rms_mm: f64,
}

impl PredictionAtN {
    /// Whether the poses determine every parameter (the figures are finite).
    pub fn is_determined(&self) -> bool {
        self.model_rms_mm.is_finite()
    }
}

/// A prediction this crate wrote as `null` was an undetermined (infinite)
/// one; a stored plan must read back as it was written.
fn infinite_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
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
