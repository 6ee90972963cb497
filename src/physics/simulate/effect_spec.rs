//! An effect entry of the spec as an effect model (one builder per effect
//! family), and the size of an effect as reported and as it moves things.

use nalgebra::{Matrix3, Vector3};

use super::EffectSpec;
use crate::kinematics::chain::{Chain, OutputFrame};
use crate::physics::effects::{Basis, Context, EffectModel, Kind};
use crate::physics::problem::EffectProblem;
use crate::rng::Rng;

/// An effect's kind and its coefficients (internal units).
type KindCoef = (Kind, Vec<f64>);

/// Effect model from a spec entry, with its magnitude in internal units
/// (or unit size when only `size_x_noise` is given).
pub(super) fn effect_model(
    es: &EffectSpec,
    ctx: &Context,
    home_deg: &[f64],
    time: &[f64],
    rng: &mut Rng,
) -> Result<EffectModel, String> {
    let mag = es.magnitude.unwrap_or(1.0);
    let (kind, coef) = match es.effect.as_str() {
        "joint_compliance" | "backlash" | "joint_periodic" | "joint_scale" => {
            joint_effect(es, mag, ctx, home_deg, rng)?
        }
        "thermal_expansion" => (
            Kind::ThermalExpansion {
                driver: ctx.thermal_driver,
                tau_h: None,
            },
            vec![mag * 1e-6],
        ),
        "sensor_scale" | "sensor_offset" | "sensor_drift" => sensor_effect(es, mag, ctx)?,
        "cable_sag" => (Kind::CableSag, vec![mag]),
        "base_tilt" => {
            if !ctx.has_masses {
                return Err("base_tilt needs link masses in robot.json".into());
            }
            (Kind::BaseTilt, vec![mag.to_radians()])
        }
        "link_bending" => {
            if !ctx.has_masses {
                return Err("link_bending needs link masses in robot.json".into());
            }
            let j = joint_index(es, ctx.n_joints)?;
            if !ctx.can_bend(j) {
                return Err(format!(
                    "link_bending: the link from joint {} to the next joint's axis is not one the analysis models (the first joint's column, or a span under {} mm)",
                    j + 1,
                    crate::physics::effects::MIN_BENDING_SPAN_MM
                ));
            }
            (Kind::LinkBending { link_index: j }, vec![mag * 1e-6])
        }
        "tool_compliance" => {
            if ctx.poses.iter().all(|p| p.flange_moment_nm == 0.0) {
                return Err("tool_compliance needs a payload: session.payload_kg (or a payload_kg column in the targets) with a nonzero payload".into());
            }
            (Kind::ToolCompliance, vec![mag.to_radians()])
        }
        "anchor_step" => anchor_step(es, mag, ctx, time, rng)?,
        "rig_step" | "rig_drift" => rig_motion(es, mag, time, rng)?,
        other => return Err(format!("unknown effect '{other}'")),
    };
    Ok(EffectModel { kind, coef })
}

/// The 0-based joint of a joint effect's entry.
fn joint_index(es: &EffectSpec, n: usize) -> Result<usize, String> {
    match es.joint {
        Some(j) if (1..=n).contains(&j) => Ok(j - 1),
        _ => Err(format!("'{}' needs a joint in 1..={n}", es.effect)),
    }
}

/// The 0-based sensor of a sensor effect's entry.
fn sensor_index(es: &EffectSpec, m: usize) -> Result<usize, String> {
    match es.sensor {
        Some(k) if (1..=m).contains(&k) => Ok(k - 1),
        _ => Err(format!("'{}' needs a sensor in 1..={m}", es.effect)),
    }
}

/// The joint effects: compliance, backlash, periodic error, scale.
fn joint_effect(
    es: &EffectSpec,
    mag: f64,
    ctx: &Context,
    home_deg: &[f64],
    rng: &mut Rng,
) -> Result<KindCoef, String> {
    let joint = || joint_index(es, ctx.n_joints);
    let rad = mag.to_radians();
    Ok(match es.effect.as_str() {
        "joint_compliance" => {
            if !ctx.has_masses {
                return Err("joint_compliance needs link masses in robot.json".into());
            }
            (
                Kind::JointCompliance {
                    joint_index: joint()?,
                    regressors: vec![],
                },
                vec![rad],
            )
        }
        "backlash" => {
            // The tour starts at home: the first pose's approach is the move
            // from there (the file does not carry it).
            let j = joint()?;
            let first = ctx.poses.first().map_or(0.0, |p| {
                let d = p.q_rad[j].to_degrees() - home_deg[j];
                if d.abs() > 1e-7 { d.signum() } else { 0.0 }
            });
            (Kind::Backlash { joint_index: j }, vec![rad, rad * first])
        }
        "joint_periodic" => {
            let ph = es
                .phase_deg
                .unwrap_or_else(|| rng.range(0.0, 360.0))
                .to_radians();
            (
                Kind::JointPeriodic {
                    joint_index: joint()?,
                    harmonic: es.harmonic.unwrap_or(1).max(1),
                },
                // A sin(hq + ph) = A cos(ph) sin(hq) + A sin(ph) cos(hq)
                vec![rad * ph.cos(), rad * ph.sin()],
            )
        }
        "joint_scale" => (
            Kind::JointScale {
                joint_index: joint()?,
            },
            vec![mag * 1e-6],
        ),
        other => unreachable!("{other} is not a joint effect"),
    })
}

/// The sensor effects on the reading: scale, offset, drift.
fn sensor_effect(es: &EffectSpec, mag: f64, ctx: &Context) -> Result<KindCoef, String> {
    let sensor_index = sensor_index(es, ctx.anchors.len())?;
    Ok(match es.effect.as_str() {
        "sensor_scale" => (Kind::SensorScale { sensor_index }, vec![mag * 1e-6]),
        "sensor_offset" => (Kind::SensorOffset { sensor_index }, vec![mag]),
        "sensor_drift" => (Kind::SensorDrift { sensor_index }, vec![mag]),
        other => unreachable!("{other} is not a sensor effect"),
    })
}

/// The entry's translation direction, or a random one.
fn direction(es: &EffectSpec, rng: &mut Rng) -> Vector3<f64> {
    match es.direction {
        Some(d) => Vector3::new(d[0], d[1], d[2]),
        None => Vector3::new(rng.normal(), rng.normal(), rng.normal()),
    }
}

/// When a step happens (s): the entry's fraction of the session, or a
/// random one in 0.2-0.8.
fn step_time(es: &EffectSpec, time: &[f64], rng: &mut Rng) -> f64 {
    let frac = es.at_fraction.unwrap_or_else(|| rng.range(0.2, 0.8));
    let last = time.last().copied().unwrap_or(0.0);
    frac * last
}

/// One anchor moved part-way through the session.
fn anchor_step(
    es: &EffectSpec,
    mag: f64,
    ctx: &Context,
    time: &[f64],
    rng: &mut Rng,
) -> Result<KindCoef, String> {
    let dir = direction(es, rng)
        .try_normalize(1e-12)
        .ok_or("anchor_step direction is zero")?;
    let t0_s = step_time(es, time, rng);
    Ok((
        Kind::AnchorStep {
            sensor_index: sensor_index(es, ctx.anchors.len())?,
            t0_s,
        },
        vec![mag * dir[0], mag * dir[1], mag * dir[2]],
    ))
}

/// The whole rig moved: a step part-way through the session (`rig_step`)
/// or a steady creep (`rig_drift`).
fn rig_motion(es: &EffectSpec, mag: f64, time: &[f64], rng: &mut Rng) -> Result<KindCoef, String> {
    let unit = |v: Vector3<f64>| v.try_normalize(1e-12);
    let dir = unit(direction(es, rng)).ok_or("rig motion direction is zero")?;
    let axis = unit(Vector3::new(rng.normal(), rng.normal(), rng.normal())).unwrap_or(Vector3::z());
    // As much rotation as translation: `mag` mrad moves a point 1 m
    // from the centre by `mag` mm.
    let coef = vec![
        mag * dir[0],
        mag * dir[1],
        mag * dir[2],
        mag * axis[0],
        mag * axis[1],
        mag * axis[2],
    ];
    Ok(if es.effect == "rig_step" {
        (
            Kind::RigStep {
                t0_s: step_time(es, time, rng),
            },
            coef,
        )
    } else {
        (Kind::RigDrift, coef)
    })
}

/// The magnitude as reported (same units as the analysis's findings).
pub fn report_magnitude(e: &EffectModel, ctx: &Context) -> (f64, &'static str) {
    let deg = 180.0 / std::f64::consts::PI;
    let c = &e.coef;
    match e.kind {
        Kind::JointCompliance { .. } => (c[0] * deg, "deg/(N*m)"),
        Kind::Backlash { .. } => (c[0] * deg, "deg (half dead band)"),
        Kind::JointPeriodic { .. } => (c[0].hypot(c[1]) * deg, "deg (amplitude)"),
        Kind::JointScale { .. } => (c[0] * 1e6, "ppm (of the joint angle)"),
        Kind::ThermalExpansion { .. } => (c[0] * 1e6, "ppm/K"),
        Kind::SensorScale { .. } => (c[0] * 1e6, "ppm"),
        Kind::SensorOffset { .. } => (c[0], "mm"),
        Kind::SensorDrift { .. } => (c[0], "mm/h"),
        Kind::CableSag => (c[0], "mm/m^3"),
        Kind::BaseTilt | Kind::ToolCompliance => (c[0] * deg, "deg/(N*m)"),
        Kind::LinkBending { .. } => (c[0] * 1e6, "1e-6/(N*m^2) (1/EI)"),
        Kind::AnchorStep { .. } => ((c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt(), "mm"),
        Kind::RigStep { .. } => (
            ctx.rigid_rms_mm(&e.kind, c, &(0..ctx.poses.len()).collect::<Vec<_>>()),
            "mm (RMS displacement of T after the move)",
        ),
        Kind::RigDrift => (
            ctx.rigid_rms_mm(&e.kind, c, &(0..ctx.poses.len()).collect::<Vec<_>>()),
            "mm (RMS displacement of T over the session)",
        ),
        // The simulator draws catalogue effects only; a data-driven
        // correction is never a truth.
        Kind::DataDriven { .. } => (f64::NAN, "data-driven correction (never simulated)"),
    }
}

/// RMS over poses of what an effect does: the displacement of T (robot
/// side) or of the multilaterated point (sensor side), mm.
pub fn effect_rms(
    chain: &Chain,
    p: &[f64],
    ctx: &Context,
    q_rad: &[Vec<f64>],
    anchors: &[Vector3<f64>],
    e: &EffectModel,
) -> f64 {
    let mut buf = Basis::default();
    let one = std::slice::from_ref(e);
    let mut s = 0.0;
    for (i, q) in q_rad.iter().enumerate() {
        let d = ctx.apply(one, i, &mut buf);
        let t0 = chain.point(p, q, OutputFrame::Rig).1;
        if e.kind.robot_side() {
            s += (EffectProblem::model_point(chain, ctx, p, one, i, q).0 - t0).norm_squared();
        } else {
            let mut gtg = Matrix3::zeros();
            let mut gtr = Vector3::zeros();
            for (k, a) in anchors.iter().enumerate() {
                let u = (t0 - a).normalize();
                gtg += u * u.transpose();
                gtr += u * d.dl[k];
            }
            if let Some(inv) = gtg.try_inverse() {
                s += (inv * gtr).norm_squared();
            }
        }
    }
    (s / q_rad.len().max(1) as f64).sqrt()
}
