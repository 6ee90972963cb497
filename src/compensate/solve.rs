//! The solver: damped least squares on the calibrated (or, for seeding,
//! the nominal) model, from given joints to joints that put T on the
//! target, or an early "cannot converge from here".

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Vector3};

use crate::kinematics::chain::{OutputFrame, PointJacobian, Trig};

use super::Compensator;

/// A damped least squares solve stops at a stationary point of its error
/// (MINPACK's `gtol`): when every column of the Jacobian is this close to
/// orthogonal to the error (`|J_j·e| <= GTOL |J_j| |e|`), with the error
/// far above the tolerance. Over the targets of `tests/engine/compensate_ik.rs`
/// the converging solves never came below 7e-4.
const GTOL: f64 = 1e-6;

/// Which model a solve runs on.
#[derive(Clone, Copy)]
pub(super) enum Model {
    /// The nominal model, without joint effects (seeding).
    Nominal,
    /// The calibrated model with its joint effects.
    Calibrated,
}

pub(super) struct Solution {
    pub(super) q: Vec<f64>,
    pub(super) residual_mm: f64,
    pub(super) iterations: usize,
}

/// A solve that did not converge: the iterations it ran before it gave up.
pub(super) struct NotConverged {
    pub(super) iterations: usize,
    /// Least distance (mm) from T to the target over the solve's iterates
    /// (for a target with an orientation: at the iterate nearest in
    /// position and orientation together).
    pub(super) closest_mm: Option<f64>,
    /// The flange's rotation (deg) from the target orientation there, for
    /// a target with one.
    pub(super) closest_deg: Option<f64>,
}

/// The nearest-solution solve's first weight on the joint change, relative
/// to the mean curvature of the task (`tr(JᵀJ)/n` at the taught joints),
/// its last, and the factor between stages.
const NEAREST_MU: (f64, f64, f64) = (1e-1, 1e-12, 0.1);
/// Gauss-Newton iterations per stage of the nearest-solution solve.
const NEAREST_ITERATIONS: usize = 8;

impl Compensator {
    /// The calibrated model's joints nearest `q0` (in the joint-space
    /// norm) that put T on `pos` (and the flange at `rot`, when given): a
    /// joint target's compensation, which must stay with the taught pose.
    ///
    /// Tikhonov continuation: each stage minimises
    /// `|e(q)|² + μ |q - q0|²` by Gauss-Newton from the last stage's
    /// joints, μ falling tenfold per stage to nothing. Where the arm is
    /// redundant for the task each step is the minimum-norm one towards
    /// `q0`; at a singular pose the weight keeps the steps short, so the
    /// solve follows the branch of solutions through the taught joints
    /// instead of wandering off to another (a UR10 stretched upright had
    /// joint 3 bent 5.2 deg by plain damped least squares where the
    /// nearest solution bends no joint more than 3.7 deg).
    pub(super) fn solve_nearest(
        &self,
        pos: &Vector3<f64>,
        rot: Option<&Matrix3<f64>>,
        q0: &[f64],
    ) -> std::result::Result<Solution, NotConverged> {
        let n = self.dof();
        let oriented = rot.is_some();
        let mut q = q0.to_vec();
        let mut buf = Buffers::new(self, oriented);
        let mut best = (f64::INFINITY, f64::INFINITY, None);
        let mut iterations = 0;
        let mut mu_scale = None;
        let (mu_first, mu_last, factor) = NEAREST_MU;
        // The first evaluation, at the taught joints, also tells a singular
        // pose (the same Jacobian `singular_for_task` would compute anew).
        let mut first = Some(self.evaluate_calibrated(&q, pos, rot, &mut buf));
        // Away from a singular pose the last stage alone is the answer:
        // with a vanishing weight each step solves the task where the
        // Jacobian reaches and moves back towards `q0` in its null space
        // (minimum-norm Gauss-Newton), which converges in a few steps. The
        // continuation's early stages are for singular poses, where that
        // step could leap to another branch (and cost five times as much).
        let mut mu_rel = if singular_task_jacobian(&buf.j) {
            mu_first
        } else {
            mu_last
        };
        let mut within = None;
        loop {
            for _ in 0..NEAREST_ITERATIONS {
                let (e_pos, e_rot) = match first.take() {
                    Some(errors) => errors,
                    None => self.evaluate_calibrated(&q, pos, rot, &mut buf),
                };
                let err = e_pos.norm() + 1000.0 * e_rot.norm();
                if err < best.0 {
                    best = (
                        err,
                        e_pos.norm(),
                        oriented.then(|| e_rot.norm().to_degrees()),
                    );
                }
                // Within the tolerance while the weight still pulls
                // towards the taught joints, the answer is that much biased:
                // the solve goes on to a thousandth of it, and answers the
                // last iterate within the tolerance if it gets no nearer.
                if e_pos.norm() <= self.tolerance_mm && e_rot.norm() <= self.tolerance_rad {
                    let solution = Solution {
                        residual_mm: e_pos.norm(),
                        q: q.clone(),
                        iterations,
                    };
                    // At the last stage the weight biases nothing.
                    if mu_rel <= mu_last
                        || (e_pos.norm() <= 1e-3 * self.tolerance_mm
                            && e_rot.norm() <= 1e-3 * self.tolerance_rad)
                    {
                        return Ok(solution);
                    }
                    within = Some(solution);
                }
                // The same products as `jᵀ j` and `jᵀ e` (the same nalgebra
                // kernels, so the same digits), into the buffers.
                buf.j.transpose_to(&mut buf.jt);
                buf.a.gemm(1.0, &buf.jt, &buf.j, 0.0);
                let scale = *mu_scale.get_or_insert(buf.a.trace() / n as f64);
                let mu = mu_rel * scale;
                for i in 0..n {
                    buf.a[(i, i)] += mu;
                }
                buf.rhs.gemv(1.0, &buf.jt, &buf.e, 0.0);
                for i in 0..n {
                    buf.rhs[i] += (q0[i] - q[i]) * mu;
                }
                // The factor takes the matrix and gives it back, so that no
                // iteration allocates.
                let a = std::mem::replace(&mut buf.a, DMatrix::zeros(0, 0));
                let Some(chol) = a.cholesky() else {
                    buf.a = DMatrix::zeros(n, n);
                    break;
                };
                chol.solve_mut(&mut buf.rhs);
                buf.a = chol.unpack_dirty();
                let step = &buf.rhs;
                iterations += 1;
                if !take_step(&mut q, step, MAX_STEP_RAD) {
                    break;
                }
                if step.norm() < 1e-13 {
                    break;
                }
            }
            if mu_rel <= mu_last || iterations >= self.max_iterations * 4 {
                if let Some(solution) = within {
                    return Ok(solution);
                }
                return Err(NotConverged {
                    iterations,
                    closest_mm: best.1.is_finite().then_some(best.1),
                    closest_deg: best.2,
                });
            }
            mu_rel *= factor;
        }
    }
}

/// The buffers of one nearest-solution solve, allocated once: its loop
/// allocated a dozen matrices and vectors per iteration, and computed the
/// parameters' sines again each time.
struct Buffers {
    /// The calibrated parameters' fixed trigonometry.
    trig: Trig,
    /// The joints the model sees, and their sines and cosines.
    qe: Vec<f64>,
    qsc: Vec<(f64, f64)>,
    jac: PointJacobian,
    /// The task's Jacobian (m × n), its transpose and error (m).
    j: DMatrix<f64>,
    jt: DMatrix<f64>,
    e: DVector<f64>,
    /// The normal matrix (n × n) and the right-hand side, then the step.
    a: DMatrix<f64>,
    rhs: DVector<f64>,
}

impl Buffers {
    fn new(comp: &Compensator, oriented: bool) -> Self {
        let n = comp.dof();
        let m = if oriented { 6 } else { 3 };
        Buffers {
            trig: comp.chain.trig(&comp.calibrated.values),
            qe: vec![0.0; n],
            qsc: vec![(0.0, 1.0); n],
            jac: comp.chain.new_jacobian(),
            j: DMatrix::zeros(m, n),
            jt: DMatrix::zeros(n, m),
            e: DVector::zeros(m),
            a: DMatrix::zeros(n, n),
            rhs: DVector::zeros(n),
        }
    }
}

impl Compensator {
    /// [`Compensator::evaluate`] on the calibrated model into `buf`, with
    /// the task's Jacobian and error filled in: T's position error and the
    /// flange's rotation error.
    fn evaluate_calibrated(
        &self,
        q: &[f64],
        pos: &Vector3<f64>,
        rot: Option<&Matrix3<f64>>,
        buf: &mut Buffers,
    ) -> (Vector3<f64>, Vector3<f64>) {
        self.effective_into(q, &mut buf.qe);
        for (sc, v) in buf.qsc.iter_mut().zip(&buf.qe) {
            *sc = v.sin_cos();
        }
        self.chain.point_jacobian_trig(
            &self.calibrated.values,
            &buf.trig,
            &buf.qsc,
            OutputFrame::Base,
            &mut buf.jac,
        );
        let e_pos = pos - buf.jac.point;
        let e_rot = rot
            .map(|r| rotation_error(r, &buf.jac.flange.r))
            .unwrap_or_else(Vector3::zeros);
        fill_task_system(
            &buf.jac,
            rot.is_some(),
            &e_pos,
            &e_rot,
            &mut buf.j,
            &mut buf.e,
        );
        (e_pos, e_rot)
    }
}

impl Compensator {
    /// A joint target's solve from its taught joints `q0`: the nearest
    /// solution ([`Compensator::solve_nearest`]); where the branch through
    /// the taught joints has none (a target beyond a stretched arm), damped
    /// least squares in bounded steps, which may find one farther off for
    /// the bound to refuse by name rather than as unreachable. Iterations
    /// add up; a failure keeps the nearer of the two misses.
    pub(super) fn solve_taught(
        &self,
        pos: &Vector3<f64>,
        rot: Option<&Matrix3<f64>>,
        q0: &[f64],
    ) -> std::result::Result<Solution, NotConverged> {
        let near = match self.solve_nearest(pos, rot, q0) {
            Ok(sol) => return Ok(sol),
            Err(near) => near,
        };
        match self.solve(pos, rot, q0, MAX_STEP_RAD) {
            Ok(mut far) => {
                far.iterations += near.iterations;
                Ok(far)
            }
            Err(far) => {
                let nearer = match (near.closest_mm, far.closest_mm) {
                    (Some(a), Some(b)) if b < a => &far,
                    (None, Some(_)) => &far,
                    _ => &near,
                };
                Err(NotConverged {
                    iterations: near.iterations + far.iterations,
                    closest_mm: nearer.closest_mm,
                    closest_deg: nearer.closest_deg,
                })
            }
        }
    }
}

/// Longest joint step (rad, Euclidean over the joints) of one iteration of
/// a solve from taught joints (the nearest-solution solve, and damped least
/// squares when it falls back).
pub(super) const MAX_STEP_RAD: f64 = 0.2;

/// One evaluation of a solve: T's position error (mm) and the flange's
/// rotation error (rad; zero without an orientation), with the Jacobian
/// filled in at the joints the model sees.
struct Evaluated {
    e_pos: Vector3<f64>,
    e_rot: Vector3<f64>,
}

impl Compensator {
    /// Evaluate `model` at the commanded joints `q` against the target
    /// (`pos`, `rot`), filling `jac`.
    fn evaluate(
        &self,
        model: Model,
        q: &[f64],
        pos: &Vector3<f64>,
        rot: Option<&Matrix3<f64>>,
        jac: &mut PointJacobian,
    ) -> Evaluated {
        let (params, qe) = match model {
            Model::Calibrated => (&self.calibrated, self.effective(q)),
            Model::Nominal => (&self.nominal, q.to_vec()),
        };
        self.chain
            .point_jacobian(&params.values, &qe, OutputFrame::Base, jac);
        Evaluated {
            e_pos: pos - jac.point,
            e_rot: rot
                .map(|r| rotation_error(r, &jac.flange.r))
                .unwrap_or_else(Vector3::zeros),
        }
    }
}

impl Compensator {
    /// Damped least squares on the calibrated model from `q0`, each step at
    /// most `max_step_rad` long.
    pub(super) fn solve(
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
    ///   [`super::reach::Reach`]'s radius in mm per radian of a joint (and
    ///   the flange one radian, weighted 1000 mm), so the error can never
    ///   come back below the best, which is above the tolerance: the
    ///   damping never falls again and the solve cannot converge. The test
    ///   uses twice that allowance ([`Compensator::frozen`]).
    ///
    /// Neither test stopped a solve that would have converged: over 6,210
    /// targets on the arms of `tests/engine/compensate_ik.rs` (BENCHMARKS.md),
    /// every answer is the same as without them, joint for joint.
    pub(super) fn solve_on(
        &self,
        model: Model,
        pos: &Vector3<f64>,
        rot: Option<&Matrix3<f64>>,
        q0: &[f64],
        max_step_rad: f64,
    ) -> std::result::Result<Solution, NotConverged> {
        let n = self.dof();
        let mut closest_mm = f64::INFINITY;
        let give_up = |iterations, closest_mm: f64| {
            Err(NotConverged {
                iterations,
                closest_mm: (rot.is_none() && closest_mm.is_finite()).then_some(closest_mm),
                closest_deg: None,
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
            let Evaluated { e_pos, e_rot } = self.evaluate(model, &q, pos, rot, &mut jac);
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
            let oriented = rot.is_some();
            let (j, e) = self.task_system(&jac, oriented, &e_pos, &e_rot);
            if err > 100.0 * converged_err && stationary(&j, &e) {
                return give_up(it, closest_mm);
            }
            let Some(step) = damped_step(&j, &e, lambda) else {
                return give_up(it, closest_mm);
            };
            if !improved
                && lambda >= m.min(n) as f64
                && best > converged_err
                && self.frozen(model, oriented, err, best, &step)
            {
                return give_up(it, closest_mm);
            }
            if !take_step(&mut q, &step, max_step_rad) {
                return give_up(it + 1, closest_mm);
            }
        }
        unreachable!("the last iteration returns")
    }

    /// The task's Jacobian with respect to the joints and its error:
    /// T's position (mm) and, when `oriented`, the flange's rotation
    /// weighted by 1000 mm/rad (the weight of the error in `solve_on`).
    pub(super) fn task_system(
        &self,
        jac: &PointJacobian,
        oriented: bool,
        e_pos: &Vector3<f64>,
        e_rot: &Vector3<f64>,
    ) -> (DMatrix<f64>, DVector<f64>) {
        let m = if oriented { 6 } else { 3 };
        let mut j = DMatrix::zeros(m, self.dof());
        let mut e = DVector::zeros(m);
        fill_task_system(jac, oriented, e_pos, e_rot, &mut j, &mut e);
        (j, e)
    }

    /// The frozen test of [`Compensator::solve_on`]: the most all the steps
    /// to come can change the error, twice over, still leaves it above
    /// `best`. `|Δq|₁ <= √n |Δq|₂`.
    fn frozen(
        &self,
        model: Model,
        oriented: bool,
        err: f64,
        best: f64,
        step: &DVector<f64>,
    ) -> bool {
        let n = self.dof();
        let reach = match model {
            Model::Calibrated => self.reach_calibrated(),
            Model::Nominal => &self.reach_nominal,
        };
        // How fast the error can change per radian of a joint.
        let per_rad = reach.radius + if oriented { 1000.0 } else { 0.0 };
        let moved = 2.0 * (11.0 / 9.0) * (n as f64).sqrt() * per_rad * step.norm();
        err - moved > best
    }
}

/// [`Compensator::task_system`] into `j` (m × n) and `e` (m), m = 6 when
/// `oriented`, else 3.
///
/// A joint's column of the flange's rotation is its axis (the rotation
/// vector per radian of its θ, which `jac` has): the same numbers as
/// `Chain::joint_axes`, without walking the chain again.
fn fill_task_system(
    jac: &PointJacobian,
    oriented: bool,
    e_pos: &Vector3<f64>,
    e_rot: &Vector3<f64>,
    j: &mut DMatrix<f64>,
    e: &mut DVector<f64>,
) {
    for c in 0..j.ncols() {
        let col = jac.d_params[5 * c + 3];
        for r in 0..3 {
            j[(r, c)] = col[r];
        }
        if oriented {
            let axis = jac.d_orientation[5 * c + 3];
            for r in 0..3 {
                j[(3 + r, c)] = 1000.0 * axis[r];
            }
        }
    }
    for r in 0..3 {
        e[r] = e_pos[r];
        if oriented {
            e[3 + r] = 1000.0 * e_rot[r];
        }
    }
}

/// True when the task's Jacobian `j` is nearly rank deficient for the
/// task: the arm has at least as many joints as the task has rows, and the
/// smallest singular value is under 2 % of the largest.
///
/// The singular values are the square roots of the eigenvalues of `j jᵀ`
/// (3 × 3, or 6 × 6 with the orientation), which a fixed-size symmetric
/// eigensolver gives without allocating: the SVD of `j` took 15,000 of
/// the 48,000 instructions of a joint target's whole compensation
/// (callgrind). Squaring costs digits only where `j` is far more singular
/// than the 2 % this tells apart: the test moves by about 1e-13 of the
/// ratio, against 5e-15 with the SVD.
pub(super) fn singular_task_jacobian(j: &DMatrix<f64>) -> bool {
    let (m, n) = j.shape();
    if n < m {
        return false;
    }
    // A non-finite Jacobian counts as singular, and is kept from the
    // eigenvalue iterations, which have no iteration limit.
    if j.iter().any(|v| !v.is_finite()) {
        return true;
    }
    let jjt = |r: usize, c: usize| (0..n).map(|k| j[(r, k)] * j[(c, k)]).sum::<f64>();
    let (min, max) = match m {
        3 => extremes(Matrix3::from_fn(jjt).symmetric_eigenvalues().as_slice()),
        6 => extremes(Matrix6::from_fn(jjt).symmetric_eigenvalues().as_slice()),
        _ => extremes(j.clone().singular_values().map(|s| s * s).as_slice()),
    };
    !(min > 0.02 * 0.02 * max)
}

/// The least and the greatest of `values`; NaN for both when one is NaN
/// (the pose then counts as singular).
fn extremes(values: &[f64]) -> (f64, f64) {
    if values.iter().any(|v| v.is_nan()) {
        return (f64::NAN, f64::NAN);
    }
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (min, max)
}

/// The damped least squares step for `j Δq = e` with damping `lambda`
/// (scaled by the mean curvature): minimum-norm when the arm has at least
/// as many joints as the task has rows. `None` when the damped system is
/// not positive definite.
fn damped_step(j: &DMatrix<f64>, e: &DVector<f64>, lambda: f64) -> Option<DVector<f64>> {
    let (m, n) = j.shape();
    if n >= m {
        // Minimum-norm: Jᵀ (J Jᵀ + λ I)⁻¹ e.
        let mut a = j * j.transpose();
        let scale = a.trace() / m as f64;
        for i in 0..m {
            a[(i, i)] += lambda * scale;
        }
        let a = a.cholesky()?;
        Some(j.transpose() * a.solve(e))
    } else {
        let mut a = j.transpose() * j;
        let scale = a.trace() / n as f64;
        for i in 0..n {
            a[(i, i)] += lambda * scale;
        }
        let a = a.cholesky()?;
        Some(a.solve(&(j.transpose() * e)))
    }
}

/// Move `q` by `step`, shortened to `max_step_rad`; false when the joints
/// are no longer finite.
///
/// A trust region: near a singular configuration (a stretched arm, a wrist
/// with aligned axes) the barely damped step can swing a joint by turns,
/// and the solve then settled on joints far from the taught ones (a UR10's
/// taught home pose came out at -831 deg of joint 1). Shorter steps follow
/// the error down from the seed instead. The frozen test used the full
/// step, which bounds the shorter ones too.
fn take_step(q: &mut [f64], step: &DVector<f64>, max_step_rad: f64) -> bool {
    let norm = step.norm();
    let scale = if norm > max_step_rad {
        max_step_rad / norm
    } else {
        1.0
    };
    for c in 0..q.len() {
        q[c] += scale * step[c];
    }
    q.iter().all(|v| v.is_finite())
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
pub(super) fn rotation_error(target: &Matrix3<f64>, current: &Matrix3<f64>) -> Vector3<f64> {
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
