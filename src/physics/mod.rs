//! Physics beyond the geometric model: a catalogue of effects
//! ([`effects`]), the calibration problem augmented with them
//! ([`problem`]), the analysis that finds, names, models and proves them
//! ([`analyse`](mod@analyse)) and says where structure no effect explains remains
//! (`unexplained`), and the simulator that puts them into recordings
//! ([`simulate`]). One implementation of each effect serves both.
//!
//! Used by the pipeline ([`crate::pipeline`]): [`analyse()`] after
//! `identify::geometric()`, [`errors_with_effects`] for `stats.test.after`;
//! by compensation: [`JointEffects`] and [`WorkspaceField`].

pub mod analyse;
pub mod effects;
pub mod evidence;
mod field;
pub mod periodogram;
pub mod problem;
pub mod simulate;
mod unexplained;

pub use analyse::{Analysis, analyse, effect_context, errors_with_effects};
pub use effects::{Context, EffectModel, Kind};
pub use field::WorkspaceField;

use crate::model::Robot;
use crate::report::Finding;

/// The robot-side effects that move T itself at a pose rather than a
/// joint's angle: a mount tilting under the arm's moment, a link bending
/// under its load, a tool tilting about the flange under its payload's.
fn moves_t_directly(kind: &Kind) -> bool {
    matches!(
        kind,
        Kind::BaseTilt | Kind::ToolCompliance | Kind::LinkBending { .. }
    )
}

/// The accepted effect models of report findings (`unexplained` has
/// none).
pub fn effects_of(findings: &[Finding]) -> Vec<EffectModel> {
    findings
        .iter()
        .filter_map(|f| f.effect_model().cloned())
        .collect()
}

/// The robot-side effects a calibration accepted (compliance, backlash,
/// periodic and scale errors of the joints; a base that tilts under the
/// arm's moment, a link that bends under its load, a tool that tilts under
/// its payload's), ready to evaluate at commanded joints: the joint
/// really sits at `q + offsets_rad(q)`, and T moves by `point_shift_mm(q)`. To put T where the calibrated model
/// puts it with angles `q_model`, command `q_model - offsets(q_model)` (one
/// fixed-point step is enough: the offsets change by their own square).
///
/// Thermal expansion is not a joint-angle effect and is left out here: it
/// changes the lengths and needs the temperature the robot runs at
/// (`Compensator::at_temperature`).
#[derive(Debug, Clone)]
pub struct JointEffects {
    robot: Robot,
    effects: Vec<EffectModel>,
    /// The payload the calibration session carried (its median; none when
    /// it recorded no `payload_kg`).
    reference_payload_kg: Option<f64>,
    /// The payload the robot carries now (kg; none: the reference).
    payload_kg: Option<f64>,
    /// The direction each joint arrives from (+1 or -1); none: +1.
    approach: Option<Vec<f64>>,
}

impl JointEffects {
    /// The joint effects among `findings`; `None` when there are none.
    /// `robot` is the nominal robot of the calibration (its geometry and
    /// link masses drive compliance).
    pub fn new(findings: &[Finding], robot: &Robot) -> Option<Self> {
        // A data-driven correction of a joint only where its driver is
        // known for a future target (a joint's angle): one by the clock,
        // a move or the gravity load is this session's, not the target's.
        let effects: Vec<EffectModel> = effects_of(findings)
            .into_iter()
            .filter(|e| e.kind.joint().is_some() || moves_t_directly(&e.kind))
            .filter(|e| match &e.kind {
                Kind::DataDriven { driver, .. } => driver.usable_for_compensation(),
                _ => true,
            })
            .collect();
        if effects.is_empty() {
            return None;
        }
        let reference_payload_kg = findings
            .iter()
            .find_map(|f| f.effect_parameters()?.reference_payload_kg);
        Some(JointEffects {
            robot: robot.clone(),
            effects,
            reference_payload_kg,
            payload_kg: None,
            approach: None,
        })
    }

    /// True when a payload changes the offsets or T's shift: an accepted
    /// compliance with link masses (the payload adds its torque), or
    /// without masses one whose session varied the payload (so that its
    /// lever was fitted); a base tilt, a bending link or a compliant tool
    /// ([`EffectModel::payload_matters`]).
    pub fn payload_matters(&self) -> bool {
        let n = self.robot.dof();
        self.effects.iter().any(|e| e.payload_matters(n))
    }

    /// The payload (kg) the offsets are evaluated with: the one set by
    /// [`JointEffects::with_payload_kg`], else the calibration session's
    /// (none: no payload).
    pub fn payload_kg(&self) -> Option<f64> {
        self.payload_kg.or(self.reference_payload_kg)
    }

    /// The same effects with the robot carrying `payload_kg` at T.
    pub fn with_payload_kg(&self, payload_kg: f64) -> Self {
        JointEffects {
            payload_kg: Some(payload_kg),
            ..self.clone()
        }
    }

    /// True when a backlash was accepted: the offsets then depend on the
    /// direction each joint arrives from.
    pub fn has_backlash(&self) -> bool {
        self.effects
            .iter()
            .any(|e| matches!(e.kind, Kind::Backlash { .. }))
    }

    /// The same effects with every joint arriving from `direction` (+1:
    /// moving in +q, -1: in -q; one per joint).
    pub fn with_approach(&self, direction: &[f64]) -> Self {
        JointEffects {
            approach: Some(direction.iter().map(|d| d.signum()).collect()),
            ..self.clone()
        }
    }

    /// A warning when `q_rad` lies outside the range of a joint angle that
    /// drives a data-driven correction (its end knots, the range the
    /// calibration's poses covered): there the correction is held at its
    /// end value, an extrapolation no pose supports.
    pub fn outside_fitted_range(&self, q_rad: &[f64]) -> Option<String> {
        let out: Vec<String> = self
            .effects
            .iter()
            .filter_map(|e| match &e.kind {
                kind @ Kind::DataDriven {
                    driver: effects::CorrectionDriver::JointAngle,
                    driver_index: Some(d),
                    target_index,
                    ..
                } => {
                    let q = *q_rad.get(*d)?;
                    let (lo, hi) = kind.fitted_range()?;
                    (q < lo || q > hi).then(|| {
                        format!(
                            "warning: joint {}'s angle {:.1} deg is outside {:.1} to {:.1} deg, the range the data-driven correction of joint {}'s angle was fitted on; {}",
                            d + 1,
                            q.to_degrees(),
                            lo.to_degrees(),
                            hi.to_degrees(),
                            target_index.map_or(0, |t| t + 1),
                            kind.beyond_range()
                        )
                    })
                }
                _ => None,
            })
            .collect();
        (!out.is_empty()).then(|| out.join("; "))
    }

    /// How far a tilting base, a bending link and a compliant tool move T
    /// (mm, robot base frame) at the commanded `q_rad` with the current
    /// payload; `None` when the calibration accepted none of them.
    pub fn point_shift_mm(&self, q_rad: &[f64]) -> Option<nalgebra::Vector3<f64>> {
        let loaded: Vec<EffectModel> = self
            .effects
            .iter()
            .filter(|e| moves_t_directly(&e.kind))
            .cloned()
            .collect();
        if loaded.is_empty() {
            return None;
        }
        let ctx = self.context(q_rad);
        let mut buf = effects::Basis::default();
        Some(ctx.apply(&loaded, 0, &mut buf).dp)
    }

    /// One pose's effect context at `q_rad` in the robot base frame (no
    /// rig), with the current payload.
    fn context(&self, q_rad: &[f64]) -> Context {
        Context::new(
            &self.robot,
            vec![],
            0.0,
            &nalgebra::Matrix3::identity(),
            &[effects::PoseInput {
                q_rad,
                time_s: None,
                temp_c: None,
                payload_kg: self.payload_kg(),
                point_rig: nalgebra::Vector3::zeros(),
            }],
        )
    }

    /// Joint-angle offsets (rad, per joint) at the commanded `q_rad`.
    /// `direction` is the approach direction of every joint (+1 or -1);
    /// without it the one set by [`JointEffects::with_approach`], else
    /// backlash takes every joint as arriving in +q, as most teach
    /// programs finish with a positive approach.
    pub fn offsets_rad(&self, q_rad: &[f64], direction: Option<&[f64]>) -> Vec<f64> {
        let mut ctx = self.context(q_rad);
        ctx.poses[0].direction = direction
            .or(self.approach.as_deref())
            .map_or_else(|| vec![1.0; q_rad.len()], <[f64]>::to_vec);
        let mut buf = effects::Basis::default();
        ctx.apply(&self.effects, 0, &mut buf).dq
    }
}

/// Joint-angle deflection (rad, per joint) that the accepted robot-side
/// effects of `findings` add at the commanded angles `q_rad`, with the
/// session's payload and every joint approaching in +q (see
/// [`JointEffects`]); zeros without joint effects.
pub fn joint_offsets_rad(findings: &[Finding], robot: &Robot, q_rad: &[f64]) -> Vec<f64> {
    JointEffects::new(findings, robot)
        .map_or_else(|| vec![0.0; robot.dof()], |e| e.offsets_rad(q_rad, None))
}
