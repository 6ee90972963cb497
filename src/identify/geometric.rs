//! The geometric calibration: the base pose and the tool point fitted on
//! the nominal joints ("before"), then every identifiable parameter
//! ("after"), optionally with a robust loss, the undetermined ones held at
//! nominal.

use nalgebra::{DMatrix, Matrix3, Vector3};

use super::lm::{self, LmResult, LmSettings};
use super::problem::CalibrationProblem;
use super::{IdentifyOptions, Method, Observations, Progress, freeset, identifiability, rig};
use crate::error::{Error, Result};
use crate::kinematics::chain::OutputFrame;
use crate::kinematics::{JointParam, Layout, Params};
use crate::model::{BasePose, Split};
use crate::report::{FixedParam, FixedReason, FreeSetChoice};
use crate::stats;

/// Rigid transform (R, t) minimising `Σ |R a + t - b|²` (Kabsch).
pub fn rigid_fit(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    if a.len() < 3 {
        return None;
    }
    let ca = a.iter().sum::<Vector3<f64>>() / a.len() as f64;
    let cb = b.iter().sum::<Vector3<f64>>() / b.len() as f64;
    let mut h = Matrix3::zeros();
    for (x, y) in a.iter().zip(b) {
        h += (x - ca) * (y - cb).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = vt.transpose() * d * u.transpose();
    Some((r, cb - r * ca))
}

pub(super) fn run_lm(
    problem: &CalibrationProblem,
    progress: &dyn Progress,
    stage: &str,
) -> Result<LmResult> {
    let settings = LmSettings::default();
    lm::minimize(problem, &problem.x0(), &settings, |it, _| {
        progress.update(stage, (it as f64 / 30.0).min(0.95));
        !progress.cancelled()
    })
}

/// The geometric calibration: base and tool first, then every identifiable
/// parameter. Returns the "before" and "after" parameter vectors and the
/// solver state.
pub struct Geometric {
    /// Nominal joints, fitted base and tool.
    pub before: Params,
    /// Calibrated.
    pub after: Params,
    /// Identifiability analysis.
    pub selection: identifiability::Selection,
    /// Solver result of the final fit (normal matrix at the solution).
    pub result: LmResult,
    /// Pose weights of the robust loss (train poses), 1 without it.
    pub weights: Vec<f64>,
    /// Residual scale of the final fit: `sqrt(2 cost / (N - k))` (mm).
    pub sigma: f64,
    /// How well the data determine the flange orientation (rad, 1 sigma,
    /// see [`Observations::flange_orientation_sigma`]), from the fit before the
    /// undetermined parameters were held.
    pub flange_orientation_sigma_rad: Option<f64>,
    /// The rig's anchors, when they were identified with the robot
    /// (`rig_anchors`): the rest of this fit is then the robot's part (see
    /// [`rig::reduce`]), and holds for T located with these anchors.
    pub rig: Option<rig::RigFit>,
    /// Which identifiable parameters were freed, and why (see
    /// [`freeset`]).
    pub free_set: FreeSetChoice,
}

/// The parameters `opts.hold` names (for a robot and rig of layout `l`), as
/// held at nominal by request: joint parameters, and string offsets when
/// those are identified. The base pose and the tool point are fitted in
/// every calibration (their nominal is a guess), and the paper's one-step
/// method identifies every parameter at once; either with `hold` is an
/// input error, as is an unknown name.
pub fn held(l: Layout, opts: &IdentifyOptions) -> Result<Vec<FixedParam>> {
    if !opts.hold.is_empty() && opts.method == Method::Paper {
        return Err(Error::field(
            "hold",
            "the paper's method identifies every parameter in one step; hold parameters with \
             the default method (lm)",
        ));
    }
    let holdable = candidates(
        l,
        &IdentifyOptions {
            hold: vec![],
            ..opts.clone()
        },
    );
    let mut fixed: Vec<FixedParam> = Vec::new();
    for name in &opts.hold {
        let Some(&k) = holdable.iter().find(|&&k| l.name(k) == *name) else {
            return Err(Error::field(
                "hold",
                format!(
                    "{name:?} is not a joint parameter of this robot (names like j2.theta, j5.a; \
                     s1.offset with string offsets); the base pose and the tool point are always \
                     fitted"
                ),
            ));
        };
        if k >= l.base() && k < l.tool() + 3 {
            return Err(Error::field(
                "hold",
                format!(
                    "{name:?}: the base pose and the tool point are fitted in every calibration \
                     (their nominal is only a starting guess)"
                ),
            ));
        }
        if !fixed.iter().any(|f| f.name == *name) {
            fixed.push(FixedParam {
                name: name.clone(),
                aliased_with: vec![],
                reason: FixedReason::Requested,
            });
        }
    }
    Ok(fixed)
}

/// Candidate parameters in priority order (see [`identifiability`]),
/// without those `opts.hold` names.
pub fn candidates(l: Layout, opts: &IdentifyOptions) -> Vec<usize> {
    let mut c: Vec<usize> = (l.base()..l.base() + 6)
        .chain(l.tool()..l.tool() + 3)
        .collect();
    for j in 0..l.n_joints {
        for p in [
            JointParam::Theta,
            JointParam::D,
            JointParam::A,
            JointParam::Alpha,
        ] {
            c.push(l.joint(j, p));
        }
    }
    for j in 0..l.n_joints {
        c.push(l.joint(j, JointParam::Beta));
    }
    if opts.identify_string_offsets && l.n_strings > 0 {
        c.extend((0..l.n_strings).map(|k| l.string_offset(k)));
    }
    // Last: where the rig's shape and the robot's geometry cannot be told
    // apart, the robot keeps the parameter and the hand-measured rig
    // stands.
    if opts.rig_anchors && l.n_strings >= rig::MIN_STRINGS {
        c.extend((0..3 * l.n_strings - 6).map(|j| l.anchor_mode(j)));
    }
    c.retain(|&k| !opts.hold.contains(&l.name(k)));
    c
}

/// The geometric calibration of `obs`: the base pose and the tool point on
/// the nominal joints, the identifiable parameters selected there, all of
/// them fitted (with the robust loss when asked), the undetermined ones
/// held at nominal.
pub fn geometric(
    obs: &Observations,
    opts: &IdentifyOptions,
    progress: &dyn Progress,
) -> Result<Geometric> {
    let before = fit_base_and_tool(obs, progress)?;
    let l = obs.chain.layout;
    // With the anchors identified, their shape modes follow the layout's
    // parameters, from rig.json's anchors (zero).
    let mut start = before.clone();
    if let (Some(m), true) = (&obs.anchor_modes, opts.rig_anchors) {
        start.values.extend(std::iter::repeat_n(0.0, m.len()));
    }
    let mut selection = select_parameters(obs, &start, opts)?;
    let free_set = freeset::choose(obs, &start, &selection, opts, progress)?;
    freeset::apply(&free_set, l, &mut selection);
    progress.update("identifying", 0.0);
    let mut problem = obs.problem(start.values.clone(), selection.free.clone());
    let mut result = run_lm(&problem, progress, "identifying")?;
    if opts.robust {
        result = reweight_robustly(&mut problem, result, progress)?;
    }
    // How well these data determine the flange orientation: from the fit
    // before the undetermined parameters are held, since holding them
    // replaces their spread by an assumption (nominal), not by knowledge.
    let flange_orientation_sigma_rad = obs.flange_orientation_sigma(
        &problem.expand(&result.x),
        &selection.free,
        &result.jtj,
        residual_scale(&problem, &result),
    );
    hold_undetermined(
        obs,
        &obs.train,
        opts,
        &start,
        &mut selection,
        &mut problem,
        &mut result,
        progress,
    )?;
    selection.condition_number = identifiability::condition_number(&result.jtj);
    let mut after = before.clone();
    after.values = problem.expand(&result.x);
    let sigma = residual_scale(&problem, &result);
    let rig = match &obs.anchor_modes {
        Some(m) if after.values.len() > l.len() => Some(rig::reduce(
            l,
            m,
            &mut after.values,
            &mut selection,
            &mut result,
            sigma,
        )),
        _ => None,
    };
    Ok(Geometric {
        free_set,
        rig,
        before,
        after,
        selection,
        result,
        weights: problem.weights,
        sigma,
        flange_orientation_sigma_rad,
    })
}

/// "Before": the nominal joints with the base pose (started from a rigid
/// fit of the nominal points to the measured ones) and the tool point
/// fitted.
fn fit_base_and_tool(obs: &Observations, progress: &dyn Progress) -> Result<Params> {
    let l = obs.chain.layout;
    let start = Params::nominal(
        obs.robot,
        &BasePose {
            xyz_mm: [0.0; 3],
            rpy_deg: [0.0; 3],
        },
        obs.rig,
        l.n_strings,
    );
    let a: Vec<Vector3<f64>> = obs
        .train
        .iter()
        .map(|&i| {
            obs.chain
                .point(&start.values, &obs.data.poses[i].q_rad, OutputFrame::Base)
                .1
        })
        .collect();
    let b: Vec<Vector3<f64>> = obs.train.iter().map(|&i| obs.measured[i]).collect();
    let mut before = start.clone();
    match rigid_fit(&a, &b) {
        Some((r, t)) => before.set_base_rt(&r, &t),
        None => return Err(Error::InsufficientData("cannot fit the base pose".into())),
    }
    progress.update("fitting base and tool", 0.0);
    let base_tool: Vec<usize> = (l.base()..l.tool() + 3).collect();
    let pb = obs.problem(before.values.clone(), base_tool);
    let rb = run_lm(&pb, progress, "fitting base and tool")?;
    before.values = pb.expand(&rb.x);
    Ok(before)
}

/// The parameters to identify, from the rank of the normal matrix at the
/// "before" solution, less those held by request; refused when the train
/// poses cannot determine them.
fn select_parameters(
    obs: &Observations,
    before: &Params,
    opts: &IdentifyOptions,
) -> Result<identifiability::Selection> {
    let l = obs.chain.layout;
    let cands = candidates(l, opts);
    let pc = obs.problem(before.values.clone(), cands.clone());
    let mut jtj = DMatrix::zeros(cands.len(), cands.len());
    let mut g = nalgebra::DVector::zeros(cands.len());
    lm::LeastSquares::normal_equations(&pc, &pc.x0(), &mut jtj, &mut g);
    let mut selection = identifiability::select(&jtj, &cands, &l, opts.identifiability_tolerance);
    selection.fixed.extend(held(l, opts)?);
    // As many equations (3 per distinct pose: T) as parameters or fewer:
    // the fit passes through the readings and its figures mean nothing.
    // (Fewer poses than parameters, but more equations, is a warning.)
    let usable = distinct_poses(obs, &obs.train);
    let k = selection.free.len();
    if 3 * usable <= k {
        return Err(Error::InsufficientData(format!(
            "{usable} usable train poses (distinct joint angles) for the {k} parameters these \
             poses identify: {}",
            more_poses_advice(obs, opts, k)
        )));
    }
    Ok(selection)
}

/// The robust (Huber) loss at the pose level: weights from the residuals'
/// robust scale, refitted until they settle. Each pass starts from the
/// last solution; the result counts the iterations of all of them.
fn reweight_robustly(
    problem: &mut CalibrationProblem,
    mut result: LmResult,
    progress: &dyn Progress,
) -> Result<LmResult> {
    let mut iterations = result.iterations;
    for _ in 0..8 {
        problem.full = problem.expand(&result.x);
        let res = pose_rms(problem, &problem.full);
        let scale = 1.4826 * stats::median(&res);
        let k = 2.5 * scale.max(1e-12);
        let w: Vec<f64> = res
            .iter()
            .map(|&e| if e <= k { 1.0 } else { k / e })
            .collect();
        let change = w
            .iter()
            .zip(&problem.weights)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        problem.weights = w;
        result = run_lm(problem, progress, "identifying (robust)")?;
        iterations += result.iterations;
        if change < 1e-3 {
            break;
        }
    }
    result.iterations = iterations;
    Ok(result)
}

/// Residual scale of a fit: `sqrt(2 cost / (N - k))` over the weighted
/// readings (mm).
fn residual_scale(problem: &CalibrationProblem, result: &LmResult) -> f64 {
    let dof =
        (lm::LeastSquares::n_residuals(problem) as f64 - problem.free().len() as f64).max(1.0);
    let wsum = problem.weights.iter().sum::<f64>() / problem.weights.len().max(1) as f64;
    (2.0 * result.cost / (dof * wsum.max(1e-12))).sqrt()
}

/// Nearly aliased joint parameters the data do not determine
/// ([`identifiability::undetermined`]): held at nominal one at a time, the
/// least significant first, refitting after each (its partner takes over
/// what it carried). The robust weights stay those of the fit before:
/// holding a parameter moves T by its deviation times its sine, a fraction
/// of the noise, which leaves every pose's weight where it was.
pub(super) fn hold_undetermined<'a>(
    obs: &Observations<'a>,
    poses: &[usize],
    opts: &IdentifyOptions,
    before: &Params,
    selection: &mut identifiability::Selection,
    problem: &mut CalibrationProblem<'a>,
    result: &mut LmResult,
    progress: &dyn Progress,
) -> Result<()> {
    let l = obs.chain.layout;
    loop {
        let values = problem.expand(&result.x);
        let deviation: Vec<f64> = selection
            .free
            .iter()
            .map(|&k| values[k] - before.values[k])
            .collect();
        let Some(held) = identifiability::undetermined(
            &result.jtj,
            &selection.free,
            &deviation,
            residual_scale(problem, result),
            opts.undetermined_z,
            |k| k < l.base(),
            &l,
        ) else {
            return Ok(());
        };
        let mut start = values;
        for (&k, d) in selection.free.iter().zip(&held.shift) {
            start[k] += d;
        }
        selection.free.remove(held.at);
        selection.fixed.push(held.fixed);
        let weights = std::mem::take(&mut problem.weights);
        *problem = obs.problem_on(poses, start, selection.free.clone());
        problem.weights = weights;
        let iterations = result.iterations;
        *result = run_lm(problem, progress, "identifying")?;
        result.iterations += iterations;
    }
}

/// A warning when the train poses are fewer than the parameters they
/// identify (but enough equations to fit: fewer is refused outright).
pub fn few_poses_warning(
    obs: &Observations,
    geo: &Geometric,
    opts: &IdentifyOptions,
) -> Option<String> {
    let (usable, k) = (distinct_poses(obs, &obs.train), geo.selection.free.len());
    (usable < k).then(|| {
        format!(
            "{usable} usable train poses (distinct joint angles) for the {k} parameters they identify: the parameters and the held-out figures are fragile; {}",
            more_poses_advice(obs, opts, k)
        )
    })
}

/// What to do about too few train poses for `k` parameters: record at
/// least `k` train poses (more, if the tool chooses the hold-out itself).
fn more_poses_advice(obs: &Observations, opts: &IdentifyOptions, k: usize) -> String {
    // The file's split is used when it marks both kinds (`choose_split`).
    let marked = |k: Split| obs.data.poses.iter().any(|p| p.split == Some(k));
    let from_file = marked(Split::Train) && marked(Split::Test);
    let hold = opts.holdout_fraction.clamp(0.0, 0.9);
    if from_file || hold == 0.0 {
        format!(
            "record at least {k} train poses, better two or three times as many (the paper identified 27 parameters from 30)"
        )
    } else {
        format!(
            "record at least {k} train poses, better two or three times as many (the paper identified 27 parameters from 30); {} of the {} poses are held out (--holdout {hold}; a job's holdout_fraction), so record at least {} in all, hold out fewer, or mark the split in a split column",
            obs.test.len(),
            obs.data.poses.len(),
            (k as f64 / (1.0 - hold)).ceil() as usize
        )
    }
}

/// How many of the poses `idx` differ in their joint angles (a pose
/// recorded twice adds readings, not information about the geometry).
pub(super) fn distinct_poses(obs: &Observations, idx: &[usize]) -> usize {
    let mut keys: Vec<Vec<i64>> = idx
        .iter()
        .map(|&i| {
            obs.data.poses[i]
                .q_rad
                .iter()
                // Angles equal to a microradian are the same pose.
                .map(|q| (q * 1e6).round() as i64)
                .collect()
        })
        .collect();
    keys.sort_unstable();
    keys.dedup();
    keys.len()
}

/// Per-pose RMS residual of a problem's poses at `p`.
pub fn pose_rms(problem: &CalibrationProblem, p: &[f64]) -> Vec<f64> {
    let mut r = Vec::new();
    problem
        .poses
        .iter()
        .map(|pose| {
            problem.pose_residuals(p, pose, &mut r);
            (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt()
        })
        .collect()
}

/// `(JᵀWJ)⁻¹`, inverted through the column-scaled matrix so that
/// parameters in mm and in radians are conditioned alike; `None` when it is
/// not positive definite.
pub fn unit_covariance(jtj: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = jtj.nrows();
    // Scale 1 for a zero column: its variance comes out infinite, not NaN.
    let d: Vec<f64> = (0..n)
        .map(|i| match jtj[(i, i)] {
            v if v > 0.0 && v.is_finite() => v.sqrt(),
            _ => 1.0,
        })
        .collect();
    let scaled = DMatrix::from_fn(n, n, |i, j| jtj[(i, j)] / (d[i] * d[j]));
    let inv = scaled.cholesky()?.inverse();
    Some(DMatrix::from_fn(n, n, |i, j| inv[(i, j)] / (d[i] * d[j])))
}

/// 1-sigma of every free parameter from `σ² (JᵀWJ)⁻¹`, in internal units.
pub fn sigmas(jtj: &DMatrix<f64>, sigma: f64) -> Vec<f64> {
    match unit_covariance(jtj) {
        Some(c) => (0..c.nrows())
            .map(|i| sigma * c[(i, i)].max(0.0).sqrt())
            .collect(),
        None => vec![f64::NAN; jtj.nrows()],
    }
}
