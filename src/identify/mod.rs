//! Geometric identification: from recorded poses to the kinematic
//! parameters of a calibrated model.
//!
//! - [`observations`]: the recordings prepared for fitting ([`Observations`]:
//!   the train/test split, T located at every pose);
//! - [`geometric()`]: base and tool first, then every identifiable parameter
//!   by Levenberg-Marquardt ([`lm`]) on the raw readings
//!   ([`problem`]), the parameters the data cannot separate held at nominal
//!   ([`identifiability`]); with few train poses, a smaller nested set of
//!   joint parameters when cross-validation says it predicts better
//!   ([`freeset`]);
//! - [`rig`]: the rig's anchors identified with the robot (`rig_anchors`),
//!   less the rigid motion the base pose takes;
//! - [`paper`]: the paper's one-step method beside it; [`warnings`]: input
//!   that parses but looks wrong.
//!
//! The whole calibration (this, then the physics analysis, then the report)
//! is [`crate::pipeline`]; this module knows nothing of the steps after it.

pub mod freeset;
pub mod geometric;
pub mod identifiability;
pub mod lm;
pub mod observations;
pub mod paper;
pub mod problem;
pub mod rig;
pub mod warnings;

pub use geometric::{
    Geometric, candidates, few_poses_warning, geometric, held, pose_rms, rigid_fit, sigmas,
    unit_covariance,
};
pub use observations::{ORIENTATION_POSES, Observations, closed_form_comparison, nominal_points};

/// Which identification method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Levenberg-Marquardt to convergence on the raw measurements.
    #[default]
    Lm,
    /// The paper: linearised error model, one pseudo-inverse step on located
    /// points.
    Paper,
}

/// Identification options.
#[derive(Debug, Clone)]
pub struct IdentifyOptions {
    /// Method.
    pub method: Method,
    /// Robust (Huber) loss at the pose level, with outlier poses flagged.
    pub robust: bool,
    /// Fraction held out when the file has no split.
    pub holdout_fraction: f64,
    /// Seed of the hold-out choice.
    pub seed: u64,
    /// Also identify each string's zero offset.
    pub identify_string_offsets: bool,
    /// Identifiability tolerance (sine of the angle to the kept columns).
    pub identifiability_tolerance: f64,
    /// Deviation (in sigmas) under which a nearly aliased joint parameter
    /// counts as undetermined and is held at nominal (see
    /// [`identifiability::undetermined`]); 0 keeps every parameter the
    /// structural test keeps.
    pub undetermined_z: f64,
    /// Parameters held at nominal whatever the data say (report names of
    /// joint parameters, `j5.a`, `j2.theta`..., or string offsets,
    /// `s1.offset`), e.g. to compare with a calibration in the same
    /// parametrisation.
    pub hold: Vec<String>,
    /// Also identify the rig's anchor coordinates (four strings or more,
    /// not with measured points nor the paper's method), less the rigid
    /// motion the base pose takes: see [`rig`].
    pub rig_anchors: bool,
    /// Which identifiable parameters to free: chosen by cross-validation
    /// on the train poses when they are few (the default), or a set asked
    /// for; see [`freeset`].
    pub free_set: freeset::FreeSet,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        IdentifyOptions {
            method: Method::Lm,
            robust: false,
            holdout_fraction: 0.3,
            seed: 1,
            identify_string_offsets: false,
            identifiability_tolerance: identifiability::DEFAULT_TOLERANCE,
            undetermined_z: identifiability::UNDETERMINED_Z,
            hold: vec![],
            rig_anchors: false,
            free_set: freeset::FreeSet::Auto,
        }
    }
}

/// Progress reporting and cancellation for long identifications.
pub trait Progress: Sync {
    /// Called as work advances; `fraction` in [0, 1].
    fn update(&self, stage: &str, fraction: f64);
    /// Polled between solver iterations; `true` stops the work with
    /// [`Error::Cancelled`](crate::Error::Cancelled).
    fn cancelled(&self) -> bool {
        false
    }
}

/// A [`Progress`] that ignores everything.
pub struct NoProgress;

impl Progress for NoProgress {
    fn update(&self, _: &str, _: f64) {}
}
