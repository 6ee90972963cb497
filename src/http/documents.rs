//! The OpenAPI schemas of robot.json and rig.json (DATA_FORMAT.md), the
//! bodies of `POST /models` and `POST /rigs`.
//!
//! Schema only: the bodies are read by the engine's own [`crate::model::Robot`]
//! and [`crate::model::Rig`], which carry no API text; these types mirror
//! their keys, with the bounds `validate` applies, and a test
//! (`tests/api/openapi.rs`) checks that the engine takes what they describe.
//! What JSON Schema cannot say stays with the engine: a joint's `q_min_deg`
//! below its `q_max_deg`, one link per joint; three anchors or more, apart
//! and not on one line, one name per anchor, `r_mm` given with anchors.
// Never built, only described: the fields are read by utoipa's derive.
#![allow(dead_code)]

use serde::Deserialize;
use utoipa::ToSchema;

use crate::model::MAX_LENGTH_MM;

/// A length (mm) of a robot or a rig: at most 100 m either way.
#[derive(Deserialize)]
pub struct LengthMm(f64);

impl utoipa::PartialSchema for LengthMm {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        utoipa::openapi::ObjectBuilder::new()
            .schema_type(utoipa::openapi::schema::Type::Number)
            .description(Some("A length (mm), at most 100 m either way."))
            .minimum(Some(-MAX_LENGTH_MM))
            .maximum(Some(MAX_LENGTH_MM))
            .into()
    }
}

impl ToSchema for LengthMm {}

/// The link-transform convention of the joint table.
#[derive(Deserialize, ToSchema, Default)]
#[serde(rename_all = "lowercase")]
pub enum ConventionJson {
    /// `T_i = Rz(q+θ) Tz(d) Tx(a) Rx(α) Ry(β)`: DH with Hayati's β.
    #[default]
    Dh,
    /// Craig's modified DH: `T_i = Rx(α) Ry(β) Tx(a) Rz(q+θ) Tz(d)`.
    Mdh,
}

/// One joint of robot.json.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JointJson {
    /// Link length a (mm).
    pub a_mm: LengthMm,
    /// Link twist α (deg).
    pub alpha_deg: f64,
    /// Link offset d (mm).
    pub d_mm: LengthMm,
    /// Joint angle offset θ (deg; default 0).
    #[serde(default)]
    pub theta_offset_deg: f64,
    /// Hayati's β (deg; default 0).
    #[serde(default)]
    pub beta_deg: f64,
    /// Lower joint limit (deg; default -360), below `q_max_deg`.
    #[serde(default)]
    pub q_min_deg: f64,
    /// Upper joint limit (deg; default 360), above `q_min_deg`.
    #[serde(default)]
    pub q_max_deg: f64,
}

/// Mass and centre of mass of a link in its own frame.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LinkJson {
    /// Mass (kg, 0 or more).
    #[schema(minimum = 0.0)]
    pub mass_kg: f64,
    /// Centre of mass (mm).
    #[schema(min_items = 3, max_items = 3)]
    pub com_mm: [LengthMm; 3],
}

/// robot.json: the nominal kinematic model (DATA_FORMAT.md).
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"name": "EFORT ER3A (nominal)", "joints": [{"a_mm": 0, "alpha_deg": -90, "d_mm": 300}, {"a_mm": 260, "alpha_deg": 0, "d_mm": 0}], "tool_point_mm": [0, 0, 100]}))]
pub struct RobotJson {
    /// Human-readable name (the model's name unless `?name=` gives one).
    #[serde(default)]
    pub name: String,
    /// `dh` (default) or `mdh`.
    #[serde(default)]
    pub convention: ConventionJson,
    /// Joints, base to flange: 1 to 12.
    #[schema(min_items = 1, max_items = 12)]
    pub joints: Vec<JointJson>,
    /// The measured point T in the flange frame (mm).
    #[schema(min_items = 3, max_items = 3)]
    pub tool_point_mm: [LengthMm; 3],
    /// Link masses, one per joint.
    #[serde(default)]
    pub links: Option<Vec<LinkJson>>,
    /// Gravity in the robot base frame (m/s²).
    #[serde(default)]
    #[schema(min_items = 3, max_items = 3)]
    pub gravity_in_base: Option<[f64; 3]>,
}

/// A pose: translation, then roll, pitch, yaw (`Rz(yaw) Ry(pitch) Rx(roll)`).
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BasePoseJson {
    /// Translation (mm).
    #[schema(min_items = 3, max_items = 3)]
    pub xyz_mm: [f64; 3],
    /// Roll, pitch, yaw (deg).
    #[schema(min_items = 3, max_items = 3)]
    pub rpy_deg: [f64; 3],
}

/// The sensor's data sheet.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SensorJson {
    /// Measuring range (mm, more than 0).
    #[serde(default)]
    #[schema(exclusive_minimum = 0.0)]
    pub range_mm: Option<f64>,
    /// Resolution (mm, 0 or more).
    #[serde(default)]
    #[schema(minimum = 0.0)]
    pub resolution_mm: Option<f64>,
    /// Linearity (percent of full scale, 0 or more).
    #[serde(default)]
    #[schema(minimum = 0.0)]
    pub linearity_pct_fs: Option<f64>,
}

/// rig.json: the measuring rig (DATA_FORMAT.md). No anchors: a point
/// instrument (tracker, camera).
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"anchors_mm": [[0, 0, 0], [1500, 0, 0], [0, 1500, 0], [0, 0, 1500]], "r_mm": 35}))]
pub struct RigJson {
    /// String exit points in the rig frame (mm): none, or 3 or more.
    #[serde(default)]
    pub anchors_mm: Vec<[LengthMm; 3]>,
    /// Names, in anchor order (one per anchor, or none).
    #[serde(default)]
    pub anchor_names: Option<Vec<String>>,
    /// Reading plus `r_mm` is the anchor-to-T distance (mm, 0 or more);
    /// required with anchors.
    #[serde(default)]
    #[schema(minimum = 0.0, maximum = 100000.0)] // MAX_LENGTH_MM
    pub r_mm: Option<f64>,
    /// Starting guess of the robot base pose in the rig frame.
    #[serde(default)]
    pub base_in_rig: Option<BasePoseJson>,
    /// Sensor data sheet.
    #[serde(default)]
    pub sensor: Option<SensorJson>,
    /// Free text naming another instrument.
    #[serde(default)]
    pub instrument: Option<String>,
}
