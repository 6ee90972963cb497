//! What the recordings conceal: the true geometry drawn from the spec's
//! deviations, and truth.json, which tells it.

use super::Spec;
use super::effect_spec::{effect_rms, report_magnitude};
use super::record::{Recording, Scene, effective_sigma};
use crate::kinematics::{JointParam, Params};
use crate::model::{BasePose, Rig, Robot};
use crate::physics::effects::EffectModel;
use crate::rng::Rng;

/// The true geometry the recordings are made with.
pub(super) struct TrueGeometry {
    /// The rig's guess of the base pose (zero without one).
    pub guess: BasePose,
    /// The true base pose.
    pub base: BasePose,
    /// Nominal parameters plus the deviations, with the true base and tool.
    pub params: Params,
    /// The joint deviations (deg and mm) as truth.json lists them.
    pub deviations: Vec<serde_json::Value>,
}

/// Draw the true base pose (unless the spec gives it), the joint deviations
/// and the tool point error, in that order from `rng`.
pub(super) fn true_geometry(spec: &Spec, robot: &Robot, rig: &Rig, rng: &mut Rng) -> TrueGeometry {
    let n = robot.dof();
    let m = rig.n_strings();
    let guess = rig.base_in_rig.unwrap_or(BasePose {
        xyz_mm: [0.0; 3],
        rpy_deg: [0.0; 3],
    });
    let dev = &spec.deviations;
    let base = spec.base_in_rig.unwrap_or_else(|| BasePose {
        xyz_mm: [
            guess.xyz_mm[0] + dev.base_mm * rng.normal(),
            guess.xyz_mm[1] + dev.base_mm * rng.normal(),
            guess.xyz_mm[2] + dev.base_mm * rng.normal(),
        ],
        rpy_deg: [
            guess.rpy_deg[0] + dev.base_deg * rng.normal(),
            guess.rpy_deg[1] + dev.base_deg * rng.normal(),
            guess.rpy_deg[2] + dev.base_deg * rng.normal(),
        ],
    });
    // True parameters: nominal plus deviations.
    let mut truth_p = Params::nominal(robot, &base, rig, m);
    let l = truth_p.layout;
    let mut devs = Vec::new();
    for j in 0..n {
        let parallel_next = j + 1 < n && robot.joints[j].alpha_deg.abs() < 1.0;
        let mut d = [0.0; 5];
        for (k, jp) in JointParam::ALL.iter().enumerate() {
            let v = match jp {
                JointParam::A | JointParam::D => dev.length_mm * rng.normal(),
                JointParam::Beta if !parallel_next => 0.0,
                _ => (dev.angle_deg * rng.normal()).to_radians(),
            };
            truth_p.values[l.joint(j, *jp)] += v;
            d[k] = if jp.is_angle() { v.to_degrees() } else { v };
        }
        devs.push(serde_json::json!({
            "joint": j + 1, "a_mm": d[0], "alpha_deg": d[1], "d_mm": d[2],
            "theta_offset_deg": d[3], "beta_deg": d[4]
        }));
    }
    for c in 0..3 {
        truth_p.values[l.tool() + c] += dev.tool_mm * rng.normal();
    }
    TrueGeometry {
        guess,
        base,
        params: truth_p,
        deviations: devs,
    }
}

/// What truth.json is made from, beyond the scene.
pub(super) struct TruthInputs<'a> {
    /// The spec.
    pub spec: &'a Spec,
    /// The preset's name, or `file`.
    pub preset_name: &'a str,
    /// Where the tour starts (deg).
    pub home_deg: &'a [f64],
    /// The robot, rig, true geometry and poses.
    pub scene: &'a Scene<'a>,
    /// The effects put in (internal units).
    pub effects: &'a [EffectModel],
    /// The true T with effects and the point noise.
    pub recording: &'a Recording,
    /// RMS 3-D error of a point located from the noisy strings (mm).
    pub point_noise_mm: f64,
}

/// truth.json: the true geometry, the noise, the effects with their size,
/// and the true T of each pose.
pub(super) fn truth_json(t: &TruthInputs) -> serde_json::Value {
    let (spec, scene) = (t.spec, t.scene);
    let (robot, rig, geometry) = (scene.robot, scene.rig, scene.geometry);
    let truth_p = &geometry.params;
    let noise = &spec.noise;
    let true_t = &t.recording.true_t;
    let true_robot = truth_p.to_robot(robot, &format!("{} (true)", robot.name));
    let total_rms = {
        let mut s = 0.0;
        for i in 0..scene.tour.qs.len() {
            s += (true_t[i] - scene.true_t0[i]).norm_squared();
        }
        (s / scene.tour.qs.len() as f64).sqrt()
    };
    serde_json::json!({
        "format": "drawcal-sim truth v1",
        "generator": "drawcal simulate",
        "robot_preset": t.preset_name,
        "deviations": geometry.deviations,
        "true_robot": true_robot,
        "base_in_rig": geometry.base,
        "base_in_rig_guess": geometry.guess,
        "tool_point_mm": truth_p.tool(),
        "tool_point_nominal_mm": robot.tool_point_mm,
        "anchors_mm": rig.anchors_mm,
        "r_mm": rig.r_mm,
        "noise": {
            "sigma_mm": noise.sigma_mm,
            "resolution_mm": noise.resolution_mm,
            "effective_sigma_mm": effective_sigma(noise),
            "model": "reading = round((l_true + N(0, sigma)) / resolution) * resolution"
        },
        "home_q_deg": t.home_deg,
        "effects": effects_json(scene, t.effects),
        "seed": spec.seed,
        "session": spec.session,
        "point_noise_mm": t.point_noise_mm,
        "effect_rms_mm": total_rms,
        "effect_rms_definition": "robot-side effects: RMS over poses of the displacement of the true T; sensor-side: of the point multilaterated from the strings",
        "true_points_mm": true_t.iter().map(|t| [t[0], t[1], t[2]]).collect::<Vec<_>>(),
    })
}

/// truth.json's `effects`: each effect as reported (magnitude in the
/// analysis's units, its RMS displacement) with its model.
fn effects_json(scene: &Scene, effects: &[EffectModel]) -> Vec<serde_json::Value> {
    let ctx0 = &scene.ctx0;
    effects
        .iter()
        .map(|e| {
            let (mag, unit) = report_magnitude(e, ctx0);
            let mut v = serde_json::json!({
                "effect": e.kind.name(),
                "magnitude": mag,
                "unit": unit,
                "description": e.kind.explanation(ctx0),
                "effect_rms_mm": effect_rms(&scene.chain, &scene.geometry.params.values, ctx0, &scene.tour.q_rad, &scene.anchors, e),
                "model": e,
            });
            if let Some(j) = e.kind.joint() {
                v["joint"] = (j + 1).into();
            }
            if let Some(k) = e.kind.sensor() {
                v["sensor"] = (k + 1).into();
            }
            v
        })
        .collect()
}
