//! The simulator behind `drawcal simulate`: recordings in the DATA_FORMAT
//! files from a robot, a rig, parameter deviations, a base pose, noise and
//! any set of physical effects (the same
//! [`Context::basis`](super::effects::Context::basis) the analysis fits).
//! The spec is documented in docs/PHYSICS.md.
//!
//! This file holds the public API and the spec types; the steps of
//! [`generate_with`] live by concept: `presets` (built-in robots, what a
//! spec names), `truth` (the true geometry and truth.json), `tour` (the
//! poses, their order, time and temperature), `record` (the true T, the
//! effects and the noisy readings, poses.csv) and `effect_spec` (an effect
//! entry as an effect model, and its size).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::effects::EffectModel;
use crate::error::{Error, Result};
use crate::kinematics::chain::Chain;
use crate::model::{BasePose, Dataset, Rig, Robot};
use crate::rng::Rng;

mod effect_spec;
mod presets;
mod record;
mod tour;
mod truth;

pub use effect_spec::{effect_rms, report_magnitude};
pub use presets::preset;

/// A simulation spec (JSON).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spec {
    /// Preset name (`er3a`, `ur5`, `arm4_mdh`) or a robot.json path.
    pub robot: String,
    /// rig.json path; default: the preset's rig.
    #[serde(default)]
    pub rig: Option<String>,
    /// Number of poses.
    #[serde(default = "default_poses")]
    pub n_poses: usize,
    /// Fraction marked `test` in the split column.
    #[serde(default = "default_test")]
    pub test_fraction: f64,
    /// Seed of everything random.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Geometric deviations: random (1-sigma sizes) unless `explicit` given.
    #[serde(default)]
    pub deviations: DeviationSpec,
    /// True base pose; default the rig's guess plus a random error.
    #[serde(default)]
    pub base_in_rig: Option<BasePose>,
    /// String noise.
    #[serde(default)]
    pub noise: NoiseSpec,
    /// Session timing and temperature.
    #[serde(default)]
    pub session: SessionSpec,
    /// Physical effects.
    #[serde(default)]
    pub effects: Vec<EffectSpec>,
}

fn default_poses() -> usize {
    80
}
fn default_test() -> f64 {
    0.3
}
fn default_seed() -> u64 {
    1
}

/// Geometric deviations from nominal.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DeviationSpec {
    /// 1-sigma of a and d (mm).
    #[serde(default = "dev_len")]
    pub length_mm: f64,
    /// 1-sigma of alpha and theta (deg); beta only between parallel axes.
    #[serde(default = "dev_ang")]
    pub angle_deg: f64,
    /// 1-sigma of each tool point coordinate (mm).
    #[serde(default = "dev_len")]
    pub tool_mm: f64,
    /// 1-sigma of the base position (mm) and orientation (deg) error
    /// relative to the rig's `base_in_rig` guess.
    #[serde(default = "dev_base")]
    pub base_mm: f64,
    /// Base orientation error (deg).
    #[serde(default = "dev_base_deg")]
    pub base_deg: f64,
}

fn dev_len() -> f64 {
    0.5
}
fn dev_ang() -> f64 {
    0.1
}
fn dev_base() -> f64 {
    2.0
}
fn dev_base_deg() -> f64 {
    0.5
}

impl Default for DeviationSpec {
    fn default() -> Self {
        DeviationSpec {
            length_mm: dev_len(),
            angle_deg: dev_ang(),
            tool_mm: dev_len(),
            base_mm: dev_base(),
            base_deg: dev_base_deg(),
        }
    }
}

/// `reading = round((l_true + N(0, sigma)) / resolution) * resolution`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NoiseSpec {
    /// Gaussian noise per reading (mm).
    #[serde(default = "noise_sigma")]
    pub sigma_mm: f64,
    /// Quantisation step (mm); 0 for none.
    #[serde(default = "noise_res")]
    pub resolution_mm: f64,
}

fn noise_sigma() -> f64 {
    0.02
}
fn noise_res() -> f64 {
    0.024
}

impl Default for NoiseSpec {
    fn default() -> Self {
        NoiseSpec {
            sigma_mm: noise_sigma(),
            resolution_mm: noise_res(),
        }
    }
}

/// Session timing and ambient temperature.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SessionSpec {
    /// Slowest joint's speed between poses (deg/s).
    #[serde(default = "speed")]
    pub speed_deg_s: f64,
    /// Settling and measuring time per pose (s).
    #[serde(default = "dwell")]
    pub dwell_s: f64,
    /// Temperature at the start (°C).
    #[serde(default = "temp0")]
    pub temp_start_c: f64,
    /// Rise towards which the temperature settles (K).
    #[serde(default = "rise")]
    pub temp_rise_c: f64,
    /// Time constant of the rise (s).
    #[serde(default = "tau")]
    pub temp_tau_s: f64,
    /// Payloads (kg) carried at the tool point, in turn, in equal blocks of
    /// the session (test weights swapped part-way); empty: no payload and
    /// no `payload_kg` column.
    #[serde(default)]
    pub payload_kg: Vec<f64>,
}

fn speed() -> f64 {
    30.0
}
fn dwell() -> f64 {
    20.0
}
fn temp0() -> f64 {
    20.0
}
fn rise() -> f64 {
    6.0
}
fn tau() -> f64 {
    1800.0
}

impl Default for SessionSpec {
    fn default() -> Self {
        SessionSpec {
            speed_deg_s: speed(),
            dwell_s: dwell(),
            temp_start_c: temp0(),
            temp_rise_c: rise(),
            temp_tau_s: tau(),
            payload_kg: Vec::new(),
        }
    }
}

/// One effect to put into the recordings. Give either `magnitude` (in the
/// unit the analysis reports) or `size_x_noise` (the effect's RMS
/// displacement of T, or of the located point for sensor effects, in
/// multiples of the point noise).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectSpec {
    /// Catalogue name.
    pub effect: String,
    /// Joint (1-based) for joint effects.
    #[serde(default)]
    pub joint: Option<usize>,
    /// Sensor (1-based) for sensor effects.
    #[serde(default)]
    pub sensor: Option<usize>,
    /// Harmonic of `joint_periodic` (default 1).
    #[serde(default)]
    pub harmonic: Option<u32>,
    /// Phase of `joint_periodic` (deg): `A sin(h q + phase)`.
    #[serde(default)]
    pub phase_deg: Option<f64>,
    /// Direction of an `anchor_step`, `rig_step` or `rig_drift` translation
    /// (rig frame, normalised; default random).
    #[serde(default)]
    pub direction: Option<[f64; 3]>,
    /// When an `anchor_step` or `rig_step` happens, as a fraction of the
    /// session (default random in 0.2-0.8); other effects ignore it.
    #[serde(default)]
    pub at_fraction: Option<f64>,
    /// Magnitude in report units: compliance deg/(N*m), backlash deg (half
    /// dead band), periodic deg (amplitude), joint_scale ppm, thermal ppm/K, sensor_scale
    /// ppm, sensor_offset mm, sensor_drift mm/h, cable_sag mm/m^3, anchor_step mm, rig_step mm
    /// (translation; plus as many mrad of rotation about a random axis),
    /// rig_drift mm/h (likewise mrad/h).
    #[serde(default)]
    pub magnitude: Option<f64>,
    /// Size as a multiple of the point noise (overrides `magnitude`).
    #[serde(default)]
    pub size_x_noise: Option<f64>,
}

/// A generated dataset, in memory.
pub struct Simulated {
    /// Nominal robot (robot.json).
    pub robot: Robot,
    /// Rig (rig.json).
    pub rig: Rig,
    /// poses.csv text.
    pub poses_csv: String,
    /// Parsed poses.
    pub dataset: Dataset,
    /// truth.json.
    pub truth: serde_json::Value,
    /// The effects as put in (internal units).
    pub effects: Vec<EffectModel>,
    /// RMS 3-D error of a point multilaterated from the noisy strings (mm).
    pub point_noise_mm: f64,
    /// Per pose: point located from the noisy readings minus the point
    /// located from the exact ones (rig frame, mm).
    pub point_noise: Vec<Vector3<f64>>,
    /// Per pose: the true T with the robot-side effects (rig frame, mm),
    /// to judge a calibrated model against.
    pub true_point: Vec<Vector3<f64>>,
}

/// The files a [`Spec`] names, read by the caller: the robot.json of a
/// `robot` that is not a preset, the rig.json of `rig` (a rig given here
/// replaces a preset's even when the spec names none).
#[derive(Debug, Clone, Default)]
pub struct SpecFiles {
    /// The robot `spec.robot` names (none for a preset).
    pub robot: Option<Robot>,
    /// The rig `spec.rig` names.
    pub rig: Option<Rig>,
    /// Poses to record, in this order, instead of drawing `spec.n_poses`
    /// and touring them (a plan's targets.csv).
    pub poses: Option<Vec<GivenPose>>,
}

/// A pose the recording visits, as a plan gives it.
#[derive(Debug, Clone, PartialEq)]
pub struct GivenPose {
    /// Id (poses.csv's `pose`).
    pub id: String,
    /// Joint angles (deg).
    pub q_deg: Vec<f64>,
    /// `Some(true)` for a `test` pose; `None` lets `spec.test_fraction`
    /// choose (for every pose, unless all have a split).
    pub test: Option<bool>,
    /// Payload at T (kg) the pose carries, as a plan's targets.csv gives
    /// it; `None` for none (0 kg). When any pose gives one, the spec's
    /// `session.payload_kg` must be empty.
    pub payload_kg: Option<f64>,
}

/// Generate a dataset from a spec whose robot is a preset (and whose rig is
/// the preset's).
pub fn generate(spec: &Spec) -> Result<Simulated> {
    generate_with(spec, SpecFiles::default())
}

/// Generate a dataset from a spec and the files it names.
pub fn generate_with(spec: &Spec, mut files: SpecFiles) -> Result<Simulated> {
    let given = files.poses.take();
    let (robot, rig, home_deg, preset_name) = presets::load(spec, files)?;
    let m = rig.n_strings();
    if m < 3 {
        return Err(Error::field(
            "spec.rig",
            "the simulator makes string recordings: at least 3 anchors",
        ));
    }
    // One generator for everything random, drawn from in this order (the
    // order is part of what a seed reproduces).
    let mut rng = Rng::new(spec.seed);
    let geometry = truth::true_geometry(spec, &robot, &rig, &mut rng);
    let chain = Chain::new(robot.convention, robot.dof(), m);
    let anchors: Vec<Vector3<f64>> = (0..m).map(|k| rig.anchor(k)).collect();
    let visits = match &given {
        Some(given) => {
            let qs = tour::given_poses(&robot, given)?;
            let ids = given.iter().map(|p| p.id.clone()).collect();
            let mut visits = tour::Tour::in_order(&spec.session, &home_deg, qs, ids, &mut rng);
            tour::given_payloads(&spec.session, given, &mut visits)?;
            visits
        }
        None => {
            let qs = tour::sample_poses(spec, &robot, &rig, &chain, &anchors, &geometry, &mut rng)?;
            tour::Tour::new(&spec.session, &home_deg, qs, &mut rng)
        }
    };
    let scene = record::Scene::new(&robot, &rig, chain, anchors, &geometry, &visits);
    let effects = record::effects(spec, &scene, &home_deg, &mut rng)?;
    let mut recording = record::Recording::new(spec, &scene, &effects, &mut rng);
    if let Some(split) = given
        .as_ref()
        .and_then(|g| g.iter().map(|p| p.test).collect::<Option<Vec<bool>>>())
    {
        recording.is_test = split;
    }
    let poses_csv = record::poses_csv(&scene, &recording);
    let dataset = Dataset::from_csv(poses_csv.as_bytes(), &robot, &rig)?;
    let point_noise_mm = (recording.noise_sq / visits.qs.len() as f64).sqrt();
    let truth = truth::truth_json(&truth::TruthInputs {
        spec,
        preset_name: &preset_name,
        home_deg: &home_deg,
        scene: &scene,
        effects: &effects,
        recording: &recording,
        point_noise_mm,
    });
    let record::Recording {
        point_noise,
        true_t: true_point,
        ..
    } = recording;
    Ok(Simulated {
        robot,
        rig,
        poses_csv,
        dataset,
        truth,
        effects,
        point_noise_mm,
        point_noise,
        true_point,
    })
}
