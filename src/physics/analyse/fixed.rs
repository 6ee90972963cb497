//! The model so far linearised once, and candidates fitted against it.
//!
//! A data-driven correction is tried at up to six targets times eight or
//! more knot counts at each located place, each beside the same geometry
//! and accepted effects. Linearising the whole model for every candidate
//! (the robot's Jacobian at every train pose) cost most of the analysis of
//! a long session. Here the train rows of the model so far are visited
//! once: their residuals, their derivative rows and, per pose, T's
//! derivatives by each joint angle ([`PoseFrame`]). A candidate's columns
//! are then formed from its basis at each pose by the same arithmetic as
//! [`EffectProblem::rows`], and only its own blocks of the normal
//! equations (against the base columns and against itself) are
//! accumulated; the base block is the one made once. The normal
//! equations are the same numbers, summed in the same order, as a full
//! pass with the candidate appended at zero (a candidate at zero does not
//! move the model).

use std::cell::RefCell;
use std::rc::Rc;

use nalgebra::DMatrix;

use super::normals::{Appended, BaseFactors, FOLDS, FoldAccumulator, Normals, cv_sse};
use super::{Inputs, State};
use crate::physics::effects::{Basis, EffectModel, Kind, live_knots};
use crate::physics::problem::{EffectProblem, PoseFrame, RowDir};

/// The train rows of the model so far (geometry and accepted effects at
/// their fitted values), linearised once.
pub(super) struct FixedBase {
    /// Columns of the model so far (free geometry, then the accepted
    /// effects' coefficients).
    pub(super) n_base: usize,
    /// Its normal equations, by fold.
    pub(super) nm: Normals,
    /// Its cross-validated SSE (the score a candidate must beat; made by
    /// [`Self::new`] only).
    pub(super) cv0: f64,
    /// Strings of the rig (0 for points).
    m: usize,
    /// Fold of each train position.
    fold_of: Vec<usize>,
    /// Per train pose (position in `obs.train`): its frame.
    frames: Vec<PoseFrame>,
    /// Per row: the train position of its pose, its residual, what it
    /// measures and its `n_base` derivatives, the nonzero ones only (a
    /// data-driven correction's row is nonzero at two knots of dozens):
    /// row `i`'s are `row_cols[row_start[i]..row_start[i + 1]]` with their
    /// values in `row_vals`.
    row_pos: Vec<usize>,
    r: Vec<f64>,
    dirs: Vec<RowDir>,
    row_start: Vec<usize>,
    row_cols: Vec<usize>,
    row_vals: Vec<f64>,
    /// [`Self::factors`] made so far, by base column set.
    factors: RefCell<Vec<(Vec<usize>, Rc<BaseFactors>)>>,
}

impl FixedBase {
    /// One pass over the train rows at `state`'s model, split by the
    /// cross-validation folds.
    pub(super) fn new(inputs: &Inputs, state: &State) -> Self {
        let mut fixed = Self::of(
            inputs,
            &state.p,
            state.accepted.clone(),
            inputs.fold_of.clone(),
        );
        let (a, b, _) = fixed.nm.total();
        let base: Vec<usize> = (0..fixed.n_base).collect();
        fixed.cv0 = cv_sse(&fixed.nm, &a, &b, &base);
        fixed
    }

    /// One pass over the train rows of geometry `p` with `effects`, the
    /// rows split by `fold_of` (fold of each train position).
    pub(super) fn of(
        inputs: &Inputs,
        p: &[f64],
        effects: Vec<EffectModel>,
        fold_of: Vec<usize>,
    ) -> Self {
        let Inputs { obs, ctx, free, .. } = inputs;
        let problem =
            EffectProblem::of_observations(obs, ctx, obs.train.clone(), p, free.clone(), effects);
        let x0 = problem.x0();
        let n_base = x0.len();
        // The normal equations in the same pass as the rows kept.
        let mut acc = FoldAccumulator::new(n_base);
        let mut frames = vec![PoseFrame::default(); obs.train.len()];
        let n_rows = problem.poses.len() * problem.rows_per_pose();
        let mut row_pos = Vec::with_capacity(n_rows);
        let mut r = Vec::with_capacity(n_rows);
        let mut dirs = Vec::with_capacity(n_rows);
        let mut row_start = Vec::with_capacity(n_rows + 1);
        let mut row_cols = Vec::new();
        let mut row_vals = Vec::new();
        row_start.push(0);
        problem.rows_framed(
            &x0,
            |pos, frame| frames[pos].clone_from(frame),
            |pos, res, row, dir| {
                acc.add(fold_of[pos], res, row);
                row_pos.push(pos);
                r.push(res);
                dirs.push(dir);
                for (c, &v) in row.iter().enumerate().filter(|(_, v)| **v != 0.0) {
                    row_cols.push(c);
                    row_vals.push(v);
                }
                row_start.push(row_cols.len());
            },
        );
        FixedBase {
            n_base,
            nm: acc.finish(),
            cv0: f64::NAN,
            m: obs.data.n_strings,
            fold_of,
            frames,
            row_pos,
            r,
            dirs,
            row_start,
            row_cols,
            row_vals,
            factors: RefCell::new(Vec::new()),
        }
    }

    /// Row `row`'s nonzero base derivatives: their columns and values.
    fn base_row(&self, row: usize) -> (&[usize], &[f64]) {
        let span = self.row_start[row]..self.row_start[row + 1];
        (&self.row_cols[span.clone()], &self.row_vals[span])
    }

    /// The normal equations, by fold, of the model so far with `kind`
    /// appended at zero: its columns after the base's. The same as
    /// [`normals`] of that augmented problem.
    pub(super) fn with(&self, inputs: &Inputs, kind: &Kind) -> Normals {
        let nb = self.n_base;
        let k = kind.n_coef();
        let n = nb + k;
        let Appended { cross, own, g, .. } = self.appended(inputs, kind);
        let a = (0..FOLDS)
            .map(|f| {
                let base = &self.nm.a[f];
                DMatrix::from_fn(n, n, |i, j| {
                    let (i, j) = if i <= j { (i, j) } else { (j, i) };
                    if j < nb {
                        base[(i, j)]
                    } else if i < nb {
                        cross[f][(j - nb) * nb + i]
                    } else {
                        own[f][(i - nb) * k + (j - nb)]
                    }
                })
            })
            .collect();
        let b = (0..FOLDS)
            .map(|f| {
                let mut b = self.nm.b[f].clone();
                b.extend_from_slice(&g[f]);
                b
            })
            .collect();
        Normals {
            n,
            a,
            b,
            rr: self.nm.rr.clone(),
            rows: self.nm.rows,
        }
    }

    /// Per train pose, what a correction of one scalar (a joint's angle,
    /// a string's reading: `probe`'s target) moves: `Σ v r` and `Σ v²` over
    /// the pose's rows, `v` each row's derivative by the scalar. Any
    /// correction of that target is a weight per pose times this pattern,
    /// so [`Self::drop_alone`] screens a scan of them without the rows.
    pub(super) fn pose_patterns(&self, inputs: &Inputs, probe: &Kind) -> Vec<(f64, f64)> {
        let t = self.target_patterns(inputs, probe);
        (0..t.start.len() - 1)
            .map(|pos| (t.g[pos * t.per], t.own[pos * t.per * t.per]))
            .collect()
    }

    /// Per train pose, the blocks a data-driven correction of `probe`'s
    /// target adds with one knot at weight 1 (its `per` coefficients).
    /// A correction of that target at any knots is, at each pose, its hat
    /// weights times these ([`Self::appended_by_weights`]): the rows are
    /// visited once per target rather than once per candidate.
    pub(super) fn target_patterns(&self, inputs: &Inputs, probe: &Kind) -> TargetPatterns {
        let Inputs { obs, ctx, .. } = inputs;
        // Knots beyond every value: knot 0's coefficients weigh 1 at every
        // pose.
        let probe = match probe {
            Kind::DataDriven {
                target,
                target_index,
                driver,
                driver_index,
                ..
            } => Kind::DataDriven {
                target: *target,
                target_index: *target_index,
                driver: *driver,
                driver_index: *driver_index,
                knots: vec![f64::MAX, f64::MAX],
                period: None,
                range: None,
                axis: None,
            },
            other => other.clone(),
        };
        let per = (probe.n_coef() / 2).max(1);
        let (nb, n_pose) = (self.n_base, obs.train.len());
        let mut t = TargetPatterns {
            per,
            start: Vec::with_capacity(n_pose + 1),
            cols: Vec::new(),
            cross: Vec::new(),
            own: vec![0.0; n_pose * per * per],
            g: vec![0.0; n_pose * per],
        };
        t.start.push(0);
        let mut buf = Basis::default();
        let mut dt = vec![nalgebra::Vector3::zeros(); per];
        // The pose's cross sums per coefficient, over the base columns its
        // rows touch (in the order first touched, sorted at the flush).
        let mut scratch = vec![vec![0.0; nb]; per];
        let mut touched: Vec<usize> = Vec::new();
        let mut mark = vec![false; nb];
        let mut v = vec![0.0; per];
        let mut last = usize::MAX;
        let flush = |t: &mut TargetPatterns,
                     scratch: &mut [Vec<f64>],
                     touched: &mut Vec<usize>,
                     mark: &mut [bool]| {
            touched.sort_unstable();
            for row in scratch.iter_mut() {
                t.cross.extend(touched.iter().map(|&i| row[i]));
                touched.iter().for_each(|&i| row[i] = 0.0);
            }
            t.cols.extend_from_slice(touched);
            touched.iter().for_each(|&i| mark[i] = false);
            touched.clear();
            t.start.push(t.cols.len());
        };
        for (row, &pos) in self.row_pos.iter().enumerate() {
            if pos != last {
                // The pose before is complete (a pose without rows, were
                // there one, would be an empty entry).
                while t.start.len() <= pos {
                    flush(&mut t, &mut scratch, &mut touched, &mut mark);
                }
                last = pos;
                ctx.basis(&probe, obs.train[pos], &mut buf);
                for (c, d) in dt.iter_mut().enumerate() {
                    *d = self.frames[pos].d_point(&buf, c);
                }
            }
            for (c, x) in v.iter_mut().enumerate() {
                *x = PoseFrame::column(self.dirs[row], &dt[c], &buf, c, self.m);
            }
            let r = self.r[row];
            let (idx, vals) = self.base_row(row);
            for c in 0..per {
                if v[c] == 0.0 {
                    continue;
                }
                t.g[pos * per + c] += v[c] * r;
                for c2 in 0..per {
                    t.own[(pos * per + c) * per + c2] += v[c] * v[c2];
                }
                for (&i, &ra) in idx.iter().zip(vals) {
                    scratch[c][i] += ra * v[c];
                    if !mark[i] {
                        mark[i] = true;
                        touched.push(i);
                    }
                }
            }
        }
        while t.start.len() <= n_pose {
            flush(&mut t, &mut scratch, &mut touched, &mut mark);
        }
        t
    }

    /// [`Self::appended`] of the data-driven correction `kind` from its
    /// target's [`Self::target_patterns`] `t`: the same blocks to
    /// rounding (each pose's hat weights times the pattern, rather than
    /// the pattern's rows each times the weight).
    pub(super) fn appended_by_weights(
        &self,
        inputs: &Inputs,
        t: &TargetPatterns,
        kind: &Kind,
    ) -> Appended {
        let Inputs { obs, ctx, .. } = inputs;
        let (nb, k, per) = (self.n_base, kind.n_coef(), t.per);
        let mut cross = vec![vec![0.0; nb * k]; FOLDS];
        let mut own = vec![vec![0.0; k * k]; FOLDS];
        let mut g = vec![vec![0.0; k]; FOLDS];
        for pos in 0..t.start.len() - 1 {
            let live = live_knots(ctx.knot_weights(kind, obs.train[pos]));
            let f = self.fold_of[pos];
            let (s, e) = (t.start[pos], t.start[pos + 1]);
            let cols = &t.cols[s..e];
            let len = e - s;
            for &(kn, w) in live.iter().filter(|(_, w)| *w != 0.0) {
                for c in 0..per {
                    let a = kn * per + c;
                    let src = &t.cross[s * per + c * len..s * per + (c + 1) * len];
                    let dst = &mut cross[f][a * nb..(a + 1) * nb];
                    for (&i, &val) in cols.iter().zip(src) {
                        dst[i] += w * val;
                    }
                    g[f][a] += w * t.g[pos * per + c];
                    for &(kn2, w2) in live.iter().filter(|(_, w)| *w != 0.0) {
                        for c2 in 0..per {
                            let b = kn2 * per + c2;
                            if a <= b {
                                own[f][a * k + b] += w * w2 * t.own[(pos * per + c) * per + c2];
                            }
                        }
                    }
                }
            }
        }
        Appended {
            nb,
            k,
            cross,
            own,
            g,
        }
    }

    /// How much `kind` (a correction of the scalar `patterns` were made
    /// for, see [`Self::pose_patterns`]) alone would take from the train
    /// residual's sum of squares, the model so far held fixed (mm²): a
    /// screen for a scan of many candidates, in one pass over the poses.
    pub(super) fn drop_alone(&self, inputs: &Inputs, kind: &Kind, patterns: &[(f64, f64)]) -> f64 {
        let Inputs { obs, ctx, .. } = inputs;
        let Kind::DataDriven { knots, .. } = kind else {
            return 0.0;
        };
        let k = knots.len();
        let mut a = DMatrix::<f64>::zeros(k, k);
        let mut g = nalgebra::DVector::<f64>::zeros(k);
        for (pos, &(vr, vv)) in patterns.iter().enumerate() {
            let w = ctx.knot_weights(kind, obs.train[pos]);
            for &(c, wc) in &w {
                g[c] += wc * vr;
                for &(c2, wc2) in &w {
                    a[(c, c2)] += wc * wc2 * vv;
                }
            }
        }
        for i in 0..k {
            a[(i, i)] += 1e-12 * a[(i, i)].max(1e-300);
        }
        a.cholesky().map_or(0.0, |c| g.dot(&c.solve(&g)))
    }

    /// The base columns `base` factored for block elimination (made once
    /// per column set and kept: a place's candidates share one or two).
    pub(super) fn factors(&self, base: &[usize]) -> Rc<BaseFactors> {
        let mut memo = self.factors.borrow_mut();
        if let Some((_, f)) = memo.iter().find(|(b, _)| b == base) {
            return f.clone();
        }
        let f = Rc::new(BaseFactors::new(&self.nm, base));
        memo.push((base.to_vec(), f.clone()));
        f
    }

    /// Per fold, the candidate's cross block with the base (k × nb, one
    /// base row per candidate column), its own block (k × k, upper) and
    /// its `Jᵀr`.
    pub(super) fn appended(&self, inputs: &Inputs, kind: &Kind) -> Appended {
        let Inputs { obs, ctx, .. } = inputs;
        let fold_of = &self.fold_of;
        let nb = self.n_base;
        let k = kind.n_coef();
        let mut cross = vec![vec![0.0; nb * k]; FOLDS];
        let mut own = vec![vec![0.0; k * k]; FOLDS];
        let mut g = vec![vec![0.0; k]; FOLDS];
        let mut buf = Basis::default();
        // The coefficients live at the current pose and T's derivative by
        // each; then their columns at the current row.
        let mut live: Vec<(usize, nalgebra::Vector3<f64>)> = Vec::new();
        let mut col: Vec<(usize, f64)> = Vec::new();
        let mut last = usize::MAX;
        for (row, &pos) in self.row_pos.iter().enumerate() {
            if pos != last {
                last = pos;
                ctx.basis(kind, obs.train[pos], &mut buf);
                live.clear();
                let frame = &self.frames[pos];
                live.extend(
                    buf.live
                        .iter()
                        .copied()
                        .filter(|&c| touches(&buf, c, frame.d_theta.len(), self.m))
                        .map(|c| (c, frame.d_point(&buf, c))),
                );
            }
            col.clear();
            col.extend(
                live.iter()
                    .map(|(c, dt)| (*c, PoseFrame::column(self.dirs[row], dt, &buf, *c, self.m)))
                    .filter(|&(_, v)| v != 0.0),
            );
            if col.is_empty() {
                continue;
            }
            let f = fold_of[pos];
            let (cross, own, g) = (&mut cross[f], &mut own[f], &mut g[f]);
            let r = self.r[row];
            // Column by column over the base row's nonzeros (a zero would
            // add a zero product: the same sums).
            let (idx, vals) = self.base_row(row);
            for &(c, v) in &col {
                let cross = &mut cross[c * nb..(c + 1) * nb];
                for (&i, &ra) in idx.iter().zip(vals) {
                    cross[i] += ra * v;
                }
            }
            for (i, &(c, v)) in col.iter().enumerate() {
                g[c] += v * r;
                for &(c2, v2) in &col[i..] {
                    own[c * k + c2] += v * v2;
                }
            }
        }
        Appended {
            nb,
            k,
            cross,
            own,
            g,
        }
    }
}

/// Per train pose, what one knot of a data-driven correction at weight 1
/// adds to the normal equations ([`FixedBase::target_patterns`]): pose
/// `p`'s base columns are `cols[start[p]..start[p + 1]]` (length `len`),
/// its cross sums of coefficient `c` against them
/// `cross[start[p] * per + c * len..][..len]`, its own block
/// `own[(p * per + c) * per + c2]` and its `Jᵀr` `g[p * per + c]`.
pub(super) struct TargetPatterns {
    per: usize,
    start: Vec<usize>,
    cols: Vec<usize>,
    cross: Vec<f64>,
    own: Vec<f64>,
    g: Vec<f64>,
}

/// Whether coefficient `c` of a basis over `n` joints and `m` strings
/// moves anything at this pose (a local correction's other knots do not).
fn touches(buf: &Basis, c: usize, n: usize, m: usize) -> bool {
    buf.thermal[c] != 0.0
        || buf.dq[c * n..(c + 1) * n].iter().any(|&v| v != 0.0)
        || buf.dl[c * m..(c + 1) * m].iter().any(|&v| v != 0.0)
        || buf.dp[c * 3..(c + 1) * 3].iter().any(|&v| v != 0.0)
}

/// The accepted effects with `kind` appended at zero: the effect list a
/// candidate is linearised with.
pub(super) fn with_candidate(accepted: &[EffectModel], kind: &Kind) -> Vec<EffectModel> {
    let mut effects = accepted.to_vec();
    effects.push(EffectModel::zero(kind.clone()));
    effects
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{IdentifyOptions, NoProgress, Observations, geometric};
    use crate::model::{Dataset, Rig, Robot};
    use crate::physics::analyse::normals::{normals, unaliased};
    use crate::physics::effects::{CorrectionDriver, CorrectionTarget};
    use crate::physics::simulate;

    /// A simulated string session (ER3A, four strings) and the first 150
    /// poses of the real UR10 tracker recording (points).
    fn sessions() -> Vec<(Robot, Rig, Dataset)> {
        let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
            "robot": "er3a", "n_poses": 120, "seed": 3,
            "effects": [{"effect": "joint_compliance", "joint": 2, "size_x_noise": 5}]
        }))
        .unwrap();
        let sim = simulate::generate(&spec).unwrap();
        let dir = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/real_ur10_ipa_random"
        );
        let read = |f: &str| std::fs::read_to_string(format!("{dir}/{f}")).unwrap();
        let robot = Robot::from_json(&read("robot.json")).unwrap();
        let rig = Rig::from_json(&read("rig.json")).unwrap();
        let mut data = Dataset::from_csv(read("poses.csv").as_bytes(), &robot, &rig).unwrap();
        data.poses.truncate(150);
        vec![(sim.robot, sim.rig, sim.dataset), (robot, rig, data)]
    }

    /// Candidates of every target (a joint's angle, T, a string's reading)
    /// and a named effect, for a session of `n` joints and `m` strings.
    fn candidates(n: usize, m: usize) -> Vec<Kind> {
        let mut kinds = vec![
            Kind::DataDriven {
                target: CorrectionTarget::JointAngle,
                target_index: Some(n - 1),
                driver: CorrectionDriver::JointAngle,
                driver_index: Some(1),
                knots: vec![-1.0, -0.3, 0.2, 1.1],
                period: None,
                range: None,
                axis: None,
            },
            Kind::DataDriven {
                target: CorrectionTarget::Point,
                target_index: None,
                driver: CorrectionDriver::Time,
                driver_index: None,
                knots: vec![0.0, 50.0, 100.0, 500.0],
                period: None,
                range: None,
                axis: None,
            },
            Kind::JointPeriodic {
                joint_index: 0,
                harmonic: 2,
            },
            // T in the spherical frame about the rig's origin, by azimuth.
            Kind::DataDriven {
                target: CorrectionTarget::PointSpherical,
                target_index: None,
                driver: CorrectionDriver::Workspace,
                driver_index: Some(3),
                knots: vec![-3.0, -1.0, 0.5, 3.0],
                period: None,
                range: None,
                axis: None,
            },
            // The same by the line of sight's component along the flange's z.
            Kind::DataDriven {
                target: CorrectionTarget::PointSpherical,
                target_index: None,
                driver: CorrectionDriver::LineOfSight,
                driver_index: Some(2),
                knots: vec![-1.0, -0.3, 0.4, 1.0],
                period: None,
                range: None,
                axis: None,
            },
            // Periodic: the driver taken modulo the period, the last knot
            // joined to the first.
            Kind::DataDriven {
                target: CorrectionTarget::JointAngle,
                target_index: Some(1),
                driver: CorrectionDriver::JointAngle,
                driver_index: Some(1),
                knots: vec![0.0, 0.3, 0.6, 0.9],
                period: Some(1.2),
                range: Some([-2.0, 2.0]),
                axis: None,
            },
        ];
        // The tool point in the flange frame, the instrument's scale and a
        // joint's zero by the clock; a joint's angle by its gravity torque.
        let by_clock = |target, target_index| Kind::DataDriven {
            target,
            target_index,
            driver: CorrectionDriver::Time,
            driver_index: None,
            knots: vec![0.0, 60.0, 300.0, 900.0],
            period: None,
            range: None,
            axis: None,
        };
        kinds.push(by_clock(CorrectionTarget::ToolPoint, None));
        kinds.push(by_clock(CorrectionTarget::InstrumentScale, None));
        // The frame's shape (the strings' or the instrument's; nine
        // coefficients per knot).
        kinds.push(by_clock(CorrectionTarget::RigShape, None));
        kinds.push(by_clock(CorrectionTarget::JointAngle, Some(1)));
        kinds.push(Kind::DataDriven {
            target: CorrectionTarget::JointAngle,
            target_index: Some(1),
            driver: CorrectionDriver::GravityTorque,
            driver_index: Some(1),
            knots: vec![-0.5, -1e-9, 1e-9, 0.5],
            period: None,
            range: None,
            axis: None,
        });
        if m > 0 {
            kinds.push(Kind::DataDriven {
                target: CorrectionTarget::StringReading,
                target_index: Some(m - 1),
                driver: CorrectionDriver::StringLength,
                driver_index: Some(m - 1),
                knots: vec![100.0, 400.0, 700.0, 1000.0],
                period: None,
                range: None,
                axis: None,
            });
            kinds.push(Kind::DataDriven {
                target: CorrectionTarget::StringReading,
                target_index: Some(0),
                driver: CorrectionDriver::StringLength,
                driver_index: Some(0),
                knots: vec![0.0, 10.0, 20.0, 30.0, 40.0, 50.0],
                period: Some(60.0),
                range: Some([100.0, 1500.0]),
                axis: None,
            });
            // The frame deflected by the strings' pull (its knots are the
            // anchors).
            if m >= 3 {
                kinds.push(Kind::frame_deflection(m));
            }
            // By its last change of length, jumping at zero.
            kinds.push(Kind::DataDriven {
                target: CorrectionTarget::StringReading,
                target_index: Some(0),
                driver: CorrectionDriver::StringMove,
                driver_index: Some(0),
                knots: vec![-200.0, -1e-6, 1e-6, 200.0],
                period: None,
                range: None,
                axis: None,
            });
            // By the string's direction: its angle from an axis.
            kinds.push(Kind::DataDriven {
                target: CorrectionTarget::StringReading,
                target_index: Some(m - 1),
                driver: CorrectionDriver::StringDirection,
                driver_index: Some(m - 1),
                knots: vec![0.0, 0.1, 0.2, 0.4],
                period: None,
                range: None,
                axis: Some([0.0, 0.6, 0.8]),
            });
            // Every string's scale by the clock.
            kinds.push(Kind::DataDriven {
                target: CorrectionTarget::ReadingScale,
                target_index: None,
                driver: CorrectionDriver::Time,
                driver_index: None,
                knots: vec![0.0, 60.0, 300.0, 900.0],
                period: None,
                range: None,
                axis: None,
            });
            // Its zero and scale by its direction (two coefficients per
            // knot).
            kinds.push(Kind::DataDriven {
                target: CorrectionTarget::StringZeroScale,
                target_index: Some(0),
                driver: CorrectionDriver::StringDirection,
                driver_index: Some(0),
                knots: vec![0.0, 0.3, 0.6, 1.2],
                period: None,
                range: None,
                axis: Some([0.6, 0.0, 0.8]),
            });
        }
        kinds
    }

    /// For each session: its inputs' parts, the state with one accepted
    /// effect, and `f` called with everything.
    fn each_session(mut f: impl FnMut(&Inputs, &State, &FixedBase)) {
        for (robot, rig, data) in sessions() {
            let po = IdentifyOptions::default();
            let obs = Observations::new(&robot, &rig, &data, &po).unwrap();
            let geo = geometric(&obs, &po, &NoProgress).unwrap();
            let inputs = Inputs::new(&obs, &geo);
            let state = State {
                p: geo.after.values.clone(),
                accepted: vec![EffectModel {
                    kind: Kind::JointPeriodic {
                        joint_index: 1,
                        harmonic: 1,
                    },
                    coef: vec![1e-4, -2e-4],
                }],
                findings: vec![],
                notes: vec![],
                rejected: vec![],
                final_fit: None,
                jumps_s: vec![],
                wrong_way: vec![],
            };
            let fixed = FixedBase::new(&inputs, &state);
            f(&inputs, &state, &fixed);
        }
    }

    fn problem_with<'a>(inputs: &'a Inputs, state: &State, kind: &Kind) -> EffectProblem<'a> {
        EffectProblem::of_observations(
            inputs.obs,
            &inputs.ctx,
            inputs.obs.train.clone(),
            &state.p,
            inputs.free.clone(),
            with_candidate(&state.accepted, kind),
        )
    }

    /// The fixed base's normal equations of a candidate equal a full
    /// linearisation of the model with the candidate appended, on a
    /// string and a point session, for every correction target and a
    /// named effect, with an effect already accepted.
    #[test]
    fn candidate_normals_equal_a_full_pass() {
        each_session(|inputs, state, fixed| {
            for kind in candidates(inputs.ctx.n_joints, inputs.ctx.anchors.len()) {
                let problem = problem_with(inputs, state, &kind);
                let full = normals(&problem, &problem.x0(), &inputs.fold_of);
                let got = fixed.with(inputs, &kind);
                assert_eq!((got.n, got.rows), (full.n, full.rows));
                for f in 0..FOLDS {
                    let scale = full.a[f].amax().max(1e-300);
                    let diff = (&got.a[f] - &full.a[f]).amax();
                    assert!(diff <= 1e-12 * scale, "{kind:?} fold {f}: A off by {diff}");
                    for (x, y) in got.b[f].iter().zip(&full.b[f]) {
                        assert!((x - y).abs() <= 1e-12 * (1.0 + y.abs()), "{kind:?}: b");
                    }
                    assert_eq!(got.rr[f], full.rr[f]);
                }
                let (a, _, _) = got.total();
                assert!((fixed.n_base..got.n).any(|c| a[(c, c)] > 0.0), "{kind:?}");
            }
        });
    }

    /// The alias check and the cross-validated SSE by block elimination
    /// against the base factored once equal those of the candidate's whole
    /// normal equations, for every candidate, with the whole base and with
    /// three columns held; a constant offset of a joint (aliased with its
    /// geometric offset) is dropped by both.
    #[test]
    fn block_elimination_equals_the_whole_block() {
        each_session(|inputs, _, fixed| {
            let n = inputs.ctx.n_joints;
            let mut kinds = candidates(n, inputs.ctx.anchors.len());
            kinds.push(Kind::DataDriven {
                target: CorrectionTarget::JointAngle,
                target_index: Some(1),
                driver: CorrectionDriver::JointAngle,
                driver_index: Some(1),
                knots: vec![0.0],
                period: None,
                range: None,
                axis: None,
            });
            let nb = fixed.n_base;
            let mut dropped = 0;
            for base in [(0..nb).collect::<Vec<_>>(), (3..nb).collect()] {
                let factors = fixed.factors(&base);
                for kind in &kinds {
                    let k = kind.n_coef();
                    let nm = fixed.with(inputs, kind);
                    let (a, b, _) = nm.total();
                    let own: Vec<usize> = (nb..nb + k).collect();
                    let whole = unaliased(&a, &base, &own);
                    let app = fixed.appended(inputs, kind);
                    let blocked: Vec<usize> = factors
                        .unaliased(&app, &(0..k).collect::<Vec<_>>())
                        .iter()
                        .map(|c| c + nb)
                        .collect();
                    assert_eq!(blocked, whole, "{kind:?}");
                    dropped += k - whole.len();
                    let mut all = base.clone();
                    all.extend(&whole);
                    let cv_whole = cv_sse(&nm, &a, &b, &all);
                    let cols: Vec<usize> = whole.iter().map(|c| c - nb).collect();
                    let cv_blocked = factors.cv_sse(&fixed.nm, &app, &cols);
                    // Rounding only: 1e-14 relative, but 5e-8 for the
                    // frame's shape on the strings (half its columns
                    // nearly aliased: an ill-conditioned solve either way).
                    assert!(
                        (cv_blocked - cv_whole).abs() <= 1e-6 * cv_whole,
                        "{kind:?}: {cv_blocked} vs {cv_whole}"
                    );
                }
            }
            assert!(dropped > 0, "no candidate column was aliased");
        });
    }

    /// A correction's blocks from its target's patterns (hat weights times
    /// one knot's sums per pose) equal those from its rows, for every
    /// correction by knots among the candidates, a periodic one included.
    #[test]
    fn blocks_from_patterns_equal_blocks_from_rows() {
        each_session(|inputs, _, fixed| {
            let n = inputs.ctx.n_joints;
            let mut kinds = candidates(n, inputs.ctx.anchors.len());
            kinds.push(Kind::DataDriven {
                target: CorrectionTarget::JointAngle,
                target_index: Some(0),
                driver: CorrectionDriver::JointAngle,
                driver_index: Some(0),
                knots: vec![0.0, 1.5, 3.0, 4.5],
                period: Some(6.0),
                range: None,
                axis: None,
            });
            let mut tried = 0;
            for kind in kinds {
                let Kind::DataDriven { target, .. } = &kind else {
                    continue;
                };
                if matches!(
                    target,
                    CorrectionTarget::RigShape | CorrectionTarget::FrameDeflection
                ) {
                    continue;
                }
                tried += 1;
                let rows = fixed.appended(inputs, &kind);
                let t = fixed.target_patterns(inputs, &kind);
                let pats = fixed.appended_by_weights(inputs, &t, &kind);
                for f in 0..FOLDS {
                    for (got, want) in [
                        (&pats.cross[f], &rows.cross[f]),
                        (&pats.own[f], &rows.own[f]),
                        (&pats.g[f], &rows.g[f]),
                    ] {
                        let scale = want.iter().fold(1e-300, |m, v| v.abs().max(m));
                        for (x, y) in got.iter().zip(want.iter()) {
                            assert!((x - y).abs() <= 1e-12 * scale, "{kind:?}: {x} vs {y}");
                        }
                    }
                }
            }
            assert!(tried >= 5);
        });
    }

    /// A basis writes no coefficient outside its live list, so reusing a
    /// buffer (which clears only the last pose's live rows) gives exactly
    /// a fresh buffer's basis, at every pose and for every candidate.
    #[test]
    fn a_reused_basis_equals_a_fresh_one_and_is_zero_outside_its_live_list() {
        each_session(|inputs, state, _| {
            let ctx = &inputs.ctx;
            let (n, m) = (ctx.n_joints, ctx.anchors.len());
            let mut kinds = candidates(n, m);
            kinds.extend(state.accepted.iter().map(|e| e.kind.clone()));
            let mut reused = Basis::default();
            for i in 0..ctx.poses.len() {
                for kind in &kinds {
                    ctx.basis(kind, i, &mut reused);
                    let mut fresh = Basis::default();
                    ctx.basis(kind, i, &mut fresh);
                    assert_eq!(
                        (
                            &reused.dq,
                            &reused.thermal,
                            &reused.dl,
                            &reused.dp,
                            &reused.live
                        ),
                        (&fresh.dq, &fresh.thermal, &fresh.dl, &fresh.dp, &fresh.live),
                        "{kind:?} at pose {i}"
                    );
                    for c in (0..kind.n_coef()).filter(|c| !fresh.live.contains(c)) {
                        assert!(!touches(&fresh, c, n, m), "{kind:?} writes {c} at pose {i}");
                    }
                }
            }
        });
    }

    /// The screen of a correction of one scalar equals the drop its own
    /// block of the full normal equations gives (`gᵀ A⁻¹ g`).
    #[test]
    fn drop_alone_equals_the_candidates_own_block() {
        each_session(|inputs, _, fixed| {
            for kind in candidates(inputs.ctx.n_joints, inputs.ctx.anchors.len()) {
                if !matches!(
                    kind,
                    Kind::DataDriven {
                        target: CorrectionTarget::JointAngle | CorrectionTarget::StringReading,
                        ..
                    }
                ) {
                    continue;
                }
                let nb = fixed.n_base;
                let k = kind.n_coef();
                let (a, b, _) = fixed.with(inputs, &kind).total();
                // The screen's jitter, for knots no pose reaches.
                let own = DMatrix::from_fn(k, k, |i, j| {
                    let v = a[(nb + i, nb + j)];
                    if i == j { v + 1e-12 * v.max(1e-300) } else { v }
                });
                let g = nalgebra::DVector::from_fn(k, |i, _| b[nb + i]);
                let want = g.dot(&own.clone().cholesky().unwrap().solve(&g));
                let patterns = fixed.pose_patterns(inputs, &kind);
                let got = fixed.drop_alone(inputs, &kind, &patterns);
                assert!(
                    (got - want).abs() <= 1e-6 * want.abs().max(1e-12),
                    "{kind:?}: {got} against {want}"
                );
            }
        });
    }

    /// The candidate's blocks of the normal equations (against the base
    /// columns, against itself, against the residuals) equal those formed
    /// from central finite differences of the residuals in each of its
    /// coefficients: its derivative columns are right.
    #[test]
    fn candidate_columns_match_finite_differences() {
        each_session(|inputs, state, fixed| {
            for kind in candidates(inputs.ctx.n_joints, inputs.ctx.anchors.len()) {
                let problem = problem_with(inputs, state, &kind);
                let x0 = problem.x0();
                let nb = fixed.n_base;
                let k = kind.n_coef();
                let residuals = |x: &[f64]| {
                    let mut r = Vec::new();
                    problem.rows(x, |_, v, _| r.push(v));
                    r
                };
                // Coefficients are radians, mm or mm per knot: a step of
                // 1e-6 is small against every one's scale of effect.
                let h = 1e-6;
                let fd: Vec<Vec<f64>> = (0..k)
                    .map(|c| {
                        let (mut xp, mut xm) = (x0.clone(), x0.clone());
                        xp[nb + c] += h;
                        xm[nb + c] -= h;
                        let (rp, rm) = (residuals(&xp), residuals(&xm));
                        rp.iter()
                            .zip(&rm)
                            .map(|(p, m)| (p - m) / (2.0 * h))
                            .collect()
                    })
                    .collect();
                let got = fixed.with(inputs, &kind);
                let (a, b, _) = got.total();
                let n_rows = fixed.r.len();
                let scale = (0..k).map(|c| a[(nb + c, nb + c)]).fold(1e-300, f64::max);
                for c in 0..k {
                    let jr: f64 = (0..n_rows).map(|i| fd[c][i] * fixed.r[i]).sum();
                    let tol = 1e-5 * (scale * fixed.nm.rr.iter().sum::<f64>()).sqrt();
                    assert!((b[nb + c] - jr).abs() <= tol, "{kind:?} Jr {c}");
                    for c2 in 0..k {
                        let jj: f64 = (0..n_rows).map(|i| fd[c][i] * fd[c2][i]).sum();
                        assert!(
                            (a[(nb + c, nb + c2)] - jj).abs() <= 1e-5 * scale,
                            "{kind:?}"
                        );
                    }
                    for col in 0..nb {
                        let jb: f64 = (0..n_rows)
                            .map(|i| {
                                let (idx, vals) = fixed.base_row(i);
                                idx.iter().position(|&j| j == col).map_or(0.0, |p| vals[p])
                                    * fd[c][i]
                            })
                            .sum();
                        let tol = 1e-5 * (scale * a[(col, col)]).sqrt().max(1e-300);
                        assert!((a[(col, nb + c)] - jb).abs() <= tol, "{kind:?} cross {col}");
                    }
                }
            }
        });
    }
}
