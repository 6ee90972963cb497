//! One target: the precondition, the quick refusals (past the limits, out
//! of reach), the starting joints (taught, closed-form or numerical
//! seeds), a solve from each in turn, and the row that says how it went.

use nalgebra::{Matrix3, Vector3};

use crate::kinematics::ik;
use crate::kinematics::rpy_matrix;
use crate::model::{Target, TargetKind};
use crate::rng::Rng;

use super::solve::Model;
use super::{Compensated, CompensationStatus, Compensator};

/// Where a target's solves start: T's wanted position, the flange's wanted
/// orientation (when held) and the first starting joints to try.
struct Start {
    pos: Vector3<f64>,
    rot: Option<Matrix3<f64>>,
    seeds: Vec<Vec<f64>>,
    /// A warning on the target from the workspace field (outside the
    /// region it was fitted on).
    field_warning: Option<String>,
}

/// Two optional warnings as one message.
fn join_warnings(a: Option<String>, b: Option<String>) -> Option<String> {
    match (a, b) {
        (Some(a), Some(b)) => Some(format!("{a}; {b}")),
        (a, b) => a.or(b),
    }
}

/// A row without joints.
fn failed(
    target: &Target,
    status: CompensationStatus,
    iterations: usize,
    message: String,
) -> Compensated {
    Compensated {
        target: target.target.clone(),
        q_deg: None,
        residual_mm: None,
        iterations,
        status,
        message: Some(message),
    }
}

impl Compensator {
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
        if let Some(problem) = self.malformed(target, reference_rad) {
            debug_assert!(
                false,
                "Compensator::compensate_near called against its precondition: {problem}"
            );
            return failed(
                target,
                CompensationStatus::Unreachable,
                0,
                format!(
                    "malformed input: {problem} (a caller's error: the target was not tried, \
                     nothing is known about its reach)"
                ),
            );
        }
        match self.start(target, orientation, reference_rad) {
            Ok(start) => self.solve_from(target, self.aimed(start)),
            Err(refused) => refused,
        }
    }

    /// Where to aim the calibrated model so that T lands on `pos` when a
    /// tilting base, a bending link or a compliant tool moves it by its
    /// shift at joints `q` (`pos` itself without any of them).
    fn load_aim(&self, pos: &Vector3<f64>, q: &[f64]) -> Vector3<f64> {
        match self
            .joint_effects
            .as_ref()
            .and_then(|e| e.point_shift_mm(q))
        {
            Some(shift) => pos - shift,
            None => *pos,
        }
    }

    /// `start` aimed against the workspace field, when the calibration
    /// has one.
    fn aimed(&self, mut start: Start) -> Start {
        if let Some(field) = &self.workspace_field {
            let (pos, warning) = field.aim(&start.pos);
            start.pos = pos;
            start.field_warning = warning;
        }
        start
    }

    /// Why the calibrated model gave no joints for a target.
    fn unreachable_message(&self) -> String {
        format!(
            "the calibrated model cannot put T on the target (no solution within {} mm)",
            self.tolerance_mm
        )
    }

    /// Where the solves of a target start, or the row of a target refused
    /// at once: a joint target more than a turn past a limit, a Cartesian
    /// one out of reach.
    fn start(
        &self,
        target: &Target,
        orientation: bool,
        reference_rad: Option<&[f64]>,
    ) -> Result<Start, Compensated> {
        match &target.kind {
            TargetKind::Joints { q_deg } => {
                // A correction is a fraction of a degree: a target more than
                // a turn past a limit stays past it, and at such angles
                // (1e15 deg) the trigonometry itself has lost its digits.
                if let Some(msg) = self.far_past_limits(q_deg) {
                    return Err(failed(target, CompensationStatus::JointLimit, 0, msg));
                }
                let q: Vec<f64> = q_deg.iter().map(|v| v.to_radians()).collect();
                let (t, r) = self.nominal_pose(&q);
                Ok(Start {
                    pos: t,
                    rot: orientation.then_some(r),
                    seeds: vec![q],
                    field_warning: None,
                })
            }
            TargetKind::Cartesian { xyz_mm, rpy_deg } => {
                let r = rpy_deg
                    .map(|a| rpy_matrix(a[0].to_radians(), a[1].to_radians(), a[2].to_radians()));
                let t = Vector3::from(*xyz_mm);
                if let Some(msg) = self.out_of_reach(&t, r.as_ref()) {
                    return Err(failed(target, CompensationStatus::Unreachable, 0, msg));
                }
                let home = self.home();
                let reference = reference_rad.unwrap_or(&home);
                let seeds = self.closed_form_seeds(&t, r.as_ref(), reference);
                Ok(Start {
                    pos: t,
                    rot: r,
                    seeds,
                    field_warning: None,
                })
            }
        }
    }

    /// Why T at `t` (with the flange at `r`, when given) is out of reach
    /// for any joints, if it is: then no seed can help.
    fn out_of_reach(&self, t: &Vector3<f64>, r: Option<&Matrix3<f64>>) -> Option<String> {
        let reach = self.reach_calibrated();
        if reach.beyond(t) > self.tolerance_mm {
            return Some(format!(
                "{}: it is {:.1} mm from the arm's root point (on joint 1's axis), \
                 beyond the {:.1} mm the arm reaches from there with any joints",
                self.unreachable_message(),
                (t - reach.centre).norm(),
                reach.radius
            ));
        }
        let (beyond, start) = reach.beyond_pose(t, r?, self.tolerance_rad);
        (beyond > self.tolerance_mm).then(|| {
            format!(
                "{}: with the flange at that orientation, joint {n}'s axis would \
                 have to pass through a point {:.1} mm from the arm's root point \
                 (on joint 1's axis), beyond the {:.1} mm the joints before it \
                 reach",
                self.unreachable_message(),
                (start - reach.centre).norm(),
                reach.radius - reach.last.norm(),
                n = self.dof(),
            )
        })
    }

    /// Solve from each starting joints in turn until one gives joints
    /// within the limits: the closed-form (or taught) seeds first, the
    /// numerical ones only when those fail, computed lazily.
    fn solve_from(&self, target: &Target, start: Start) -> Compensated {
        let Start {
            pos,
            rot,
            seeds,
            field_warning,
        } = start;
        let cartesian = matches!(target.kind, TargetKind::Cartesian { .. });
        // A joint target's one seed is its taught joints, which the answer
        // must stay with.
        let taught = (!cartesian).then(|| seeds[0].clone());
        let mut last_iterations = 0;
        let mut limit_msg = None;
        let mut closest_mm = f64::INFINITY;
        let mut closest_deg = None;
        let mut tried: Vec<Vec<f64>> = Vec::new();
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
            // Taught joints are where the answer should stay.
            let run = |aim: &Vector3<f64>| {
                if cartesian {
                    self.solve(aim, rot.as_ref(), &seed, f64::INFINITY)
                } else {
                    self.solve_taught(aim, rot.as_ref(), &seed)
                }
            };
            // A tilting base (a bending link, a compliant tool) moves T by
            // an amount that depends on the joints: aimed from the seed's, then once more from the
            // solution's when they differ (a far numerical seed).
            let aim = self.load_aim(&pos, &seed);
            let mut solved = run(&aim);
            if let Ok(sol) = &solved {
                let again = self.load_aim(&pos, &sol.q);
                if (again - aim).norm() > 0.1 * self.tolerance_mm {
                    solved = run(&again);
                }
            }
            tried.push(seed);
            match solved {
                Ok(sol) => {
                    last_iterations += sol.iterations;
                    // A swing is refused as such, even when it also ends
                    // past a limit (the limit's "a turn away" hint would
                    // not be the point).
                    if let Some(msg) = taught
                        .as_ref()
                        .and_then(|t| self.change_beyond_bound(t, &sol.q, rot.is_some()))
                    {
                        return failed(
                            target,
                            CompensationStatus::JointChange,
                            last_iterations,
                            msg,
                        );
                    }
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
                        message: join_warnings(
                            self.joint_effects
                                .as_ref()
                                .and_then(|e| e.outside_fitted_range(&sol.q)),
                            field_warning,
                        ),
                    };
                }
                Err(failed) => {
                    last_iterations += failed.iterations;
                    if let Some(c) = failed.closest_mm.filter(|c| *c < closest_mm) {
                        closest_mm = c;
                        closest_deg = failed.closest_deg;
                    }
                }
            }
        }
        match limit_msg {
            Some(msg) => failed(target, CompensationStatus::JointLimit, last_iterations, msg),
            // How near it came tells a target just out of reach (or an arm
            // with too few joints to place T anywhere, like a two-axis
            // positioner) from a wrong target.
            None if closest_mm.is_finite() => failed(
                target,
                CompensationStatus::Unreachable,
                last_iterations,
                format!(
                    "{}; the nearest the calibrated model came is {closest_mm:.4} mm{}",
                    self.unreachable_message(),
                    closest_deg
                        .map(|d| format!(", with the flange {d:.4} deg from the orientation asked"))
                        .unwrap_or_default()
                ),
            ),
            None => failed(
                target,
                CompensationStatus::Unreachable,
                last_iterations,
                self.unreachable_message(),
            ),
        }
    }

    /// Why the compensated joints `q` of a joint target taught at `taught`
    /// are refused: a joint moves further than
    /// [`Compensator::max_joint_change_deg`]; which joint, how far, and
    /// whether the taught pose is singular (where the nearest solution can
    /// lie far from the taught joints).
    fn change_beyond_bound(&self, taught: &[f64], q: &[f64], oriented: bool) -> Option<String> {
        let (j, change_deg) = q
            .iter()
            .zip(taught)
            .map(|(a, b)| (a - b).to_degrees())
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))?;
        if change_deg.abs() <= self.max_joint_change_deg {
            return None;
        }
        let why = if self.singular_for_task(taught, oriented) {
            "the taught pose is singular for the task (the arm stretched or folded, or axes aligned): there the calibrated model's nearest solution lies far from the taught joints; teach the pose away from the singularity"
        } else {
            "the calibrated model differs from the nominal one more than a calibration should here; check the calibration"
        };
        let correction_mm = (self.nominal_pose(taught).0 - self.calibrated_pose(taught).0).norm();
        // A tool point far from robot.json's is most of the correction at
        // every target, and is the tool's, not the arm's.
        let tool = if self.tool_difference_mm > 1.0 {
            format!(
                "; the correction asked is {correction_mm:.2} mm, and the calibrated tool point is \
                 {:.2} mm from robot.json's: if robot.json's was only a guess, put the calibrated \
                 one (calibrated_robot.tool_point_mm) in robot.json and in the controller's TCP",
                self.tool_difference_mm
            )
        } else {
            format!("; the correction asked is {correction_mm:.2} mm")
        };
        Some(format!(
            "joint {} would move {change_deg:+.2} deg from the taught {:.2} deg (more than the {} deg bound on a compensation's change): {why}{tool}; not compensated",
            j + 1,
            taught[j].to_degrees(),
            self.max_joint_change_deg
        ))
    }

    /// True when the task's Jacobian at `q` (calibrated model: T's
    /// position, and the flange's rotation when `oriented`) is nearly rank
    /// deficient: its smallest singular value under 2 % of its largest.
    pub(super) fn singular_for_task(&self, q: &[f64], oriented: bool) -> bool {
        let qe = self.effective(q);
        let mut jac = self.chain.new_jacobian();
        self.chain.point_jacobian(
            &self.calibrated.values,
            &qe,
            crate::kinematics::chain::OutputFrame::Base,
            &mut jac,
        );
        let zero = nalgebra::Vector3::zeros();
        let (j, _) = self.task_system(&jac, oriented, &zero, &zero);
        super::solve::singular_task_jacobian(&j)
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
    /// [`ik::ClosedFormIk::solve_position`]), ordered by [`ik::order_near`]:
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
}

/// An angle limit (rad) in degrees as robot.json gave it: the round trip
/// through radians leaves 119.99999999999999 where the file said 120.
pub(super) fn display_deg(rad: f64) -> f64 {
    (rad.to_degrees() * 1e9).round() / 1e9
}
