//! The recording itself: the true T of each pose, the effects sized
//! against the point noise, the noisy string readings and poses.csv.

use nalgebra::{Matrix3, Vector3};

use super::effect_spec::{effect_model, effect_rms};
use super::tour::Tour;
use super::truth::TrueGeometry;
use super::{NoiseSpec, Spec};
use crate::error::{Error, Result};
use crate::kinematics::chain::{Chain, OutputFrame};
use crate::model::{Rig, Robot};
use crate::physics::effects::{Basis, Context, EffectModel, PoseInput};
use crate::physics::problem::EffectProblem;
use crate::rng::Rng;

/// What the effects act on: the robot, the rig, the true geometry and the
/// tour, with T of the true geometry before any effect.
pub(super) struct Scene<'a> {
    /// Nominal robot.
    pub robot: &'a Robot,
    /// Rig.
    pub rig: &'a Rig,
    /// Kinematic structure with the rig's strings.
    pub chain: Chain,
    /// Anchor positions (rig frame, mm).
    pub anchors: Vec<Vector3<f64>>,
    /// True geometry.
    pub geometry: &'a TrueGeometry,
    /// Poses in visiting order.
    pub tour: &'a Tour,
    /// T of the true geometry without effects, per pose (rig frame, mm).
    pub true_t0: Vec<Vector3<f64>>,
    /// The effects' context at those points.
    pub ctx0: Context,
}

impl<'a> Scene<'a> {
    /// T of the true geometry at each pose of the tour, and the effects'
    /// context there.
    pub(super) fn new(
        robot: &'a Robot,
        rig: &'a Rig,
        chain: Chain,
        anchors: Vec<Vector3<f64>>,
        geometry: &'a TrueGeometry,
        tour: &'a Tour,
    ) -> Scene<'a> {
        let true_t0: Vec<Vector3<f64>> = tour
            .q_rad
            .iter()
            .map(|q| chain.point(&geometry.params.values, q, OutputFrame::Rig).1)
            .collect();
        let ctx0 = context(robot, rig, &anchors, geometry, tour, &true_t0);
        Scene {
            robot,
            rig,
            chain,
            anchors,
            geometry,
            tour,
            true_t0,
            ctx0,
        }
    }

    /// The effects' context with T at `pts` (one per pose).
    pub(super) fn context(&self, pts: &[Vector3<f64>]) -> Context {
        context(
            self.robot,
            self.rig,
            &self.anchors,
            self.geometry,
            self.tour,
            pts,
        )
    }
}

/// The effects' context of the tour's poses with T at `pts`: joint angles,
/// time, temperature, payload, and gravity from the true base rotation.
fn context(
    robot: &Robot,
    rig: &Rig,
    anchors: &[Vector3<f64>],
    geometry: &TrueGeometry,
    tour: &Tour,
    pts: &[Vector3<f64>],
) -> Context {
    let (rb, _) = geometry.params.base_rt();
    let inputs: Vec<PoseInput> = (0..tour.qs.len())
        .map(|i| PoseInput {
            q_rad: &tour.q_rad[i],
            time_s: Some(tour.time[i]),
            temp_c: Some(tour.temp[i]),
            payload_kg: tour.payload[i],
            point_rig: pts[i],
        })
        .collect();
    Context::new(robot, anchors.to_vec(), rig.r_mm, &rb, &inputs)
}

/// The noise of a reading with its quantisation (mm, 1 sigma).
pub(super) fn effective_sigma(noise: &NoiseSpec) -> f64 {
    (noise.sigma_mm.powi(2) + noise.resolution_mm.powi(2) / 12.0).sqrt()
}

/// The RMS 3-D error of a point located from readings with that noise,
/// predicted from the strings' geometry at each true T (mm).
fn predicted_point_noise(scene: &Scene, noise: &NoiseSpec) -> f64 {
    let cov_traces: Vec<f64> = scene
        .true_t0
        .iter()
        .map(|t| {
            let mut g = Matrix3::zeros();
            for a in &scene.anchors {
                let u = (t - a).normalize();
                g += u * u.transpose();
            }
            g.try_inverse().map_or(0.0, |i| i.trace())
        })
        .collect();
    effective_sigma(noise) * (cov_traces.iter().sum::<f64>() / cov_traces.len() as f64).sqrt()
}

/// The spec's effects as effect models, their coefficients from the
/// magnitudes given or scaled to `size_x_noise` times the point noise.
pub(super) fn effects(
    spec: &Spec,
    scene: &Scene,
    home_deg: &[f64],
    rng: &mut Rng,
) -> Result<Vec<EffectModel>> {
    let point_noise_pred = predicted_point_noise(scene, &spec.noise);
    let (ctx0, p) = (&scene.ctx0, &scene.geometry.params.values);
    let mut effects = Vec::new();
    for (ei, es) in spec.effects.iter().enumerate() {
        let e = effect_model(es, ctx0, home_deg, &scene.tour.time, rng)
            .map_err(|msg| Error::field(format!("spec.effects[{ei}]"), msg))?;
        let e = match es.size_x_noise {
            Some(size) => {
                let unit_rms =
                    effect_rms(&scene.chain, p, ctx0, &scene.tour.q_rad, &scene.anchors, &e);
                if unit_rms <= 0.0 {
                    return Err(Error::field(
                        format!("spec.effects[{ei}]"),
                        "this effect does not move anything on these poses",
                    ));
                }
                let s = size * point_noise_pred / unit_rms;
                EffectModel {
                    kind: e.kind,
                    coef: e.coef.iter().map(|c| c * s).collect(),
                }
            }
            None => e,
        };
        effects.push(e);
    }
    Ok(effects)
}

/// The recorded session: what the strings read, and what they conceal.
pub(super) struct Recording {
    /// True T with the robot-side effects, per pose (rig frame, mm).
    pub true_t: Vec<Vector3<f64>>,
    /// String readings per pose (mm, noisy and quantised).
    pub readings: Vec<Vec<f64>>,
    /// Whether each pose is marked `test`.
    pub is_test: Vec<bool>,
    /// Per pose: the point located from the noisy readings minus the one
    /// located from the exact ones (rig frame, mm).
    pub point_noise: Vec<Vector3<f64>>,
    /// Sum over poses of the squared point noise (mm²).
    pub noise_sq: f64,
}

impl Recording {
    /// Put the robot-side effects into T, draw the test poses, then read
    /// the strings at that T with the sensor-side effects and the noise.
    pub(super) fn new(
        spec: &Spec,
        scene: &Scene,
        effects: &[EffectModel],
        rng: &mut Rng,
    ) -> Recording {
        // Robot side first (true T), then the sensors see the true T.
        let robot_eff: Vec<EffectModel> = effects
            .iter()
            .filter(|e| e.kind.robot_side())
            .cloned()
            .collect();
        let sensor_eff: Vec<EffectModel> = effects
            .iter()
            .filter(|e| !e.kind.robot_side())
            .cloned()
            .collect();
        let (chain, q_rad) = (&scene.chain, &scene.tour.q_rad);
        let true_t: Vec<Vector3<f64>> = (0..q_rad.len())
            .map(|i| {
                let p = &scene.geometry.params.values;
                EffectProblem::model_point(chain, &scene.ctx0, p, &robot_eff, i, &q_rad[i]).0
            })
            .collect();
        let ctx1 = scene.context(&true_t);
        let is_test = test_poses(q_rad.len(), spec.test_fraction, rng);
        let mut buf = Basis::default();
        let mut rec = Recording {
            true_t: vec![],
            readings: Vec::with_capacity(q_rad.len()),
            is_test,
            point_noise: Vec::with_capacity(q_rad.len()),
            noise_sq: 0.0,
        };
        for (i, t) in true_t.iter().enumerate() {
            let dl = ctx1.apply(&sensor_eff, i, &mut buf).dl;
            let readings = read_strings(scene, &spec.noise, t, &dl, rng);
            // Point noise: the located point from these readings against the
            // located point from the exact (effect-including) readings.
            match located_difference(scene, t, &dl, &readings) {
                Some(e) => {
                    rec.noise_sq += e.norm_squared();
                    rec.point_noise.push(e);
                }
                None => rec.point_noise.push(Vector3::zeros()),
            }
            rec.readings.push(readings);
        }
        rec.true_t = true_t;
        rec
    }
}

/// Which of `n` poses are marked `test`: a random `fraction` of them, at
/// most all but three.
fn test_poses(n: usize, fraction: f64, rng: &mut Rng) -> Vec<bool> {
    let mut n_test = ((n as f64) * fraction).round() as usize;
    n_test = n_test.min(n.saturating_sub(3));
    let mut idx: Vec<usize> = (0..n).collect();
    rng.shuffle(&mut idx);
    let mut is_test = vec![false; n];
    for &i in &idx[..n_test] {
        is_test[i] = true;
    }
    is_test
}

/// The strings' readings with T at `t`: the true length with the sensor
/// effects `dl`, plus noise, quantised.
fn read_strings(
    scene: &Scene,
    noise: &NoiseSpec,
    t: &Vector3<f64>,
    dl: &[f64],
    rng: &mut Rng,
) -> Vec<f64> {
    let mut readings = Vec::with_capacity(scene.anchors.len());
    for (k, a) in scene.anchors.iter().enumerate() {
        let l_true = (t - a).norm() - scene.rig.r_mm + dl[k];
        let mut v = l_true + noise.sigma_mm * rng.normal();
        if noise.resolution_mm > 0.0 {
            v = (v / noise.resolution_mm).round() * noise.resolution_mm;
        }
        readings.push(v);
    }
    readings
}

/// The point located from `readings` minus the one located from the exact
/// readings at `t` (effects included); None when either does not locate.
fn located_difference(
    scene: &Scene,
    t: &Vector3<f64>,
    dl: &[f64],
    readings: &[f64],
) -> Option<Vector3<f64>> {
    let anchors = &scene.anchors;
    let exact: Vec<f64> = anchors
        .iter()
        .enumerate()
        .map(|(k, a)| (t - a).norm() + dl[k])
        .collect();
    let noisy: Vec<f64> = readings.iter().map(|v| v + scene.rig.r_mm).collect();
    match (
        crate::measure::locate(anchors, &noisy, Some(t)),
        crate::measure::locate(anchors, &exact, Some(t)),
    ) {
        (Ok(a), Ok(b)) => Some(a.point - b.point),
        _ => None,
    }
}

/// poses.csv: pose, joint angles, readings, time, temperature, the payload
/// when the session carries payloads, and the split.
pub(super) fn poses_csv(scene: &Scene, rec: &Recording) -> String {
    let tour = scene.tour;
    let (n, m) = (scene.robot.dof(), scene.anchors.len());
    let mut rows = Vec::new();
    let mut header = vec!["pose".to_string()];
    header.extend((1..=n).map(|j| format!("q{j}_deg")));
    header.extend((1..=m).map(|k| format!("l{k}_mm")));
    header.extend(["time_s", "temp_c"].map(String::from));
    if tour.payload.iter().any(Option::is_some) {
        header.push("payload_kg".into());
    }
    header.push("split".into());
    rows.push(header.join(","));
    for i in 0..tour.qs.len() {
        let mut row = vec![tour.ids[i].clone()];
        row.extend(tour.qs[i].iter().map(|v| format!("{v:.4}")));
        row.extend(rec.readings[i].iter().map(|v| format!("{v:.6}")));
        row.push(format!("{:.3}", tour.time[i]));
        row.push(format!("{:.4}", tour.temp[i]));
        if let Some(p) = tour.payload[i] {
            row.push(format!("{p}"));
        }
        row.push(if rec.is_test[i] { "test" } else { "train" }.into());
        rows.push(row.join(","));
    }
    rows.join("\n") + "\n"
}
