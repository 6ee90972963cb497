//! The design's columns (the parameters the identification frees and the
//! effects' coefficients, with their prior sizes), each candidate's rows
//! over them, and the linear predictions made from them.

use nalgebra::{DMatrix, Vector3};

use super::payload::Entries;
use super::{Candidate, PlanOptions, PredictedParam, PredictionAtN, Scene, design};
use crate::identify::{IdentifyOptions, geometric::candidates as free_candidates, identifiability};
use crate::kinematics::JointParam;
use crate::kinematics::chain::PointJacobian;
use crate::physics::Kind;
use crate::physics::effects::{Basis, Context, PoseInput};
use crate::report::FixedParam;

/// The columns the design determines: parameters of the identification
/// and effect coefficients.
pub(super) struct Columns {
    /// Parameter indices, identification priority order.
    pub(super) params: Vec<usize>,
    /// Prior size of each parameter (mm or rad).
    pub(super) param_scale: Vec<f64>,
    /// Effects (kind, name) with their coefficient count.
    pub(super) effects: Vec<(Kind, String)>,
    /// Prior size of each effect coefficient (its unit).
    pub(super) effect_scale: Vec<f64>,
    /// What no pose of this rig can separate: the identification's
    /// structural selection over the whole pool, held at nominal.
    pub(super) aliased: Vec<FixedParam>,
}

impl Columns {
    pub(super) fn len(&self) -> usize {
        self.params.len() + self.effect_scale.len()
    }
}

/// The parameters the identification frees that the pool can determine,
/// with their prior sizes, and the effects' coefficients (a plan builds
/// them in steps, [`free_params`] and [`effect_columns`], to share them
/// with the plan without its payload).
#[cfg(test)]
pub(super) fn columns(
    scene: &Scene,
    pool: &[Candidate],
    entries: &Entries,
    opts: &PlanOptions,
    noise: f64,
) -> crate::error::Result<Columns> {
    let design = entries.of(pool);
    let ctx = effect_context(scene, &design);
    Ok(effect_columns(
        scene,
        &free_params(scene, pool),
        &ctx,
        &design,
        opts,
        noise,
    ))
}

/// The parameters the identification frees that the pool can determine:
/// its structural selection over the whole pool (which no payload
/// changes), with their prior sizes, and what it holds at nominal.
pub(super) struct FreeParams {
    /// Parameter indices, identification priority order.
    params: Vec<usize>,
    /// Prior size of each (mm or rad).
    scale: Vec<f64>,
    /// What no pose of this rig can separate.
    aliased: Vec<FixedParam>,
}

/// The pool's [`FreeParams`].
pub(super) fn free_params(scene: &Scene, pool: &[Candidate]) -> FreeParams {
    let l = scene.chain.layout;
    let cand = free_candidates(l, &IdentifyOptions::default());
    let jtj = normal_matrix(scene, pool, &cand);
    let sel = identifiability::select(&jtj, &cand, &l, identifiability::DEFAULT_TOLERANCE);
    FreeParams {
        scale: sel.free.iter().map(|&i| prior_size(l, i)).collect(),
        params: sel.free,
        aliased: sel.fixed,
    }
}

/// The columns of a design over `design` (the entries' candidates with
/// their payloads, pose `i` of `ctx` being entry `i`; `ctx` may hold more
/// poses after them): the `free` parameters, then the effects asked for,
/// each coefficient with its prior size over these entries.
pub(super) fn effect_columns(
    scene: &Scene,
    free: &FreeParams,
    ctx: &Context,
    design: &[(&Candidate, Option<f64>)],
    opts: &PlanOptions,
    noise: f64,
) -> Columns {
    let l = scene.chain.layout;
    let mut effects = Vec::new();
    let n = scene.robot.dof();
    for e in &opts.effects {
        match e.as_str() {
            "joint_compliance" => {
                for j in 0..n {
                    let regressors = if ctx.has_masses {
                        vec![]
                    } else {
                        ctx.compliance_regressors(j, &(0..design.len()).collect::<Vec<_>>())
                    };
                    effects.push((
                        Kind::JointCompliance {
                            joint_index: j,
                            regressors,
                        },
                        format!("j{}.compliance", j + 1),
                    ));
                }
            }
            "joint_scale" => {
                effects.extend((0..n).map(|j| {
                    (
                        Kind::JointScale { joint_index: j },
                        format!("j{}.scale", j + 1),
                    )
                }));
            }
            "sensor_scale" => effects.extend((0..l.n_strings).map(|k| {
                (
                    Kind::SensorScale { sensor_index: k },
                    format!("{}.scale", scene.rig.sensor_name(k)),
                )
            })),
            "cable_sag" => effects.push((Kind::CableSag, "cable_sag".into())),
            "base_tilt" => effects.push((Kind::BaseTilt, "base_tilt".into())),
            // Every link the analysis would propose as bending.
            "link_bending" => effects.extend((0..n).filter(|&j| ctx.can_bend(j)).map(|j| {
                (
                    Kind::LinkBending { link_index: j },
                    format!("j{}.link_bending", j + 1),
                )
            })),
            _ => {} // backlash: a matter of the tour's approach directions
        }
    }
    let mut cols = Columns {
        params: free.params.clone(),
        aliased: free.aliased.clone(),
        param_scale: free.scale.clone(),
        effects,
        effect_scale: vec![],
    };
    // An effect coefficient's prior: the size at which it moves the
    // readings by three times their noise (RMS over the entries). One
    // Jacobian per entry serves every effect; each effect's sums run over
    // the entries in order.
    let mut buf = Basis::default();
    let mut jac = scene.chain.new_jacobian();
    let mut sq: Vec<Vec<f64>> = cols
        .effects
        .iter()
        .map(|(kind, _)| vec![0.0; kind.n_coef()])
        .collect();
    if !cols.effects.is_empty() {
        for (i, (c, _)) in design.iter().enumerate() {
            scene.point_jacobian(&c.q_rad, &mut jac);
            for ((kind, _), sq) in cols.effects.iter().zip(sq.iter_mut()) {
                let rows = effect_rows(scene, ctx, kind, i, c, &jac, &mut buf);
                let per = rows.len() / kind.n_coef();
                for (k, r) in rows.iter().enumerate() {
                    sq[k / per] += r * r;
                }
            }
        }
    }
    let rows_per = (scene.rig.n_strings().max(3) * design.len()) as f64;
    cols.effect_scale = sq
        .into_iter()
        .flatten()
        .map(|s| {
            let rms = (s / rows_per).sqrt();
            if rms > 0.0 { 3.0 * noise / rms } else { 0.0 }
        })
        .collect();
    cols
}

/// Prior size of parameter `i`: a manufacturing tolerance (the
/// simulator's deviations: 0.5 mm, 0.1 deg; the base 2 mm, 0.5 deg).
pub(super) fn prior_size(l: crate::kinematics::Layout, i: usize) -> f64 {
    let b = l.base();
    if (b..b + 3).contains(&i) {
        2.0
    } else if (b + 3..b + 6).contains(&i) {
        0.5f64.to_radians()
    } else if l.is_angle(i) {
        0.1f64.to_radians()
    } else {
        0.5
    }
}

/// Normal matrix of the readings over `pool` for parameters `cand`
/// (natural units).
pub(super) fn normal_matrix(scene: &Scene, pool: &[Candidate], cand: &[usize]) -> DMatrix<f64> {
    let p = cand.len();
    let mut jtj = DMatrix::zeros(p, p);
    let mut jac = scene.chain.new_jacobian();
    let mut row = vec![0.0; p];
    for c in pool {
        scene.point_jacobian(&c.q_rad, &mut jac);
        for dir in reading_directions(scene, &c.t_rig) {
            for (k, &i) in cand.iter().enumerate() {
                row[k] = dir.dot(&jac.d_params[i]);
            }
            // Column b (column-major) gains row · row[b].
            for (col, &rb) in jtj.as_mut_slice().chunks_exact_mut(p).zip(&row) {
                for (x, &ra) in col.iter_mut().zip(&row) {
                    *x += ra * rb;
                }
            }
        }
    }
    jtj
}

/// The direction each reading measures T along: the strings' unit
/// vectors, or the three axes for a point instrument.
pub(super) fn reading_directions(scene: &Scene, t: &Vector3<f64>) -> Vec<Vector3<f64>> {
    if scene.anchors().is_empty() {
        vec![Vector3::x(), Vector3::y(), Vector3::z()]
    } else {
        scene
            .anchors()
            .iter()
            .map(|a| (t - a).normalize())
            .collect()
    }
}

/// The effects' context of candidates with their payloads (kg at T).
pub(super) fn effect_context(scene: &Scene, poses: &[(&Candidate, Option<f64>)]) -> Context {
    let inputs: Vec<PoseInput> = poses
        .iter()
        .map(|(c, payload_kg)| PoseInput {
            q_rad: &c.q_rad,
            time_s: None,
            temp_c: None,
            payload_kg: *payload_kg,
            point_rig: c.t_rig,
        })
        .collect();
    let (r, _) = scene.nominal.base_rt();
    Context::new(
        scene.robot,
        scene.anchors().to_vec(),
        scene.rig.r_mm,
        &r,
        &inputs,
    )
}

/// An effect's reading rows at candidate `c`, pose `i` of `ctx`, whose
/// point Jacobian is `jac` (per coefficient, per reading,
/// coefficient-major): the joint changes through T, plus the readings' own
/// change.
fn effect_rows(
    scene: &Scene,
    ctx: &Context,
    kind: &Kind,
    i: usize,
    c: &Candidate,
    jac: &PointJacobian,
    buf: &mut Basis,
) -> Vec<f64> {
    let (dt, dl) = effect_displacement(scene, ctx, kind, i, jac, buf);
    let dirs = reading_directions(scene, &c.t_rig);
    let nc = kind.n_coef();
    let mut out = Vec::with_capacity(nc * dirs.len());
    for (k, d) in dt.iter().enumerate() {
        for (s, u) in dirs.iter().enumerate() {
            out.push(
                u.dot(d)
                    + dl.get(k * scene.anchors().len() + s)
                        .copied()
                        .unwrap_or(0.0),
            );
        }
    }
    out
}

/// Per coefficient: T's displacement (rig frame, mm) and the readings'
/// change (mm, `n_coef × m`), at pose `i` of `ctx` whose point Jacobian is
/// `jac`.
fn effect_displacement(
    scene: &Scene,
    ctx: &Context,
    kind: &Kind,
    i: usize,
    jac: &PointJacobian,
    buf: &mut Basis,
) -> (Vec<Vector3<f64>>, Vec<f64>) {
    ctx.basis(kind, i, buf);
    let n = scene.robot.dof();
    let l = scene.chain.layout;
    let nc = kind.n_coef();
    let dt = (0..nc)
        .map(|k| {
            (0..n).fold(Vector3::zeros(), |acc, j| {
                acc + jac.d_params[l.joint(j, JointParam::Theta)] * buf.dq[k * n + j]
            }) + Vector3::new(buf.dp[k * 3], buf.dp[k * 3 + 1], buf.dp[k * 3 + 2])
        })
        .collect();
    (dt, buf.dl.clone())
}

/// The design pool: each entry's readings over the columns, scaled by the
/// priors and divided by the noise, and the prediction weight from the
/// validation poses (with a payload planned, each taken unloaded and
/// loaded: compensation may be asked for either).
pub(super) fn design_pool(
    scene: &Scene,
    cols: &Columns,
    pool: &[Candidate],
    entries: &Entries,
    validation: &[Candidate],
    noise: f64,
) -> design::Pool {
    let design = entries.of(pool);
    let ctx = effect_context(scene, &design);
    design_pool_in(scene, cols, &ctx, &design, entries, validation, noise)
}

/// [`design_pool`] with the entries' effect context `ctx` given (pose `i`
/// of `ctx` is entry `i` of `design`, the `entries`' candidates with their
/// payloads; it may hold more poses after them).
pub(super) fn design_pool_in(
    scene: &Scene,
    cols: &Columns,
    ctx: &Context,
    design: &[(&Candidate, Option<f64>)],
    entries: &Entries,
    validation: &[Candidate],
    noise: f64,
) -> design::Pool {
    let m = scene.anchors().len().max(3);
    let rows = design_rows_in(scene, cols, ctx, design, noise);
    let loads: Vec<Option<f64>> = match entries.payload.last() {
        Some(Some(p)) => vec![Some(0.0), Some(*p)],
        _ => vec![None],
    };
    let mut w = DMatrix::zeros(cols.len(), cols.len());
    for load in &loads {
        let v: Vec<(&Candidate, Option<f64>)> = validation.iter().map(|c| (c, *load)).collect();
        w += prediction_weight(scene, cols, &v);
    }
    w /= (validation.len() * loads.len()) as f64;
    design::Pool {
        m,
        p: cols.len(),
        rows,
        w,
    }
}

/// Each entry's `m × p` rows (row-major), scaled by the priors, in noise
/// units.
pub(super) fn design_rows(
    scene: &Scene,
    cols: &Columns,
    entries: &[(&Candidate, Option<f64>)],
    noise: f64,
) -> Vec<Vec<f64>> {
    let ctx = effect_context(scene, entries);
    design_rows_in(scene, cols, &ctx, entries, noise)
}

/// [`design_rows`] with the entries' effect context given (as for
/// [`design_pool_in`]): one Jacobian per entry serves the parameters and
/// every effect.
fn design_rows_in(
    scene: &Scene,
    cols: &Columns,
    ctx: &Context,
    entries: &[(&Candidate, Option<f64>)],
    noise: f64,
) -> Vec<Vec<f64>> {
    let p = cols.len();
    let m = scene.anchors().len().max(3);
    let mut jac = scene.chain.new_jacobian();
    let mut buf = Basis::default();
    entries
        .iter()
        .enumerate()
        .map(|(i, (c, _))| {
            scene.point_jacobian(&c.q_rad, &mut jac);
            let dirs = reading_directions(scene, &c.t_rig);
            let mut r = vec![0.0; m * p];
            for (s, u) in dirs.iter().enumerate() {
                for (k, (&pi, sc)) in cols.params.iter().zip(&cols.param_scale).enumerate() {
                    r[s * p + k] = u.dot(&jac.d_params[pi]) * sc / noise;
                }
            }
            let mut k0 = cols.params.len();
            for (kind, _) in &cols.effects {
                let er = effect_rows(scene, ctx, kind, i, c, &jac, &mut buf);
                let nc = kind.n_coef();
                for k in 0..nc {
                    for s in 0..m {
                        r[s * p + k0 + k] =
                            er[k * m + s] * cols.effect_scale[k0 - cols.params.len() + k] / noise;
                    }
                }
                k0 += nc;
            }
            r
        })
        .collect()
}

/// The sum over `poses` of `J_Tᵀ J_T`, scaled like the rows (no noise).
fn prediction_weight(
    scene: &Scene,
    cols: &Columns,
    poses: &[(&Candidate, Option<f64>)],
) -> DMatrix<f64> {
    let p = cols.len();
    let mut jac = scene.chain.new_jacobian();
    let mut buf = Basis::default();
    let vctx = effect_context(scene, poses);
    let mut w = DMatrix::zeros(p, p);
    for (i, (c, _)) in poses.iter().enumerate() {
        scene.point_jacobian(&c.q_rad, &mut jac);
        let mut jt = DMatrix::zeros(3, p);
        for (k, (&pi, sc)) in cols.params.iter().zip(&cols.param_scale).enumerate() {
            for a in 0..3 {
                jt[(a, k)] = jac.d_params[pi][a] * sc;
            }
        }
        let mut k0 = cols.params.len();
        for (kind, _) in &cols.effects {
            let (dt, _) = effect_displacement(scene, &vctx, kind, i, &jac, &mut buf);
            for (k, d) in dt.iter().enumerate() {
                for a in 0..3 {
                    jt[(a, k0 + k)] = d[a] * cols.effect_scale[k0 - cols.params.len() + k];
                }
            }
            k0 += dt.len();
        }
        w += jt.transpose() * jt;
    }
    w
}

/// Information of a set without the prior (what least squares gives);
/// a column no pose of the set determines keeps its prior.
pub(super) fn information(pool: &design::Pool, set: &[usize]) -> DMatrix<f64> {
    let mut mm = DMatrix::zeros(pool.p, pool.p);
    for &i in set {
        let j = DMatrix::from_row_slice(pool.m, pool.p, &pool.rows[i]);
        mm += j.transpose() * j;
    }
    for c in 0..pool.p {
        if mm[(c, c)] < 1e-9 {
            mm[(c, c)] = 1.0;
        }
    }
    mm
}

/// The inverse of an information matrix, where it determines every column:
/// `None` where it is not positive definite (a plain inverse of a singular
/// information returns whatever the rounding makes of it).
pub(super) fn determined_inverse(info: DMatrix<f64>) -> Option<DMatrix<f64>> {
    info.clone().cholesky()?;
    info.try_inverse()
}

/// What least squares on the poses `set` predicts: the model's RMS error
/// at random valid poses and the held-out RMS. Infinite where the set does
/// not determine every column (fewer readings than columns, or columns its
/// poses cannot tell apart: the information is then not positive
/// definite), rather than the number the rounding makes of a singular
/// inverse.
pub(super) fn prediction(
    pool: &design::Pool,
    set: &[usize],
    point_noise_rms_mm: f64,
) -> PredictionAtN {
    let model = determined_inverse(information(pool, set))
        .map_or(f64::INFINITY, |inv| (&pool.w * inv).trace());
    let model = if model > 0.0 { model } else { f64::INFINITY };
    PredictionAtN {
        n_poses: set.len(),
        model_rms_mm: model.sqrt(),
        holdout_rms_mm: (model + point_noise_rms_mm.powi(2)).sqrt(),
    }
}

/// Each column's 1-sigma from the covariance `inv` (rows in noise units:
/// the information's inverse), in the parameters' units.
pub(super) fn predicted_sigmas(
    inv: &Option<DMatrix<f64>>,
    cols: &Columns,
    scene: &Scene,
) -> Vec<PredictedParam> {
    let Some(inv) = inv else {
        return vec![];
    };
    let l = scene.chain.layout;
    let mut out: Vec<PredictedParam> = cols
        .params
        .iter()
        .zip(&cols.param_scale)
        .enumerate()
        .map(|(k, (&i, sc))| {
            let s = inv[(k, k)].max(0.0).sqrt() * sc;
            let angle = l.is_angle(i);
            PredictedParam {
                name: l.name(i),
                sigma: if angle { s.to_degrees() } else { s },
                unit: if angle { "deg" } else { "mm" }.into(),
            }
        })
        .collect();
    let mut k = cols.params.len();
    for (kind, name) in &cols.effects {
        for c in 0..kind.n_coef() {
            out.push(PredictedParam {
                name: if kind.n_coef() > 1 {
                    format!("{name}[{c}]")
                } else {
                    name.clone()
                },
                sigma: inv[(k, k)].max(0.0).sqrt() * cols.effect_scale[k - cols.params.len()],
                unit: "coefficient (rad per N·m, per unit)".into(),
            });
            k += 1;
        }
    }
    out
}

pub(super) fn point_noise_rms(scene: &Scene, poses: &[Candidate], noise: f64) -> f64 {
    let m = scene.anchors().len();
    if m == 0 {
        return noise * 3f64.sqrt();
    }
    let mean: f64 = poses
        .iter()
        .map(|c| {
            let g = DMatrix::from_fn(m, 3, |k, a| (c.t_rig - scene.anchors()[k]).normalize()[a]);
            (g.transpose() * g)
                .try_inverse()
                .map_or(0.0, |inv| inv.trace())
        })
        .sum::<f64>()
        / poses.len() as f64;
    noise * mean.sqrt()
}
