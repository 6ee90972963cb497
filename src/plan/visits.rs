//! The poses to record (the chosen ones, then the check poses) and their
//! visiting order: a short tour from home, one payload group after the
//! other, reordered for the dead bands when backlash is planned for.

use nalgebra::DMatrix;

use super::backlash::{
    self, BACKLASH_SEARCH_BUDGET, BACKLASH_TRAVEL_BOUND, BacklashDesign, BacklashSigma,
    BacklashTour, backlash_design,
};
use super::columns::{determined_inverse, information};
use super::payload::Entries;
use super::tour::{self, grouped_tour};
use super::{Candidate, PlanOptions, PlannedPose, Scene, design};
use crate::physics::effects::approach_directions;

/// One pose to record, before the tour orders them.
pub(super) struct VisitSpec {
    /// Candidate.
    pub(super) cand: usize,
    /// The design entry of a chosen pose; `None` for a check pose.
    pub(super) entry: Option<usize>,
    /// Payload (kg), when payloads are planned.
    pub(super) payload_kg: Option<f64>,
}

/// The chosen poses, then the check poses, these sharing the payload
/// groups in the chosen poses' proportion (the last of them loaded).
pub(super) fn visits(entries: &Entries, chosen: &[usize], checks: &[usize]) -> Vec<VisitSpec> {
    let loaded = chosen
        .iter()
        .filter(|&&e| entries.payload[e].is_some_and(|p| p > 0.0))
        .count();
    let payload = entries
        .payload
        .iter()
        .flatten()
        .cloned()
        .fold(0.0, f64::max);
    let n_loaded = (checks.len() * loaded + chosen.len() / 2) / chosen.len().max(1);
    let planned = entries.payload.first().is_some_and(|p| p.is_some());
    chosen
        .iter()
        .map(|&e| VisitSpec {
            cand: entries.cand[e],
            entry: Some(e),
            payload_kg: entries.payload[e],
        })
        .chain(checks.iter().enumerate().map(|(k, &c)| VisitSpec {
            cand: c,
            entry: None,
            payload_kg: planned.then(|| {
                if k + n_loaded >= checks.len() {
                    payload
                } else {
                    0.0
                }
            }),
        }))
        .collect()
}

/// The visiting order and, with backlash, its dead bands' design.
pub(super) struct Toured {
    /// Visits (indices into the plan's visits) in order.
    pub(super) order: Vec<usize>,
    /// The shortest tour, when backlash reordered it.
    pub(super) shortest: Vec<usize>,
    /// The dead bands' design, when backlash is planned for.
    pub(super) backlash: Option<BacklashDesign>,
    /// Travel of the shortest tour (deg).
    pub(super) shortest_travel_deg: f64,
    /// Angles of each visit (rad) and whether it is fitted.
    pub(super) q_rad: Vec<(Vec<f64>, bool)>,
}

impl Toured {
    /// Order the visits: a short tour from `home`, one payload group after
    /// the other (unloaded first), reordered within
    /// [`BACKLASH_TRAVEL_BOUND`] for the dead bands when backlash is
    /// planned for.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        scene: &Scene,
        dpool: &design::Pool,
        pool: &[Candidate],
        visits: &[VisitSpec],
        home: &[f64],
        chosen: &[usize],
        opts: &PlanOptions,
        noise: f64,
    ) -> Self {
        let refs: Vec<&[f64]> = visits
            .iter()
            .map(|v| pool[v.cand].q_deg.as_slice())
            .collect();
        let group: Vec<usize> = visits
            .iter()
            .map(|v| usize::from(v.payload_kg.is_some_and(|p| p > 0.0)))
            .collect();
        let shortest = grouped_tour(home, &refs, &group);
        let travel = |o: &[usize]| {
            tour::path_travel_deg(home, &o.iter().map(|&k| refs[k]).collect::<Vec<_>>())
        };
        let shortest_travel_deg = travel(&shortest);
        let q_rad = visits
            .iter()
            .map(|v| (pool[v.cand].q_rad.clone(), v.entry.is_some()))
            .collect();
        let backlash = opts
            .effects
            .iter()
            .any(|e| e == "backlash")
            .then(|| backlash_design(scene, dpool, pool, visits, chosen, noise))
            .flatten();
        let order = match &backlash {
            Some(b) => tour::improve(
                home,
                &refs,
                shortest.clone(),
                &group,
                BACKLASH_TRAVEL_BOUND * shortest_travel_deg,
                BACKLASH_SEARCH_BUDGET * 40 / refs.len().max(40),
                &mut |o| b.cost(o),
            ),
            None => shortest.clone(),
        };
        Toured {
            order,
            shortest,
            backlash,
            shortest_travel_deg,
            q_rad,
        }
    }

    /// The poses in visiting order with their ids (`p01`..., `c01`...).
    pub(super) fn poses(&self, pool: &[Candidate], visits: &[VisitSpec]) -> Vec<PlannedPose> {
        let (mut n_train, mut n_test) = (0, 0);
        self.order
            .iter()
            .map(|&k| {
                let v = &visits[k];
                let check = v.entry.is_none();
                let id = if check {
                    n_test += 1;
                    format!("c{n_test:02}")
                } else {
                    n_train += 1;
                    format!("p{n_train:02}")
                };
                PlannedPose {
                    id,
                    q_deg: pool[v.cand].q_deg.clone(),
                    split: if check { "test" } else { "train" }.into(),
                    payload_kg: v.payload_kg,
                }
            })
            .collect()
    }

    /// Covariance of the design's columns over the chosen entries (rows in
    /// noise units), the dead bands fitted beside them when planned for.
    pub(super) fn covariance(
        &self,
        dpool: &design::Pool,
        chosen: &[usize],
    ) -> Option<DMatrix<f64>> {
        let a = information(dpool, chosen);
        let Some(b) = &self.backlash else {
            return determined_inverse(a);
        };
        let (bb, cc) = b.blocks(&self.order);
        let (p, k) = (a.nrows(), cc.nrows());
        let mut full = DMatrix::zeros(p + k, p + k);
        full.view_mut((0, 0), (p, p)).copy_from(&a);
        full.view_mut((0, p), (p, k)).copy_from(&bb);
        full.view_mut((p, 0), (k, p)).copy_from(&bb.transpose());
        full.view_mut((p, p), (k, k)).copy_from(&cc);
        determined_inverse(full).map(|inv| inv.view((0, 0), (p, p)).into_owned())
    }

    /// The dead bands' report, when backlash is planned for.
    pub(super) fn report(&self, n: usize) -> Option<BacklashTour> {
        let b = self.backlash.as_ref()?;
        let sd = |v: Option<f64>| v.filter(|v| v.is_finite()).map(|v| v.sqrt().to_degrees());
        let now = b.variances(&self.order);
        let before = b.variances(&self.shortest);
        let train: Vec<&(Vec<f64>, bool)> = self.order.iter().map(|&k| &self.q_rad[k]).collect();
        let qs: Vec<&[f64]> = train.iter().map(|(q, _)| q.as_slice()).collect();
        let dirs = approach_directions(&qs);
        let joints = (0..n)
            .map(|j| {
                let (q, d): (Vec<f64>, Vec<f64>) = train
                    .iter()
                    .zip(&dirs)
                    .filter(|((_, fitted), _)| *fitted)
                    .map(|((q, _), d)| (q[j], d[j]))
                    .unzip();
                BacklashSigma {
                    joint: j + 1,
                    sigma_deg: sd(now[j]),
                    sigma_shortest_deg: sd(before[j]),
                    direction_angle_correlation: backlash::direction_angle_correlation(&q, &d),
                }
            })
            .collect();
        Some(BacklashTour {
            travel_bound: BACKLASH_TRAVEL_BOUND,
            shortest_travel_deg: self.shortest_travel_deg,
            joints,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::Workspace;
    use crate::plan::columns::{columns, design_pool};
    use crate::plan::options::{default_noise, home_pose};
    use crate::rng::Rng;

    /// Poses sweeping joint 1 of the ER3A in 8 deg steps, the other joints
    /// within ±2 deg of one valid pose: the shortest tour walks joint 1
    /// one way, where its dead band is an offset.
    fn sweep(scene: &Scene) -> Vec<Candidate> {
        let mut rng = Rng::new(3);
        let (pool, _, _) = scene.sample(50, 50_000, &mut rng);
        let mut jac = scene.chain.new_jacobian();
        let centre = pool
            .iter()
            .max_by_key(|c| {
                (-12..=12)
                    .filter(|k| {
                        let mut q = c.q_deg.clone();
                        q[0] += 8.0 * *k as f64;
                        q[0].abs() < 168.0 && scene.check(q, &mut jac).is_ok()
                    })
                    .count()
            })
            .unwrap()
            .clone();
        (-12..=12)
            .filter_map(|k| {
                let mut q = centre.q_deg.clone();
                q[0] += 8.0 * k as f64;
                for v in q.iter_mut().skip(1) {
                    *v = ((*v + rng.range(-2.0, 2.0)) * 1e4).round() / 1e4;
                }
                let inside = q
                    .iter()
                    .zip(&scene.robot.joints)
                    .all(|(v, j)| *v >= j.q_min_deg && *v <= j.q_max_deg);
                inside.then(|| scene.check(q, &mut jac).ok()).flatten()
            })
            .collect()
    }

    #[test]
    fn a_tour_sweeping_a_joint_one_way_is_reordered_to_see_its_dead_band() {
        let (robot, rig, _) = crate::physics::simulate::preset("er3a").unwrap();
        let ws = Workspace::default();
        let scene = Scene::new(&robot, &rig, &ws).unwrap();
        let poses = sweep(&scene);
        assert!(poses.len() >= 12, "{} poses", poses.len());
        let mut opts = PlanOptions::new(poses.len());
        opts.effects = vec!["backlash".into()];
        let noise = default_noise(&rig);
        let entries = Entries::new(poses.len(), None);
        let cols = columns(&scene, &poses, &entries, &opts, noise).unwrap();
        let dpool = design_pool(&scene, &cols, &poses, &entries, &poses, noise);
        let chosen: Vec<usize> = (0..poses.len()).collect();
        let v = visits(&entries, &chosen, &[]);
        let home = home_pose(&robot, &opts);
        let toured = Toured::new(&scene, &dpool, &poses, &v, &home, &chosen, &opts, noise);
        let q1 = |o: &[usize]| -> Vec<f64> { o.iter().map(|&k| poses[k].q_deg[0]).collect() };
        let ups = |q: &[f64]| q.windows(2).filter(|w| w[1] > w[0]).count();
        let (before, after) = (q1(&toured.shortest), q1(&toured.order));
        let n = before.len() - 1;
        // The shortest tour sweeps joint 1 one way.
        assert!(ups(&before) == 0 || ups(&before) == n, "{before:?}");
        // The tour planned approaches it from both sides within the travel
        // bound (a one-way sweep of small steps can only be partly
        // balanced: each step back costs twice its size).
        let up = ups(&after);
        assert!(6 * up.min(n - up) >= n, "{up} of {n} up: {after:?}");
        let refs =
            |o: &[usize]| -> Vec<&[f64]> { o.iter().map(|&k| poses[k].q_deg.as_slice()).collect() };
        let travel = tour::path_travel_deg(&home, &refs(&toured.order));
        assert!(travel <= BACKLASH_TRAVEL_BOUND * toured.shortest_travel_deg + 1e-9);
        // And its predicted sigma falls.
        let r = toured.report(robot.dof()).unwrap();
        let j1 = &r.joints[0];
        let s = j1.sigma_deg.unwrap();
        assert!(
            j1.sigma_shortest_deg.is_none_or(|s0| s < 0.5 * s0),
            "joint 1: {s} deg against {:?} deg with the shortest tour",
            j1.sigma_shortest_deg
        );
    }
}
