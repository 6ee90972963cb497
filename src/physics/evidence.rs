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
//! The `unexplained` finding has no effect to leave out: its plot
//! ([`unexplained_plot`]) is the final model's residual along the ordering
//! that located the structure, beside the running mean of its neighbours.
//!
//! Size: at most [`EvidencePlot::MAX_POINTS`] points per plot. Poses are
//! kept by a fixed stride in visiting order (`ceil(poses / (MAX_POINTS /
//! points per pose))`),
//! so the choice is deterministic and spread over the whole session.

use std::collections::HashSet;

use nalgebra::{Matrix3, Vector3};

use super::analyse::errors_with_effects;
use super::effects::{Basis, Context, CorrectionDriver, EffectModel, Kind, ThermalDriver};
use super::problem::EffectProblem;
use crate::identify::Observations;
use crate::kinematics::chain::OutputFrame;
use crate::model::Split;
use crate::report::{EvidencePlot, EvidencePoint};

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

impl Driver {
    /// One point per pose.
    fn per_pose(label: String, unit: &str) -> Self {
        Driver {
            label,
            unit: unit.into(),
            per_string: false,
        }
    }
}

fn driver(ctx: &Context, kind: &Kind) -> Driver {
    let d = Driver::per_pose;
    match kind {
        Kind::JointCompliance {
            joint_index,
            regressors,
        } => compliance_driver(ctx, *joint_index, regressors),
        Kind::Backlash { joint_index } => d(
            format!("direction joint {} approached from", joint_index + 1),
            "±1; 0 unknown",
        ),
        Kind::JointPeriodic { joint_index, .. } | Kind::JointScale { joint_index } => {
            d(format!("joint {} angle", joint_index + 1), "deg")
        }
        Kind::ThermalExpansion { driver, .. } => match driver {
            ThermalDriver::Temperature => d("temperature change since the first pose".into(), "K"),
            ThermalDriver::Time => d("hours since the session began".into(), "h"),
            ThermalDriver::Order => d(
                "rows since the first (no time_s), thousands".into(),
                "1000 rows",
            ),
        },
        Kind::SensorScale { sensor_index } => {
            d(format!("length of string {}", sensor_index + 1), "mm")
        }
        Kind::SensorOffset { .. } => {
            let (label, unit) = ctx.time_axis();
            d(label.into(), unit)
        }
        Kind::SensorDrift { .. } if ctx.timed => d("hours since the session began".into(), "h"),
        Kind::SensorDrift { .. } => d(
            "rows since the first (no time_s), thousands".into(),
            "1000 rows",
        ),
        Kind::AnchorStep { t0_s, .. } => {
            let (label, unit) = ctx.time_axis();
            d(format!("{label} (step {})", ctx.when(*t0_s)), unit)
        }
        Kind::BaseTilt => d("gravity moment of the arm about the base".into(), "N*m"),
        Kind::LinkBending { link_index } => d(
            format!(
                "bending moment at the root of the link from joint {} to joint {}",
                link_index + 1,
                link_index + 2
            ),
            "N*m",
        ),
        Kind::ToolCompliance => d(
            "gravity moment of the payload about the flange".into(),
            "N*m",
        ),
        Kind::CableSag => Driver {
            label: "horizontal span of the string".into(),
            unit: "m".into(),
            per_string: true,
        },
        Kind::DataDriven {
            driver,
            driver_index,
            ..
        } => correction_driver(ctx, *driver, *driver_index),
        // A moved rig: the session's clock (the row order without one).
        Kind::RigStep { .. } | Kind::RigDrift => Driver {
            label: if ctx.timed {
                "hours since the session began"
            } else {
                ctx.time_axis().0
            }
            .into(),
            unit: if ctx.timed { "h" } else { "row" }.into(),
            per_string: false,
        },
    }
}

/// A compliance's driver: the gravity torque on the joint (with link
/// masses), or the lever of its first unit-mass regressor (without).
fn compliance_driver(ctx: &Context, joint_index: usize, regressors: &[usize]) -> Driver {
    let d = Driver::per_pose;
    match regressors.first() {
        None => d(
            format!("gravity torque on joint {}", joint_index + 1),
            "N*m",
        ),
        Some(&k) if k == ctx.n_joints + 1 => d(
            format!(
                "gravity lever on joint {} of the payload at the tool point",
                joint_index + 1
            ),
            "kg*m",
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
    }
}

/// A data-driven correction's driver, in its unit.
fn correction_driver(
    ctx: &Context,
    driver: CorrectionDriver,
    driver_index: Option<usize>,
) -> Driver {
    let d = Driver::per_pose;
    let words = super::effects::correction_driver_words(driver, driver_index);
    match driver {
        CorrectionDriver::JointAngle
        | CorrectionDriver::JointMove
        | CorrectionDriver::MoveDirection => d(words, "deg"),
        CorrectionDriver::Time => {
            let (label, unit) = ctx.time_axis();
            d(label.into(), unit)
        }
        CorrectionDriver::Temperature => d(words, "degrees C"),
        CorrectionDriver::StringLength | CorrectionDriver::StringMove => d(words, "mm"),
        CorrectionDriver::GravityTorque | CorrectionDriver::GravityTorqueChange => d(words, "N*m"),
        CorrectionDriver::StringDirection => d(words, "deg"),
        CorrectionDriver::Motion => d(words, "mm"),
        CorrectionDriver::Workspace if matches!(driver_index, Some(3 | 4)) => d(words, "deg"),
        CorrectionDriver::Workspace => d(words, "mm"),
        CorrectionDriver::LineOfSight => d(words, "1"),
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
        Kind::JointPeriodic { joint_index, .. } | Kind::JointScale { joint_index } => {
            pc.q_rad[*joint_index].to_degrees()
        }
        Kind::ThermalExpansion { .. } => pc.thermal,
        Kind::SensorScale { sensor_index } => {
            (pc.point_rig - ctx.anchors[*sensor_index]).norm() - ctx.r_mm
        }
        Kind::SensorDrift { .. } => ctx.clock_h(pc),
        Kind::SensorOffset { .. } | Kind::AnchorStep { .. } if !ctx.timed => pc.time_s + 1.0,
        Kind::SensorOffset { .. } | Kind::AnchorStep { .. } => pc.time_s,
        Kind::BaseTilt => pc.base_moment_nm,
        Kind::ToolCompliance => pc.flange_moment_nm,
        Kind::LinkBending { link_index } => pc
            .bending_moment_nm
            .get(*link_index)
            .copied()
            .unwrap_or(0.0),
        Kind::CableSag => {
            let v = pc.point_rig - ctx.anchors[k];
            let vert = v.dot(&ctx.gravity_rig);
            (v.norm_squared() - vert * vert).max(0.0).sqrt() * 1e-3
        }
        Kind::RigStep { .. } | Kind::RigDrift if !ctx.timed => pc.time_s + 1.0,
        Kind::RigStep { .. } | Kind::RigDrift => ctx.clock_h(pc),
        Kind::DataDriven {
            driver,
            driver_index,
            axis,
            ..
        } => {
            let v = ctx.driver_value(pc, *driver, *driver_index, axis.as_ref());
            match driver {
                CorrectionDriver::JointAngle
                | CorrectionDriver::JointMove
                | CorrectionDriver::MoveDirection
                | CorrectionDriver::StringDirection => v.to_degrees(),
                CorrectionDriver::Workspace if matches!(driver_index, Some(3 | 4)) => {
                    v.to_degrees()
                }
                CorrectionDriver::Time if !ctx.timed => v + 1.0,
                _ => v,
            }
        }
    }
}

/// Model point T (rig frame) at pose `i` with the joint and thermal part
/// of `effects`, plus an extra rotation of one joint and an extra thermal
/// multiplier: for finite differences only (a difference of two calls).
fn point(
    obs: &Observations,
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
    let mut q: Vec<f64> = obs.data.poses[i]
        .q_rad
        .iter()
        .zip(&delta.dq)
        .map(|(a, b)| a + b)
        .collect();
    if let Some((j, h)) = extra_dq {
        q[j] += h;
    }
    obs.chain.point(&pp, &q, OutputFrame::Rig).1
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
    obs: &Observations,
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
    let n = obs.data.poses.len();
    let m = ctx.anchors.len();
    // The instrument's scale or frame moves a tracker's or a camera's
    // points (there are no strings to plot): plotted as T's displacement.
    let robot = e.kind.robot_side()
        || (m == 0
            && matches!(
                e.kind,
                Kind::DataDriven {
                    target: crate::physics::effects::CorrectionTarget::InstrumentScale
                        | crate::physics::effects::CorrectionTarget::RigShape,
                    ..
                }
            ));
    if !robot && (m == 0 || obs.data.n_strings != m) {
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
    // Whole poses are kept, so the bound is on poses: MAX_POINTS / per_pose.
    let stride = n
        .div_ceil((EvidencePlot::MAX_POINTS / per_pose.max(1)).max(1))
        .max(1);
    let idx: Vec<usize> = (0..n).step_by(stride).collect();
    let test: HashSet<usize> = obs.held_out().into_iter().collect();
    let model = Fitted {
        obs,
        ctx,
        p,
        effects,
        without,
        k,
    };
    let points = if robot {
        model.robot_points(&idx, &test)
    } else {
        model.reading_points(&idx, &strings, &test)
    };
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

/// Train or test, as the session split pose `i`.
fn split_of(test: &HashSet<usize>, i: usize) -> Split {
    if test.contains(&i) {
        Split::Test
    } else {
        Split::Train
    }
}

/// The model an evidence plot is drawn from: effect `k` of `effects`, and
/// the same model `without` it (the partial residual's reference).
struct Fitted<'a> {
    obs: &'a Observations<'a>,
    ctx: &'a Context,
    p: &'a [f64],
    effects: &'a [EffectModel],
    without: Vec<EffectModel>,
    k: usize,
}

impl Fitted<'_> {
    /// A robot-side effect's points at poses `idx`: the error without the
    /// effect and the effect's own displacement, both along the unit
    /// displacement of a positive change of what the effect moves, so
    /// that the two are compared in one direction per pose.
    fn robot_points(&self, idx: &[usize], test: &HashSet<usize>) -> Vec<EvidencePoint> {
        let Fitted {
            obs,
            ctx,
            p,
            effects,
            ..
        } = *self;
        let (e, without) = (&effects[self.k], &self.without);
        let mut buf = Basis::default();
        let mut points = Vec::with_capacity(idx.len());
        let b = obs.chain.layout.base();
        let rb: Matrix3<f64> = crate::kinematics::rpy_matrix(p[b + 3], p[b + 4], p[b + 5]);
        // Model minus measured (base frame) without the effect; measured
        // points re-located with the other sensor-side effects applied.
        let errs = errors_with_effects(obs, ctx, p, without, idx);
        // The displacement the effect causes at every pose (rig frame).
        let disp: Vec<Vector3<f64>> = idx
            .iter()
            .map(|&i| {
                let q = &obs.data.poses[i].q_rad;
                EffectProblem::model_point(&obs.chain, ctx, p, effects, i, q).0
                    - EffectProblem::model_point(&obs.chain, ctx, p, without, i, q).0
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
                    point(obs, ctx, p, effects, i, Some((j, STEP)), 0.0)
                        - point(obs, ctx, p, effects, i, None, 0.0)
                }
                (Kind::ThermalExpansion { .. }, _) => {
                    point(obs, ctx, p, effects, i, None, STEP)
                        - point(obs, ctx, p, effects, i, None, 0.0)
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
                pose: obs.data.poses[i].id.clone(),
                split: split_of(test, i),
                sensor: None,
                x: driver_value(ctx, &e.kind, i, 0, &mut buf),
                y,
                model,
            });
        }
        points
    }

    /// A sensor-side effect's points at poses `idx`, one per reading of
    /// `strings`: the reading residual without the effect beside the
    /// correction the effect makes to that reading.
    fn reading_points(
        &self,
        idx: &[usize],
        strings: &[usize],
        test: &HashSet<usize>,
    ) -> Vec<EvidencePoint> {
        let Fitted { obs, ctx, p, k, .. } = *self;
        let e = &self.effects[k];
        let m = ctx.anchors.len();
        let mut buf = Basis::default();
        let mut points = Vec::with_capacity(idx.len() * strings.len());
        // Reading residuals (predicted minus read) without the effect.
        let problem =
            EffectProblem::of_observations(obs, ctx, idx.to_vec(), p, vec![], self.without.clone());
        let mut res = vec![0.0; idx.len() * m];
        let mut seen = vec![0usize; idx.len()];
        problem.residuals(&problem.x0(), |pos, r| {
            if seen[pos] < m {
                res[pos * m + seen[pos]] = r;
            }
            seen[pos] += 1;
        });
        let only = std::slice::from_ref(e);
        for (pos, &i) in idx.iter().enumerate() {
            let dl = ctx.apply(only, i, &mut buf).dl;
            for &s in strings {
                let (y, model) = (-res[pos * m + s], dl[s]);
                if !(y.is_finite() && model.is_finite()) {
                    continue;
                }
                points.push(EvidencePoint {
                    pose: obs.data.poses[i].id.clone(),
                    split: split_of(test, i),
                    sensor: Some(s + 1),
                    x: driver_value(ctx, &e.kind, i, s, &mut buf),
                    y,
                    model,
                });
            }
        }
        points
    }
}

/// What the `unexplained` plot puts on x.
#[derive(Clone, Copy)]
enum OrderKey {
    Joint(usize),
    Time,
    Temperature,
}

/// The x axis of the `unexplained` plot: the key, and the clock's origin
/// when the session has one (else time is the visiting order).
struct Axis {
    key: OrderKey,
    has_time: bool,
    t0: f64,
}

impl Axis {
    /// The key's value at pose `i`, in the unit the label gives.
    fn value(&self, obs: &Observations, ctx: &Context, i: usize) -> f64 {
        match self.key {
            OrderKey::Joint(j) => ctx.poses[i].q_rad[j].to_degrees(),
            OrderKey::Time if self.has_time => (ctx.poses[i].time_s - self.t0) / 3600.0,
            OrderKey::Time => i as f64,
            OrderKey::Temperature => obs.data.poses[i].temp_c.unwrap_or(f64::NAN),
        }
    }
}

/// The axis of the winning ordering (see [`unexplained_plot`]), its label
/// and unit: joint-space neighbours have no single axis, so the joint
/// whose own ordering agreed most stands in and the label says so.
fn unexplained_axis(
    obs: &Observations,
    ctx: &Context,
    winner: usize,
    z: &[f64],
) -> (Axis, String, &'static str) {
    let nj = ctx.n_joints;
    let with_temp = z.len() == nj + 3;
    let (key, located_by) = match winner {
        j if j < nj => (OrderKey::Joint(j), None),
        j if j == nj => (OrderKey::Time, None),
        j if with_temp && j == nj + 1 => (OrderKey::Temperature, None),
        _ => {
            let best = (0..nj)
                .filter(|&j| z[j].is_finite())
                .max_by(|a, b| z[*a].total_cmp(&z[*b]));
            (
                best.map_or(OrderKey::Time, OrderKey::Joint),
                Some(
                    best.map_or("no joint ordering had a z, time shown".to_string(), |j| {
                        format!("the joint whose own ordering agreed most, z = {:.1}", z[j])
                    }),
                ),
            )
        }
    };
    let has_time = obs.data.poses.iter().all(|p| p.time_s.is_some());
    let t0 = ctx.poses.first().map_or(0.0, |p| p.time_s);
    let (mut x_label, x_unit) = match key {
        OrderKey::Joint(j) => (format!("joint {} angle", j + 1), "deg"),
        OrderKey::Time if has_time => ("hours since the session began".to_string(), "h"),
        OrderKey::Time => ("visiting order (no time column)".to_string(), "pose"),
        OrderKey::Temperature => ("temperature".to_string(), "°C"),
    };
    if let Some(why) = located_by {
        x_label = format!("{x_label} (located by nearest neighbours in joint space; {why})");
    }
    (Axis { key, has_time, t0 }, x_label, x_unit)
}

/// The residuals' dominant direction: the largest eigenvector of `Σ e eᵀ`
/// over the train poses that are `ok`, its largest component positive;
/// `None` when there is none.
fn dominant_direction(
    err: &[Vector3<f64>],
    train: &[usize],
    ok: impl Fn(usize) -> bool,
) -> Option<Vector3<f64>> {
    let mut m2 = Matrix3::zeros();
    for &i in train.iter().filter(|&&i| ok(i)) {
        m2 += err[i] * err[i].transpose();
    }
    let eig = nalgebra::SymmetricEigen::new(m2);
    let top = (0..3).max_by(|a, b| eig.eigenvalues[*a].total_cmp(&eig.eigenvalues[*b]))?;
    let mut u: Vector3<f64> = eig.eigenvectors.column(top).into_owned();
    let big = (0..3).max_by(|a, b| u[*a].abs().total_cmp(&u[*b].abs()))?;
    if u[big] < 0.0 {
        u = -u;
    }
    (u.norm() > 0.5).then_some(u)
}

/// Leave-one-out running mean of the `k` train poses nearest in x: the
/// plot's model, which on pure noise does not predict y.
struct RunningMean {
    /// Train poses as (x, pose, y), sorted by (x, pose).
    sorted: Vec<(f64, usize, f64)>,
    k: usize,
}

impl RunningMean {
    /// Over the train poses `(x, pose, y)` (any order), with `k` the
    /// rounded square root of their number.
    fn new(mut sorted: Vec<(f64, usize, f64)>) -> Self {
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let len = sorted.len();
        let k = ((len as f64).sqrt().round() as usize).clamp(1, len.saturating_sub(1).max(1));
        RunningMean { sorted, k }
    }

    /// The mean of y over the `k` train poses nearest `x`, pose `i` itself
    /// left out (NaN without any).
    fn at(&self, x: f64, i: usize) -> f64 {
        let (sorted, k) = (&self.sorted, self.k);
        let len = sorted.len();
        let pos = sorted.partition_point(|s| s.0.total_cmp(&x).then(s.1.cmp(&i)).is_lt());
        let (mut lo, mut hi) = (pos, pos);
        if hi < len && sorted[hi].1 == i {
            hi += 1;
        }
        let (mut sum, mut count) = (0.0, 0usize);
        while count < k && (lo > 0 || hi < len) {
            let take = if lo == 0 {
                hi
            } else if hi == len || x - sorted[lo - 1].0 <= sorted[hi].0 - x {
                lo - 1
            } else {
                hi
            };
            if take == hi {
                hi += 1;
            } else {
                lo -= 1;
            }
            sum += sorted[take].2;
            count += 1;
        }
        if count == 0 {
            f64::NAN
        } else {
            sum / count as f64
        }
    }
}

/// The evidence plot of the `unexplained` finding: the structure the
/// locator found, along the ordering that found it.
///
/// `winner` is the index of the winning ordering and `z[k]` the z of
/// ordering `k` (NaN where it had none), the orderings in the order
/// `unexplained` builds them: joint 1..n angles, time, temperature (when
/// every pose has one, i.e. `z.len() == n + 3`), and last the nearest
/// neighbour in joint space.
///
/// - x: the winning key per pose: the joint angle (deg), hours since the
///   session began (the pose index in visiting order without a `time_s`
///   column), or the temperature (°C). For the joint-space neighbours,
///   which have no single axis, the joint whose own 1-D ordering had the
///   largest z (time where no joint has one); `x_label` says so.
/// - y: each pose's 3-D error (measured minus the final model: geometry
///   and the accepted effects, sensor-side ones applied to the readings
///   before the point is located again, as [`errors_with_effects`] has it)
///   projected on the residuals' dominant direction: the first principal
///   direction (largest eigenvector of `Σ e eᵀ` over the train poses, base
///   frame, sign such that its largest component is positive). The 3-D
///   error rather than the string residual vector for string data too:
///   the same quantity for point and string data and for test poses, and
///   one direction means the same displacement of T at every pose (a
///   direction in reading space would not, the strings' directions change
///   with the pose).
/// - model: a smooth of y along x, the leave-one-out running mean of the
///   `k = round(sqrt(train poses))` train poses nearest in x (the pose
///   itself left out, so that on pure noise y and model are uncorrelated;
///   test poses get the running mean of the train poses around them).
///   `correlation` measures how much of y the neighbours along x predict.
///
/// Same bound and stride rule as [`evidence_plot`]; train and test poses
/// marked. `None` without train poses or with an unknown `winner`.
pub fn unexplained_plot(
    obs: &Observations,
    ctx: &Context,
    p: &[f64],
    effects: &[EffectModel],
    winner: usize,
    z: &[f64],
) -> Option<EvidencePlot> {
    let nj = ctx.n_joints;
    let n = obs.data.poses.len();
    if winner >= z.len() || z.len() < nj + 2 || obs.train.is_empty() {
        return None;
    }
    let (axis, x_label, x_unit) = unexplained_axis(obs, ctx, winner, z);
    let key_value = |i: usize| axis.value(obs, ctx, i);

    // Errors of the final model at every pose, measured minus model.
    let all: Vec<usize> = (0..n).collect();
    let err: Vec<Vector3<f64>> = errors_with_effects(obs, ctx, p, effects, &all)
        .into_iter()
        .map(|e| -e)
        .collect();
    let ok = |i: usize| err[i].iter().all(|v| v.is_finite()) && key_value(i).is_finite();
    let u = dominant_direction(&err, &obs.train, ok)?;
    let y = |i: usize| err[i].dot(&u);

    // Train poses sorted by (x, pose): the running mean's neighbours.
    let smooth = RunningMean::new(
        obs.train
            .iter()
            .filter(|&&i| ok(i))
            .map(|&i| (key_value(i), i, y(i)))
            .collect(),
    );

    let stride = n.div_ceil(EvidencePlot::MAX_POINTS).max(1);
    let test: HashSet<usize> = obs.held_out().into_iter().collect();
    let mut points = Vec::new();
    for i in (0..n).step_by(stride) {
        if !ok(i) {
            continue;
        }
        let (x, yi) = (key_value(i), y(i));
        let model = smooth.at(x, i);
        if !(yi.is_finite() && model.is_finite()) {
            continue;
        }
        points.push(EvidencePoint {
            pose: obs.data.poses[i].id.clone(),
            split: split_of(&test, i),
            sensor: None,
            x,
            y: yi,
            model,
        });
    }
    let ys: Vec<f64> = points.iter().map(|q| q.y).collect();
    let ms: Vec<f64> = points.iter().map(|q| q.model).collect();
    Some(EvidencePlot {
        x_label,
        x_unit: x_unit.into(),
        y_label: format!(
            "error (measured minus the final model) along the residuals' dominant direction ({:.3}, {:.3}, {:.3}) in the base frame; model: running mean of the {} train poses nearest in x, the pose itself left out",
            u[0], u[1], u[2], smooth.k
        ),
        y_unit: "mm".into(),
        correlation: pearson(&ys, &ms),
        n_total: n,
        stride,
        points,
    })
}
