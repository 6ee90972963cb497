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
//! to its gravity torque, the payload hanging at T included.
//! [`Compensator::from_report`] compensates with the payload the
//! calibration session carried (its median `payload_kg`, none if it
//! recorded none); [`Compensator::with_payload_kg`] gives the compensator
//! for the payload the robot carries now.
//!
//! Backlash: where a joint stops depends on the side it arrives from. A
//! compensator takes every joint as arriving in +q (most teach programs
//! finish so); [`Compensator::with_approach`] sets the directions, and
//! [`compensate_in_order`] takes them from the moves between targets the
//! robot visits in order.

use std::sync::{Arc, OnceLock};

use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::kinematics::chain::{Chain, OutputFrame};
use crate::kinematics::ik::{self, ClosedFormIk};
use crate::kinematics::{JointParam, Params, rpy_matrix};
use crate::model::{Convention, Robot, Target, TargetKind};
use crate::physics::JointEffects;
use crate::report::Report;
use crate::rng::Rng;

/// Outcome of one target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CompensationStatus {
    /// Compensated joints found within the limits.
    Ok,
    /// No joints put T on the target.
    Unreachable,
    /// The joints that reach the target violate a joint limit.
    JointLimit,
}

impl CompensationStatus {
    /// The compensated.csv spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            CompensationStatus::Ok => "ok",
            CompensationStatus::Unreachable => "unreachable",
            CompensationStatus::JointLimit => "joint_limit",
        }
    }
}

/// One compensated target (a row of compensated.csv).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Compensated {
    /// Target id.
    pub target: String,
    /// Joint angles to send (deg); `None` unless `status` is ok.
    pub q_deg: Option<Vec<f64>>,
    /// Distance from the calibrated model's T to the target (mm).
    pub residual_mm: Option<f64>,
    /// Solver iterations.
    pub iterations: usize,
    /// Outcome.
    pub status: CompensationStatus,
    /// Why, when not ok.
    pub message: Option<String>,
}

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
    /// Temperature-driven thermal expansion accepted by the analysis.
    thermal: Option<Arc<Thermal>>,
    /// The temperature `calibrated` holds at (°C), with `thermal`.
    temp_c: Option<f64>,
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
}

impl std::fmt::Debug for Compensator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Compensator")
            .field("joints", &self.chain.layout.n_joints)
            .finish()
    }
}

/// Lowest and highest temperature (°C) a compensation is asked for.
pub const TEMP_C_RANGE: (f64, f64) = (-50.0, 150.0);

/// A run-time temperature (°C) checked: finite and within
/// [`TEMP_C_RANGE`]; the error names `field`.
pub fn check_temp_c(field: &str, temp_c: f64) -> Result<f64> {
    let (lo, hi) = TEMP_C_RANGE;
    if temp_c.is_finite() && (lo..=hi).contains(&temp_c) {
        Ok(temp_c)
    } else {
        Err(Error::field(
            field,
            format!("a temperature in degrees C from {lo} to {hi}, got {temp_c}"),
        ))
    }
}

pub use crate::model::MAX_PAYLOAD_KG;

/// A run-time payload (kg) checked: finite, from 0 to [`MAX_PAYLOAD_KG`];
/// the error names `field`.
pub fn check_payload_kg(field: &str, payload_kg: f64) -> Result<f64> {
    if payload_kg.is_finite() && (0.0..=MAX_PAYLOAD_KG).contains(&payload_kg) {
        Ok(payload_kg)
    } else {
        Err(Error::field(
            field,
            format!("a payload in kg from 0 to {MAX_PAYLOAD_KG}, got {payload_kg}"),
        ))
    }
}

/// Thermal expansion driven by the temperature, as the analysis accepted it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ThermalInfo {
    /// Growth of every nominal a and d per kelvin (1/K).
    pub coef_per_k: f64,
    /// The temperature the calibrated geometry holds at (°C): the first
    /// pose's of the calibration session.
    pub reference_temp_c: f64,
}

/// What a compensator needs to move its geometry to a temperature.
#[derive(Debug)]
struct Thermal {
    info: ThermalInfo,
    /// `(parameter index, nominal value)` of the lengths that grow
    /// ([`crate::physics::effects::nominal_lengths`]).
    lengths: Vec<(usize, f64)>,
    /// Calibrated parameters at the reference temperature.
    reference_values: Vec<f64>,
}

/// The temperature-driven thermal expansion a report's findings accepted
/// (with the reference temperature that reports since it was recorded
/// carry), if any.
fn thermal_of(report: &Report) -> Option<ThermalInfo> {
    use crate::physics::effects::{Kind, ThermalDriver};
    report.findings.iter().find_map(|f| {
        let p = f.effect_parameters()?;
        let e = &p.model;
        if !matches!(
            e.kind,
            Kind::ThermalExpansion {
                driver: ThermalDriver::Temperature,
                ..
            }
        ) {
            return None;
        }
        let coef_per_k = *e.coef.first()?;
        let reference_temp_c = p.reference_temp_c?;
        (coef_per_k.is_finite() && reference_temp_c.is_finite()).then_some(ThermalInfo {
            coef_per_k,
            reference_temp_c,
        })
    })
}

/// True when the report accepted a thermal expansion driven by time or by
/// the row order (not compensated: see the module documentation).
pub fn has_time_thermal(report: &Report) -> bool {
    use crate::physics::effects::{Kind, ThermalDriver};
    crate::physics::effects_of(&report.findings)
        .iter()
        .any(|e| {
            matches!(
                e.kind,
                Kind::ThermalExpansion {
                    driver: ThermalDriver::Time | ThermalDriver::Order,
                    ..
                }
            )
        })
}

/// Which model a solve runs on.
#[derive(Clone, Copy)]
enum Model {
    /// The nominal model, without joint effects (seeding).
    Nominal,
    /// The calibrated model with its joint effects.
    Calibrated,
}

struct Solution {
    q: Vec<f64>,
    residual_mm: f64,
    iterations: usize,
}

/// A solve that did not converge: the iterations it ran before it gave up.
struct NotConverged {
    iterations: usize,
    /// Least distance (mm) from T to the target over the solve's iterates,
    /// for a position-only target.
    closest_mm: Option<f64>,
}

/// A ball that holds T for every joint angle (limits ignored): a true upper
/// bound on the arm's reach, for either convention, tool point included.
///
/// Every joint is revolute and only `a`, `d` and the tool point translate,
/// so the arm is a chain of rigid segments, each joining a point on one
/// joint axis to a point on the next (the last one joins it to T); a joint
/// turns everything after its axis without moving the axis. Each segment
/// keeps its length whatever the joints, so T is never farther from the
/// first point (on joint 1's axis, fixed in the base frame) than the sum of
/// the lengths, by the triangle inequality.
///
/// - DH, `Rz(q+θ) Tz(d) Tx(a) Rx(α) Ry(β)`: the points are `P_j = o_j +
///   d_{j+1} z_j` (on axis j+1, which is `z_j`), from `P_0 = (0, 0, d_1)`;
///   `P_j - P_{j-1} = R (a_j x + Rx(α_j) Ry(β_j) d_{j+1} z)` with `R =
///   R_{j-1} Rz(q_j + θ_j)` a rotation, and `T - P_{n-1} = R (a_n x +
///   Rx(α_n) Ry(β_n) tool) = R_n ((Rx(α_n) Ry(β_n))ᵀ a_n x + tool)`.
/// - MDH, `Rx(α) Ry(β) Tx(a) Rz(q+θ) Tz(d)`: the points are the frame
///   origins `o_j` (on axis j), from `o_1 = Rx(α_1) Ry(β_1) (a_1, 0, d_1)`;
///   `|o_j - o_{j-1}| = sqrt(a_j² + d_j²)` and `T - o_n = R_n tool`.
///
/// With the flange orientation `R_n` given, the last segment is fixed too:
/// its start, `T - R_n last`, is within `radius - |last|` of the centre.
///
/// The same sums bound the distance from T to any joint axis (the segments
/// after that axis), so they also bound how fast T moves as a joint turns:
/// at most `radius` mm per radian.
#[derive(Debug, Clone, Copy)]
struct Reach {
    centre: Vector3<f64>,
    radius: f64,
    /// The last segment in the flange frame: from the point on the last
    /// joint's axis to T.
    last: Vector3<f64>,
}

impl Reach {
    fn of(chain: &Chain, p: &[f64]) -> Reach {
        let l = chain.layout;
        let n = l.n_joints;
        let t = l.tool();
        let tool = Vector3::new(p[t], p[t + 1], p[t + 2]);
        let at = |j: usize, k: JointParam| p[l.joint(j, k)];
        let twist = |j: usize| {
            Rotation3::from_axis_angle(&Vector3::x_axis(), at(j, JointParam::Alpha))
                * Rotation3::from_axis_angle(&Vector3::y_axis(), at(j, JointParam::Beta))
        };
        let a_x = |j: usize| Vector3::new(at(j, JointParam::A), 0.0, 0.0);
        if n == 0 {
            return Reach {
                centre: Vector3::zeros(),
                radius: tool.norm(),
                last: tool,
            };
        }
        match chain.convention {
            Convention::Dh => {
                let last = twist(n - 1).inverse() * a_x(n - 1) + tool;
                Reach {
                    centre: Vector3::new(0.0, 0.0, at(0, JointParam::D)),
                    radius: (0..n - 1)
                        .map(|j| {
                            let d_next = Vector3::new(0.0, 0.0, at(j + 1, JointParam::D));
                            (a_x(j) + twist(j) * d_next).norm()
                        })
                        .sum::<f64>()
                        + last.norm(),
                    last,
                }
            }
            Convention::Mdh => Reach {
                centre: twist(0) * Vector3::new(at(0, JointParam::A), 0.0, at(0, JointParam::D)),
                radius: (1..n)
                    .map(|j| at(j, JointParam::A).hypot(at(j, JointParam::D)))
                    .sum::<f64>()
                    + tool.norm(),
                last: tool,
            },
        }
    }

    /// How far `point` is outside a ball of `radius` about the centre (mm;
    /// negative inside), less a rounding allowance, so that a positive
    /// answer is out of reach for sure.
    fn outside(&self, point: &Vector3<f64>, radius: f64) -> f64 {
        let d = (point - self.centre).norm();
        d - radius - 1e-9 * (d + self.radius + self.centre.norm())
    }

    /// How far T at `point` is out of reach for any joints (mm; negative
    /// when it may be within reach).
    fn beyond(&self, point: &Vector3<f64>) -> f64 {
        self.outside(point, self.radius)
    }

    /// The same for T at `point` with the flange at `rot` (to within
    /// `tolerance_rad`): how far the start of the last segment is out of
    /// the reach of the others, and where it is.
    fn beyond_pose(
        &self,
        point: &Vector3<f64>,
        rot: &Matrix3<f64>,
        tolerance_rad: f64,
    ) -> (f64, Vector3<f64>) {
        let start = point - rot * self.last;
        let len = self.last.norm();
        // The flange may turn by `tolerance_rad`: the start moves as much
        // times the segment's length.
        let slack = tolerance_rad * len;
        (self.outside(&start, self.radius - len) - slack, start)
    }
}

/// A damped least squares solve stops at a stationary point of its error
/// (MINPACK's `gtol`): when every column of the Jacobian is this close to
/// orthogonal to the error (`|J_j·e| <= GTOL |J_j| |e|`), with the error
/// far above the tolerance. Over the targets of `tests/engine/compensate_ik.rs`
/// the converging solves never came below 7e-4.
const GTOL: f64 = 1e-6;

/// Longest joint step (rad, Euclidean over the joints) of one solver
/// iteration from taught joints.
const MAX_STEP_RAD: f64 = 0.2;

impl Compensator {
    /// From the nominal and calibrated models (robot.json form).
    pub fn new(nominal: &Robot, calibrated: &Robot) -> Result<Self> {
        if nominal.dof() != calibrated.dof() || nominal.convention != calibrated.convention {
            return Err(Error::field(
                "calibrated_robot",
                "does not match the nominal robot's joints or convention",
            ));
        }
        let chain = Chain::new(nominal.convention, nominal.dof(), 0);
        let (nominal_p, calibrated_p) = (Params::of_robot(nominal), Params::of_robot(calibrated));
        Ok(Compensator {
            chain,
            reach_nominal: Reach::of(&chain, &nominal_p.values),
            reach_calibrated: OnceLock::new(),
            nominal: nominal_p,
            calibrated: calibrated_p,
            limits_rad: calibrated
                .joints
                .iter()
                .map(|j| (j.q_min_deg.to_radians(), j.q_max_deg.to_radians()))
                .collect(),
            joint_effects: None,
            thermal: None,
            temp_c: None,
            ik: ClosedFormIk::from_robot(nominal).map(Arc::new),
            closed_form: true,
            tolerance_mm: 1e-3,
            tolerance_rad: 1e-6,
            max_iterations: 50,
        })
    }

    /// From a calibration report, with the robot-side effects its physics
    /// analysis accepted (a compliant joint's correction depends on the pose).
    /// A temperature-driven thermal expansion is kept and applied at its
    /// reference temperature (multiplier 0, the geometry as calibrated):
    /// use [`Compensator::at_temperature`] for the temperature the robot
    /// runs at. A time-driven one is left out (see the module docs).
    pub fn from_report(report: &Report) -> Result<Self> {
        // A report may have been edited by hand: check what compensation
        // relies on before any index is used.
        for (field, robot) in [
            ("nominal_robot", &report.nominal_robot),
            ("calibrated_robot", &report.calibrated_robot),
        ] {
            robot
                .validate()
                .map_err(|e| Error::field(field, e.to_string()))?;
        }
        let robot = &report.nominal_robot;
        let has_masses = robot.links.as_ref().is_some_and(|l| l.len() == robot.dof());
        for (i, f) in report.findings.iter().enumerate() {
            // `unexplained` has no model; every other finding must carry
            // one that fits the robot, or compensation would drop it.
            if f.effect == "unexplained" {
                continue;
            }
            let field = || format!("findings[{i}].parameters");
            let e = f
                .effect_model()
                .ok_or_else(|| Error::field(field(), format!("{}: no effect model", f.effect)))?;
            e.check(robot.dof(), has_masses)
                .map_err(|m| Error::field(field(), m))?;
        }
        let mut comp = Self::new(&report.nominal_robot, &report.calibrated_robot)?;
        if let Some(info) = thermal_of(report) {
            comp.thermal = Some(Arc::new(Thermal {
                info,
                lengths: crate::physics::effects::nominal_lengths(&report.nominal_robot),
                reference_values: comp.calibrated.values.clone(),
            }));
            comp.temp_c = Some(info.reference_temp_c);
        }
        comp.joint_effects =
            JointEffects::new(&report.findings, &report.nominal_robot).map(Arc::new);
        Ok(comp)
    }

    /// The accepted temperature-driven thermal expansion, if any.
    pub fn thermal(&self) -> Option<ThermalInfo> {
        self.thermal.as_ref().map(|t| t.info)
    }

    /// The temperature (°C) this compensator compensates at: `None` without
    /// a temperature-driven thermal effect.
    pub fn temperature_c(&self) -> Option<f64> {
        self.temp_c
    }

    /// True when the calibration accepted a backlash: the joints to send
    /// then depend on the direction each joint arrives from
    /// ([`Compensator::with_approach`]; default: every joint moving in +q).
    pub fn has_backlash(&self) -> bool {
        self.joint_effects
            .as_ref()
            .is_some_and(|e| e.has_backlash())
    }

    /// This compensator with every joint arriving from `direction` (+1:
    /// moving in +q, -1: in -q; one per joint). Without a backlash, an
    /// unchanged copy.
    pub fn with_approach(&self, direction: &[f64]) -> Compensator {
        let mut c = self.clone();
        if let Some(e) = self.joint_effects.as_ref().filter(|e| e.has_backlash()) {
            c.joint_effects = Some(Arc::new(e.with_approach(direction)));
        }
        c
    }

    /// The payload (kg at T) this compensator compensates with, when the
    /// accepted effects depend on it (a compliance): the one given to
    /// [`Compensator::with_payload_kg`], else the calibration session's
    /// (`Some(0.0)` when it recorded none). `None` when the payload does
    /// not matter.
    pub fn payload_kg(&self) -> Option<f64> {
        self.joint_effects
            .as_ref()
            .filter(|e| e.payload_matters())
            .map(|e| e.payload_kg().unwrap_or(0.0))
    }

    /// This compensator with the robot carrying `payload_kg` at T: a
    /// compliant joint deflects under the payload's gravity torque too.
    /// When the payload does not matter ([`Compensator::payload_kg`] is
    /// `None`), an unchanged copy.
    pub fn with_payload_kg(&self, payload_kg: f64) -> Compensator {
        let mut c = self.clone();
        if self.payload_kg().is_some()
            && let Some(e) = &self.joint_effects
        {
            c.joint_effects = Some(Arc::new(e.with_payload_kg(payload_kg)));
        }
        c
    }

    /// This compensator with the robot at `temp_c` (°C): every nominal a
    /// and d of the calibrated geometry grows by `k · (temp_c - T_ref)`
    /// times its nominal value. Without a temperature-driven thermal
    /// effect, an unchanged copy. A clone of the parameter vectors; no
    /// other work (the calibrated arm's reach, which the lengths change, is
    /// worked out again when first needed).
    pub fn at_temperature(&self, temp_c: f64) -> Compensator {
        let mut c = self.clone();
        if let Some(t) = &self.thermal {
            let m = t.info.coef_per_k * (temp_c - t.info.reference_temp_c);
            c.calibrated.values.copy_from_slice(&t.reference_values);
            for &(i, v) in &t.lengths {
                c.calibrated.values[i] += m * v;
            }
            c.reach_calibrated = OnceLock::new();
            c.temp_c = Some(temp_c);
        }
        c
    }

    /// Where the calibrated arm's T can be, whatever the joints.
    fn reach_calibrated(&self) -> &Reach {
        self.reach_calibrated
            .get_or_init(|| Reach::of(&self.chain, &self.calibrated.values))
    }

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

    /// Where the calibrated robot (with its effects) puts T and the flange
    /// when commanded `q_rad`.
    pub fn calibrated_pose(&self, q_rad: &[f64]) -> (Vector3<f64>, Matrix3<f64>) {
        let q = self.effective(q_rad);
        let (f, t) = self
            .chain
            .point(&self.calibrated.values, &q, OutputFrame::Base);
        (t, f.r)
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

    /// Compensate one target. `orientation` also holds the flange
    /// orientation (the nominal one for joint targets, the given one for
    /// Cartesian targets with angles).
    ///
    /// Precondition: a joint target has one angle per joint (see
    /// [`Compensator::compensate_near`]).
    pub fn compensate(&self, target: &Target, orientation: bool) -> Compensated {
        self.compensate_near(target, orientation, None)
    }

    /// [`Compensator::compensate`], trying the closed-form branches of a
    /// Cartesian target nearest `reference_rad` first (e.g. the robot's
    /// current joints; default: home). Joint targets ignore it.
    ///
    /// A Cartesian target farther from the arm's root point (on joint 1's
    /// axis) than the calibrated arm reaches with any joints, or whose
    /// flange at the given orientation would be beyond what the joints
    /// before the last reach, is answered unreachable at once, without a
    /// solve.
    ///
    /// # Precondition
    ///
    /// A joint target has one angle per joint ([`Compensator::dof`]), and
    /// so has `reference_rad` when given with a Cartesian target (`drawcal
    /// compensate` and `POST /compensate` check the targets before they
    /// get here, and pass no reference). Anything else is a bug in the
    /// caller, not a fact about the robot: debug builds panic on it
    /// (`debug_assert!`); release builds answer a row without joints whose
    /// message begins `malformed input:` and says the target was never
    /// tried (its status is `Unreachable`, the only "no joints" status
    /// there is: a new one would change the public type and the HTTP
    /// answer's schema for a case those layers never let through).
    pub fn compensate_near(
        &self,
        target: &Target,
        orientation: bool,
        reference_rad: Option<&[f64]>,
    ) -> Compensated {
        let fail = |status, iterations, message: String| Compensated {
            target: target.target.clone(),
            q_deg: None,
            residual_mm: None,
            iterations,
            status,
            message: Some(message),
        };
        if let Some(problem) = self.malformed(target, reference_rad) {
            debug_assert!(
                false,
                "Compensator::compensate_near called against its precondition: {problem}"
            );
            return fail(
                CompensationStatus::Unreachable,
                0,
                format!(
                    "malformed input: {problem} (a caller's error: the target was not tried, \
                     nothing is known about its reach)"
                ),
            );
        }
        let unreachable_message = || {
            format!(
                "the calibrated model cannot put T on the target (no solution within {} mm)",
                self.tolerance_mm
            )
        };
        let (pos, rot, seeds) = match &target.kind {
            TargetKind::Joints { q_deg } => {
                // A correction is a fraction of a degree: a target more than
                // a turn past a limit stays past it, and at such angles
                // (1e15 deg) the trigonometry itself has lost its digits.
                if let Some(msg) = self.far_past_limits(q_deg) {
                    return fail(CompensationStatus::JointLimit, 0, msg);
                }
                let q: Vec<f64> = q_deg.iter().map(|v| v.to_radians()).collect();
                let (t, r) = self.nominal_pose(&q);
                (t, orientation.then_some(r), vec![q])
            }
            TargetKind::Cartesian { xyz_mm, rpy_deg } => {
                let r = rpy_deg
                    .map(|a| rpy_matrix(a[0].to_radians(), a[1].to_radians(), a[2].to_radians()));
                let t = Vector3::from(*xyz_mm);
                // Out of reach for any joints: no seed can help.
                let reach = self.reach_calibrated();
                if reach.beyond(&t) > self.tolerance_mm {
                    return fail(
                        CompensationStatus::Unreachable,
                        0,
                        format!(
                            "{}: it is {:.1} mm from the arm's root point (on joint 1's axis), \
                             beyond the {:.1} mm the arm reaches from there with any joints",
                            unreachable_message(),
                            (t - reach.centre).norm(),
                            reach.radius
                        ),
                    );
                }
                if let Some(r) = &r {
                    let (beyond, start) = reach.beyond_pose(&t, r, self.tolerance_rad);
                    if beyond > self.tolerance_mm {
                        return fail(
                            CompensationStatus::Unreachable,
                            0,
                            format!(
                                "{}: with the flange at that orientation, joint {n}'s axis would \
                                 have to pass through a point {:.1} mm from the arm's root point \
                                 (on joint 1's axis), beyond the {:.1} mm the joints before it \
                                 reach",
                                unreachable_message(),
                                (start - reach.centre).norm(),
                                reach.radius - reach.last.norm(),
                                n = self.dof(),
                            ),
                        );
                    }
                }
                let home = self.home();
                let reference = reference_rad.unwrap_or(&home);
                (t, r, self.closed_form_seeds(&t, r.as_ref(), reference))
            }
        };
        let cartesian = matches!(target.kind, TargetKind::Cartesian { .. });
        let mut last_iterations = 0;
        let mut limit_msg = None;
        let mut closest_mm = f64::INFINITY;
        let mut tried: Vec<Vec<f64>> = Vec::new();
        // Closed-form (or taught) seeds first; the numerical ones only when
        // those fail, computed lazily.
        let numeric = cartesian
            .then(|| self.numeric_seeds(&pos, rot.as_ref()))
            .into_iter()
            .flatten();
        for seed in seeds.into_iter().chain(numeric) {
            // A seed already tried gives the same answer again.
            if tried
                .iter()
                .any(|t| t.iter().zip(&seed).all(|(a, b)| (a - b).abs() < 1e-9))
            {
                continue;
            }
            // Taught joints are where the answer should stay: their solve
            // takes bounded steps.
            let max_step = if cartesian {
                f64::INFINITY
            } else {
                MAX_STEP_RAD
            };
            let solved = self.solve(&pos, rot.as_ref(), &seed, max_step);
            tried.push(seed);
            match solved {
                Ok(sol) => {
                    last_iterations += sol.iterations;
                    if let Some(msg) = self.limit_violation(&sol.q, !cartesian) {
                        limit_msg.get_or_insert(msg);
                        continue;
                    }
                    return Compensated {
                        target: target.target.clone(),
                        q_deg: Some(sol.q.iter().map(|v| v.to_degrees()).collect()),
                        residual_mm: Some(sol.residual_mm),
                        iterations: last_iterations,
                        status: CompensationStatus::Ok,
                        message: None,
                    };
                }
                Err(failed) => {
                    last_iterations += failed.iterations;
                    if let Some(c) = failed.closest_mm {
                        closest_mm = closest_mm.min(c);
                    }
                }
            }
        }
        match limit_msg {
            Some(msg) => fail(CompensationStatus::JointLimit, last_iterations, msg),
            // How near it came tells a target just out of reach (or an arm
            // with too few joints to place T anywhere, like a two-axis
            // positioner) from a wrong target.
            None if closest_mm.is_finite() => fail(
                CompensationStatus::Unreachable,
                last_iterations,
                format!(
                    "{}; the nearest the calibrated model came is {closest_mm:.4} mm",
                    unreachable_message()
                ),
            ),
            None => fail(
                CompensationStatus::Unreachable,
                last_iterations,
                unreachable_message(),
            ),
        }
    }

    /// What breaks [`Compensator::compensate_near`]'s precondition, if
    /// anything.
    fn malformed(&self, target: &Target, reference_rad: Option<&[f64]>) -> Option<String> {
        let n = self.dof();
        match (&target.kind, reference_rad) {
            (TargetKind::Joints { q_deg }, _) if q_deg.len() != n => Some(format!(
                "{} joint angles for a {n}-joint robot",
                q_deg.len()
            )),
            (TargetKind::Cartesian { .. }, Some(q)) if q.len() != n => Some(format!(
                "a reference of {} joint angles for a {n}-joint robot",
                q.len()
            )),
            _ => None,
        }
    }

    /// The first joint whose solved angle is past its limits, said with
    /// the limits and, for a `taught` joint target whose same joint angle a
    /// turn away is within them, that too (never taken silently: a turn
    /// away is another motion of the arm, its cables wound the other way;
    /// a Cartesian target's branches are the solver's own choice).
    fn limit_violation(&self, q: &[f64], taught: bool) -> Option<String> {
        let within = |v: f64, (lo, hi): (f64, f64)| v >= lo - 1e-9 && v <= hi + 1e-9;
        q.iter()
            .zip(&self.limits_rad)
            .enumerate()
            .find_map(|(j, (&v, &limits))| {
                (!within(v, limits)).then(|| {
                    let mut msg = format!(
                        "joint {} would need {:.4} deg, outside its limits [{}, {}] deg",
                        j + 1,
                        v.to_degrees(),
                        display_deg(limits.0),
                        display_deg(limits.1)
                    );
                    let turn = std::f64::consts::TAU;
                    let turned = [v - turn, v + turn]
                        .into_iter()
                        .find(|&w| within(w, limits));
                    if let Some(w) = turned.filter(|_| taught) {
                        msg += &format!(
                            " (the same angle a turn away, {:.4} deg, is within them: \
                             teach the target there to use it)",
                            w.to_degrees()
                        );
                    }
                    msg
                })
            })
    }

    /// The first joint of a joint target more than a turn past its limits.
    fn far_past_limits(&self, q_deg: &[f64]) -> Option<String> {
        q_deg
            .iter()
            .zip(&self.limits_rad)
            .enumerate()
            .find_map(|(j, (&v, &(lo, hi)))| {
                (v < lo.to_degrees() - 360.0 || v > hi.to_degrees() + 360.0).then(|| {
                    format!(
                        "joint {}'s target {v} deg is more than a turn outside its limits \
                         [{}, {}] deg: no compensation brings it back",
                        j + 1,
                        display_deg(lo),
                        display_deg(hi)
                    )
                })
            })
    }

    /// The closed-form solutions of the nominal arm for a Cartesian target
    /// (position-only targets with the canonical orientation of
    /// [`ClosedFormIk::solve_position`]), ordered by [`ik::order_near`]:
    /// inside the limits first, then nearest `reference`. Empty when the arm
    /// has no closed form or the pose is out of its reach.
    fn closed_form_seeds(
        &self,
        pos: &Vector3<f64>,
        rot: Option<&Matrix3<f64>>,
        reference: &[f64],
    ) -> Vec<Vec<f64>> {
        let Some(ik) = self.ik.as_ref().filter(|_| self.closed_form) else {
            return vec![];
        };
        let mut out = match rot {
            Some(r) => ik.solve(pos, r, reference),
            None => ik.solve_position(pos, reference),
        };
        ik::order_near(&mut out, reference, &self.limits_rad);
        out
    }

    /// Starting joints for a Cartesian target, any arm: inverse kinematics
    /// on the nominal model from a fixed set of seeds (home first), each
    /// solved only when the previous ones are used up.
    fn numeric_seeds<'a>(
        &'a self,
        pos: &'a Vector3<f64>,
        rot: Option<&'a Matrix3<f64>>,
    ) -> impl Iterator<Item = Vec<f64>> + 'a {
        let n = self.dof();
        let mut rng = Rng::new(0x5EED);
        let mut starts = vec![self.home()];
        for _ in 0..11 {
            starts.push(
                self.limits_rad
                    .iter()
                    .map(|(lo, hi)| {
                        rng.range(lo.max(-std::f64::consts::PI), hi.min(std::f64::consts::PI))
                    })
                    .collect(),
            );
        }
        let home = self.home();
        let mut starts = starts.into_iter();
        let mut any = false;
        std::iter::from_fn(move || {
            for s in starts.by_ref() {
                if let Ok(mut sol) = self.solve_on(Model::Nominal, pos, rot, &s, f64::INFINITY) {
                    any = true;
                    // The solve may wander whole turns away: the same pose
                    // nearer home, inside the limits when it can be.
                    ik::turn_near(&mut sol.q, &home, &self.limits_rad);
                    return Some(sol.q);
                }
            }
            if !any {
                // Let the calibrated solve try from home anyway: the nominal
                // model may just miss a target at the edge of the workspace.
                any = true;
                return Some(vec![0.0; n]);
            }
            None
        })
    }

    /// Damped least squares on the calibrated model from `q0`, each step at
    /// most `max_step_rad` long.
    fn solve(
        &self,
        pos: &Vector3<f64>,
        rot: Option<&Matrix3<f64>>,
        q0: &[f64],
        max_step_rad: f64,
    ) -> std::result::Result<Solution, NotConverged> {
        self.solve_on(Model::Calibrated, pos, rot, q0, max_step_rad)
    }

    /// Damped least squares on either model from `q0`, each step at most
    /// `max_step_rad` long (a trust region; infinite for none).
    ///
    /// Besides converging or using up its iterations, a solve gives up as
    /// soon as it cannot converge from where it is (unreachable targets
    /// used to cost every seed its full iteration budget):
    ///
    /// - at a stationary point of the error far above the tolerance
    ///   (MINPACK's `gtol` test, [`GTOL`]): the error is orthogonal to every
    ///   column of the Jacobian, so the damped step is nil; it is a local
    ///   minimum (or a saddle) of the distance to the target, not the
    ///   target.
    /// - frozen: the error did not beat the best so far (the damping has
    ///   just grown tenfold), the damping is at least the Jacobian's
    ///   largest curvature (`λ >= min(m, n)`, as it is scaled by the mean
    ///   one), and the step is too short to bring the error back below that
    ///   best. From there every further failure grows the damping tenfold
    ///   and shrinks the step to at most 2/11 of the last, so all the steps
    ///   still to come add up to at most 11/9 of this one; T moves at most
    ///   [`Reach`]'s radius in mm per radian of a joint (and the flange one
    ///   radian, weighted 1000 mm), so the error can never come back below
    ///   the best, which is above the tolerance: the damping never falls
    ///   again and the solve cannot converge. The test uses twice that
    ///   allowance.
    ///
    /// Neither test stopped a solve that would have converged: over 6,210
    /// targets on the arms of `tests/engine/compensate_ik.rs` (BENCHMARKS.md),
    /// every answer is the same as without them, joint for joint.
    fn solve_on(
        &self,
        model: Model,
        pos: &Vector3<f64>,
        rot: Option<&Matrix3<f64>>,
        q0: &[f64],
        max_step_rad: f64,
    ) -> std::result::Result<Solution, NotConverged> {
        let n = self.dof();
        let (params, effective) = match model {
            Model::Calibrated => (&self.calibrated, true),
            Model::Nominal => (&self.nominal, false),
        };
        let mut closest_mm = f64::INFINITY;
        let give_up = |iterations, closest_mm: f64| {
            Err(NotConverged {
                iterations,
                closest_mm: (rot.is_none() && closest_mm.is_finite()).then_some(closest_mm),
            })
        };
        let mut q = q0.to_vec();
        let mut jac = self.chain.new_jacobian();
        let m = if rot.is_some() { 6 } else { 3 };
        // The largest error (below) a converged solve can have.
        let converged_err = match rot {
            Some(_) => self.tolerance_mm + 1000.0 * self.tolerance_rad,
            None => self.tolerance_mm,
        };
        let mut lambda: f64 = 1e-6;
        let mut prev_err = f64::INFINITY;
        for it in 0..=self.max_iterations {
            let qe = if effective {
                self.effective(&q)
            } else {
                q.clone()
            };
            self.chain
                .point_jacobian(&params.values, &qe, OutputFrame::Base, &mut jac);
            let e_pos = pos - jac.point;
            let e_rot = rot
                .map(|r| rotation_error(r, &jac.flange.r))
                .unwrap_or_else(Vector3::zeros);
            closest_mm = closest_mm.min(e_pos.norm());
            let pos_ok = e_pos.norm() <= self.tolerance_mm;
            let rot_ok = e_rot.norm() <= self.tolerance_rad;
            if pos_ok && rot_ok {
                return Ok(Solution {
                    residual_mm: e_pos.norm(),
                    q,
                    iterations: it,
                });
            }
            if it == self.max_iterations {
                // A step now would never be checked.
                return give_up(it, closest_mm);
            }
            // Error in mm with rotation weighted by 1000 mm/rad so both
            // parts count alike in the damping.
            let err = e_pos.norm() + 1000.0 * e_rot.norm();
            let best = prev_err;
            let improved = err < best;
            lambda = if improved {
                (lambda * 0.3).max(1e-12)
            } else {
                lambda * 10.0
            };
            prev_err = prev_err.min(err);
            let mut j = DMatrix::zeros(m, n);
            let mut e = DVector::zeros(m);
            let axes = rot.map(|_| {
                self.chain
                    .joint_axes(&params.values, &qe, OutputFrame::Base)
            });
            for c in 0..n {
                let col = jac.d_params[5 * c + 3];
                for r in 0..3 {
                    j[(r, c)] = col[r];
                }
                if let Some(ax) = &axes {
                    for r in 0..3 {
                        j[(3 + r, c)] = 1000.0 * ax[c].0[r];
                    }
                }
            }
            for r in 0..3 {
                e[r] = e_pos[r];
                if m == 6 {
                    e[3 + r] = 1000.0 * e_rot[r];
                }
            }
            if err > 100.0 * converged_err && stationary(&j, &e) {
                return give_up(it, closest_mm);
            }
            let step = if n >= m {
                // Minimum-norm: Jᵀ (J Jᵀ + λ I)⁻¹ e.
                let mut a = &j * j.transpose();
                let scale = a.trace() / m as f64;
                for i in 0..m {
                    a[(i, i)] += lambda * scale;
                }
                let Some(a) = a.cholesky() else {
                    return give_up(it, closest_mm);
                };
                j.transpose() * a.solve(&e)
            } else {
                let mut a = j.transpose() * &j;
                let scale = a.trace() / n as f64;
                for i in 0..n {
                    a[(i, i)] += lambda * scale;
                }
                let Some(a) = a.cholesky() else {
                    return give_up(it, closest_mm);
                };
                a.solve(&(j.transpose() * &e))
            };
            if !improved && lambda >= m.min(n) as f64 && best > converged_err {
                // Frozen (see above): the most all the steps to come can
                // change the error, twice over. `|Δq|₁ <= √n |Δq|₂`.
                let reach = match model {
                    Model::Calibrated => self.reach_calibrated(),
                    Model::Nominal => &self.reach_nominal,
                };
                // How fast the error can change per radian of a joint.
                let per_rad = reach.radius + if rot.is_some() { 1000.0 } else { 0.0 };
                let moved = 2.0 * (11.0 / 9.0) * (n as f64).sqrt() * per_rad * step.norm();
                if err - moved > best {
                    return give_up(it, closest_mm);
                }
            }
            // A trust region: near a singular configuration (a stretched
            // arm, a wrist with aligned axes) the barely damped step can
            // swing a joint by turns, and the solve then settled on joints
            // far from the taught ones (a UR10's taught home pose came out
            // at -831 deg of joint 1). Shorter steps follow the error down
            // from the seed instead. The frozen test above used the full
            // step, which bounds the shorter ones too.
            let norm = step.norm();
            let scale = if norm > max_step_rad {
                max_step_rad / norm
            } else {
                1.0
            };
            for c in 0..n {
                q[c] += scale * step[c];
            }
            if !q.iter().all(|v| v.is_finite()) {
                return give_up(it + 1, closest_mm);
            }
        }
        unreachable!("the last iteration returns")
    }
}

/// An angle limit (rad) in degrees as robot.json gave it: the round trip
/// through radians leaves 119.99999999999999 where the file said 120.
fn display_deg(rad: f64) -> f64 {
    (rad.to_degrees() * 1e9).round() / 1e9
}

/// True when every column of `j` is orthogonal to `e` to within [`GTOL`]
/// (a column of zeros counts as orthogonal).
fn stationary(j: &DMatrix<f64>, e: &DVector<f64>) -> bool {
    let e_norm = e.norm();
    j.column_iter()
        .all(|c| c.dot(e).abs() <= GTOL * c.norm() * e_norm)
}

/// Rotation vector taking `current` to `target`, in the output frame.
///
/// The angle comes from `atan2(sin, cos)` of the relative rotation, so it
/// stays exact (and finite) when the two agree to rounding: the `acos` of
/// the trace, as in `Rotation3::angle`, is NaN there once rounding puts the
/// cosine a hair above 1, which made a converging solve fail (and near a
/// half turn, below -1).
fn rotation_error(target: &Matrix3<f64>, current: &Matrix3<f64>) -> Vector3<f64> {
    let d = target * current.transpose();
    let v = 0.5
        * Vector3::new(
            d[(2, 1)] - d[(1, 2)],
            d[(0, 2)] - d[(2, 0)],
            d[(1, 0)] - d[(0, 1)],
        );
    let (s, c) = (v.norm(), 0.5 * (d.trace() - 1.0));
    let angle = s.atan2(c);
    if c < 0.0 {
        // Beyond a quarter turn the axis comes from the symmetric part,
        // `c I + (1 - c) n nᵀ`, which stays accurate up to a half turn.
        let nn = (0.5 * (d + d.transpose()) - Matrix3::identity() * c) / (1.0 - c);
        let k = (0..3)
            .max_by(|&i, &j| nn[(i, i)].total_cmp(&nn[(j, j)]))
            .unwrap_or(0);
        let mut n = nn.column(k) / nn[(k, k)].sqrt();
        if n.dot(&v) < 0.0 {
            n = -n;
        }
        return n * angle;
    }
    if s == 0.0 {
        return Vector3::zeros();
    }
    v * (angle / s)
}

/// Compensate a batch in order; one bad target never fails the others.
pub fn compensate_all(
    comp: &Compensator,
    targets: &[Target],
    orientation: bool,
) -> Vec<Compensated> {
    targets
        .iter()
        .map(|t| comp.compensate(t, orientation))
        .collect()
}

/// Compensate targets the robot visits in the given order: with an
/// accepted backlash each joint arrives from the direction it moves in from
/// the previous target's compensated joints (the first target, and a joint
/// that does not move, keep the direction before: +q at the start). A
/// target is solved with the directions carried over, and solved again
/// when its joints turn out to arrive from the other side. Without a
/// backlash, [`compensate_all`].
pub fn compensate_in_order(
    comp: &Compensator,
    targets: &[Target],
    orientation: bool,
) -> Vec<Compensated> {
    if !comp.has_backlash() {
        return compensate_all(comp, targets, orientation);
    }
    let mut direction = vec![1.0; comp.dof()];
    let mut previous: Option<Vec<f64>> = None;
    let mut out = Vec::with_capacity(targets.len());
    for t in targets {
        let arriving = |q_deg: &[f64], carried: &[f64]| -> Vec<f64> {
            match &previous {
                Some(p) => q_deg
                    .iter()
                    .zip(p)
                    .zip(carried)
                    .map(|((a, b), &d)| {
                        crate::physics::effects::step_direction(b.to_radians(), a.to_radians(), d)
                    })
                    .collect(),
                None => carried.to_vec(),
            }
        };
        let mut row = comp.with_approach(&direction).compensate(t, orientation);
        if let Some(q) = &row.q_deg {
            let d = arriving(q, &direction);
            if d != direction {
                let again = comp.with_approach(&d).compensate(t, orientation);
                // Keep the second answer when it is consistent with its own
                // approach (a move of a few micro-degrees could flip back).
                if again
                    .q_deg
                    .as_ref()
                    .is_some_and(|q2| arriving(q2, &direction) == d)
                {
                    row = again;
                }
            }
        }
        if let Some(q) = &row.q_deg {
            direction = arriving(q, &direction);
            previous = Some(q.clone());
        }
        out.push(row);
    }
    out
}

/// Write compensated.csv rows.
pub fn write_csv<W: std::io::Write>(
    out: W,
    dof: usize,
    rows: &[Compensated],
) -> std::io::Result<()> {
    let mut w = csv::Writer::from_writer(out);
    let mut header = vec!["target".to_string()];
    header.extend((1..=dof).map(|j| format!("q{j}_deg")));
    header.extend(["residual_mm", "iterations", "status", "message"].map(String::from));
    w.write_record(&header)?;
    for r in rows {
        let mut rec = vec![r.target.clone()];
        match &r.q_deg {
            Some(q) => rec.extend(q.iter().map(|v| format!("{v:.6}"))),
            None => rec.extend(std::iter::repeat_n(String::new(), dof)),
        }
        rec.push(r.residual_mm.map(|v| format!("{v:.6}")).unwrap_or_default());
        rec.push(r.iterations.to_string());
        rec.push(r.status.as_str().to_string());
        rec.push(r.message.clone().unwrap_or_default());
        w.write_record(&rec)?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robots() -> (Robot, Robot) {
        let nominal =
            Robot::from_json(include_str!("../../tests/data/er3a_paper_like/robot.json")).unwrap();
        let truth: serde_json::Value =
            serde_json::from_str(include_str!("../../tests/data/er3a_paper_like/truth.json"))
                .unwrap();
        let true_robot: Robot = serde_json::from_value(truth["true_robot"].clone()).unwrap();
        (nominal, true_robot)
    }

    #[test]
    fn joint_target_lands_within_a_micrometre() {
        let (nominal, cal) = robots();
        let comp = Compensator::new(&nominal, &cal).unwrap();
        for q_deg in [
            vec![10.0, 20.0, 30.0, 40.0, 50.0, 60.0],
            vec![-60.0, -10.0, 45.0, 90.0, -30.0, 10.0],
        ] {
            let t = Target {
                target: "a".into(),
                kind: TargetKind::Joints {
                    q_deg: q_deg.clone(),
                },
            };
            let r = comp.compensate(&t, false);
            assert_eq!(r.status, CompensationStatus::Ok, "{r:?}");
            let q: Vec<f64> = r.q_deg.unwrap().iter().map(|v| v.to_radians()).collect();
            let q_nom: Vec<f64> = q_deg.iter().map(|v| v.to_radians()).collect();
            let want = comp.nominal_pose(&q_nom).0;
            assert!((comp.calibrated_pose(&q).0 - want).norm() < 1e-3);
            // And without compensation the true robot misses by millimetres.
            assert!((comp.calibrated_pose(&q_nom).0 - want).norm() > 0.5);
            let r = comp.compensate(&t, true);
            assert_eq!(r.status, CompensationStatus::Ok, "{r:?}");
            let q: Vec<f64> = r.q_deg.unwrap().iter().map(|v| v.to_radians()).collect();
            let (p, rot) = comp.calibrated_pose(&q);
            assert!((p - want).norm() < 1e-3);
            assert!(rotation_error(&comp.nominal_pose(&q_nom).1, &rot).norm() < 1e-6);
        }
    }

    #[test]
    fn rotation_error_is_finite_and_exact_near_zero_and_a_half_turn() {
        let r = rpy_matrix(0.3, -0.2, 1.1);
        for angle in [
            0.0,
            1e-12,
            1e-9,
            1e-6,
            0.3,
            3.0,
            std::f64::consts::PI - 1e-9,
        ] {
            let axis = nalgebra::Unit::new_normalize(Vector3::new(0.2, -0.5, 0.8));
            let d = nalgebra::Rotation3::from_axis_angle(&axis, angle);
            let e = rotation_error(&(d.matrix() * r), &r);
            assert!(e.iter().all(|v| v.is_finite()), "{angle}: {e:?}");
            assert!(
                (e - axis.into_inner() * angle).norm() < 1e-9 * (1.0 + angle),
                "{angle}: {e:?}"
            );
        }
        // A computed product that agrees to rounding (the old acos gave NaN).
        let q = [0.3, -1.2, 1.4, -0.5, 1.1, 2.0];
        let (nominal, _) = robots();
        let comp = Compensator::new(&nominal, &nominal).unwrap();
        let a = comp.nominal_pose(&q).1;
        let b = rpy_matrix(0.0, 0.0, 1e-17) * a;
        assert!(rotation_error(&a, &b).norm() < 1e-15);
    }

    #[test]
    fn cartesian_targets_and_failures() {
        let (nominal, cal) = robots();
        let comp = Compensator::new(&nominal, &cal).unwrap();
        let reach = comp.nominal_pose(&[0.3, 0.2, 0.4, 0.1, 0.5, 0.0]).0;
        let t = Target {
            target: "c".into(),
            kind: TargetKind::Cartesian {
                xyz_mm: reach.into(),
                rpy_deg: None,
            },
        };
        let r = comp.compensate(&t, false);
        assert_eq!(r.status, CompensationStatus::Ok, "{r:?}");
        let q: Vec<f64> = r.q_deg.unwrap().iter().map(|v| v.to_radians()).collect();
        assert!((comp.calibrated_pose(&q).0 - reach).norm() < 1e-3);
        let far = Target {
            target: "far".into(),
            kind: TargetKind::Cartesian {
                xyz_mm: [5000.0, 0.0, 0.0],
                rpy_deg: None,
            },
        };
        assert_eq!(
            comp.compensate(&far, false).status,
            CompensationStatus::Unreachable
        );
        // A calibrated joint 2 offset by +0.5 deg: a pose taught 0.2 deg
        // inside the lower limit needs 0.3 deg past it.
        let mut shifted = nominal.clone();
        shifted.joints[1].theta_offset_deg += 0.5;
        let comp = Compensator::new(&nominal, &shifted).unwrap();
        let t = Target {
            target: "lim".into(),
            kind: TargetKind::Joints {
                q_deg: vec![10.0, -109.8, 30.0, 40.0, 50.0, 60.0],
            },
        };
        let r = comp.compensate(&t, true);
        assert_eq!(r.status, CompensationStatus::JointLimit, "{r:?}");
        assert!(r.message.unwrap().contains("joint 2"));
        assert!(r.q_deg.is_none());
    }

    #[test]
    fn joint_targets_past_the_limits_say_so() {
        let (nominal, _) = robots();
        let joints = |q1: f64, q6: f64| Target {
            target: "t".into(),
            kind: TargetKind::Joints {
                q_deg: vec![q1, -30.0, 30.0, 40.0, 50.0, q6],
            },
        };
        // Joint 6 turns +-360 deg; a calibrated joint 6 whose zero is 0.5
        // deg off needs 360.5 deg for a target taught at the limit, and the same
        // angle a turn away is within the limits: said, not taken.
        let mut cal = nominal.clone();
        cal.joints[5].q_min_deg = -360.0;
        cal.joints[5].q_max_deg = 360.0;
        let mut nom = nominal.clone();
        nom.joints[5].q_min_deg = -360.0;
        nom.joints[5].q_max_deg = 360.0;
        cal.joints[5].theta_offset_deg -= 0.5;
        let comp = Compensator::new(&nom, &cal).unwrap();
        let r = comp.compensate(&joints(10.0, 360.0), true);
        assert_eq!(r.status, CompensationStatus::JointLimit, "{r:?}");
        let msg = r.message.unwrap();
        assert!(
            msg.contains("joint 6") && msg.contains("[-360, 360] deg"),
            "{msg}"
        );
        assert!(
            msg.contains("a turn away, 0.5000 deg, is within them"),
            "{msg}"
        );
        // Limits print as robot.json gave them, not as the round trip
        // through radians leaves them.
        assert_ne!(120f64.to_radians().to_degrees(), 120.0);
        assert_eq!(display_deg(120f64.to_radians()), 120.0);
        // Absurd angles: refused at once as past the limits, whatever the
        // trigonometry makes of them.
        for q1 in [1e16, -1e16, 600.0] {
            let r = comp.compensate(&joints(q1, 0.0), false);
            assert_eq!(r.status, CompensationStatus::JointLimit, "{q1}: {r:?}");
            assert_eq!(r.iterations, 0);
            assert!(r.message.unwrap().contains("joint 1's target"));
        }
    }

    /// ER3A-like arms with every parameter random, in both conventions.
    fn random_arms(rng: &mut Rng) -> Vec<Robot> {
        let (er3a, _) = robots();
        let mut arms = vec![];
        for convention in [Convention::Dh, Convention::Mdh] {
            for _ in 0..20 {
                let mut r = er3a.clone();
                r.convention = convention;
                for j in &mut r.joints {
                    j.a_mm = rng.range(-400.0, 400.0);
                    j.d_mm = rng.range(-400.0, 400.0);
                    j.alpha_deg = rng.range(-180.0, 180.0);
                    j.theta_offset_deg = rng.range(-180.0, 180.0);
                    j.beta_deg = rng.range(-30.0, 30.0);
                }
                r.tool_point_mm = [0; 3].map(|_| rng.range(-150.0, 150.0));
                arms.push(r);
            }
        }
        arms
    }

    #[test]
    fn the_reach_ball_holds_t_for_any_joints() {
        let mut rng = Rng::new(11);
        let (er3a, er3a_true) = robots();
        let mut arms = random_arms(&mut rng);
        arms.extend([er3a, er3a_true]);
        for robot in &arms {
            let comp = Compensator::new(robot, robot).unwrap();
            let reach = *comp.reach_calibrated();
            for _ in 0..2000 {
                let q: Vec<f64> = (0..6)
                    .map(|_| rng.range(-std::f64::consts::PI, std::f64::consts::PI))
                    .collect();
                let (t, r) = comp.calibrated_pose(&q);
                assert!(reach.beyond(&t) < 0.0, "{robot:?} {q:?}");
                // With the flange orientation: the start of the last
                // segment is on the last joint's axis, and within reach of
                // the others.
                let (beyond, start) = reach.beyond_pose(&t, &r, 0.0);
                assert!(beyond < 0.0, "{robot:?} {q:?}");
                let axes = comp
                    .chain
                    .joint_axes(&comp.calibrated.values, &q, OutputFrame::Base);
                let (axis, o) = axes[5];
                assert!((start - o).cross(&axis.normalize()).norm() < 1e-9);
                // And every joint axis is within `radius` of T (the bound
                // on how fast T moves as a joint turns).
                for (axis, o) in
                    comp.chain
                        .joint_axes(&comp.calibrated.values, &q, OutputFrame::Base)
                {
                    let arm = (t - o).cross(&axis.normalize()).norm();
                    assert!(arm <= reach.radius * (1.0 + 1e-12), "{arm} {reach:?}");
                }
            }
        }
    }

    #[test]
    fn beyond_the_reach_ball_is_unreachable_at_once_and_just_inside_is_solved() {
        let (nominal, cal) = robots();
        let comp = Compensator::new(&nominal, &cal).unwrap();
        let reach = *comp.reach_calibrated();
        // The nominal ER3A stretches out to the whole radius: 275 mm upper
        // arm, the 60 x 312 mm forearm, 70 + 60 mm to T.
        assert!(
            (comp.reach_nominal.radius - 722.72).abs() < 0.01,
            "{reach:?}"
        );
        let u = Vector3::new(-0.6, 0.0, 0.8);
        let at = |r: f64| Target {
            target: "r".into(),
            kind: TargetKind::Cartesian {
                xyz_mm: (reach.centre + r * u).into(),
                rpy_deg: None,
            },
        };
        // (The true ER3A's 2 mm joint-1 offset turns only about the
        // vertical, so it cannot all point up this slanted direction.)
        // Solved: the joints put T there, though stretching the elbow out
        // takes joint 3 past its limit (so the status says that).
        let inside = comp.compensate(&at(reach.radius - 3.0), false);
        assert_eq!(inside.status, CompensationStatus::JointLimit, "{inside:?}");
        assert!(inside.message.unwrap().contains("joint 3"));
        for r in [reach.radius + 0.01, 5000.0] {
            let out = comp.compensate(&at(r), false);
            assert_eq!(out.status, CompensationStatus::Unreachable);
            assert_eq!(out.iterations, 0);
            assert!(out.message.unwrap().contains("beyond the 72"));
        }
        // The ball follows the temperature: lengths 10 % longer.
        let mut warm = comp.clone();
        warm.thermal = Some(Arc::new(Thermal {
            info: ThermalInfo {
                coef_per_k: 1e-3,
                reference_temp_c: 20.0,
            },
            lengths: crate::physics::effects::nominal_lengths(&nominal),
            reference_values: comp.calibrated.values.clone(),
        }));
        let warm = warm.at_temperature(120.0);
        let grown = *warm.reach_calibrated();
        let want = Reach::of(&warm.chain, &warm.calibrated.values);
        assert_eq!((grown.centre, grown.radius), (want.centre, want.radius));
        assert!(
            (grown.radius / reach.radius - 1.1).abs() < 0.01,
            "{grown:?}"
        );
        assert_eq!(
            warm.compensate(&at(reach.radius + 1.0), false).status,
            CompensationStatus::Ok
        );
    }

    #[test]
    fn a_solve_that_cannot_converge_gives_up_early() {
        let (nominal, cal) = robots();
        let comp = Compensator::new(&nominal, &cal).unwrap();
        let home = comp.home();
        let far = Vector3::new(5000.0, 0.0, 0.0);
        let back = rpy_matrix(0.3, 2.5, 0.2);
        for (model, rot) in [
            (Model::Calibrated, None),
            (Model::Nominal, None),
            (Model::Calibrated, Some(&back)),
        ] {
            let Err(failed) = comp.solve_on(model, &far, rot, &home, f64::INFINITY) else {
                panic!("converged on a target 5 m away");
            };
            assert!(failed.iterations < 20, "{}", failed.iterations);
        }
        // The last step is never taken: the budget, not one more.
        let mut c = comp.clone();
        c.max_iterations = 3;
        let Err(failed) = c.solve_on(Model::Calibrated, &far, None, &home, f64::INFINITY) else {
            panic!()
        };
        assert!(failed.iterations <= 3);
        // A target within reach converges from home as before.
        let q = [0.3, 0.2, 0.4, 0.1, 0.5, 0.0];
        let (t, r) = comp.nominal_pose(&q);
        let sol = comp.solve(&t, Some(&r), &q, f64::INFINITY).ok().unwrap();
        assert!(sol.residual_mm < 1e-3);
    }
}
