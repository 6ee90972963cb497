//! Compensation: the joint angles to send so that the calibrated robot puts
//! T where it was meant to go.
//!
//! This is the paper's Cartesian-space compensation (its Figure 4) iterated
//! to convergence: at the current joints the calibrated model's error
//! against the target is measured and the joints are corrected through the
//! calibrated Jacobian (damped least squares, minimum-norm when the arm is
//! redundant for the task), until T is within 1 micrometre of the target
//! (and the flange orientation within 1 microradian, when asked). Nominal
//! joint targets start from the taught angles. Cartesian targets start from
//! the closed-form inverse kinematics of the nominal arm when its geometry
//! allows one ([`crate::kinematics::ik`]: spherical wrist, UR family), every
//! branch, those inside the joint limits and nearest a reference first;
//! then, for any arm, from a numerical inverse kinematics on the nominal
//! model tried from several seeds. Joint limits are checked, never clamped.
//! An unreachable target is given up early: a Cartesian target beyond what
//! the calibrated arm reaches with any joints is answered at once, and a
//! solve stops as soon as it cannot converge from where it is (at a
//! stationary point of its error, or with the damping grown so large that
//! it can no longer get back below its best error; see
//! `Compensator::solve_on`).
//!
//! Thermal expansion: when the physics analysis accepted it with the
//! temperature as its driver, the calibrated geometry holds at the
//! session's reference temperature (the first pose's) and every nominal a
//! and d grows by `k · (T - T_ref)` times its value at temperature T.
//! [`Compensator::from_report`] compensates at the reference temperature
//! (the behaviour without a temperature); [`Compensator::at_temperature`]
//! gives the compensator for the temperature the robot runs at. A thermal
//! effect driven by time or row order (no temperature was recorded) depends on how long
//! the robot has been warming up since the session began, which nothing at
//! run time knows: it is left out of compensation.
//!
//! Payload: an accepted joint compliance deflects the joint in proportion
//! to its gravity torque, the payload hanging at T included; a compliant
//! tool droops under the payload's moment about the flange.
//! [`Compensator::from_report`] compensates with the payload the
//! calibration session carried (its median `payload_kg`, none if it
//! recorded none); [`Compensator::with_payload_kg`] gives the compensator
//! for the payload the robot carries now.
//!
//! A field over the workspace (a data-driven correction of T as a
//! function of where T is, accepted where the analysis located structure
//! no named effect explains): the calibrated model is aimed at the target
//! minus the field's displacement there, with a warning for a target
//! outside the region the calibration's poses covered.
//!
//! A base that tilts under the arm's gravity moment, a link that bends
//! under its load, and a tool that tilts about the flange under its
//! payload's, move T by an amount that
//! depends on the joints (and the payload): each solve aims the
//! calibrated model at the target minus that shift at its starting joints,
//! and once more at the solution's when they differ.
//!
//! Backlash: where a joint stops depends on the side it arrives from. A
//! compensator takes every joint as arriving in +q (most teach programs
//! finish so); [`Compensator::with_approach`] sets the directions, and
//! [`compensate_in_order`] takes them from the moves between targets the
//! robot visits in order.
//!
//! The module by concept: [`Compensator::new`] and
//! [`Compensator::from_report`] build a compensator and check what it is
//! built from (`build`); the run-time conditions, [`Conditions`] asked and
//! [`Applied`] with what was used and the notes (`conditions`); the bound on
//! the arm's reach (`reach`); one target, from its starting joints to its
//! row (`target`), by damped least squares (`solve`); batches, in any order
//! or in the robot's (`batch`). The rows and their file, compensated.csv,
//! are [`crate::model::compensated`]'s.

mod batch;
mod build;
mod conditions;
mod reach;
mod solve;
mod target;
#[cfg(test)]
mod tests;

use std::sync::{Arc, OnceLock};

use nalgebra::{Matrix3, Vector3};

use crate::kinematics::Params;
use crate::kinematics::chain::{Chain, OutputFrame};
use crate::kinematics::ik::{self, ClosedFormIk};
use crate::physics::{JointEffects, WorkspaceField};

pub use crate::model::MAX_PAYLOAD_KG;
pub use crate::model::compensated::{Compensated, CompensationStatus, write_csv};
pub use batch::{compensate_all, compensate_in_order};
pub use conditions::{
    Applied, Approach, ConditionNames, Conditions, ConditionsUsed, Note, NoteKind, TEMP_C_RANGE,
    ThermalInfo, check_payload_kg, check_temp_c, has_time_thermal,
};

use conditions::Thermal;
use reach::Reach;

/// Compensation for one calibration; build once, use for many targets.
#[derive(Clone)]
pub struct Compensator {
    chain: Chain,
    nominal: Params,
    calibrated: Params,
    limits_rad: Vec<(f64, f64)>,
    /// Robot-side effects accepted by the analysis (the robot really sits
    /// at `q + offsets(q)`), at the payload this compensator runs with.
    joint_effects: Option<Arc<JointEffects>>,
    /// A data-driven field over the workspace accepted by the analysis: T
    /// lands displaced by it, so targets are aimed against it.
    workspace_field: Option<Arc<WorkspaceField>>,
    /// Temperature-driven thermal expansion accepted by the analysis.
    thermal: Option<Arc<Thermal>>,
    /// The temperature `calibrated` holds at (°C), with `thermal`.
    temp_c: Option<f64>,
    /// The report accepted a thermal expansion driven by time or row order,
    /// which compensation leaves out (see the module documentation): kept
    /// so that the conditions can say so.
    time_thermal: bool,
    /// The nominal arm's closed-form inverse kinematics, if it has one.
    ik: Option<Arc<ClosedFormIk>>,
    /// Where the nominal arm's T can be, whatever the joints.
    reach_nominal: Reach,
    /// Where the calibrated arm's T can be: computed when first needed
    /// (emptied when `calibrated` changes), so that `at_temperature` stays
    /// a copy.
    reach_calibrated: OnceLock<Reach>,
    /// Seed Cartesian targets with the closed form when there is one
    /// (default); `false` leaves only the numerical seeds (for comparison).
    pub closed_form: bool,
    /// Stop when T is this close to the target (mm).
    pub tolerance_mm: f64,
    /// Stop when the flange orientation is this close (rad).
    pub tolerance_rad: f64,
    /// Iteration limit per solve.
    pub max_iterations: usize,
    /// Largest change of any joint (deg) a joint target's compensation may
    /// make; beyond it the target is refused (`joint_change`), saying which
    /// joint and how far ([`DEFAULT_MAX_JOINT_CHANGE_DEG`]).
    pub max_joint_change_deg: f64,
    /// How far the calibrated tool point is from the nominal one (mm, in
    /// the flange frame): a correction the joints make up for at every
    /// joint target, said when a target is refused.
    tool_difference_mm: f64,
}

/// The default of [`Compensator::max_joint_change_deg`]: a calibration
/// corrects millimetres, which takes a fraction of a degree of any joint
/// away from singular poses; a compensated target that moves a joint
/// further would swing the arm through the cell.
pub const DEFAULT_MAX_JOINT_CHANGE_DEG: f64 = 5.0;

impl std::fmt::Debug for Compensator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Compensator")
            .field("joints", &self.chain.layout.n_joints)
            .finish()
    }
}

impl Compensator {
    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.chain.layout.n_joints
    }

    /// Which closed-form inverse kinematics seeds Cartesian targets
    /// (`None`: the numerical seeds only).
    pub fn closed_form_geometry(&self) -> Option<ik::Geometry> {
        self.ik.as_ref().map(|k| k.geometry())
    }

    /// The home joints: zero, moved into the limits.
    fn home(&self) -> Vec<f64> {
        self.limits_rad
            .iter()
            .map(|(lo, hi)| 0.0f64.clamp(*lo, *hi))
            .collect()
    }

    /// Where the nominal model puts T and the flange at `q_rad`.
    pub fn nominal_pose(&self, q_rad: &[f64]) -> (Vector3<f64>, Matrix3<f64>) {
        let (f, t) = self
            .chain
            .point(&self.nominal.values, q_rad, OutputFrame::Base);
        (t, f.r)
    }

    /// Where the calibrated robot (with its effects, the shift of T by a
    /// tilting base, a bending link or a compliant tool included) puts T and the flange when commanded `q_rad`.
    pub fn calibrated_pose(&self, q_rad: &[f64]) -> (Vector3<f64>, Matrix3<f64>) {
        let q = self.effective(q_rad);
        let (f, t) = self
            .chain
            .point(&self.calibrated.values, &q, OutputFrame::Base);
        let shift = self
            .joint_effects
            .as_ref()
            .and_then(|e| e.point_shift_mm(q_rad))
            .unwrap_or_default();
        (t + shift, f.r)
    }

    /// [`Compensator::effective`] into `out` (one slot per joint), the
    /// same sums without allocating when there are no joint effects.
    fn effective_into(&self, q: &[f64], out: &mut [f64]) {
        match &self.joint_effects {
            Some(e) => {
                for ((o, a), b) in out.iter_mut().zip(q).zip(e.offsets_rad(q, None)) {
                    *o = a + b;
                }
            }
            None => out.copy_from_slice(q),
        }
    }

    fn effective(&self, q: &[f64]) -> Vec<f64> {
        match &self.joint_effects {
            Some(e) => q
                .iter()
                .zip(e.offsets_rad(q, None))
                .map(|(a, b)| a + b)
                .collect(),
            None => q.to_vec(),
        }
    }
}
