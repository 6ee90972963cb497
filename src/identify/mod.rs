//! Identification: from recorded poses to a calibrated model and its report.
//!
//! The pipeline ([`identify`]):
//! 1. split the poses into train and test (the file's `split`, or a seeded
//!    random hold-out);
//! 2. locate T at every pose (least-squares multilateration) to start the
//!    base pose (a rigid fit of the nominal model's points) and for the
//!    statistics;
//! 3. "before": the nominal model with only the base pose and tool point
//!    fitted, by Levenberg-Marquardt on the raw string readings;
//! 4. identifiability: the parameters the data cannot separate are held at
//!    nominal and named;
//! 5. "after": Levenberg-Marquardt on all identifiable parameters, optionally
//!    with a robust loss that down-weights and flags outlier poses;
//! 6. covariance, statistics, the paper's one-step method beside it.
//!
//! Input that parses but looks wrong (angles in radians in the `_deg`
//! columns) does not stop it: it is named in the report's `warnings`
//! ([`warnings`]).

pub mod identifiability;
pub mod lm;
pub mod paper;
pub mod problem;
pub mod report;
pub mod stats;
pub mod warnings;

use nalgebra::{DMatrix, Matrix3, Vector3};

use crate::error::{Error, Result};
use crate::kinematics::chain::{Chain, OutputFrame, PointJacobian, joint_trig};
use crate::kinematics::{JointParam, Layout, Params};
use crate::measure::{self, Located};
use crate::model::{BasePose, Dataset, Measurement, Rig, Robot, Split};
use crate::rng::Rng;
use lm::{LmResult, LmSettings};
use problem::CalibrationProblem;
use report::*;

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
    /// Run the physics analysis after the geometric identification.
    pub physics: bool,
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
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        IdentifyOptions {
            method: Method::Lm,
            robust: false,
            physics: true,
            holdout_fraction: 0.3,
            seed: 1,
            identify_string_offsets: false,
            identifiability_tolerance: identifiability::DEFAULT_TOLERANCE,
            undetermined_z: identifiability::UNDETERMINED_Z,
            hold: vec![],
        }
    }
}

/// Progress reporting and cancellation for long identifications.
pub trait Progress: Sync {
    /// Called as work advances; `fraction` in [0, 1].
    fn update(&self, stage: &str, fraction: f64);
    /// Polled between solver iterations; `true` stops the work with
    /// [`Error::Cancelled`].
    fn cancelled(&self) -> bool {
        false
    }
}

/// A [`Progress`] that ignores everything.
pub struct NoProgress;
impl Progress for NoProgress {
    fn update(&self, _: &str, _: f64) {}
}

/// The working state shared by the pipeline's steps.
pub struct Session<'a> {
    /// Nominal robot.
    pub robot: &'a Robot,
    /// Rig.
    pub rig: &'a Rig,
    /// All poses.
    pub data: &'a Dataset,
    /// Kinematic structure.
    pub chain: Chain,
    /// Anchors (empty for point data).
    pub anchors: Vec<Vector3<f64>>,
    /// Indices of the train poses.
    pub train: Vec<usize>,
    /// Indices of the test poses.
    pub test: Vec<usize>,
    /// Measured T per pose in the rig frame (located from the strings with
    /// the nominal string constants, or as measured).
    pub measured: Vec<Vector3<f64>>,
    /// Multilateration results per pose (string data).
    pub located: Vec<Located>,
    /// Sines and cosines of every pose's joint angles, computed once.
    pub q_trig: Vec<Vec<(f64, f64)>>,
}

impl<'a> Session<'a> {
    /// Prepare: check shapes, split, locate.
    pub fn new(
        robot: &'a Robot,
        rig: &'a Rig,
        data: &'a Dataset,
        opts: &IdentifyOptions,
    ) -> Result<Self> {
        let n = robot.dof();
        if let Some(p) = data.poses.iter().find(|p| p.q_rad.len() != n) {
            return Err(Error::field(
                "poses",
                format!(
                    "pose {} has {} joint angles for a {n}-joint robot",
                    p.id,
                    p.q_rad.len()
                ),
            ));
        }
        let m = data.n_strings;
        if m > 0 && m != rig.n_strings() {
            return Err(Error::field(
                "poses",
                format!(
                    "{m} string columns for a rig with {} anchors",
                    rig.n_strings()
                ),
            ));
        }
        let chain = Chain::new(robot.convention, n, m);
        let anchors: Vec<Vector3<f64>> = if m > 0 {
            (0..m).map(|k| rig.anchor(k)).collect()
        } else {
            vec![]
        };
        let (train, test) = choose_split(data, opts);
        if train.len() < 3 {
            return Err(Error::InsufficientData(format!(
                "{} train poses: at least 3 are needed",
                train.len()
            )));
        }
        let hints = nominal_points(robot, rig, data);
        let mut measured = Vec::with_capacity(data.poses.len());
        let mut located = Vec::new();
        for (pose, hint) in data.poses.iter().zip(&hints) {
            match &pose.measurement {
                Measurement::Strings(l) => {
                    let dist: Vec<f64> = l.iter().map(|v| v + rig.r_mm).collect();
                    let loc = measure::locate(&anchors, &dist, hint.as_ref())
                        .map_err(|e| Error::field("poses", format!("pose {}: {e}", pose.id)))?;
                    measured.push(loc.point);
                    located.push(loc);
                }
                Measurement::Point(p) => measured.push(*p),
            }
        }
        let q_trig = data.poses.iter().map(|p| joint_trig(&p.q_rad)).collect();
        Ok(Session {
            q_trig,
            robot,
            rig,
            data,
            chain,
            anchors,
            train,
            test,
            measured,
            located,
        })
    }

    /// The train poses.
    pub fn train_poses(&self) -> Vec<&'a crate::model::PoseRecord> {
        self.train.iter().map(|&i| &self.data.poses[i]).collect()
    }

    /// A problem over the train poses.
    pub fn problem(&self, full: Vec<f64>, free: Vec<usize>) -> CalibrationProblem<'a> {
        CalibrationProblem::new(
            self.chain,
            self.anchors.clone(),
            self.train_poses(),
            full,
            free,
        )
    }

    /// Errors (model minus measured T, robot base frame) of `p` at poses `idx`.
    pub fn errors(&self, p: &[f64], idx: &[usize]) -> Vec<Vector3<f64>> {
        let b = self.chain.layout.base();
        let rb = crate::kinematics::rpy_matrix(p[b + 3], p[b + 4], p[b + 5]);
        let trig = self.chain.trig(p);
        idx.iter()
            .map(|&i| {
                rb.transpose()
                    * (self.chain.point_trig(p, &trig, &self.q_trig[i]) - self.measured[i])
            })
            .collect()
    }

    /// Before/after figures on train and test from per-pose errors of every
    /// pose (indexed like `data.poses`).
    pub fn stats_of(&self, before: &[Vector3<f64>], after: &[Vector3<f64>]) -> Stats {
        let split = |idx: &[usize]| SplitStats {
            n: idx.len(),
            before: stats::error_stats(&idx.iter().map(|&i| before[i]).collect::<Vec<_>>()),
            after: stats::error_stats(&idx.iter().map(|&i| after[i]).collect::<Vec<_>>()),
        };
        Stats {
            train: split(&self.train),
            test: split(&self.test),
        }
    }

    /// String noise (1 sigma, mm) from the strings' redundancy.
    pub fn string_sigma(&self) -> Option<f64> {
        measure::string_sigma(&self.located)
    }

    /// Held-out 3-D RMS a perfect model would show: the located points'
    /// own scatter, from the string noise and each test pose's geometry.
    pub fn noise_floor(&self, sigma: Option<f64>) -> Option<f64> {
        let s = sigma?;
        if self.located.is_empty() || self.test.is_empty() {
            return None;
        }
        let mean_trace = self
            .test
            .iter()
            .map(|&i| self.located[i].cov_unit.trace())
            .sum::<f64>()
            / self.test.len() as f64;
        Some(s * mean_trace.sqrt())
    }

    /// Held-out 3-D RMS that an exact model, identified from these train
    /// poses, shows on average: the noise floor plus the spread of the
    /// identified parameters (`σ² (JᵀWJ)⁻¹` of the fit at `values` over the
    /// `free` parameters) carried to each test pose's T. The two are
    /// independent (test readings versus train readings), so their
    /// variances add. More train poses shrink the second part, never the
    /// first. `None` without a noise floor or a covariance.
    pub fn expected_test_rms(
        &self,
        values: &[f64],
        free: &[usize],
        jtj: &DMatrix<f64>,
        sigma: Option<f64>,
    ) -> Option<f64> {
        let floor = self.noise_floor(sigma)?;
        let s = sigma?;
        let cov = unit_covariance(jtj)?;
        // String offsets (past the geometric block) do not move T.
        let spread = self.mean_spread(values, free, &cov, &self.test, OutputFrame::Rig, |pj| {
            &pj.d_params
        });
        let spread = s * s * spread;
        spread.is_finite().then(|| (floor * floor + spread).sqrt())
    }

    /// Mean over `poses` of `Σ_c g_cᵀ C g_c`: the unit covariance `cov`
    /// (over `free`) carried to a per-pose 3-vector whose derivative per
    /// parameter `columns` reads from the chain's Jacobian in `frame` (T's,
    /// or the flange's rotation); parameters past the columns count zero.
    fn mean_spread(
        &self,
        values: &[f64],
        free: &[usize],
        cov: &DMatrix<f64>,
        poses: &[usize],
        frame: OutputFrame,
        columns: impl Fn(&PointJacobian) -> &Vec<Vector3<f64>>,
    ) -> f64 {
        let trig = self.chain.trig(values);
        let mut pj = self.chain.new_jacobian();
        let mut sum = 0.0;
        for &i in poses {
            self.chain
                .point_jacobian_trig(values, &trig, &self.q_trig[i], frame, &mut pj);
            let col = columns(&pj);
            for c in 0..3 {
                let g = nalgebra::DVector::from_iterator(
                    free.len(),
                    free.iter().map(|&k| col.get(k).map_or(0.0, |v| v[c])),
                );
                sum += g.dot(&(cov * &g));
            }
        }
        sum / poses.len().max(1) as f64
    }

    /// 1-sigma of the calibrated flange orientation in the robot base frame
    /// (rad), RMS over the poses (at most [`ORIENTATION_POSES`] of them,
    /// evenly spread): the identified parameters' covariance
    /// `σ² (JᵀWJ)⁻¹` over `free`, at `values`, carried to the flange's
    /// rotation: the RMS rotation angle (the square root of the trace of its
    /// covariance). Parameters held at nominal add nothing: those position
    /// data never see (the last joint's θ...) count as exact. `None`
    /// without a covariance.
    pub fn flange_orientation_sigma(
        &self,
        values: &[f64],
        free: &[usize],
        jtj: &DMatrix<f64>,
        sigma: f64,
    ) -> Option<f64> {
        let cov = unit_covariance(jtj)?;
        let n = self.data.poses.len();
        let poses: Vec<usize> = (0..n)
            .step_by(n.div_ceil(ORIENTATION_POSES).max(1))
            .collect();
        let v = sigma
            * sigma
            * self.mean_spread(values, free, &cov, &poses, OutputFrame::Base, |pj| {
                &pj.d_orientation
            });
        v.is_finite().then(|| v.sqrt())
    }
}

/// Most poses [`Session::flange_orientation_sigma`] looks at: an RMS over
/// a few hundred poses is as good as over all 11,911 of a grid.
pub const ORIENTATION_POSES: usize = 500;

fn choose_split(data: &Dataset, opts: &IdentifyOptions) -> (Vec<usize>, Vec<usize>) {
    let has_test = data.poses.iter().any(|p| p.split == Some(Split::Test));
    let has_train = data.poses.iter().any(|p| p.split == Some(Split::Train));
    if has_test && has_train {
        let test = (0..data.poses.len())
            .filter(|&i| data.poses[i].split == Some(Split::Test))
            .collect();
        let train = (0..data.poses.len())
            .filter(|&i| data.poses[i].split != Some(Split::Test))
            .collect();
        return (train, test);
    }
    let n = data.poses.len();
    let n_test = ((n as f64 * opts.holdout_fraction.clamp(0.0, 0.9)).round() as usize)
        .min(n.saturating_sub(3));
    let mut order: Vec<usize> = (0..n).collect();
    Rng::new(opts.seed).shuffle(&mut order);
    let mut test: Vec<usize> = order[..n_test].to_vec();
    let mut train: Vec<usize> = order[n_test..].to_vec();
    test.sort_unstable();
    train.sort_unstable();
    (train, test)
}

/// Describe where the split came from.
fn split_source(data: &Dataset, session: &Session, opts: &IdentifyOptions) -> String {
    let from_file = data.poses.iter().any(|p| p.split == Some(Split::Test))
        && data.poses.iter().any(|p| p.split == Some(Split::Train));
    if from_file {
        return "file".into();
    }
    // A split column that marks only one kind cannot be used as it is:
    // say so, rather than seem to ignore it.
    let marked = |k: Split| data.poses.iter().any(|p| p.split == Some(k));
    let why = if marked(Split::Train) {
        "the split column marks no pose test; "
    } else if marked(Split::Test) {
        "the split column marks no pose train; "
    } else {
        ""
    };
    format!(
        "chosen: {why}{} of {} poses held out at random (seed {}; --holdout sets the fraction)",
        session.test.len(),
        data.poses.len(),
        opts.seed
    )
}

/// Where the nominal model, placed at the rig's `base_in_rig` guess, puts T
/// at each pose (rig frame): the side hint that picks a located point's
/// mirror image across a plane of anchors. All `None` without a guess.
pub fn nominal_points(robot: &Robot, rig: &Rig, data: &Dataset) -> Vec<Option<Vector3<f64>>> {
    let m = rig.n_strings();
    let chain = Chain::new(robot.convention, robot.dof(), m);
    let nominal = rig.base_in_rig.map(|b| Params::nominal(robot, &b, rig, m));
    data.poses
        .iter()
        .map(|pose| {
            nominal
                .as_ref()
                .map(|p| chain.point(&p.values, &pose.q_rad, OutputFrame::Rig).1)
        })
        .collect()
}

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

fn run_lm(problem: &CalibrationProblem, progress: &dyn Progress, stage: &str) -> Result<LmResult> {
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
    /// see [`Session::flange_orientation_sigma`]), from the fit before the
    /// undetermined parameters were held.
    pub flange_orientation_sigma_rad: Option<f64>,
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
    c.retain(|&k| !opts.hold.contains(&l.name(k)));
    c
}

/// Steps 3-5 of the pipeline.
pub fn geometric(
    session: &Session,
    opts: &IdentifyOptions,
    progress: &dyn Progress,
) -> Result<Geometric> {
    let robot = session.robot;
    let l = session.chain.layout;
    // Start the base from a rigid fit of the nominal points to the measured ones.
    let start = Params::nominal(
        robot,
        &BasePose {
            xyz_mm: [0.0; 3],
            rpy_deg: [0.0; 3],
        },
        session.rig,
        l.n_strings,
    );
    let a: Vec<Vector3<f64>> = session
        .train
        .iter()
        .map(|&i| {
            session
                .chain
                .point(
                    &start.values,
                    &session.data.poses[i].q_rad,
                    OutputFrame::Base,
                )
                .1
        })
        .collect();
    let b: Vec<Vector3<f64>> = session.train.iter().map(|&i| session.measured[i]).collect();
    let mut before = start.clone();
    match rigid_fit(&a, &b) {
        Some((r, t)) => before.set_base_rt(&r, &t),
        None => return Err(Error::InsufficientData("cannot fit the base pose".into())),
    }
    progress.update("fitting base and tool", 0.0);
    let base_tool: Vec<usize> = (l.base()..l.tool() + 3).collect();
    let pb = session.problem(before.values.clone(), base_tool);
    let rb = run_lm(&pb, progress, "fitting base and tool")?;
    before.values = pb.expand(&rb.x);

    // Identifiability at the before solution.
    let cands = candidates(l, opts);
    let pc = session.problem(before.values.clone(), cands.clone());
    let mut jtj = DMatrix::zeros(cands.len(), cands.len());
    let mut g = nalgebra::DVector::zeros(cands.len());
    lm::LeastSquares::normal_equations(&pc, &pc.x0(), &mut jtj, &mut g);
    let mut selection = identifiability::select(&jtj, &cands, &l, opts.identifiability_tolerance);
    selection.fixed.extend(held(l, opts)?);
    // As many equations (3 per distinct pose: T) as parameters or fewer:
    // the fit passes through the readings and its figures mean nothing.
    // (Fewer poses than parameters, but more equations, is a warning.)
    let usable = distinct_poses(session, &session.train);
    let k = selection.free.len();
    if 3 * usable <= k {
        return Err(Error::InsufficientData(format!(
            "{usable} usable train poses (distinct joint angles) for the {k} parameters these \
             poses identify: {}",
            more_poses_advice(session, opts, k)
        )));
    }
    progress.update("identifying", 0.0);
    let mut problem = session.problem(before.values.clone(), selection.free.clone());
    let mut result = run_lm(&problem, progress, "identifying")?;
    if opts.robust {
        // Each reweighting pass starts from the last solution; the report
        // counts the iterations of all of them.
        let mut iterations = result.iterations;
        for _ in 0..8 {
            problem.full = problem.expand(&result.x);
            let res = pose_rms(&problem, &problem.full);
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
            result = run_lm(&problem, progress, "identifying (robust)")?;
            iterations += result.iterations;
            if change < 1e-3 {
                break;
            }
        }
        result.iterations = iterations;
    }
    // Nearly aliased joint parameters the data do not determine: held at
    // nominal one at a time, the least significant first, refitting after
    // each (its partner takes over what it carried).
    let residual_scale = |problem: &CalibrationProblem, result: &LmResult| {
        let dof =
            (lm::LeastSquares::n_residuals(problem) as f64 - problem.free().len() as f64).max(1.0);
        let wsum = problem.weights.iter().sum::<f64>() / problem.weights.len().max(1) as f64;
        (2.0 * result.cost / (dof * wsum.max(1e-12))).sqrt()
    };
    // How well these data determine the flange orientation: from the fit
    // before the undetermined parameters are held, since holding them
    // replaces their spread by an assumption (nominal), not by knowledge.
    let flange_orientation_sigma_rad = session.flange_orientation_sigma(
        &problem.expand(&result.x),
        &selection.free,
        &result.jtj,
        residual_scale(&problem, &result),
    );
    // (The robust weights stay those of the fit before: holding a
    // parameter moves T by its deviation times its sine, a fraction of the
    // noise, which leaves every pose's weight where it was.)
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
            residual_scale(&problem, &result),
            opts.undetermined_z,
            |k| k < l.base(),
            &l,
        ) else {
            break;
        };
        let mut start = values;
        for (&k, d) in selection.free.iter().zip(&held.shift) {
            start[k] += d;
        }
        selection.free.remove(held.at);
        selection.fixed.push(held.fixed);
        let weights = std::mem::take(&mut problem.weights);
        problem = session.problem(start, selection.free.clone());
        problem.weights = weights;
        let iterations = result.iterations;
        result = run_lm(&problem, progress, "identifying")?;
        result.iterations += iterations;
    }
    selection.condition_number = identifiability::condition_number(&result.jtj);
    let mut after = before.clone();
    after.values = problem.expand(&result.x);
    let sigma = residual_scale(&problem, &result);
    Ok(Geometric {
        before,
        after,
        selection,
        result,
        weights: problem.weights,
        sigma,
        flange_orientation_sigma_rad,
    })
}

/// What to do about too few train poses for `k` parameters: record at
/// least `k` train poses (more, if the tool chooses the hold-out itself).
fn more_poses_advice(session: &Session, opts: &IdentifyOptions, k: usize) -> String {
    // The file's split is used when it marks both kinds (`choose_split`).
    let marked = |k: Split| session.data.poses.iter().any(|p| p.split == Some(k));
    let from_file = marked(Split::Train) && marked(Split::Test);
    let hold = opts.holdout_fraction.clamp(0.0, 0.9);
    if from_file || hold == 0.0 {
        format!(
            "record at least {k} train poses, better two or three times as many (the paper identified 27 parameters from 30)"
        )
    } else {
        format!(
            "record at least {k} train poses, better two or three times as many (the paper identified 27 parameters from 30); {} of the {} poses are held out (--holdout {hold}; a job's holdout_fraction), so record at least {} in all, hold out fewer, or mark the split in a split column",
            session.test.len(),
            session.data.poses.len(),
            (k as f64 / (1.0 - hold)).ceil() as usize
        )
    }
}

/// How many of the poses `idx` differ in their joint angles (a pose
/// recorded twice adds readings, not information about the geometry).
fn distinct_poses(session: &Session, idx: &[usize]) -> usize {
    let mut keys: Vec<Vec<i64>> = idx
        .iter()
        .map(|&i| {
            session.data.poses[i]
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

/// Train RMS (mm) after the geometric calibration beyond which the physics
/// analysis is not run: physical effects are fractions of a millimetre, and
/// a calibrated arm that misses by more than this is a wrong model or wrong
/// data (angles in radians, another robot, a swapped string), not physics.
pub const PHYSICS_MAX_GEOMETRIC_RMS_MM: f64 = 10.0;

/// How a physics note that says the analysis did not run begins.
pub const PHYSICS_NOT_RUN: &str = "not run";

/// Run the whole identification and build the report.
pub fn identify(
    robot: &Robot,
    rig: &Rig,
    data: &Dataset,
    opts: &IdentifyOptions,
    progress: &dyn Progress,
) -> Result<Report> {
    let session = Session::new(robot, rig, data, opts)?;
    let mut warnings = warnings::input_warnings(&session);
    let geo = geometric(&session, opts, progress)?;
    let (usable, k) = (
        distinct_poses(&session, &session.train),
        geo.selection.free.len(),
    );
    if usable < k {
        warnings.push(format!(
            "{usable} usable train poses (distinct joint angles) for the {k} parameters they identify: the parameters and the held-out figures are fragile; {}",
            more_poses_advice(&session, opts, k)
        ));
    }
    let l = session.chain.layout;
    let string_sigma = session
        .string_sigma()
        .or_else(|| (l.n_strings > 0).then_some(geo.sigma));
    let noise_floor_mm = session.noise_floor(string_sigma);
    let expected_test_rms_mm = session.expected_test_rms(
        &geo.after.values,
        &geo.selection.free,
        &geo.result.jtj,
        string_sigma,
    );

    let flange_orientation_sigma_deg = (opts.method == Method::Lm)
        .then_some(geo.flange_orientation_sigma_rad)
        .flatten()
        .map(f64::to_degrees);
    let paper = paper::one_step(&session, &geo.before);
    let (mut after_values, method, fixed_sel, mut sig) = match opts.method {
        Method::Lm => (
            geo.after.values.clone(),
            "lm",
            Some(&geo.selection),
            sigmas(&geo.result.jtj, geo.sigma),
        ),
        Method::Paper => {
            let p = paper
                .as_ref()
                .map_err(|e| Error::Numerical(format!("paper method: {e}")))?;
            (p.values.clone(), "paper", None, vec![])
        }
    };
    let all: Vec<usize> = (0..data.poses.len()).collect();
    let eb = session.errors(&geo.before.values, &all);
    let mut ea = session.errors(&after_values, &all);
    let mut findings = vec![];
    let mut physics_notes = vec![];
    let mut accepted = None;
    let train_rms_mm = {
        let e = session.errors(&after_values, &session.train);
        (e.iter().map(|v| v.norm_squared()).sum::<f64>() / e.len().max(1) as f64).sqrt()
    };
    // NaN counts as broken.
    let broken = !(train_rms_mm <= PHYSICS_MAX_GEOMETRIC_RMS_MM);
    if !opts.physics {
        physics_notes.push(format!("{PHYSICS_NOT_RUN} (physics off)"));
    } else if opts.method == Method::Paper {
        physics_notes.push(format!(
            "{PHYSICS_NOT_RUN} (method paper: the analysis builds on the Levenberg-Marquardt fit; run --method lm)"
        ));
    }
    if opts.physics && opts.method == Method::Lm && broken {
        physics_notes.push(format!(
            "{PHYSICS_NOT_RUN}: the calibrated geometric model still misses the train poses by {train_rms_mm:.1} mm RMS (more than {PHYSICS_MAX_GEOMETRIC_RMS_MM} mm), so it does not describe these recordings and any effect fitted on top would fit a broken model; check the units (degrees, mm), the robot model and the rig first"
        ));
    }
    if opts.physics && opts.method == Method::Lm && !broken {
        progress.update("physics analysis", 0.0);
        let an = crate::physics::analyse(&session, &geo, opts, progress)?;
        if !an.effects.is_empty() {
            // The final model is the geometry refitted with the accepted
            // effects; its errors are what stats.*.after and per_pose report.
            ea = crate::physics::errors_with_effects(
                &session,
                &an.context,
                &an.final_params.values,
                &an.effects,
                &all,
            );
            after_values = an.final_params.values.clone();
            // Uncertainties of the final model, not of the geometric fit
            // it started from.
            if let Some(s) = an.final_sigmas {
                sig = s;
            }
            accepted = Some((an.context, an.effects));
        }
        findings = an.findings;
        physics_notes = an.notes;
    }
    let stats = session.stats_of(&eb, &ea);
    let paper_stats = match (&paper, opts.method) {
        (Ok(p), Method::Lm) => Some(session.stats_of(&eb, &session.errors(&p.values, &all))),
        _ => None,
    };

    let mut sigma_of = vec![None; l.len()];
    if let Some(sel) = fixed_sel {
        for (k, &i) in sel.free.iter().enumerate() {
            sigma_of[i] = sig.get(k).copied();
        }
    }
    let after = Params {
        layout: l,
        values: after_values,
    };
    let nominal = Params::nominal(robot, &geo.before.base(), rig, l.n_strings);
    let unit = |i: usize| {
        if l.is_angle(i) {
            (f64::to_degrees as fn(f64) -> f64, "deg")
        } else {
            (std::convert::identity as fn(f64) -> f64, "mm")
        }
    };
    let deviations = (0..l.n_joints)
        .map(|j| {
            let dev = |p: JointParam| {
                let i = l.joint(j, p);
                let (conv, _) = unit(i);
                (
                    conv(after.values[i] - nominal.values[i]),
                    sigma_of[i].map(conv),
                )
            };
            let (a, a_s) = dev(JointParam::A);
            let (al, al_s) = dev(JointParam::Alpha);
            let (d, d_s) = dev(JointParam::D);
            let (th, th_s) = dev(JointParam::Theta);
            let (be, be_s) = dev(JointParam::Beta);
            JointDeviation {
                joint: j + 1,
                a_mm: a,
                a_mm_sigma: a_s,
                alpha_deg: al,
                alpha_deg_sigma: al_s,
                d_mm: d,
                d_mm_sigma: d_s,
                theta_offset_deg: th,
                theta_offset_deg_sigma: th_s,
                beta_deg: be,
                beta_deg_sigma: be_s,
            }
        })
        .collect();
    let parameters = match fixed_sel {
        Some(sel) => sel
            .free
            .iter()
            .map(|&i| {
                let (conv, u) = unit(i);
                // `nominal` carries the fitted "before" base pose, so base
                // deviations are from that fit, the rest from nominal.
                let start = nominal.values[i];
                ParamEstimate {
                    name: l.name(i),
                    value: conv(after.values[i]),
                    deviation: conv(after.values[i] - start),
                    sigma: sigma_of[i].map(conv).unwrap_or(f64::NAN),
                    unit: u.into(),
                }
            })
            .collect(),
        None => vec![],
    };
    let identifiability = Identifiability {
        // Every parameter considered, held by request or not.
        n_candidates: candidates(
            session.chain.layout,
            &IdentifyOptions {
                hold: vec![],
                ..opts.clone()
            },
        )
        .len(),
        n_identified: fixed_sel.map(|s| s.free.len()).unwrap_or(5 * l.n_joints),
        condition_number: geo.selection.condition_number,
        fixed: fixed_sel.map(|s| s.fixed.clone()).unwrap_or_default(),
    };

    // Outliers: poses far beyond the robust residual scale.
    let train_problem = session.problem(after.values.clone(), vec![]);
    let res = pose_rms(&train_problem, &after.values);
    let scale = 1.4826 * stats::median(&res);
    let outliers = session
        .train
        .iter()
        .zip(&res)
        .filter(|(_, e)| scale > 0.0 && **e > 4.0 * scale)
        .map(|(&i, &e)| Outlier {
            pose: session.data.poses[i].id.clone(),
            residual_mm: e,
            score: e / scale,
        })
        .collect();

    let mut per_pose = Vec::with_capacity(data.poses.len());
    let test_set: std::collections::HashSet<usize> = session.test.iter().copied().collect();
    let mut r = Vec::new();
    for i in all {
        let strings_mm = if l.n_strings > 0 {
            match (&accepted, &data.poses[i].measurement) {
                // With accepted effects: the residual of the final model,
                // effects included (as the physics fit defines it).
                (Some((ctx, effects)), Measurement::Strings(readings)) => {
                    let (t, dl) = crate::physics::problem::EffectProblem::model_point(
                        &session.chain,
                        ctx,
                        &after.values,
                        effects,
                        i,
                        &data.poses[i].q_rad,
                    );
                    let g = l.n_geometric();
                    let rr = after.values[l.r()];
                    r = (0..l.n_strings)
                        .map(|k| {
                            (t - session.anchors[k]).norm() - rr - after.values[g + k] + dl[k]
                                - readings[k]
                        })
                        .collect();
                }
                _ => train_problem.pose_residuals(&after.values, &data.poses[i], &mut r),
            }
            Some(r.clone())
        } else {
            None
        };
        per_pose.push(PoseResidual {
            pose: data.poses[i].id.clone(),
            split: if test_set.contains(&i) {
                Split::Test
            } else {
                Split::Train
            },
            before_mm: eb[i].into(),
            after_mm: ea[i].into(),
            strings_mm,
        });
    }

    let closed_form_vs_lsq = closed_form_comparison(&session);
    let calibrated_robot = after.to_robot(robot, &format!("{} (calibrated)", robot.name));
    Ok(Report {
        format: REPORT_FORMAT.into(),
        method: method.into(),
        robust: opts.robust,
        nominal_robot: robot.clone(),
        calibrated_robot,
        base_in_rig: after.base(),
        tool_point_mm: after.tool(),
        deviations,
        parameters,
        fixed: identifiability
            .fixed
            .iter()
            .map(|f| f.name.clone())
            .collect(),
        identifiability,
        stats,
        paper_stats,
        noise_floor_mm,
        expected_test_rms_mm,
        flange_orientation_sigma_deg,
        string_sigma_mm: string_sigma,
        held_out: session
            .test
            .iter()
            .map(|&i| data.poses[i].id.clone())
            .collect(),
        split_source: split_source(data, &session, opts),
        outliers,
        convergence: Convergence {
            iterations: geo.result.iterations,
            termination: geo.result.termination.as_str().into(),
            residual_rms_mm: (2.0 * geo.result.cost
                / lm::LeastSquares::n_residuals(&train_problem).max(1) as f64)
                .sqrt(),
        },
        closed_form_vs_lsq,
        per_pose,
        findings,
        physics_notes,
        warnings,
    })
}

/// The paper's closed form against least squares over every pose (rigs
/// with at least four anchors).
pub fn closed_form_comparison(session: &Session) -> Option<ClosedFormComparison> {
    if session.anchors.len() < 4 {
        return None;
    }
    let r = session.rig.r_mm;
    let mut d2 = Vec::new();
    let mut mirrored = 0;
    for (pose, loc) in session.data.poses.iter().zip(&session.located) {
        if let Measurement::Strings(l) = &pose.measurement {
            if let Ok(p) = measure::paper_closed_form(&session.anchors, l[0], l[2], l[3], r) {
                if measure::is_paper_mirror(&session.anchors, &p, &loc.point) {
                    mirrored += 1;
                }
                d2.push((p - loc.point).norm());
            }
        }
    }
    ClosedFormComparison::from_distances(&d2, mirrored)
}
