//! The calibration report: what `drawcal identify` writes and the service
//! stores. Documented field by field in docs/CLI.md (the report).

use serde::{Deserialize, Serialize};

pub mod activation;
pub mod effect;
pub mod verdict;

use nalgebra::Vector3;

use crate::model::{BasePose, Rig, Robot};
use effect::{EffectModel, Kind};

/// A number this crate wrote: JSON has no NaN or infinity, so serde_json
/// writes them as `null`; read that back as NaN (an unknown, not a
/// malformed report). Every plain number of the report reads this way.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// NaN, the default of a figure a report does not carry.
fn nan() -> f64 {
    f64::NAN
}

/// Current report format tag. v2 (drawcal 0.1, 2026-12) added `physics`
/// (whether the physics analysis ran, [`PhysicsRun`]; v1 said it only by a
/// note beginning "not run").
pub const REPORT_FORMAT: &str = "drawcal report v2";

/// The previous format tag: still read ([`Report::from_json`]).
pub const REPORT_FORMAT_V1: &str = "drawcal report v1";

/// Error figures of one model on one set of poses (the paper's Tables 3 and
/// 4 plus RMS). Errors are model T minus measured T, in the robot base frame.
/// Every figure is NaN (`null` in JSON) when the set has no poses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct ErrorStats {
    /// 3-D RMS (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub rms_mm: f64,
    /// 3-D mean (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub mean_mm: f64,
    /// 3-D max (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub max_mm: f64,
    /// Per axis x, y, z of the robot base frame.
    pub x: AxisStats,
    /// y axis.
    pub y: AxisStats,
    /// z axis.
    pub z: AxisStats,
}

impl ErrorStats {
    /// Figures of a set of error vectors (mm).
    pub fn of(errors: &[Vector3<f64>]) -> ErrorStats {
        let n = errors.len();
        if n == 0 {
            // No poses, no figures: NaN, written as null, never a perfect 0.
            let none = AxisStats {
                max_abs_mm: f64::NAN,
                mean_abs_mm: f64::NAN,
                rms_mm: f64::NAN,
            };
            return ErrorStats {
                rms_mm: f64::NAN,
                mean_mm: f64::NAN,
                max_mm: f64::NAN,
                x: none,
                y: none,
                z: none,
            };
        }
        let nf = n as f64;
        let axis = |c: usize| {
            let abs: Vec<f64> = errors.iter().map(|e| e[c].abs()).collect();
            AxisStats {
                max_abs_mm: abs.iter().cloned().fold(0.0, f64::max),
                mean_abs_mm: abs.iter().sum::<f64>() / nf,
                rms_mm: crate::stats::rms(&abs),
            }
        };
        let norms: Vec<f64> = errors.iter().map(|e| e.norm()).collect();
        ErrorStats {
            rms_mm: crate::stats::rms(&norms),
            mean_mm: norms.iter().sum::<f64>() / nf,
            max_mm: norms.iter().cloned().fold(0.0, f64::max),
            x: axis(0),
            y: axis(1),
            z: axis(2),
        }
    }
}

/// Per-axis figures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct AxisStats {
    /// Max absolute error (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub max_abs_mm: f64,
    /// Mean absolute error (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub mean_abs_mm: f64,
    /// RMS (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub rms_mm: f64,
}

/// Before (nominal model, base and tool fitted) and after (calibrated).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct SplitStats {
    /// Number of poses.
    pub n: usize,
    /// Nominal joints, fitted base and tool.
    pub before: ErrorStats,
    /// Calibrated model.
    pub after: ErrorStats,
}

/// Train and test figures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct Stats {
    /// Poses used for identification.
    pub train: SplitStats,
    /// Held-out poses.
    pub test: SplitStats,
    /// The held-out poses whose residuals no decision of the physics analysis read (half
    /// of `test`, alternate poses in session order; `--confirm-half`):
    /// `test.after` is measured on poses the analysis's held-out gates
    /// also chose by, so it runs optimistic where effects were kept, while
    /// this is not. Absent when the held-out poses were not halved (the
    /// analysis off or not run, fewer than 20 held-out poses, or reports
    /// written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confirmation: Option<SplitStats>,
}

/// Identified deviation of one joint from nominal, with 1-sigma
/// uncertainties (`None` where the parameter was fixed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[allow(missing_docs)]
pub struct JointDeviation {
    /// Joint number, 1-based.
    pub joint: usize,
    #[serde(deserialize_with = "nan_if_null")]
    pub a_mm: f64,
    pub a_mm_sigma: Option<f64>,
    #[serde(deserialize_with = "nan_if_null")]
    pub alpha_deg: f64,
    pub alpha_deg_sigma: Option<f64>,
    #[serde(deserialize_with = "nan_if_null")]
    pub d_mm: f64,
    pub d_mm_sigma: Option<f64>,
    #[serde(deserialize_with = "nan_if_null")]
    pub theta_offset_deg: f64,
    pub theta_offset_deg_sigma: Option<f64>,
    #[serde(deserialize_with = "nan_if_null")]
    pub beta_deg: f64,
    pub beta_deg_sigma: Option<f64>,
}

/// A parameter held at nominal, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FixedParam {
    /// Parameter name (`j3.d`).
    pub name: String,
    /// The free parameters it moves T like (its alias), strongest first.
    pub aliased_with: Vec<String>,
    /// Why it is held (`aliased` in reports written before the field).
    #[serde(default)]
    pub reason: FixedReason,
}

/// Why a parameter is held at nominal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FixedReason {
    /// It moves T like a combination of the kept parameters: no data of
    /// this kind can separate it.
    #[default]
    Aliased,
    /// Nearly aliased, and its deviation from nominal was under
    /// `undetermined_z` sigmas: these data do not determine it.
    Undetermined,
    /// Held by the choice of the free set ([`FreeSetChoice`]): with these
    /// few poses, the model without it predicted the train poses left out
    /// of each fit clearly better than the model with it.
    FreeSet,
    /// Held by the caller (`hold`).
    Requested,
}

impl FixedReason {
    /// How the CLI summary and the HTML report head each group.
    pub fn heading(self) -> &'static str {
        match self {
            FixedReason::Aliased => "held at nominal (this data cannot separate them)",
            FixedReason::Undetermined => {
                "held at nominal (nearly aliased and not significantly off nominal: this data does not determine them)"
            }
            FixedReason::Requested => "held at nominal by request",
            FixedReason::FreeSet => {
                "held at nominal by the free-set choice (with these few poses the smaller model predicts better)"
            }
        }
    }
}

/// Poses that would determine what a session left undetermined (the
/// planner's advice after a calibration; `plan::extend`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExtraPoses {
    /// The parameters aimed at, with their predicted 1-sigma.
    pub parameters: Vec<ExtraParam>,
    /// The poses (`e01`...), in a tour from the last recorded pose; empty
    /// when every parameter held is inseparable.
    pub poses: Vec<ExtraPose>,
    /// Parameters held for want of data that no pose of this rig would
    /// separate from the identified ones (with those they move T like).
    #[serde(default)]
    pub inseparable: Vec<FixedParam>,
    /// How they were chosen and what the user must still check.
    pub criterion: String,
}

impl ExtraPoses {
    /// The poses as targets.csv (split `train`): what to record next
    /// (a header alone when there are none).
    pub fn targets_csv(&self) -> String {
        crate::model::targets::joint_targets_csv(
            self.poses
                .iter()
                .map(|p| (p.id.as_str(), p.q_deg.as_slice(), "train")),
        )
    }
}

/// One extra pose: nominal joint targets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExtraPose {
    /// Id (`e01`...).
    pub id: String,
    /// Nominal joint targets (deg).
    pub q_deg: Vec<f64>,
}

/// A parameter the extra poses aim at.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExtraParam {
    /// Report name (`j3.d`).
    pub name: String,
    /// `mm` or `deg`.
    pub unit: String,
    /// Predicted 1-sigma from the recorded train poses alone (linear least
    /// squares at the nominal model); `None` when they do not determine
    /// it at all.
    pub sigma_recorded: Option<f64>,
    /// Predicted 1-sigma with the extra poses added; `None` when even
    /// they do not determine it.
    pub sigma_with_extra: Option<f64>,
    /// The manufacturing tolerance the 1-sigma is judged against: a
    /// parameter counts as determined at a third of it.
    pub tolerance: f64,
}

/// Which identifiable parameters the geometric fit freed, and why: every
/// one (the default, and always with enough poses), or a smaller nested
/// set that cross-validation on the train poses chose (see
/// `identify::freeset`), or the set the caller asked for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FreeSetChoice {
    /// The set freed: `all` (every identifiable parameter), `lengths`
    /// (the joint offsets, link lengths and link offsets: θ, d, a) or
    /// `offsets` (the joint offsets θ alone); the base pose, the tool point
    /// and the sensor parameters asked for are free in every set.
    pub chosen: String,
    /// How it was chosen: `cross_validation`, `requested`, or
    /// `not_tried` (enough poses for every parameter, the paper's method,
    /// or no smaller set to try).
    pub how: String,
    /// Why, in one sentence.
    pub reason: String,
    /// Folds of the cross-validation (0 when not tried).
    pub folds: usize,
    /// Each candidate set with its cross-validated RMS (empty when not
    /// tried).
    pub candidates: Vec<FreeSetScore>,
}

/// One candidate free set and how well it predicted the train poses left
/// out of each fold's fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FreeSetScore {
    /// `offsets`, `lengths` or `all` (see [`FreeSetChoice::chosen`]).
    pub name: String,
    /// Parameters it frees (base, tool and sensor parameters included).
    pub n_free: usize,
    /// RMS of the left-out train poses' residuals (string lengths or point
    /// coordinates, mm), each predicted by the fit without its fold; NaN
    /// when a fold had too few poses to fit the set.
    #[serde(deserialize_with = "nan_if_null")]
    pub cv_rms_mm: f64,
}

/// What the data can identify.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Identifiability {
    /// Parameters considered.
    pub n_candidates: usize,
    /// Parameters identified.
    pub n_identified: usize,
    /// Condition number of the column-scaled Jacobian of the identified set.
    #[serde(deserialize_with = "nan_if_null")]
    pub condition_number: f64,
    /// Fixed parameters and their aliases.
    pub fixed: Vec<FixedParam>,
}

/// An identified parameter's value and 1-sigma, in report units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamEstimate {
    /// Name (`j2.theta`, `base.x`...).
    pub name: String,
    /// Value (mm or deg).
    #[serde(deserialize_with = "nan_if_null")]
    pub value: f64,
    /// Deviation from the starting value (mm or deg).
    #[serde(deserialize_with = "nan_if_null")]
    pub deviation: f64,
    /// 1 sigma (mm or deg); `null` in JSON when the data leave it unknown
    /// (a singular covariance), read back as NaN.
    #[serde(deserialize_with = "nan_if_null")]
    pub sigma: f64,
    /// Unit.
    pub unit: String,
}

/// A pose flagged by the robust loss.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Outlier {
    /// Pose id.
    pub pose: String,
    /// Its residual RMS (mm) under the calibrated model.
    #[serde(deserialize_with = "nan_if_null")]
    pub residual_mm: f64,
    /// Residual in units of the robust scale.
    #[serde(deserialize_with = "nan_if_null")]
    pub score: f64,
}

/// Residual of one pose, for plots.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseResidual {
    /// Pose id.
    pub pose: String,
    /// `train` or `test`.
    pub split: crate::model::Split,
    /// A held-out pose whose residuals no decision of the physics analysis read (see
    /// `stats.confirmation`); written only when true.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub confirmation: bool,
    /// Error before calibration, base frame (mm).
    pub before_mm: [f64; 3],
    /// Error after calibration, base frame (mm).
    pub after_mm: [f64; 3],
    /// String residuals after calibration (mm), string data only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub strings_mm: Option<Vec<f64>>,
}

/// How the solver ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Convergence {
    /// Iterations used.
    pub iterations: usize,
    /// Why it stopped.
    pub termination: String,
    /// Final RMS of the residuals it minimised (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub residual_rms_mm: f64,
}

/// Distance between the paper's closed-form points and the least-squares
/// multilaterated points over the dataset.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClosedFormComparison {
    /// Poses compared.
    pub n: usize,
    /// RMS distance (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub rms_mm: f64,
    /// Max distance (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub max_mm: f64,
    /// Poses where the closed form gave the mirror image of the
    /// least-squares point across the plane of anchors A, C and D (it
    /// assumes the paper's side, z >= 0); they dominate the distances above.
    #[serde(default)]
    pub mirrored: usize,
}

impl ClosedFormComparison {
    /// The figures of per-pose distances (mm) between the closed form and
    /// least squares, `mirrored` of them mirror images; `None` without any.
    pub fn from_distances(d: &[f64], mirrored: usize) -> Option<Self> {
        (!d.is_empty()).then(|| ClosedFormComparison {
            n: d.len(),
            rms_mm: (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt(),
            max_mm: d.iter().cloned().fold(0.0, f64::max),
            mirrored,
        })
    }

    /// Why the two differ, for a summary: what the closed form is and
    /// where it does not hold.
    pub const WHY: &str = "the closed form is the paper's equations (26)-(38) on strings A, C and D alone, without least squares; it holds where the paper's geometry does (T above the plane of A, C and D, and not behind A along AC, where its tangents change sign), and a few poses outside it make most of the RMS (`drawcal locate` gives each pose's distance); identification uses the least-squares points";

    /// What a summary adds when the closed form gave mirror images (empty
    /// when it gave none).
    pub fn mirrored_note(&self) -> String {
        match self.mirrored {
            0 => String::new(),
            n => format!(
                " ({n} of them below the plane of anchors A, C and D, where the closed form, which assumes the paper's z >= 0, gives the mirror image)"
            ),
        }
    }
}

/// One physical effect found beyond the geometric model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Finding {
    /// Effect name from the catalogue (`joint_compliance`...), or
    /// `unexplained`.
    pub effect: String,
    /// Joint it applies to (1-based).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint: Option<usize>,
    /// Sensor it applies to (1-based).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<usize>,
    /// Fitted magnitude.
    #[serde(deserialize_with = "nan_if_null")]
    pub magnitude: f64,
    /// Its 1-sigma.
    #[serde(deserialize_with = "nan_if_null")]
    pub sigma: f64,
    /// Unit of magnitude and sigma.
    pub unit: String,
    /// The physics, in one sentence.
    pub explanation: String,
    /// What located it.
    pub evidence: String,
    /// Held-out RMS before the effect was modelled (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub test_rms_before_mm: f64,
    /// Held-out RMS after (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub test_rms_after_mm: f64,
    /// The effect's fitted model, for compensation and re-use; for
    /// `unexplained`, where the structure was located.
    #[serde(default)]
    pub parameters: Option<FindingModel>,
    /// The plot that is the finding's evidence: per pose, the residual the
    /// effect explains against what drives it, beside the fitted effect
    /// (for `unexplained`: the final model's residual along the ordering
    /// that located the structure, beside its running mean; see
    /// `physics::evidence::unexplained_plot`). `None` for reports written
    /// before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub evidence_plot: Option<EvidencePlot>,
}

impl Finding {
    /// The fitted effect of a named finding (none for `unexplained`).
    pub fn effect_model(&self) -> Option<&EffectModel> {
        match &self.parameters {
            Some(FindingModel::Effect(p)) => Some(&p.model),
            _ => None,
        }
    }

    /// The fitted effect with what was recorded beside it (none for
    /// `unexplained`).
    pub fn effect_parameters(&self) -> Option<&EffectParameters> {
        match &self.parameters {
            Some(FindingModel::Effect(p)) => Some(p),
            _ => None,
        }
    }

    /// Where an `unexplained` finding was located (none for named ones).
    pub fn unexplained(&self) -> Option<&UnexplainedLocation> {
        match &self.parameters {
            Some(FindingModel::Unexplained(u)) => Some(u),
            _ => None,
        }
    }
}

/// What a finding carries beyond its figures: the fitted model of a named
/// effect, or where an unexplained structure was located. In JSON, the
/// object's own fields tell which: an effect has `kind` (and `coef`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum FindingModel {
    /// A named effect of the catalogue.
    Effect(EffectParameters),
    /// Structure no effect of the catalogue explains.
    Unexplained(UnexplainedLocation),
}

impl<'de> Deserialize<'de> for FindingModel {
    /// By the `kind` field, so that a damaged effect model is refused with
    /// what is wrong in it (not "matches no variant").
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let v = serde_json::Value::deserialize(d)?;
        if v.get("kind").is_some() {
            serde_json::from_value(v).map(FindingModel::Effect)
        } else {
            serde_json::from_value(v).map(FindingModel::Unexplained)
        }
        .map_err(D::Error::custom)
    }
}

/// A named finding's model: the effect with its coefficients, and what
/// compensation needs beside them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EffectParameters {
    /// The effect and its coefficients (internal units, see `units`).
    #[serde(flatten)]
    pub model: EffectModel,
    /// The internal units of the coefficients, in words.
    #[serde(default)]
    pub units: String,
    /// A compliance: the payload (kg) it was fitted around, what
    /// compensation assumes the robot carries unless told.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_payload_kg: Option<f64>,
    /// A compliance: whether compensation takes a payload for it (what a
    /// client should send).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload_matters: Option<bool>,
    /// A thermal expansion: where its driver is zero, in words.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<String>,
    /// A temperature-driven thermal expansion: the temperature (°C) the
    /// calibrated lengths hold at, which compensation scales from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_temp_c: Option<f64>,
}

impl EffectParameters {
    /// The words of [`EffectParameters::units`].
    pub const UNITS: &str = "internal: angles rad, lengths mm; compliance rad/(N*m) with masses, rad/m per unit-mass regressor without; thermal per K, per hour (initial rate with tau_h) or per 1000 rows; joint scale rad per rad; string drift mm per hour or per 1000 rows";

    /// `model` with nothing recorded beside it yet.
    pub fn new(model: EffectModel) -> Self {
        EffectParameters {
            model,
            units: Self::UNITS.into(),
            reference_payload_kg: None,
            payload_matters: None,
            reference: None,
            reference_temp_c: None,
        }
    }

    /// The effect's kind.
    pub fn kind(&self) -> &Kind {
        &self.model.kind
    }
}

/// Where an `unexplained` finding's structure was located.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnexplainedLocation {
    /// The ordering of the poses along which the residual varies
    /// smoothly (`joint 2 angle`, `time`...).
    #[serde(default)]
    pub ordering: String,
    /// True when the ordering is a joint's angle and the residual was
    /// projected on that joint's motion (absent, false, in v1 reports
    /// written before it existed).
    #[serde(default)]
    pub along_joint_motion: bool,
    /// Significance (z) of the structure along `ordering`.
    #[serde(default = "nan", deserialize_with = "nan_if_null")]
    pub z: f64,
    /// A mismatch confined to a stretch of one joint's range: the joint
    /// (1-based).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confined_joint: Option<usize>,
    /// The stretch (deg).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confined_deg: Option<[f64; 2]>,
    /// The train poses far off the rest in it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confined_train_poses: Option<Vec<String>>,
    /// Its permutation p-value.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confined_p: Option<f64>,
    /// Robot-side residual variance over what the string noise explains
    /// (when that excess located it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot_side_variance_ratio: Option<f64>,
    /// The ratio's threshold.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variance_ratio_threshold: Option<f64>,
    /// Every place the structure was located, strongest first: each test
    /// that passed its threshold (empty in reports written before it
    /// existed).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub places: Vec<Place>,
    /// The catalogue effects the structure resembles and why they do not
    /// explain it, one sentence each.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub resembles: Vec<String>,
}

/// One place an `unexplained` structure was located: what it follows
/// (the driver), on which joint or string, on which side of the
/// measurement, how significant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Place {
    /// `joint` (a joint's angle), `time`, `temperature`, `configuration`
    /// (nearest poses in joint space), `workspace` (nearest poses by T's
    /// position), `motion` (the move that led to each pose), `string` (one
    /// string's reading), `robot` (a robot-side excess that follows no
    /// driver tested).
    pub driver: String,
    /// The joint (1-based) whose angle it follows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint: Option<usize>,
    /// The string (1-based) it lives in; with driver `workspace`, that
    /// string's own part by its direction from its anchor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<usize>,
    /// `robot` (T itself is off), `sensor` (one string reads wrong),
    /// `point` (tracker points: the two cannot be told apart), `strings`
    /// (string residuals taken whole).
    pub side: String,
    /// Significance: z of the neighbour test (or, for a confined stretch
    /// or a robot-side excess, the normal quantile of its p-value).
    #[serde(deserialize_with = "nan_if_null")]
    pub z: f64,
    /// The z it had to pass.
    #[serde(default = "nan", deserialize_with = "nan_if_null")]
    pub threshold: f64,
    /// A stretch of the driver, where the structure is confined to one
    /// (degrees for a joint).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<[f64; 2]>,
}

/// Evidence of one finding, computed by the engine
/// (`physics::evidence`): at every pose (or string reading), the residual
/// of the model with this effect left out, projected on the effect's own
/// signature, against the effect's driver, beside the fitted effect's
/// contribution along the same direction. Where the effect is real the
/// points follow the model.
///
/// Robot-side effects: `y` is the 3-D error (measured minus model, with
/// the geometry and the other effects as refitted with this one) along the
/// unit displacement this effect causes at the pose, `model` the effect's
/// displacement along it. Sensor-side effects: `y` is the string's reading
/// minus the model's reading without the effect, `model` the effect's
/// change of that reading (one point per string for cable sag).
///
/// Bounded: at most [`EvidencePlot::MAX_POINTS`] points, the poses
/// subsampled deterministically by a fixed stride in visiting order
/// (`stride` > 1 says so); `n_total` counts the points before.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvidencePlot {
    /// What `x` is (`gravity torque on joint 2`...).
    pub x_label: String,
    /// Unit of `x` (`N*m`, `deg`, `mm`, `s`, `h`, `K`, `m`, `±1; 0 unknown`).
    pub x_unit: String,
    /// What `y` and `model` are.
    pub y_label: String,
    /// Unit of `y` and `model` (mm).
    pub y_unit: String,
    /// Pearson correlation of `y` with `model` over the points (`None`
    /// where either does not vary).
    pub correlation: Option<f64>,
    /// Points before subsampling.
    pub n_total: usize,
    /// Every `stride`-th pose was kept (1: all).
    pub stride: usize,
    /// The points, in visiting order.
    pub points: Vec<EvidencePoint>,
}

impl EvidencePlot {
    /// Most points one plot holds (bounds the report's size).
    pub const MAX_POINTS: usize = 2000;
}

/// One point of an [`EvidencePlot`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvidencePoint {
    /// Pose id.
    pub pose: String,
    /// `train` or `test`.
    pub split: crate::model::Split,
    /// String (1-based) for effects plotted per string reading.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<usize>,
    /// The effect's driver at the pose.
    #[serde(deserialize_with = "nan_if_null")]
    pub x: f64,
    /// Residual with the effect left out, on its signature (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub y: f64,
    /// The fitted effect along the same direction (mm).
    #[serde(deserialize_with = "nan_if_null")]
    pub model: f64,
}

/// One anchor's correction, identified with the robot (`rig_anchors`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnchorCorrection {
    /// The anchor's name (rig.json's `anchor_names`, else `s1`, `s2`...).
    pub anchor: String,
    /// rig.json's coordinates (mm, rig frame).
    pub nominal_mm: [f64; 3],
    /// Identified coordinates (mm, rig frame).
    pub calibrated_mm: [f64; 3],
    /// `calibrated_mm - nominal_mm` (mm), in the gauge of [`RigAnchors::gauge`].
    pub correction_mm: [f64; 3],
    /// 1-sigma of each coordinate of the correction (mm), the robot's
    /// parameters' uncertainty included.
    pub correction_mm_sigma: [f64; 3],
    /// How well the data separate this anchor's moves from everything else
    /// fitted, as a sine (1: nothing else mimics them; under 0.001, the
    /// identifiability tolerance, not determined): the smallest over x, y,
    /// z (see `identify::rig::coordinate_sines`).
    #[serde(deserialize_with = "nan_if_null")]
    pub identifiability: f64,
    /// Whether the data determine the anchor (`identifiability` above the
    /// tolerance).
    pub identified: bool,
}

/// The rig's anchors identified with the robot (`--rig-anchors`, a job's
/// `rig_anchors`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RigAnchors {
    /// How the rigid motion no string length sees was removed.
    pub gauge: String,
    /// Shape modes of the anchor set (`3m - 6`) and how many the data
    /// determine (the others held at rig.json's, named in `held`).
    pub n_modes: usize,
    /// Shape modes identified.
    pub n_identified: usize,
    /// Shape modes held at rig.json's, with what they are aliased with.
    #[serde(default)]
    pub held: Vec<FixedParam>,
    /// Per anchor, in rig.json's order.
    pub anchors: Vec<AnchorCorrection>,
}

impl RigAnchors {
    /// The gauge, as the report states it.
    pub const GAUGE: &str = "corrections orthogonal to the six rigid motions of rig.json's \
        anchors (the corrections sum to zero, and so do their moments A x dA): the best rigid \
        fit of the calibrated anchors onto rig.json's is the identity, and the rigid part of \
        any anchor error is in base_in_rig";

    /// The largest correction of any anchor (mm) and that anchor.
    pub fn largest(&self) -> Option<(&AnchorCorrection, f64)> {
        self.anchors
            .iter()
            .map(|a| (a, Vector3::from(a.correction_mm).norm()))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }
}

/// Whether the physics analysis ran on a calibration, and if not, why.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PhysicsRun {
    /// It ran (its findings and notes are in the report).
    Ran,
    /// Turned off (`--no-physics`, a job's `"physics": false`).
    Off,
    /// The paper's one-step method was used; the analysis builds on the
    /// Levenberg-Marquardt fit.
    PaperMethod,
    /// The calibrated geometric model misses the train poses by more than
    /// physics can explain (wrong units, model or rig).
    GeometryMisses,
}

impl PhysicsRun {
    /// How a physics note that says the analysis did not run begins.
    pub const NOTE_PREFIX: &str = "not run";

    /// True when the analysis ran.
    pub fn ran(self) -> bool {
        self == PhysicsRun::Ran
    }

    /// What a report of format v1 (which had no such field) says in its
    /// notes.
    fn from_v1_notes(notes: &[String]) -> PhysicsRun {
        match notes.iter().find(|n| n.starts_with(Self::NOTE_PREFIX)) {
            None => PhysicsRun::Ran,
            Some(n) if n.contains("(physics off)") => PhysicsRun::Off,
            Some(n) if n.contains("(method paper") => PhysicsRun::PaperMethod,
            Some(_) => PhysicsRun::GeometryMisses,
        }
    }
}

/// The whole result of an identification.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Format tag, [`REPORT_FORMAT`].
    pub format: String,
    /// `lm` or `paper`.
    pub method: String,
    /// Whether the robust loss was used.
    pub robust: bool,
    /// The nominal model the calibration started from.
    pub nominal_robot: Robot,
    /// The identified model, in robot.json form.
    pub calibrated_robot: Robot,
    /// Identified pose of the robot base in the rig frame.
    pub base_in_rig: BasePose,
    /// Identified tool point in the flange frame (mm).
    pub tool_point_mm: [f64; 3],
    /// Deviations from nominal, one per joint.
    pub deviations: Vec<JointDeviation>,
    /// Every identified parameter with its 1-sigma (joints, base, tool,
    /// sensors).
    pub parameters: Vec<ParamEstimate>,
    /// Names of the parameters held at nominal.
    pub fixed: Vec<String>,
    /// Rank analysis behind `fixed`.
    pub identifiability: Identifiability,
    /// Which identifiable parameters were freed and why (absent in
    /// reports written before the choice existed, which freed all).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub free_set: Option<FreeSetChoice>,
    /// Before/after figures, train and test.
    pub stats: Stats,
    /// The paper's one-step method on the same split, for comparison
    /// (present when `method` is `lm` and the paper method could run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub paper_stats: Option<Stats>,
    /// Expected held-out 3-D RMS of a perfect model: the point noise implied
    /// by the string noise and the rig geometry (mm). `None` for point data.
    pub noise_floor_mm: Option<f64>,
    /// Expected held-out 3-D RMS of an exact model identified from these
    /// train poses (mm): the noise floor plus the identified parameters'
    /// spread carried to the test poses. `stats.test.after` well above it
    /// means the model misses something; near it, that only more train
    /// poses would help. `None` for point data (and in reports written
    /// before it existed).
    #[serde(default)]
    pub expected_test_rms_mm: Option<f64>,
    /// How well these data determine the flange orientation in the robot
    /// base frame (deg: 1-sigma RMS rotation angle, RMS over the poses):
    /// the geometric fit's covariance, before the undetermined parameters
    /// are held (holding them at nominal assumes, it does not measure), and
    /// before any physics refit. What holding the flange orientation
    /// (`compensate --orientation`) can rest on, beyond what position data
    /// never see: every parameter held at nominal (the last joint's θ, in
    /// DH also its α and β, aliased with the tool point) counts as exact.
    /// `None` with the paper's method (and in reports written before it
    /// existed).
    #[serde(default)]
    pub flange_orientation_sigma_deg: Option<f64>,
    /// String noise (1 sigma, mm) estimated from the strings' redundancy.
    pub string_sigma_mm: Option<f64>,
    /// Held-out pose ids.
    pub held_out: Vec<String>,
    /// `file` when the split came from the `split` column, else how it was
    /// chosen.
    pub split_source: String,
    /// Poses flagged as outliers by the robust loss.
    pub outliers: Vec<Outlier>,
    /// Solver summary.
    pub convergence: Convergence,
    /// Paper closed form versus least squares, four-anchor rigs only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub closed_form_vs_lsq: Option<ClosedFormComparison>,
    /// Per-pose errors before and after.
    pub per_pose: Vec<PoseResidual>,
    /// Physics found beyond geometry (see the physics analysis).
    pub findings: Vec<Finding>,
    /// Whether the physics analysis ran, and if not, why.
    pub physics: PhysicsRun,
    /// What the physics analysis saw: where the residual lives (robot or
    /// sensor side, joints, time) and the candidates it tried and rejected;
    /// when it did not run, why (beginning with
    /// [`PhysicsRun::NOTE_PREFIX`]).
    #[serde(default)]
    pub physics_notes: Vec<String>,
    /// Warnings about the input, one sentence each: what did not stop the
    /// identification but makes its result suspect, e.g. joint angles
    /// that look like radians in the `q*_deg` columns (the whole file, or
    /// single poses; see [`crate::identify::warnings`]). Empty when nothing is
    /// suspect; reports written before it existed read as empty.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// The rig's anchors, when identified with the robot (`--rig-anchors`):
    /// each anchor's correction with its 1-sigma and identifiability.
    /// Absent otherwise (and in reports written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rig_anchors: Option<RigAnchors>,
    /// The rig with the identified anchors and base pose, in rig.json form:
    /// the rig.json of the next session. Present with `rig_anchors`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibrated_rig: Option<Rig>,
    /// Poses that would determine the parameters these poses left
    /// undetermined (held at nominal, not structurally aliased), when there
    /// are such parameters.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra_poses: Option<ExtraPoses>,
    /// "Is my result good?": green, amber or red and why (absent in reports
    /// written before it existed: [`verdict::Verdict::read`] computes it then).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<verdict::Verdict>,
}

impl Report {
    /// Read a report: `drawcal identify`'s JSON, or the service's
    /// calibration answer wrapping it under `report`. Reports of the
    /// previous format ([`REPORT_FORMAT_V1`]) are read and brought to the
    /// current one (see [`REPORT_FORMAT`] for what changed); any other
    /// format version is refused by name rather than half read.
    pub fn from_json(text: &str) -> crate::Result<Report> {
        let field = |m: String| crate::Error::field("report", m);
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| field(e.to_string()))?;
        let mut inner = match v.get("report") {
            Some(r) if r.is_object() => r.clone(),
            _ => v,
        };
        match inner.get("format").and_then(|f| f.as_str()) {
            Some(REPORT_FORMAT) | None => {}
            Some(REPORT_FORMAT_V1) => upgrade_v1(&mut inner),
            Some(f) => {
                return Err(crate::Error::field(
                    "format",
                    format!(
                        "'{f}': this drawcal reads '{REPORT_FORMAT}' and '{REPORT_FORMAT_V1}' reports"
                    ),
                ));
            }
        }
        // The path of what does not parse, so that a damaged report names
        // the field (`findings[0].parameters`).
        serde_path_to_error::deserialize(inner).map_err(|e| {
            let path = e.path().to_string();
            let inner = e.into_inner();
            match path.as_str() {
                "." | "" => field(format!("not a drawcal report: {inner}")),
                _ => crate::Error::field(path, format!("not a drawcal report: {inner}")),
            }
        })
    }
}

/// A v1 report as v2: the `physics` field from what its notes say.
fn upgrade_v1(report: &mut serde_json::Value) {
    let notes: Vec<String> = report
        .get("physics_notes")
        .and_then(|n| serde_json::from_value(n.clone()).ok())
        .unwrap_or_default();
    if let Some(o) = report.as_object_mut() {
        o.insert("format".into(), REPORT_FORMAT.into());
        o.entry("physics").or_insert_with(|| {
            serde_json::to_value(PhysicsRun::from_v1_notes(&notes)).unwrap_or_default()
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_of_known_errors() {
        let e = [Vector3::new(3.0, 4.0, 0.0), Vector3::new(0.0, 0.0, -1.0)];
        let s = ErrorStats::of(&e);
        assert_eq!(s.max_mm, 5.0);
        assert_eq!(s.mean_mm, 3.0);
        assert!((s.rms_mm - 13.0f64.sqrt()).abs() < 1e-12);
        assert_eq!(s.z.max_abs_mm, 1.0);
        assert_eq!(s.x.mean_abs_mm, 1.5);
        assert!(ErrorStats::of(&[]).rms_mm.is_nan());
    }

    #[test]
    fn an_unexplained_finding_of_an_early_v1_report_reads_typed() {
        // Before `along_joint_motion` (and older still, before `z`).
        for v in [
            serde_json::json!({"ordering": "time", "z": 4.2}),
            serde_json::json!({"ordering": "joint 2 angle"}),
        ] {
            let m: FindingModel = serde_json::from_value(v).unwrap();
            let FindingModel::Unexplained(u) = m else {
                panic!("read as an effect")
            };
            assert!(!u.along_joint_motion);
        }
    }

    #[test]
    fn a_v1_report_says_whether_the_physics_ran_by_its_notes() {
        let notes = |n: &[&str]| n.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let of = |n: &[&str]| PhysicsRun::from_v1_notes(&notes(n));
        assert_eq!(of(&["robot side: 12 %"]), PhysicsRun::Ran);
        assert_eq!(of(&[]), PhysicsRun::Ran);
        assert_eq!(of(&["not run (physics off)"]), PhysicsRun::Off);
        assert_eq!(
            of(&["not run (method paper: the analysis builds on ...)"]),
            PhysicsRun::PaperMethod
        );
        assert_eq!(
            of(&["not run: the calibrated geometric model still misses ..."]),
            PhysicsRun::GeometryMisses
        );
    }
}
