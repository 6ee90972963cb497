//! The size a finding reports for its effect, in a unit a reader knows
//! (degrees, ppm, mm), with its 1-sigma by the delta method from the
//! refit's covariance of the effect's coefficients.

use super::refit::FitInfo;
use crate::identify::Observations;
use crate::physics::effects::{self, Context, CorrectionTarget, EffectModel, Kind, ThermalDriver};

/// Reported magnitude, 1-sigma and unit of an effect.
pub(super) fn magnitude(
    ctx: &Context,
    obs: &Observations,
    e: &EffectModel,
    fit: &FitInfo,
) -> (f64, f64, String) {
    let unit = unit_of(ctx, &e.kind);
    if e.kind.is_data_driven() {
        let (v, s) = data_driven_size(ctx, &e.kind, &e.coef, &obs.train, fit);
        return (v, s, unit);
    }
    let f = size_of(ctx, obs, e);
    let c = &e.coef;
    let v = f(c);
    // Delta method with a numerical gradient of the magnitude.
    let mut grad = vec![0.0; c.len()];
    for i in 0..c.len() {
        let h = 1e-6 * c.iter().map(|x| x.abs()).fold(0.0, f64::max).max(1e-12);
        let mut cp = c.clone();
        cp[i] += h;
        let mut cm = c.clone();
        cm[i] -= h;
        grad[i] = (f(&cp) - f(&cm)) / (2.0 * h);
    }
    let mut var = 0.0;
    for i in 0..c.len() {
        for j in 0..c.len() {
            if i < fit.cov_last.nrows() && j < fit.cov_last.ncols() {
                var += grad[i] * fit.cov_last[(i, j)] * grad[j];
            }
        }
    }
    (v, var.max(0.0).sqrt(), unit)
}

/// The magnitude as a function of the effect's coefficients, so that the
/// delta method can differentiate it.
fn size_of<'a>(
    ctx: &'a Context,
    obs: &Observations,
    e: &EffectModel,
) -> Box<dyn Fn(&[f64]) -> f64 + 'a> {
    let deg = 180.0 / std::f64::consts::PI;
    match &e.kind {
        Kind::JointCompliance {
            regressors,
            joint_index,
        } => {
            if regressors.is_empty() {
                Box::new(move |c: &[f64]| c[0] * deg)
            } else {
                // Lumped coefficients: report the RMS deflection.
                let j = *joint_index;
                let kind = e.kind.clone();
                let train = obs.train.clone();
                Box::new(move |c: &[f64]| {
                    let mut buf = effects::Basis::default();
                    let mut s = 0.0;
                    for &i in &train {
                        ctx.basis(&kind, i, &mut buf);
                        let n = ctx.n_joints;
                        let d: f64 = (0..c.len()).map(|k| c[k] * buf.dq[k * n + j]).sum();
                        s += d * d;
                    }
                    (s / train.len().max(1) as f64).sqrt() * deg
                })
            }
        }
        Kind::LinkBending { .. } => Box::new(|c: &[f64]| c[0] * 1e6),
        Kind::Backlash { .. } | Kind::BaseTilt | Kind::ToolCompliance => {
            Box::new(move |c: &[f64]| c[0] * deg)
        }
        Kind::JointPeriodic { .. } => Box::new(move |c: &[f64]| c[0].hypot(c[1]) * deg),
        Kind::JointScale { .. } => Box::new(|c: &[f64]| c[0] * 1e6),
        // A settling warm-up: its initial rate per hour says little at a
        // glance; the growth it reached over the session does.
        Kind::ThermalExpansion {
            tau_h: Some(tau), ..
        } => {
            let growth = warm_up_growth(ctx, *tau);
            Box::new(move |c: &[f64]| c[0] * growth * 1e6)
        }
        Kind::ThermalExpansion { .. } => Box::new(|c: &[f64]| c[0] * 1e6),
        Kind::SensorScale { .. } => Box::new(|c: &[f64]| c[0] * 1e6),
        Kind::SensorOffset { .. } | Kind::SensorDrift { .. } | Kind::CableSag => {
            Box::new(|c: &[f64]| c[0])
        }
        Kind::AnchorStep { .. } => {
            Box::new(|c: &[f64]| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt())
        }
        Kind::RigStep { .. } | Kind::RigDrift => {
            let kind = e.kind.clone();
            let train = obs.train.clone();
            Box::new(move |c: &[f64]| ctx.rigid_rms_mm(&kind, c, &train))
        }
        Kind::DataDriven { target, .. } => {
            let kind = e.kind.clone();
            let train = obs.train.clone();
            let scale = data_driven_scale(*target);
            Box::new(move |c: &[f64]| data_driven_spread(ctx, &kind, c, &train) * scale)
        }
    }
}

/// A data-driven correction's size ([`data_driven_spread`], in degrees for
/// a joint's angle) and its 1-sigma, with the gradient in closed form: the
/// size is the RMS of a linear function of the coefficients, and a long
/// session's correction has hundreds of them (a numerical gradient would
/// evaluate the whole session twice per coefficient).
fn data_driven_size(
    ctx: &Context,
    kind: &Kind,
    coef: &[f64],
    poses: &[usize],
    fit: &FitInfo,
) -> (f64, f64) {
    let scale = match kind {
        Kind::DataDriven { target, .. } => data_driven_scale(*target),
        _ => 1.0,
    };
    let v = data_driven_spread(ctx, kind, coef, poses);
    if v <= 0.0 || poses.is_empty() {
        return (v * scale, 0.0);
    }
    // u_i = B_i c per pose (1, 3 or one per string); d v / d c = Σ B_iᵀ (u_i - ū) / (N v).
    let mut buf = effects::Basis::default();
    let width = match kind {
        Kind::DataDriven {
            target: CorrectionTarget::RigShape | CorrectionTarget::FrameDeflection,
            ..
        } if !ctx.anchors.is_empty() => ctx.anchors.len(),
        _ => 3,
    };
    let rows: Vec<Vec<(usize, usize, f64)>> = poses
        .iter()
        .map(|&i| basis_entries(ctx, kind, i, coef.len(), &mut buf))
        .collect();
    let u: Vec<Vec<f64>> = rows
        .iter()
        .map(|nz| {
            let mut u = vec![0.0; width];
            for &(r, k, w) in nz {
                u[r] += w * coef[k];
            }
            u
        })
        .collect();
    let count = u.len() as f64;
    let mut mean = vec![0.0; width];
    for x in &u {
        for r in 0..width {
            mean[r] += x[r] / count;
        }
    }
    let mut grad = vec![0.0; coef.len()];
    for (nz, x) in rows.iter().zip(&u) {
        for &(r, k, w) in nz {
            grad[k] += w * (x[r] - mean[r]) / (count * v);
        }
    }
    let c = &fit.cov_last;
    let mut var = 0.0;
    for i in 0..grad.len().min(c.nrows()) {
        if grad[i] == 0.0 {
            continue;
        }
        for j in 0..grad.len().min(c.ncols()) {
            var += grad[i] * c[(i, j)] * grad[j];
        }
    }
    (v * scale, var.max(0.0).sqrt() * scale)
}

/// What a data-driven correction's size is reported in per internal unit:
/// degrees for a joint's angle or play, ppm for a scale, mm otherwise.
fn data_driven_scale(target: CorrectionTarget) -> f64 {
    match target {
        CorrectionTarget::JointAngle | CorrectionTarget::JointPlay => 180.0 / std::f64::consts::PI,
        CorrectionTarget::InstrumentScale | CorrectionTarget::ReadingScale => 1e6,
        _ => 1.0,
    }
}

/// The nonzero entries `(row, coefficient, weight)` of a data-driven
/// correction's basis at pose `i`: row 0 for a joint's angle, one
/// string's reading or a scale's knot weight; each string's row for the
/// frame's shape or deflection; x, y, z of T otherwise.
fn basis_entries(
    ctx: &Context,
    kind: &Kind,
    i: usize,
    n_coef: usize,
    buf: &mut effects::Basis,
) -> Vec<(usize, usize, f64)> {
    let (n, m) = (ctx.n_joints, ctx.anchors.len());
    ctx.basis(kind, i, buf);
    let mut nz = Vec::new();
    let Kind::DataDriven {
        target,
        target_index,
        ..
    } = kind
    else {
        return nz;
    };
    let at = target_index.unwrap_or(0);
    for k in 0..n_coef {
        match target {
            // The play's basis already carries the side the joint arrived from.
            CorrectionTarget::JointAngle | CorrectionTarget::JointPlay => {
                nz.push((0, k, buf.dq[k * n + at]))
            }
            CorrectionTarget::StringReading | CorrectionTarget::StringZeroScale => {
                nz.push((0, k, buf.dl[k * m + at]))
            }
            CorrectionTarget::LinkLength
            | CorrectionTarget::InstrumentScale
            | CorrectionTarget::ReadingScale => {
                let w: f64 = ctx
                    .knot_weights(kind, i)
                    .iter()
                    .filter(|&&(at, _)| at == k)
                    .map(|&(_, w)| w)
                    .sum();
                nz.push((0, k, w));
            }
            CorrectionTarget::RigShape | CorrectionTarget::FrameDeflection if m > 0 => {
                nz.extend((0..m).map(|s| (s, k, buf.dl[k * m + s])))
            }
            _ => nz.extend((0..3).map(|r| (r, k, buf.dp[k * 3 + r]))),
        }
    }
    nz.retain(|&(_, _, w)| w != 0.0);
    nz
}

/// RMS of a data-driven correction's contribution over `poses` about its
/// mean (rad of the joint, or mm of T or of the reading): its constant part
/// is a zero offset the geometry takes.
fn data_driven_spread(ctx: &Context, kind: &Kind, coef: &[f64], poses: &[usize]) -> f64 {
    let mut buf = effects::Basis::default();
    let (n, m) = (ctx.n_joints, ctx.anchors.len());
    let values: Vec<Vec<f64>> = poses
        .iter()
        .map(|&i| {
            ctx.basis(kind, i, &mut buf);
            let sum = |v: &[f64], width: usize, at: usize| -> f64 {
                coef.iter()
                    .enumerate()
                    .map(|(k, c)| c * v[k * width + at])
                    .sum()
            };
            match kind {
                Kind::DataDriven {
                    target: CorrectionTarget::JointAngle | CorrectionTarget::JointPlay,
                    target_index,
                    ..
                } => vec![sum(&buf.dq, n, target_index.unwrap_or(0))],
                Kind::DataDriven {
                    target: CorrectionTarget::StringReading | CorrectionTarget::StringZeroScale,
                    target_index,
                    ..
                } => vec![sum(&buf.dl, m, target_index.unwrap_or(0))],
                // Every string's reading.
                Kind::DataDriven {
                    target: CorrectionTarget::RigShape | CorrectionTarget::FrameDeflection,
                    ..
                } if m > 0 => (0..m).map(|s| sum(&buf.dl, m, s)).collect(),
                Kind::DataDriven {
                    target:
                        CorrectionTarget::LinkLength
                        | CorrectionTarget::InstrumentScale
                        | CorrectionTarget::ReadingScale,
                    ..
                } => vec![
                    ctx.knot_weights(kind, i)
                        .iter()
                        .map(|&(k, w)| coef[k] * w)
                        .sum(),
                ],
                _ => (0..3).map(|r| sum(&buf.dp, 3, r)).collect(),
            }
        })
        .collect();
    let count = values.len().max(1) as f64;
    let width = values.first().map_or(0, Vec::len);
    let mut ss = 0.0;
    for r in 0..width {
        let mean = values.iter().map(|v| v[r]).sum::<f64>() / count;
        ss += values.iter().map(|v| (v[r] - mean).powi(2)).sum::<f64>();
    }
    (ss / count).sqrt()
}

/// The unit of an effect's magnitude, naming a warm-up's time constant
/// and a creep's clock where the session sets them.
fn unit_of(ctx: &Context, kind: &Kind) -> String {
    match kind {
        Kind::ThermalExpansion {
            tau_h: Some(tau),
            driver,
        } => match driver {
            ThermalDriver::Order => format!(
                "ppm (growth over the session, a warm-up settling over about {:.0} rows)",
                tau * 1000.0
            ),
            _ => format!(
                "ppm (growth over the session, a warm-up settling with a time constant of {tau:.2} h)"
            ),
        },
        Kind::SensorDrift { .. } if !ctx.timed => "mm per 1000 rows".into(),
        // Point data: the instrument's frame moves T itself.
        Kind::DataDriven {
            target: CorrectionTarget::RigShape,
            ..
        } if ctx.anchors.is_empty() => "mm (RMS displacement of T over the train poses)".into(),
        other => fixed_unit(other).into(),
    }
}

/// How far a warm-up with time constant `tau_h` settled over the session:
/// its driver at the last hour recorded (h).
pub(super) fn warm_up_growth(ctx: &Context, tau_h: f64) -> f64 {
    let hours = ctx.poses.iter().map(|p| p.thermal).fold(0.0, f64::max);
    effects::warm_up(hours, tau_h)
}

/// Unit of an effect's magnitude (see [`magnitude`]).
fn fixed_unit(kind: &Kind) -> &'static str {
    match kind {
        Kind::JointCompliance { regressors, .. } if regressors.is_empty() => "deg/(N*m)",
        Kind::JointCompliance { .. } => "deg (RMS deflection)",
        Kind::Backlash { .. } => "deg (half dead band)",
        Kind::JointPeriodic { .. } => "deg (amplitude)",
        Kind::JointScale { .. } => "ppm (of the joint angle)",
        Kind::ThermalExpansion { driver, .. } => match driver {
            ThermalDriver::Temperature => "ppm/K",
            ThermalDriver::Time => "ppm/h",
            ThermalDriver::Order => "ppm per 1000 rows",
        },
        Kind::SensorScale { .. } => "ppm",
        Kind::SensorOffset { .. } => "mm",
        Kind::SensorDrift { .. } => "mm/h",
        Kind::CableSag => "mm/m^3",
        Kind::BaseTilt | Kind::ToolCompliance => "deg/(N*m)",
        Kind::LinkBending { .. } => "1e-6/(N*m^2) (1/EI)",
        Kind::AnchorStep { .. } => "mm",
        Kind::RigStep { .. } => "mm (RMS displacement of T after the move)",
        Kind::RigDrift => "mm (RMS displacement of T over the session)",
        Kind::DataDriven {
            target: CorrectionTarget::JointAngle | CorrectionTarget::JointPlay,
            ..
        } => "deg (RMS of the correction over the train poses)",
        Kind::DataDriven {
            target:
                CorrectionTarget::Point | CorrectionTarget::PointSpherical | CorrectionTarget::ToolPoint,
            ..
        } => "mm (RMS displacement of T over the train poses)",
        Kind::DataDriven {
            target: CorrectionTarget::LinkLength,
            ..
        } => "mm (RMS change of the length over the train poses)",
        Kind::DataDriven {
            target: CorrectionTarget::InstrumentScale,
            ..
        } => "ppm (RMS change of the instrument's scale over the train poses)",
        Kind::DataDriven {
            target: CorrectionTarget::ReadingScale,
            ..
        } => "ppm (RMS change of every string's scale over the train poses)",
        Kind::DataDriven {
            target: CorrectionTarget::RigShape | CorrectionTarget::FrameDeflection,
            ..
        } => {
            "mm (RMS over the train poses of the strings' reading changes, root-sum-square over the strings)"
        }
        Kind::DataDriven { .. } => "mm (RMS change of the reading over the train poses)",
    }
}
