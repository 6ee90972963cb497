//! The evidence plot of a finding: what the residual does along the
//! effect's own signature, against what drives the effect, beside the
//! fitted effect (see [`EvidencePlot`] for the definition of every number).
//!
//! Computed here, in the numerical core, so the browser page and the
//! offline HTML report only draw what the report holds.
//!
//! The residual is a partial residual: the model fitted with the effect
//! (geometry, the other effects and this one, as the analysis refitted
//! them) with this effect's contribution taken out. It is the part of the
//! data that this effect has to explain, free of what the geometry or the
//! other effects absorb; where the effect is real, the points follow the
//! model.
//!
//! Size: at most [`EvidencePlot::MAX_POINTS`] points per plot. Poses are
//! kept by a fixed stride in visiting order (`ceil(points / MAX_POINTS)`),
//! so the choice is deterministic and spread over the whole session.

use nalgebra::{Matrix3, Vector3};

use super::analyse::errors_with_effects;
use super::effects::{Basis, Context, EffectModel, Kind, ThermalDriver};
use super::problem::EffectProblem;
use crate::identify::Session;
use crate::identify::report::{EvidencePlot, EvidencePoint};
use crate::kinematics::chain::OutputFrame;
use crate::model::Split;

/// Finite-difference step of the signature direction (rad of a joint, or
/// thermal multiplier).
const STEP: f64 = 1e-6;

/// What drives an effect: axis label, unit, and its value at (pose, string).
struct Driver {
    label: String,
    unit: String,
    /// One point per string reading (cable sag and sensor-side effects with
    /// no single string), rather than one per pose.
    per_string: bool,
}

fn driver(ctx: &Context, kind: &Kind) -> Driver {
    let d = |label: String, unit: &str| Driver {
        label,
        unit: unit.into(),
        per_string: false,
    };
    match kind {
        Kind::JointCompliance {
            joint_index,
            regressors,
        } => match regressors.first() {
            None => d(
                format!("gravity torque on joint {}", joint_index + 1),
                "N*m",
            ),
            Some(&k) if k == ctx.n_joints => d(
                format!(
                    "gravity lever on joint {} of a unit mass at the tool point",
                    joint_index + 1
                ),
                "m",
            ),
            Some(&k) => d(
                format!(
                    "gravity lever on joint {} of a unit mass at the origin of link frame {k}",
                    joint_index + 1
                ),
                "m",
            ),
        },
        Kind::Backlash { joint_index } => d(
            format!("direction joint {} approached from", joint_index + 1),
            "±1; 0 unknown",
        ),
        Kind::JointPeriodic { joint_index, .. } => {
            d(format!("joint {} angle", joint_index + 1), "deg")
        }
        Kind::ThermalExpansion { driver } => match driver {
            ThermalDriver::Temperature => d("temperature change since the first pose".into(), "K"),
            ThermalDriver::Time => d("hours since the session began".into(), "h"),
        },
        Kind::SensorScale { sensor_index } => {
            d(format!("length of string {}", sensor_index + 1), "mm")
        }
        Kind::SensorOffset { .. } => d("time since the session began".into(), "s"),
        Kind::AnchorStep { t0_s, .. } => d(
            format!("time since the session began (step at {t0_s:.0} s)"),
            "s",
        ),
        Kind::CableSag => Driver {
            label: "horizontal span of the string".into(),
            unit: "m".into(),
            per_string: true,
        },
        // Effects added to the catalogue later: time as the driver.
        #[allow(unreachable_patterns)]
        _ => Driver {
            label: "hours since the session began".into(),
            unit: "h".into(),
            per_string: !kind.robot_side() && kind.sensor().is_none(),
        },
    }
}

/// Value of the driver of `kind` at pose `i` (string `k` where it matters).
fn driver_value(ctx: &Context, kind: &Kind, i: usize, k: usize, buf: &mut Basis) -> f64 {
    let pc = &ctx.poses[i];
    match kind {
        Kind::JointCompliance {
            joint_index,
            regressors,
        } => {
            // The torque (with masses) or the lever of the first regressor,
            // as the effect's own basis gives it.
            let one = Kind::JointCompliance {
                joint_index: *joint_index,
                regressors: regressors.first().map(|&r| vec![r]).unwrap_or_default(),
            };
            ctx.basis(&one, i, buf);
            buf.dq[*joint_index]
        }
        Kind::Backlash { joint_index } => pc.direction[*joint_index],
        Kind::JointPeriodic { joint_index, .. } => pc.q_rad[*joint_index].to_degrees(),
        Kind::ThermalExpansion { .. } => pc.thermal,
        Kind::SensorScale { sensor_index } => {
            (pc.point_rig - ctx.anchors[*sensor_index]).norm() - ctx.r_mm
        }
        Kind::SensorOffset { .. } | Kind::AnchorStep { .. } => pc.time_s,
        Kind::CableSag => {
            let v = pc.point_rig - ctx.anchors[k];
            let vert = v.dot(&ctx.gravity_rig);
            (v.norm_squared() - vert * vert).max(0.0).sqrt() * 1e-3
        }
        #[allow(unreachable_patterns)]
        _ => (pc.time_s - ctx.poses.first().map_or(0.0, |p| p.time_s)) / 3600.0,
    }
}

/// Model point T (rig frame) at pose `i` with the joint and thermal part
/// of `effects`, plus an extra rotation of one joint and an extra thermal
/// multiplier: for finite differences only (a difference of two calls).
fn point(
    session: &Session,
    ctx: &Context,
    p: &[f64],
    effects: &[EffectModel],
    i: usize,
    extra_dq: Option<(usize, f64)>,
    extra_thermal: f64,
) -> Vector3<f64> {
    let mut buf = Basis::default();
    let delta = ctx.apply(effects, i, &mut buf);
    let mut pp = p.to_vec();
    ctx.apply_thermal(&mut pp, delta.thermal + extra_thermal);
    let mut q: Vec<f64> = session.data.poses[i]
        .q_rad
        .iter()
        .zip(&delta.dq)
        .map(|(a, b)| a + b)
        .collect();
    if let Some((j, h)) = extra_dq {
        q[j] += h;
    }
    session.chain.point(&pp, &q, OutputFrame::Rig).1
}

fn pearson(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len().min(b.len());
    if n < 2 {
        return None;
    }
    let ma = a.iter().sum::<f64>() / n as f64;
    let mb = b.iter().sum::<f64>() / n as f64;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    let r = sab / (saa * sbb).sqrt();
    r.is_finite().then_some(r)
}

/// The evidence plot of `effects[k]` in the model (`p`, `effects`) that
/// was fitted with it, over every pose of the session (train and test),
/// subsampled to at most [`EvidencePlot::MAX_POINTS`] points. `None` when
/// `k` is out of range, or for a sensor-side effect on point data.
pub fn evidence_plot(
    session: &Session,
    ctx: &Context,
    p: &[f64],
    effects: &[EffectModel],
    k: usize,
) -> Option<EvidencePlot> {
    let e = effects.get(k)?;
    let without: Vec<EffectModel> = effects
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != k)
        .map(|(_, e)| e.clone())
        .collect();
    let n = session.data.poses.len();
    let m = ctx.anchors.len();
    let robot = e.kind.robot_side();
    if !robot && (m == 0 || session.data.n_strings != m) {
        return None;
    }
    let drv = driver(ctx, &e.kind);
    let strings: Vec<usize> = match e.kind.sensor() {
        _ if robot => vec![0],
        Some(s) if !drv.per_string => vec![s],
        _ => (0..m).collect(),
    };
    let per_pose = strings.len();
    let n_total = n * per_pose;
    let stride = n_total.div_ceil(EvidencePlot::MAX_POINTS).max(1);
    let idx: Vec<usize> = (0..n).step_by(stride).collect();
    let test: std::collections::HashSet<usize> = session.test.iter().copied().collect();
    let split = |i: usize| {
        if test.contains(&i) {
            Split::Test
        } else {
            Split::Train
        }
    };
    let mut buf = Basis::default();
    let mut points = Vec::with_capacity(idx.len() * per_pose);
    if robot {
        let b = session.chain.layout.base();
        let rb: Matrix3<f64> = crate::kinematics::rpy_matrix(p[b + 3], p[b + 4], p[b + 5]);
        // Model minus measured (base frame) without the effect; measured
        // points re-located with the other sensor-side effects applied.
        let errs = errors_with_effects(session, ctx, p, &without, &idx);
        // The displacement the effect causes at every pose (rig frame).
        let disp: Vec<Vector3<f64>> = idx
            .iter()
            .map(|&i| {
                let q = &session.data.poses[i].q_rad;
                EffectProblem::model_point(&session.chain, ctx, p, effects, i, q).0
                    - EffectProblem::model_point(&session.chain, ctx, p, &without, i, q).0
            })
            .collect();
        // For effects without a joint angle or thermal multiplier to
        // differentiate (added to the catalogue later, e.g. a rigid motion
        // of the rig): the direction of the largest displacement orients
        // every pose's own, and stands in where the effect does nothing.
        let reference = disp
            .iter()
            .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))
            .copied()
            .unwrap_or_else(Vector3::zeros);
        for (pos, &i) in idx.iter().enumerate() {
            let d = disp[pos];
            // Unit displacement of a positive change of what the effect
            // moves (a joint angle, the thermal multiplier).
            let g = match (&e.kind, e.kind.joint()) {
                (_, Some(j)) => {
                    point(session, ctx, p, effects, i, Some((j, STEP)), 0.0)
                        - point(session, ctx, p, effects, i, None, 0.0)
                }
                (Kind::ThermalExpansion { .. }, _) => {
                    point(session, ctx, p, effects, i, None, STEP)
                        - point(session, ctx, p, effects, i, None, 0.0)
                }
                _ if d.norm() > 1e-9 * reference.norm() => {
                    if d.dot(&reference) < 0.0 {
                        -d
                    } else {
                        d
                    }
                }
                _ => reference,
            };
            let gn = g.norm();
            if !(gn > 1e-12) {
                continue;
            }
            let u = g / gn;
            let residual = -(rb * errs[pos]);
            let (y, model) = (residual.dot(&u), d.dot(&u));
            if !(y.is_finite() && model.is_finite()) {
                continue;
            }
            points.push(EvidencePoint {
                pose: session.data.poses[i].id.clone(),
                split: split(i),
                sensor: None,
                x: driver_value(ctx, &e.kind, i, 0, &mut buf),
                y,
                model,
            });
        }
    } else {
        // Reading residuals (predicted minus read) without the effect.
        let problem = EffectProblem {
            chain: session.chain,
            ctx,
            data: session.data,
            poses: idx.clone(),
            full: p.to_vec(),
            free: vec![],
            effects: without,
        };
        let mut res = vec![0.0; idx.len() * m];
        let mut seen = vec![0usize; idx.len()];
        problem.rows(&problem.x0(), |pos, r, _| {
            if seen[pos] < m {
                res[pos * m + seen[pos]] = r;
            }
            seen[pos] += 1;
        });
        let only = std::slice::from_ref(e);
        for (pos, &i) in idx.iter().enumerate() {
            let dl = ctx.apply(only, i, &mut buf).dl;
            for &s in &strings {
                let (y, model) = (-res[pos * m + s], dl[s]);
                if !(y.is_finite() && model.is_finite()) {
                    continue;
                }
                points.push(EvidencePoint {
                    pose: session.data.poses[i].id.clone(),
                    split: split(i),
                    sensor: Some(s + 1),
                    x: driver_value(ctx, &e.kind, i, s, &mut buf),
                    y,
                    model,
                });
            }
        }
    }
    let ys: Vec<f64> = points.iter().map(|q| q.y).collect();
    let ms: Vec<f64> = points.iter().map(|q| q.model).collect();
    Some(EvidencePlot {
        x_label: drv.label,
        x_unit: drv.unit,
        y_label: if robot {
            "error along the displacement the effect causes (measured minus the model without the effect)".into()
        } else {
            "string reading minus the model's reading without the effect".into()
        },
        y_unit: "mm".into(),
        correlation: pearson(&ys, &ms),
        n_total,
        stride,
        points,
    })
}
