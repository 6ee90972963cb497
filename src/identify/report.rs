//! The calibration report: what `drawcal identify` writes and the service
//! stores. Documented field by field in the README.

use serde::{Deserialize, Serialize};

use crate::model::{BasePose, Robot};

/// A number this crate wrote: JSON has no NaN or infinity, so serde_json
/// writes them as `null`; read that back as NaN (an unknown, not a
/// malformed report). Every plain number of the report reads this way.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Current report format tag.
pub const REPORT_FORMAT: &str = "drawcal report v1";

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
        }
    }
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
    /// The effect's fitted parameters, for compensation and re-use.
    #[serde(default)]
    pub parameters: serde_json::Value,
    /// The plot that is the finding's evidence: per pose, the residual the
    /// effect explains against what drives it, beside the fitted effect
    /// (for `unexplained`: the final model's residual along the ordering
    /// that located the structure, beside its running mean; see
    /// `physics::evidence::unexplained_plot`). `None` for reports written
    /// before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub evidence_plot: Option<EvidencePlot>,
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
    /// What the physics analysis saw: where the residual lives (robot or
    /// sensor side, joints, time) and the candidates it tried and rejected.
    #[serde(default)]
    pub physics_notes: Vec<String>,
    /// Warnings about the input, one sentence each: what did not stop the
    /// identification but makes its result suspect, e.g. joint angles
    /// that look like radians in the `q*_deg` columns (the whole file, or
    /// single poses; see [`super::warnings`]). Empty when nothing is
    /// suspect; reports written before it existed read as empty.
    #[serde(default)]
    pub warnings: Vec<String>,
}

impl Report {
    /// Read a report: `drawcal identify`'s JSON, or the service's
    /// calibration answer wrapping it under `report`. A report of another
    /// format version is refused by name rather than half read.
    pub fn from_json(text: &str) -> crate::Result<Report> {
        let field = |m: String| crate::Error::field("report", m);
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| field(e.to_string()))?;
        let inner = match v.get("report") {
            Some(r) if r.is_object() => r.clone(),
            _ => v,
        };
        if let Some(f) = inner.get("format").and_then(|f| f.as_str()) {
            if f != REPORT_FORMAT {
                return Err(crate::Error::field(
                    "format",
                    format!("'{f}': this drawcal reads '{REPORT_FORMAT}' reports"),
                ));
            }
        }
        serde_json::from_value(inner).map_err(|e| field(format!("not a drawcal report: {e}")))
    }
}
