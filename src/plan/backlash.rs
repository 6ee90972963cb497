//! Backlash in a plan: each joint's dead band as the identification models
//! it ([`Kind::Backlash`](crate::physics::Kind::Backlash): `dq = b ·
//! sign(last move)`, plus a free offset at the poses reached before the
//! joint's first recorded move), predicted from the approach directions
//! of a visiting order.
//!
//! The directions are the ones `identify` computes from the recorded rows
//! ([`approach_directions`]): the first recorded pose has none (poses.csv
//! does not carry the move from home to it). Check poses are recorded
//! rows, so they count for the directions, but not for the fit.
//!
//! With `A` the information of the plan's other columns (geometry and the
//! effects in the selection) over the train poses, `B` their cross terms
//! with the dead bands and offsets and `C` the dead bands' and offsets'
//! own, the dead bands' covariance is the `b` block of `(C - Bᵀ A⁻¹ B)⁻¹`:
//! a joint whose direction follows the geometry (its own angle's offset
//! above all: one direction throughout is an offset) is badly determined
//! however many poses it is seen at. `A⁻¹` and each pose's part of `B`
//! and `C` are computed once; an order costs `O(N n p + n p²)`.
//!
//! Here too what the plan makes of it: the travel a tour ordered for
//! backlash may take ([`BACKLASH_TRAVEL_BOUND`]), the design built from
//! the plan's visits ([`backlash_design`]), and the report's dead bands
//! ([`BacklashTour`]) as predicted parameters and in words. The order
//! itself is made in `visits` (`Toured`).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::columns::{information, reading_directions};
use super::visits::VisitSpec;
use super::{Candidate, PredictedParam, Scene, design};
use crate::kinematics::JointParam;
use crate::physics::effects::step_direction;

/// A joint's dead band as the plan predicts it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BacklashSigma {
    /// Joint (1-based).
    pub joint: usize,
    /// Predicted 1-sigma of half the dead band (deg) with the tour
    /// planned; `None` when it is not determined: the joint's angle does
    /// not move the readings, or every pose is approached from one side
    /// (the dead band is then a joint offset).
    pub sigma_deg: Option<f64>,
    /// The same with the shortest tour.
    pub sigma_shortest_deg: Option<f64>,
    /// Correlation over the train poses of the joint's approach direction
    /// with its angle (near ±1 the dead band looks like an error growing
    /// with the angle).
    pub direction_angle_correlation: f64,
}

/// The tour ordered for backlash.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BacklashTour {
    /// The travel allowed, as a multiple of the shortest tour's.
    pub travel_bound: f64,
    /// The shortest tour's travel (deg).
    pub shortest_travel_deg: f64,
    /// Per joint.
    pub joints: Vec<BacklashSigma>,
}

/// Travel a tour ordered for backlash may take, over the shortest tour's:
/// a session's time is mostly the dwell at each pose (settling and
/// measuring, 20 s in the simulator's session against about 4 s of moving
/// at its 30 deg/s on the ER3A's planned tour), so a fifth more travel
/// costs about 3 % of it.
pub const BACKLASH_TRAVEL_BOUND: f64 = 1.2;

/// Moves the backlash tour's local search tries, at most, for a tour of
/// 40 poses or fewer (about ten passes over every move of a 40-pose
/// tour); a longer tour gets proportionally fewer, each move costing in
/// proportion to its length.
pub(super) const BACKLASH_SEARCH_BUDGET: usize = 20_000;

/// Prior size of a dead band and of an offset (rad): a joint offset's
/// tolerance, 0.1 deg, so that their columns are scaled like the
/// geometry's.
pub(super) const BACKLASH_SCALE_RAD: f64 = 0.1 * std::f64::consts::PI / 180.0;

/// Information a free offset carries a priori (in the scaled columns, a
/// millionth of a pose's): it keeps the first pose's offsets bounded where
/// they outnumber its readings, which they then absorb as in the fit, and
/// is too weak to determine a dead band that only an offset separates
/// from the geometry (one direction throughout).
const OFFSET_PRIOR: f64 = 1e-6;

/// One recorded pose of the tour as the dead bands see it.
pub(super) struct Visit {
    /// Commanded angles (rad).
    pub q_rad: Vec<f64>,
    /// For a train pose: its design rows (`m × p`, row-major, as in
    /// [`super::design::Pool`]) and, per joint, the readings' change per
    /// scaled unit of that joint's angle (`n × m`). `None` for a check pose.
    pub fitted: Option<(Vec<f64>, Vec<Vec<f64>>)>,
}

/// The dead bands' part of a plan's information, per pose.
pub(super) struct BacklashDesign {
    n: usize,
    p: usize,
    a_inv: DMatrix<f64>,
    q_rad: Vec<Vec<f64>>,
    /// Per visit, per joint: `J_iᵀ a_ij` (empty for check poses).
    g: Vec<Vec<DVector<f64>>>,
    /// Per visit: `a_ijᵀ a_ik` (`n × n`; empty for check poses).
    k: Vec<DMatrix<f64>>,
    /// Joints whose angle moves the readings at all.
    moves: Vec<bool>,
}

impl BacklashDesign {
    /// The design of `visits` (indexed as the orders given later will be)
    /// beside the other columns' information `a` over the train poses.
    pub fn new(a: &DMatrix<f64>, visits: &[Visit], n: usize) -> Option<Self> {
        let a_inv = a.clone().try_inverse()?;
        let p = a.nrows();
        let mut g = Vec::with_capacity(visits.len());
        let mut k = Vec::with_capacity(visits.len());
        let mut diag = vec![0.0; n];
        for v in visits {
            let Some((rows, per_joint)) = &v.fitted else {
                g.push(vec![]);
                k.push(DMatrix::zeros(0, 0));
                continue;
            };
            let m = rows.len() / p;
            let jm = DMatrix::from_row_slice(m, p, rows);
            g.push(
                per_joint
                    .iter()
                    .map(|aj| jm.transpose() * DVector::from_column_slice(aj))
                    .collect(),
            );
            let kk = DMatrix::from_fn(n, n, |r, c| dot(&per_joint[r], &per_joint[c]));
            for (j, d) in diag.iter_mut().enumerate() {
                *d += kk[(j, j)];
            }
            k.push(kk);
        }
        let top = diag.iter().cloned().fold(0.0, f64::max);
        Some(BacklashDesign {
            n,
            p,
            a_inv,
            q_rad: visits.iter().map(|v| v.q_rad.clone()).collect(),
            g,
            k,
            moves: diag.iter().map(|&d| d > 1e-9 * top && d > 0.0).collect(),
        })
    }

    /// Per joint, the direction it arrives from at each visit of `order`
    /// (0 before its first recorded move), as identify computes them.
    fn directions(&self, order: &[usize]) -> Vec<Vec<f64>> {
        let mut dir = vec![0.0; self.n];
        let mut out = Vec::with_capacity(order.len());
        for (k, &i) in order.iter().enumerate() {
            if k > 0 {
                let prev = &self.q_rad[order[k - 1]];
                for (j, d) in dir.iter_mut().enumerate() {
                    *d = step_direction(prev[j], self.q_rad[i][j], *d);
                }
            }
            out.push(dir.clone());
        }
        out
    }

    /// `B` (`p × 2n`) and `C` (`2n × 2n`, the offsets' prior included) of
    /// the order: columns `0..n` the dead bands, `n..2n` the offsets.
    pub fn blocks(&self, order: &[usize]) -> (DMatrix<f64>, DMatrix<f64>) {
        let n = self.n;
        let mut b = DMatrix::zeros(self.p, 2 * n);
        let mut c = DMatrix::zeros(2 * n, 2 * n);
        for (i, s) in order.iter().zip(self.directions(order)) {
            if self.g[*i].is_empty() {
                continue;
            }
            // Column value per joint: the direction, or the offset's 1.
            let col = |j: usize| if s[j] != 0.0 { j } else { n + j };
            let val = |j: usize| if s[j] != 0.0 { s[j] } else { 1.0 };
            for j in 0..n {
                let mut bc = b.column_mut(col(j));
                bc.axpy(val(j), &self.g[*i][j], 1.0);
                for l in 0..n {
                    c[(col(j), col(l))] += val(j) * val(l) * self.k[*i][(j, l)];
                }
            }
        }
        for j in 0..n {
            c[(n + j, n + j)] += OFFSET_PRIOR;
            if !self.moves[j] {
                // Not seen: keep the column out of the others' way.
                b.column_mut(j).fill(0.0);
                for l in 0..2 * n {
                    c[(j, l)] = 0.0;
                    c[(l, j)] = 0.0;
                }
                c[(j, j)] = 1.0;
            }
        }
        (b, c)
    }

    /// Predicted variance of each joint's dead band (rad²) for `order`,
    /// infinite when the order does not determine it; `None` for a joint
    /// whose angle does not move the readings.
    pub fn variances(&self, order: &[usize]) -> Vec<Option<f64>> {
        let (b, c) = self.blocks(order);
        let s = c - b.transpose() * &self.a_inv * &b;
        let inv = s.try_inverse();
        (0..self.n)
            .map(|j| {
                self.moves[j].then(|| {
                    // A variance the rounding made negative is one no
                    // data bound: an order that leaves the dead band to
                    // the offsets' prior.
                    match inv.as_ref().map(|m| m[(j, j)]) {
                        Some(v) if v > 0.0 && v.is_finite() => v * BACKLASH_SCALE_RAD.powi(2),
                        _ => f64::INFINITY,
                    }
                })
            })
            .collect()
    }

    /// What the tour's local search lowers: the sum over the joints seen of
    /// the log of their dead band's variance (every joint's relative gain
    /// counts alike; a plain sum would weigh the wrist alone, whose short
    /// lever gives it the largest variance).
    pub fn cost(&self, order: &[usize]) -> f64 {
        self.variances(order)
            .into_iter()
            .flatten()
            .map(|v| {
                if v.is_finite() && v > 0.0 {
                    v.ln()
                } else {
                    700.0
                }
            })
            .sum()
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Correlation over the train poses of a joint's approach direction with
/// its angle (the poses with a direction only): near ±1 the dead band
/// looks like an error that grows with the angle.
pub(super) fn direction_angle_correlation(q: &[f64], dir: &[f64]) -> f64 {
    let pairs: Vec<(f64, f64)> = q
        .iter()
        .zip(dir)
        .filter(|(_, d)| **d != 0.0)
        .map(|(a, b)| (*a, *b))
        .collect();
    let n = pairs.len() as f64;
    if n < 2.0 {
        return 0.0;
    }
    let (mq, md) = pairs
        .iter()
        .fold((0.0, 0.0), |(a, b), (q, d)| (a + q / n, b + d / n));
    let (mut sqd, mut sqq, mut sdd) = (0.0, 0.0, 0.0);
    for (q, d) in &pairs {
        sqd += (q - mq) * (d - md);
        sqq += (q - mq).powi(2);
        sdd += (d - md).powi(2);
    }
    if sqq <= 0.0 || sdd <= 0.0 {
        0.0
    } else {
        sqd / (sqq * sdd).sqrt()
    }
}

/// The dead bands' design of the visits: the chosen entries' rows, and per
/// joint how the readings change with its angle (scaled by
/// [`BACKLASH_SCALE_RAD`], in noise units).
pub(super) fn backlash_design(
    scene: &Scene,
    dpool: &design::Pool,
    pool: &[Candidate],
    visits: &[VisitSpec],
    chosen: &[usize],
    noise: f64,
) -> Option<BacklashDesign> {
    let n = scene.robot.dof();
    let l = scene.chain.layout;
    let mut jac = scene.chain.new_jacobian();
    let list: Vec<Visit> = visits
        .iter()
        .map(|v| {
            let c = &pool[v.cand];
            let fitted = v.entry.map(|e| {
                scene.point_jacobian(&c.q_rad, &mut jac);
                let dirs = reading_directions(scene, &c.t_rig);
                let per_joint = (0..n)
                    .map(|j| {
                        let dt = jac.d_params[l.joint(j, JointParam::Theta)];
                        dirs.iter()
                            .map(|u| u.dot(&dt) * BACKLASH_SCALE_RAD / noise)
                            .collect()
                    })
                    .collect();
                (dpool.rows[e].clone(), per_joint)
            });
            Visit {
                q_rad: c.q_rad.clone(),
                fitted,
            }
        })
        .collect();
    BacklashDesign::new(&information(dpool, chosen), &list, n)
}

/// The dead bands as predicted parameters (`j2.backlash`, deg).
pub(super) fn backlash_params(b: Option<&BacklashTour>) -> Vec<PredictedParam> {
    b.into_iter()
        .flat_map(|b| &b.joints)
        .filter_map(|j| {
            Some(PredictedParam {
                name: format!("j{}.backlash", j.joint),
                sigma: j.sigma_deg?,
                unit: "deg".into(),
            })
        })
        .collect()
}

/// The backlash tour in words: how far it went beyond the shortest, and
/// the joints whose dead band the readings cannot see.
pub(super) fn backlash_note(b: &BacklashTour) -> String {
    let unseen: Vec<String> = b
        .joints
        .iter()
        .filter(|j| j.sigma_deg.is_none())
        .map(|j| j.joint.to_string())
        .collect();
    let mut s = format!(
        "the tour is ordered for the approach directions backlash needs, within {}x the shortest tour's travel ({:.0} deg); no via-points: poses.csv's row order is what tells identify the direction",
        b.travel_bound, b.shortest_travel_deg
    );
    if !unseen.is_empty() {
        s += &format!(
            "; the dead band of joint(s) {} does not move the measured point, so no order determines it",
            unseen.join(", ")
        );
    }
    s
}
