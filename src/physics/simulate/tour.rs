//! The poses of a session: sampled inside the joint limits and the string
//! range, visited as a nearest-neighbour tour from home, each with its time,
//! temperature and payload.

use nalgebra::Vector3;

use super::truth::TrueGeometry;
use super::{SessionSpec, Spec};
use crate::error::{Error, Result};
use crate::kinematics::chain::{Chain, OutputFrame};
use crate::kinematics::{JointParam, Params};
use crate::model::{Rig, Robot};
use crate::rng::Rng;

/// Draw `spec.n_poses` joint poses (deg) the rig can measure: T clear of
/// the anchor plane on the side the nominal model puts it, every string
/// inside its range, away from singularities.
pub(super) fn sample_poses(
    spec: &Spec,
    robot: &Robot,
    rig: &Rig,
    chain: &Chain,
    anchors: &[Vector3<f64>],
    geometry: &TrueGeometry,
    rng: &mut Rng,
) -> Result<Vec<Vec<f64>>> {
    let n = robot.dof();
    let m = rig.n_strings();
    let truth_p = &geometry.params;
    let l = truth_p.layout;
    let range = rig.sensor.and_then(|s| s.range_mm).unwrap_or(2000.0);
    // Side of the anchor plane the nominal model puts T on (the analysis
    // locates with that hint; stay clear of the plane).
    let normal = (anchors[1] - anchors[0])
        .cross(&(anchors[2] - anchors[0]))
        .normalize();
    let nominal_guess = Params::nominal(robot, &geometry.guess, rig, m);
    let reach: f64 = robot
        .joints
        .iter()
        .map(|j| j.a_mm.abs() + j.d_mm.abs())
        .sum::<f64>()
        .max(100.0);

    let mut qs: Vec<Vec<f64>> = Vec::new();
    let mut jac = chain.new_jacobian();
    let mut tries = 0;
    while qs.len() < spec.n_poses {
        tries += 1;
        if tries > 2000 * spec.n_poses.max(1) {
            return Err(Error::InsufficientData(
                "the simulator found too few poses inside the string range and joint limits".into(),
            ));
        }
        let q: Vec<f64> = robot
            .joints
            .iter()
            .map(|j| {
                let lo = j.q_min_deg.max(-170.0);
                let hi = j.q_max_deg.min(170.0);
                // Commanded angles as a controller would log them (1e-4 deg).
                (rng.range(lo, hi) * 1e4).round() / 1e4
            })
            .collect();
        let q_rad: Vec<f64> = q.iter().map(|v| v.to_radians()).collect();
        chain.point_jacobian(&truth_p.values, &q_rad, OutputFrame::Rig, &mut jac);
        let t = jac.point;
        let t_nom = chain
            .point(&nominal_guess.values, &q_rad, OutputFrame::Rig)
            .1;
        let side = (t - anchors[0]).dot(&normal);
        let side_nom = (t_nom - anchors[0]).dot(&normal);
        if side.abs() < 100.0 || side.signum() != side_nom.signum() {
            continue;
        }
        let lens_ok = anchors.iter().all(|a| {
            let len = (t - a).norm() - rig.r_mm;
            len > 100.0 && len < range - 50.0
        });
        if !lens_ok {
            continue;
        }
        // Away from singularities: the point must move well with the joints.
        let jq =
            nalgebra::DMatrix::from_fn(3, n, |r, c| jac.d_params[l.joint(c, JointParam::Theta)][r]);
        let sv = jq.singular_values();
        let smin = sv.iter().cloned().fold(f64::INFINITY, f64::min);
        if smin < 0.08 * reach {
            continue;
        }
        qs.push(q);
    }
    Ok(qs)
}

/// Poses given by the caller (a plan), checked against the robot: as many
/// angles as joints, finite, inside the limits.
pub(super) fn given_poses(robot: &Robot, given: &[super::GivenPose]) -> Result<Vec<Vec<f64>>> {
    if given.is_empty() {
        return Err(Error::field("targets", "no poses given"));
    }
    for (r, p) in given.iter().enumerate() {
        if p.q_deg.len() != robot.dof() {
            return Err(Error::cell(
                r + 1,
                "q_deg",
                format!(
                    "{} angles for a robot with {} joints",
                    p.q_deg.len(),
                    robot.dof()
                ),
            ));
        }
        for (j, (q, js)) in p.q_deg.iter().zip(&robot.joints).enumerate() {
            if !q.is_finite() || *q < js.q_min_deg || *q > js.q_max_deg {
                return Err(Error::cell(
                    r + 1,
                    format!("q{}_deg", j + 1),
                    format!(
                        "{q} is outside joint {}'s limits [{}, {}]",
                        j + 1,
                        js.q_min_deg,
                        js.q_max_deg
                    ),
                ));
            }
        }
    }
    Ok(given.iter().map(|p| p.q_deg.clone()).collect())
}

/// The payloads of poses given by the caller (a plan's targets.csv with a
/// `payload_kg` column): each pose carries its own (none: 0 kg), in place
/// of the session's blocks, which the spec must then leave empty.
pub(super) fn given_payloads(
    ss: &SessionSpec,
    given: &[super::GivenPose],
    tour: &mut Tour,
) -> Result<()> {
    if given.iter().all(|p| p.payload_kg.is_none()) {
        return Ok(());
    }
    if !ss.payload_kg.is_empty() {
        return Err(Error::field(
            "session.payload_kg",
            "the poses given carry their own payload_kg (a plan's targets.csv): leave the session's payloads out",
        ));
    }
    for (r, p) in given.iter().enumerate() {
        let kg = p.payload_kg.unwrap_or(0.0);
        if !(kg.is_finite() && (0.0..=crate::model::MAX_PAYLOAD_KG).contains(&kg)) {
            return Err(Error::cell(
                r + 1,
                "payload_kg",
                format!(
                    "{kg}: a payload from 0 to {} kg",
                    crate::model::MAX_PAYLOAD_KG
                ),
            ));
        }
        tour.payload[r] = Some(kg);
    }
    Ok(())
}

/// The poses in visiting order, with what the file records of each.
pub(super) struct Tour {
    /// Pose ids (poses.csv's `pose`).
    pub ids: Vec<String>,
    /// Joint angles (deg), in visiting order.
    pub qs: Vec<Vec<f64>>,
    /// The same in rad.
    pub q_rad: Vec<Vec<f64>>,
    /// Time of each pose from the start (s, to the ms).
    pub time: Vec<f64>,
    /// Temperature at each pose (°C, to 1e-4).
    pub temp: Vec<f64>,
    /// Payload at T (kg), when the session carries payloads.
    pub payload: Vec<Option<f64>>,
}

impl Tour {
    /// Order the sampled poses as a tour from `home_deg` and give each its
    /// time (the move plus a randomised dwell, from `rng`), temperature and
    /// payload.
    pub(super) fn new(
        ss: &SessionSpec,
        home_deg: &[f64],
        qs: Vec<Vec<f64>>,
        rng: &mut Rng,
    ) -> Tour {
        let qs = visiting_order(home_deg, qs);
        let ids = (1..=qs.len()).map(|i| i.to_string()).collect();
        Tour::in_order(ss, home_deg, qs, ids, rng)
    }

    /// The poses visited in the order given, with these ids.
    pub(super) fn in_order(
        ss: &SessionSpec,
        home_deg: &[f64],
        qs: Vec<Vec<f64>>,
        ids: Vec<String>,
        rng: &mut Rng,
    ) -> Tour {
        let (time, temp) = clock(ss, home_deg, &qs, rng);
        let payload: Vec<Option<f64>> = (0..qs.len())
            .map(|i| {
                (!ss.payload_kg.is_empty())
                    .then(|| ss.payload_kg[i * ss.payload_kg.len() / qs.len().max(1)])
            })
            .collect();
        let q_rad: Vec<Vec<f64>> = qs
            .iter()
            .map(|q| q.iter().map(|v| v.to_radians()).collect())
            .collect();
        Tour {
            ids,
            qs,
            q_rad,
            time,
            temp,
            payload,
        }
    }
}

/// Largest joint move between two poses (deg): what the slowest joint
/// has to travel.
fn joint_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// A realistic tour: greedy nearest neighbour in joint space from home.
fn visiting_order(home_deg: &[f64], qs: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
    let mut order = Vec::with_capacity(qs.len());
    let mut left: Vec<usize> = (0..qs.len()).collect();
    let mut cur = home_deg.to_vec();
    while !left.is_empty() {
        let (pos, _) = left
            .iter()
            .enumerate()
            .map(|(p, &i)| (p, joint_distance(&cur, &qs[i])))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("non-empty");
        let i = left.swap_remove(pos);
        cur = qs[i].clone();
        order.push(i);
    }
    order.into_iter().map(|i| qs[i].clone()).collect()
}

/// Time and temperature at each pose of the tour: the slowest joint's
/// move plus a dwell of 0.8-1.2 times the spec's, and the ambient rise
/// towards its settled value.
fn clock(
    ss: &SessionSpec,
    home_deg: &[f64],
    qs: &[Vec<f64>],
    rng: &mut Rng,
) -> (Vec<f64>, Vec<f64>) {
    let mut time = Vec::with_capacity(qs.len());
    let mut temp = Vec::with_capacity(qs.len());
    let mut t = 0.0;
    let mut prev = home_deg.to_vec();
    for q in qs {
        t += joint_distance(&prev, q) / ss.speed_deg_s.max(1e-3)
            + ss.dwell_s * (0.8 + 0.4 * rng.uniform());
        prev = q.clone();
        time.push((t * 1000.0).round() / 1000.0);
        let tc = ss.temp_start_c + ss.temp_rise_c * (1.0 - (-t / ss.temp_tau_s.max(1.0)).exp());
        temp.push((tc * 1e4).round() / 1e4);
    }
    (time, temp)
}
