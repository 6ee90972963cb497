//! drawcal: kinematic calibration of serial robots from drawstring sensors
//! (or laser trackers, CMMs, cameras).
//!
//! The crate is layered. The numerical core is plain synchronous Rust with no
//! I/O beyond parsing the data files it is handed:
//!
//! - [`model`]: the inputs (robot.json, rig.json, poses.csv, targets.csv) as
//!   typed, validated values;
//! - [`kinematics`]: the parameter vector, forward kinematics of the measured
//!   point with its analytic Jacobian, and the paper's error model;
//! - [`measure`]: locating the tool point from string lengths (the paper's
//!   closed form and least-squares multilateration), string noise;
//! - [`identify`]: the Levenberg-Marquardt solver, identifiability analysis,
//!   the paper's one-step method, statistics and the JSON report;
//! - [`compensate`]: corrected joint targets from a calibration;
//! - [`physics`]: effects beyond the geometric model (compliance, thermal
//!   growth, backlash, ...), their blind detection and the simulator.
//!
//! Thin layers around it: the CLI ([`cli`]) and the service: [`store`] (the
//! only SQL), [`jobs`] (background identification) and [`http`].

pub mod cli;
pub mod compensate;
pub mod error;
pub mod export;
pub mod http;
pub mod identify;
pub mod jobs;
pub mod kinematics;
pub mod measure;
pub mod model;
pub mod physics;
pub mod pipeline;
pub mod plan;
pub mod report;
pub mod report_html;
pub mod rng;
pub mod stats;
pub mod store;

pub use error::{Error, Result};
