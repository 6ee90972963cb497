//! Physics beyond the geometric model: a catalogue of effects
//! ([`effects`]), the calibration problem augmented with them
//! ([`problem`]), the analysis that finds, names, models and proves them
//! ([`analyse`]), and the simulator that puts them into recordings
//! ([`simulate`]). One implementation of each effect serves both.
//!
//! Hooks for the engine: [`analyse()`] after `identify::geometric()`,
//! [`errors_with_effects`] for `stats.test.after`, and
//! [`joint_offsets_rad`] for compensation.

pub mod analyse;
pub mod effects;
pub mod evaluate;
pub mod evidence;
pub mod problem;
pub mod simulate;
pub mod stats;

pub use analyse::{Analysis, analyse, errors_with_effects, session_context};
pub use effects::{Context, EffectModel, Kind};

use crate::identify::report::Finding;
use crate::model::Robot;

/// Accepted effect models recovered from report findings (those whose
/// `parameters` hold an effect model; `unexplained` is skipped).
pub fn effects_of(findings: &[Finding]) -> Vec<EffectModel> {
    findings
        .iter()
        .filter_map(|f| serde_json::from_value::<EffectModel>(f.parameters.clone()).ok())
        .collect()
}

/// Joint-angle deflection (rad, per joint) that the accepted robot-side
/// effects add at the commanded angles `q_rad`: the joint really sits at
/// `q + offsets`. To put T where the calibrated model puts it with angles
/// `q_model`, command `q_model - offsets(q_model)` (one fixed-point step is
/// enough: the offsets change by their own square).
///
/// Assumptions: backlash takes the approach direction as positive (joint
/// arrives moving in +q, as most teach programs finish with a positive
/// approach); use [`joint_offsets_rad_with_direction`] when the direction is
/// known. Thermal expansion is not a joint-angle effect and is left out
/// here: it changes the lengths and needs the temperature the robot runs at
/// (`Compensator::at_temperature`). Compliance without link masses uses the
/// unit-mass regressors stored in the finding; compliance is evaluated with
/// the payload the calibration session carried (its median,
/// `reference_payload_kg` of the finding; none when the session recorded no
/// `payload_kg`).
pub fn joint_offsets_rad(findings: &[Finding], robot: &Robot, q_rad: &[f64]) -> Vec<f64> {
    joint_offsets_rad_with_direction(findings, robot, q_rad, &vec![1.0; q_rad.len()])
}

/// As [`joint_offsets_rad`] with the approach direction of every joint
/// (+1 or -1) given.
pub fn joint_offsets_rad_with_direction(
    findings: &[Finding],
    robot: &Robot,
    q_rad: &[f64],
    direction: &[f64],
) -> Vec<f64> {
    let n = robot.dof();
    let effects: Vec<EffectModel> = effects_of(findings)
        .into_iter()
        .filter(|e| e.kind.joint().is_some())
        .collect();
    if effects.is_empty() {
        return vec![0.0; n];
    }
    let payload_kg = findings
        .iter()
        .find_map(|f| f.parameters.get("reference_payload_kg")?.as_f64());
    let mut ctx = Context::new(
        robot,
        vec![],
        0.0,
        &nalgebra::Matrix3::identity(),
        &[effects::PoseInput {
            q_rad,
            time_s: None,
            temp_c: None,
            payload_kg,
            point_rig: nalgebra::Vector3::zeros(),
        }],
    );
    ctx.poses[0].direction = direction.to_vec();
    let mut buf = effects::Basis::default();
    ctx.apply(&effects, 0, &mut buf).dq
}
