//! What to record next: poses added to a recorded session so that the
//! parameters it left undetermined are determined (the verdict's advice,
//! `report.extra_poses`).
//!
//! The recorded poses' information is the start; candidates are drawn as
//! for a plan (inside the limits, strings in range and well spread, clear
//! of singularities) and kept above the lowest point the recorded poses
//! reached, since the cell's floor and fixtures are not known here; the
//! greedy step then adds the candidate that lowers the summed variance of
//! the wanted parameters most (each relative to its manufacturing
//! tolerance), until each is determined to a third of its tolerance or
//! [`MAX_EXTRA_POSES`] are added.

use nalgebra::DMatrix;

use super::columns::{Columns, design_pool, design_rows, normal_matrix, prior_size};
use super::options::default_noise;
use super::payload::Entries;
use super::{Candidate, Scene, Workspace, design, tour};
use crate::error::Result;
use crate::identify::{IdentifyOptions, geometric::candidates as free_candidates, identifiability};
use crate::model::{Rig, Robot};
use crate::report::{ExtraParam, ExtraPose, ExtraPoses, FixedParam};
use crate::rng::Rng;

/// Most poses suggested.
pub const MAX_EXTRA_POSES: usize = 20;
/// Candidates drawn to choose from.
const EXTRA_CANDIDATES: usize = 2000;
/// A parameter counts as determined when its predicted 1-sigma is at most
/// this fraction of its manufacturing tolerance (a deviation of the
/// tolerance is then a 3-sigma one).
const DETERMINED_FRACTION: f64 = 1.0 / 3.0;

/// Extra poses for `wanted` (report names: parameters the session held at
/// nominal for want of data) after the recorded train poses
/// `recorded_q_deg`, whose identification freed `free` (report names),
/// with readings of `noise_mm` (default: as for a plan). A wanted
/// parameter that no pose of this rig separates from the freed ones (its
/// column nearly a combination of theirs over every candidate) is listed
/// as inseparable instead. `None` when no valid candidate can be drawn.
pub fn extend(
    robot: &Robot,
    rig: &Rig,
    recorded_q_deg: &[Vec<f64>],
    free: &[String],
    wanted: &[String],
    noise_mm: Option<f64>,
    seed: u64,
) -> Result<Option<ExtraPoses>> {
    let loose = Workspace::default();
    let scene = Scene::new(robot, rig, &loose)?;
    let recorded: Vec<Candidate> = recorded_q_deg.iter().map(|q| scene.recorded(q)).collect();
    let Some(floor) = recorded
        .iter()
        .map(|c| scene.lowest_z_mm(c))
        .reduce(f64::min)
    else {
        return Ok(None);
    };
    let workspace = Workspace {
        floor_z_mm: Some(floor),
        ..Workspace::default()
    };
    let scene = Scene::new(robot, rig, &workspace)?;
    let mut rng = Rng::new(seed);
    let (pool, _, _) = scene.sample(EXTRA_CANDIDATES, 50 * EXTRA_CANDIDATES, &mut rng);
    if pool.len() < MAX_EXTRA_POSES {
        return Ok(None);
    }
    let noise = noise_mm.unwrap_or_else(|| default_noise(rig));
    let (cols, targets, inseparable) = aimed_columns(&scene, &pool, free, wanted);
    if targets.is_empty() {
        return Ok(Some(ExtraPoses {
            parameters: vec![],
            poses: vec![],
            inseparable,
            criterion: "no pose of this rig separates the parameters held at nominal from \
                        those identified"
                .into(),
        }));
    }
    let l = scene.chain.layout;
    let unloaded = Entries::new(pool.len(), None);
    let mut design = design_pool(&scene, &cols, &pool, &unloaded, &pool, noise);
    let recorded: Vec<(&Candidate, Option<f64>)> = recorded.iter().map(|c| (c, None)).collect();
    let recorded_rows = design_rows(&scene, &cols, &recorded, noise);
    let p = design.p;
    design.w = DMatrix::from_fn(p, p, |a, b| {
        if a == b && targets.contains(&a) {
            1.0
        } else {
            0.0
        }
    });
    let mut information = DMatrix::zeros(p, p);
    for r in &recorded_rows {
        let j = DMatrix::from_row_slice(design.m, p, r);
        information += j.transpose() * j;
    }
    let sigma_recorded = scaled_sigmas(&information, &targets);
    let with_prior = &information + DMatrix::identity(p, p);
    let determined = |minv: &DMatrix<f64>| {
        targets
            .iter()
            .all(|&k| minv[(k, k)] <= DETERMINED_FRACTION.powi(2))
    };
    let Some((chosen, _)) = design::extend(&design, &with_prior, MAX_EXTRA_POSES, determined)
    else {
        return Ok(None);
    };
    let mut after = information;
    for &i in &chosen {
        let j = DMatrix::from_row_slice(design.m, p, &design.rows[i]);
        after += j.transpose() * j;
    }
    let sigma_after = scaled_sigmas(&after, &targets);
    let parameters = targets
        .iter()
        .enumerate()
        .map(|(t, &k)| {
            let (i, scale) = (cols.params[k], cols.param_scale[k]);
            let unit = |s: f64| if l.is_angle(i) { s.to_degrees() } else { s };
            ExtraParam {
                name: l.name(i),
                unit: if l.is_angle(i) { "deg" } else { "mm" }.into(),
                sigma_recorded: sigma_recorded[t].map(|s| unit(s * scale)),
                sigma_with_extra: sigma_after[t].map(|s| unit(s * scale)),
                tolerance: unit(scale),
            }
        })
        .collect();
    let home = recorded_q_deg.last().cloned().unwrap_or_default();
    let refs: Vec<&[f64]> = chosen.iter().map(|&i| pool[i].q_deg.as_slice()).collect();
    let poses = tour::order(&home, &refs)
        .into_iter()
        .enumerate()
        .map(|(n, k)| ExtraPose {
            id: format!("e{:02}", n + 1),
            q_deg: refs[k].to_vec(),
        })
        .collect();
    Ok(Some(ExtraPoses {
        parameters,
        poses,
        inseparable,
        criterion: format!(
            "added one at a time to the {} recorded train poses, each the pose of {} drawn that most lowers the summed variance of these parameters (linear least squares, {noise:.3} mm per reading), until each is determined to a third of its tolerance or {MAX_EXTRA_POSES} poses are added; drawn inside the joint limits, measurable by this rig and kept no lower than the recorded poses went, but without your cell's fixtures: check each pose before running it",
            recorded_q_deg.len(),
            pool.len()
        ),
    }))
}

/// The columns of the design: the parameters the session freed, then the
/// wanted ones (report names) that stand clear of them over the whole
/// pool; which columns are aimed at (the wanted ones kept); and the wanted
/// ones that do not stand clear, with what they move T like.
fn aimed_columns(
    scene: &Scene,
    pool: &[Candidate],
    free: &[String],
    wanted: &[String],
) -> (Columns, Vec<usize>, Vec<FixedParam>) {
    let l = scene.chain.layout;
    // The robot's geometry only: the sensor's parameters (string offsets,
    // anchors) are not what poses are chosen for.
    let index = |names: &[String]| -> Vec<usize> {
        names
            .iter()
            .filter_map(|n| l.index_of(n))
            .filter(|&i| i < l.n_geometric())
            .collect()
    };
    // In the identification's priority order, so that of an aliased pair
    // the one it would keep is the one aimed at.
    let order = free_candidates(l, &IdentifyOptions::default());
    let rank = |i: &usize| order.iter().position(|c| c == i).unwrap_or(usize::MAX);
    let (free, mut wanted) = (index(free), index(wanted));
    wanted.sort_by_key(rank);
    // The freed parameters first: a wanted one is kept only if it stands
    // clear of them (and of the wanted ones before it) by more than the
    // near-alias sine, below which the identification would hold it again
    // however many poses it had.
    let cand: Vec<usize> = free.iter().chain(&wanted).copied().collect();
    let jtj = normal_matrix(scene, pool, &cand);
    let sel = identifiability::select(&jtj, &cand, &l, identifiability::NEAR_ALIAS_SINE);
    let inseparable = sel
        .fixed
        .into_iter()
        .filter(|f| wanted.iter().any(|&w| l.name(w) == f.name))
        .collect();
    let targets = (0..sel.free.len())
        .filter(|&k| wanted.contains(&sel.free[k]))
        .collect();
    let cols = Columns {
        param_scale: sel.free.iter().map(|&i| prior_size(l, i)).collect(),
        params: sel.free,
        aliased: vec![],
        effects: vec![],
        effect_scale: vec![],
    };
    (cols, targets, inseparable)
}

/// 1-sigma of columns `targets` (in the pool's scaled units) from an
/// information matrix without the prior; `None` where it does not
/// determine them.
fn scaled_sigmas(information: &DMatrix<f64>, targets: &[usize]) -> Vec<Option<f64>> {
    // A tiny ridge keeps the inverse finite; what it alone holds is
    // reported as undetermined.
    let p = information.nrows();
    let ridge = 1e-9 * information.diagonal().max().max(1.0);
    let Some(inv) = (information + DMatrix::identity(p, p) * ridge).try_inverse() else {
        return vec![None; targets.len()];
    };
    targets
        .iter()
        .map(|&k| {
            let s = inv[(k, k)].max(0.0).sqrt();
            (s < 1e3).then_some(s)
        })
        .collect()
}
