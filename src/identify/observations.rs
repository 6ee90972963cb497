//! The recordings prepared for fitting: shapes checked, the poses split
//! into train and test, T located at every pose, joint trigonometry cached.

use nalgebra::{DMatrix, Vector3};

use super::IdentifyOptions;
use super::geometric::unit_covariance;
use super::problem::CalibrationProblem;
use super::rig::{self, AnchorModes};
use crate::error::{Error, Result};
use crate::kinematics::Params;
use crate::kinematics::chain::{Chain, OutputFrame, PointJacobian, joint_trig};
use crate::measure::{self, Located};
use crate::model::{Dataset, Measurement, Rig, Robot, Split};
use crate::report::{ClosedFormComparison, ErrorStats, SplitStats, Stats};
use crate::rng::Rng;

/// The working state shared by the pipeline's steps.
pub struct Observations<'a> {
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
    /// Indices of the test poses: the held-out poses the steps read.
    pub test: Vec<usize>,
    /// Held-out poses set aside from every decision (see
    /// [`Observations::gate_half`]): no step reads them, the report
    /// measures the final model on them. Empty unless set aside.
    pub confirmation: Vec<usize>,
    /// Measured T per pose in the rig frame (located from the strings with
    /// the nominal string constants, or as measured).
    pub measured: Vec<Vector3<f64>>,
    /// Multilateration results per pose (string data).
    pub located: Vec<Located>,
    /// Sines and cosines of every pose's joint angles, computed once.
    pub q_trig: Vec<Vec<(f64, f64)>>,
    /// rig.json's anchors' shape modes, when the anchors are identified
    /// with the robot (`rig_anchors`); a problem whose parameter vector
    /// runs past the layout moves the anchors by them.
    pub anchor_modes: Option<AnchorModes>,
}

impl<'a> Observations<'a> {
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
        if opts.rig_anchors {
            if let Some(why) = rig::refusal(m) {
                return Err(Error::field("rig_anchors", why));
            }
            if opts.method == super::Method::Paper {
                return Err(Error::field(
                    "rig_anchors",
                    "the paper's method identifies the robot alone; identify the anchors with \
                     the default method (lm)",
                ));
            }
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
        let anchor_modes = if opts.rig_anchors {
            Some(AnchorModes::new(&anchors)?)
        } else {
            None
        };
        let hints = nominal_points(robot, rig, data);
        let (measured, located) = locate_all(data, &anchors, rig.r_mm, &[], &hints)?;
        let q_trig = data.poses.iter().map(|p| joint_trig(&p.q_rad)).collect();
        Ok(Observations {
            anchor_modes,
            q_trig,
            robot,
            rig,
            data,
            chain,
            anchors,
            train,
            test,
            confirmation: Vec::new(),
            measured,
            located,
        })
    }

    /// These observations with the held-out poses split in two, for a
    /// selection that decides on held-out poses (the physics analysis):
    /// `test` keeps the gate half, which the decisions read, and
    /// `confirmation` holds the other half, which none reads, so that the
    /// final model's held-out error there is free of the selection's bias.
    /// The halves alternate in session order ([`confirmation_split`]).
    /// `None` when the held-out poses are too few to halve
    /// ([`MIN_CONFIRMATION`]).
    pub fn gate_half(&self) -> Option<Observations<'a>> {
        let (gate, confirmation) = confirmation_split(&self.test)?;
        Some(Observations {
            robot: self.robot,
            rig: self.rig,
            data: self.data,
            chain: self.chain,
            anchors: self.anchors.clone(),
            train: self.train.clone(),
            test: gate,
            confirmation,
            measured: self.measured.clone(),
            located: self.located.clone(),
            q_trig: self.q_trig.clone(),
            anchor_modes: self.anchor_modes.clone(),
        })
    }

    /// Every held-out pose, gate and confirmation halves alike, in
    /// session order.
    pub fn held_out(&self) -> Vec<usize> {
        let mut all: Vec<usize> = self
            .test
            .iter()
            .chain(&self.confirmation)
            .copied()
            .collect();
        all.sort_unstable();
        all
    }

    /// The train poses.
    pub fn train_poses(&self) -> Vec<&'a crate::model::PoseRecord> {
        self.train.iter().map(|&i| &self.data.poses[i]).collect()
    }

    /// A problem over the train poses; one whose `full` runs past the
    /// layout moves the anchors by their shape modes (see
    /// [`Observations::anchor_modes`]).
    pub fn problem(&self, full: Vec<f64>, free: Vec<usize>) -> CalibrationProblem<'a> {
        self.problem_on(&self.train, full, free)
    }

    /// As [`Observations::problem`], over the poses `idx` (indices into
    /// `data.poses`): the folds of a cross-validation.
    pub fn problem_on(
        &self,
        idx: &[usize],
        full: Vec<f64>,
        free: Vec<usize>,
    ) -> CalibrationProblem<'a> {
        let with_modes = full.len() > self.chain.layout.len();
        let p = CalibrationProblem::new(
            self.chain,
            self.anchors.clone(),
            idx.iter().map(|&i| &self.data.poses[i]).collect(),
            full,
            free,
        );
        match (&self.anchor_modes, with_modes) {
            (Some(m), true) => p.with_anchor_modes(m.clone()),
            _ => p,
        }
    }

    /// Use `anchors` from now on (the rig's, identified), with the string
    /// zero offsets `offsets_mm` fitted beside them (zeros when they were
    /// not identified): every pose's T located again, from where it was
    /// located before (which side of a plane of anchors it is on does not
    /// change by a millimetre's correction). The offsets count here because
    /// the anchors were fitted with them: where the two trade (an anchor
    /// moved along its string against that string's offset), the anchors
    /// alone would locate T inconsistently with the fit.
    pub fn set_anchors(&mut self, anchors: Vec<Vector3<f64>>, offsets_mm: &[f64]) -> Result<()> {
        let hints: Vec<Option<Vector3<f64>>> = self.measured.iter().copied().map(Some).collect();
        let (measured, located) =
            locate_all(self.data, &anchors, self.rig.r_mm, offsets_mm, &hints)?;
        self.anchors = anchors;
        self.measured = measured;
        self.located = located;
        Ok(())
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
            before: ErrorStats::of(&idx.iter().map(|&i| before[i]).collect::<Vec<_>>()),
            after: ErrorStats::of(&idx.iter().map(|&i| after[i]).collect::<Vec<_>>()),
        };
        Stats {
            train: split(&self.train),
            test: split(&self.test),
            confirmation: None,
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

    /// Where the split came from: `file`, or how it was chosen.
    pub fn split_source(&self, opts: &IdentifyOptions) -> String {
        let (data, obs) = (self.data, self);
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
            obs.test.len(),
            data.poses.len(),
            opts.seed
        )
    }
}

/// T at every pose of `data` (the rig frame): located from the strings
/// with `anchors`, `r_mm` and each string's zero offset (`offsets_mm`; none
/// given count zero), on the side of each `hints` point, or as measured;
/// and the multilateration results of string poses.
pub(crate) fn locate_all(
    data: &Dataset,
    anchors: &[Vector3<f64>],
    r_mm: f64,
    offsets_mm: &[f64],
    hints: &[Option<Vector3<f64>>],
) -> Result<(Vec<Vector3<f64>>, Vec<Located>)> {
    let mut measured = Vec::with_capacity(data.poses.len());
    let mut located = Vec::new();
    for (pose, hint) in data.poses.iter().zip(hints) {
        match &pose.measurement {
            Measurement::Strings(l) => {
                let dist: Vec<f64> = l
                    .iter()
                    .enumerate()
                    .map(|(k, v)| v + r_mm + offsets_mm.get(k).copied().unwrap_or(0.0))
                    .collect();
                let loc = measure::locate(anchors, &dist, hint.as_ref())
                    .map_err(|e| Error::field("poses", format!("pose {}: {e}", pose.id)))?;
                measured.push(loc.point);
                located.push(loc);
            }
            Measurement::Point(p) => measured.push(*p),
        }
    }
    Ok((measured, located))
}

/// Most poses [`Observations::flange_orientation_sigma`] looks at: an RMS over
/// a few hundred poses is as good as over all 11,911 of a grid.
pub const ORIENTATION_POSES: usize = 500;

/// Fewest held-out poses in either half of [`confirmation_split`]: with
/// fewer, the held-out poses are not halved (a paired test on a handful of
/// poses decides little, and a handful confirms little).
pub const MIN_CONFIRMATION: usize = 10;

/// The held-out poses `test` (session order) split into a gate half and a
/// confirmation half: alternate poses, the first to the gate. Alternating
/// in session order rather than drawing at random keeps both halves spread
/// alike over the session (time, temperature, a drift) and over the
/// workspace a plan walks through, needs no seed, and gives a recording
/// and its effect-free twin with the same split the same halves. `None`
/// with fewer than twice [`MIN_CONFIRMATION`] held-out poses.
pub fn confirmation_split(test: &[usize]) -> Option<(Vec<usize>, Vec<usize>)> {
    if test.len() < 2 * MIN_CONFIRMATION {
        return None;
    }
    let gate = test.iter().step_by(2).copied().collect();
    let confirmation = test.iter().skip(1).step_by(2).copied().collect();
    Some((gate, confirmation))
}

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

/// The paper's closed form against least squares over every pose (rigs
/// with at least four anchors).
pub fn closed_form_comparison(obs: &Observations) -> Option<ClosedFormComparison> {
    if obs.anchors.len() < 4 {
        return None;
    }
    let r = obs.rig.r_mm;
    let mut d2 = Vec::new();
    let mut mirrored = 0;
    for (pose, loc) in obs.data.poses.iter().zip(&obs.located) {
        if let Measurement::Strings(l) = &pose.measurement {
            if let Ok(p) = measure::paper_closed_form(&obs.anchors, l[0], l[2], l[3], r) {
                if measure::is_paper_mirror(&obs.anchors, &p, &loc.point) {
                    mirrored += 1;
                }
                d2.push((p - loc.point).norm());
            }
        }
    }
    ClosedFormComparison::from_distances(&d2, mirrored)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn confirmation_split_alternates_and_needs_enough_poses() {
        let test: Vec<usize> = (0..45).map(|i| 3 * i + 1).collect();
        let (gate, confirmation) = confirmation_split(&test).unwrap();
        assert_eq!(gate.len(), 23);
        assert_eq!(confirmation.len(), 22);
        assert_eq!(&gate[..3], &[1, 7, 13]);
        assert_eq!(&confirmation[..3], &[4, 10, 16]);
        let mut all: Vec<usize> = gate.iter().chain(&confirmation).copied().collect();
        all.sort_unstable();
        assert_eq!(all, test);
        assert!(confirmation_split(&test[..2 * MIN_CONFIRMATION - 1]).is_none());
        assert!(confirmation_split(&test[..2 * MIN_CONFIRMATION]).is_some());
    }
}
