//! The simulator behind `drawcal simulate`: recordings in the DATA_FORMAT
//! files from a robot, a rig, parameter deviations, a base pose, noise and
//! any set of physical effects (the same [`Context::basis`] the analysis
//! fits). The spec is documented in docs/PHYSICS.md.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::effects::{Basis, Context, EffectModel, Kind, PoseInput};
use super::problem::EffectProblem;
use crate::error::{Error, Result};
use crate::kinematics::chain::{Chain, OutputFrame};
use crate::kinematics::{JointParam, Params};
use crate::model::{BasePose, Convention, Dataset, JointSpec, LinkMass, Rig, Robot, SensorSpec};
use crate::rng::Rng;

/// A simulation spec (JSON).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spec {
    /// Preset name (`er3a`, `ur5`, `arm4_mdh`) or a robot.json path.
    pub robot: String,
    /// rig.json path; default: the preset's rig.
    #[serde(default)]
    pub rig: Option<String>,
    /// Number of poses.
    #[serde(default = "default_poses")]
    pub n_poses: usize,
    /// Fraction marked `test` in the split column.
    #[serde(default = "default_test")]
    pub test_fraction: f64,
    /// Seed of everything random.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Geometric deviations: random (1-sigma sizes) unless `explicit` given.
    #[serde(default)]
    pub deviations: DeviationSpec,
    /// True base pose; default the rig's guess plus a random error.
    #[serde(default)]
    pub base_in_rig: Option<BasePose>,
    /// String noise.
    #[serde(default)]
    pub noise: NoiseSpec,
    /// Session timing and temperature.
    #[serde(default)]
    pub session: SessionSpec,
    /// Physical effects.
    #[serde(default)]
    pub effects: Vec<EffectSpec>,
}

fn default_poses() -> usize {
    80
}
fn default_test() -> f64 {
    0.3
}
fn default_seed() -> u64 {
    1
}

/// Geometric deviations from nominal.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DeviationSpec {
    /// 1-sigma of a and d (mm).
    #[serde(default = "dev_len")]
    pub length_mm: f64,
    /// 1-sigma of alpha and theta (deg); beta only between parallel axes.
    #[serde(default = "dev_ang")]
    pub angle_deg: f64,
    /// 1-sigma of each tool point coordinate (mm).
    #[serde(default = "dev_len")]
    pub tool_mm: f64,
    /// 1-sigma of the base position (mm) and orientation (deg) error
    /// relative to the rig's `base_in_rig` guess.
    #[serde(default = "dev_base")]
    pub base_mm: f64,
    /// Base orientation error (deg).
    #[serde(default = "dev_base_deg")]
    pub base_deg: f64,
}

fn dev_len() -> f64 {
    0.5
}
fn dev_ang() -> f64 {
    0.1
}
fn dev_base() -> f64 {
    2.0
}
fn dev_base_deg() -> f64 {
    0.5
}

impl Default for DeviationSpec {
    fn default() -> Self {
        DeviationSpec {
            length_mm: dev_len(),
            angle_deg: dev_ang(),
            tool_mm: dev_len(),
            base_mm: dev_base(),
            base_deg: dev_base_deg(),
        }
    }
}

/// `reading = round((l_true + N(0, sigma)) / resolution) * resolution`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NoiseSpec {
    /// Gaussian noise per reading (mm).
    #[serde(default = "noise_sigma")]
    pub sigma_mm: f64,
    /// Quantisation step (mm); 0 for none.
    #[serde(default = "noise_res")]
    pub resolution_mm: f64,
}

fn noise_sigma() -> f64 {
    0.02
}
fn noise_res() -> f64 {
    0.024
}

impl Default for NoiseSpec {
    fn default() -> Self {
        NoiseSpec {
            sigma_mm: noise_sigma(),
            resolution_mm: noise_res(),
        }
    }
}

/// Session timing and ambient temperature.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SessionSpec {
    /// Slowest joint's speed between poses (deg/s).
    #[serde(default = "speed")]
    pub speed_deg_s: f64,
    /// Settling and measuring time per pose (s).
    #[serde(default = "dwell")]
    pub dwell_s: f64,
    /// Temperature at the start (°C).
    #[serde(default = "temp0")]
    pub temp_start_c: f64,
    /// Rise towards which the temperature settles (K).
    #[serde(default = "rise")]
    pub temp_rise_c: f64,
    /// Time constant of the rise (s).
    #[serde(default = "tau")]
    pub temp_tau_s: f64,
    /// Payloads (kg) carried at the tool point, in turn, in equal blocks of
    /// the session (test weights swapped part-way); empty: no payload and
    /// no `payload_kg` column.
    #[serde(default)]
    pub payload_kg: Vec<f64>,
}

fn speed() -> f64 {
    30.0
}
fn dwell() -> f64 {
    20.0
}
fn temp0() -> f64 {
    20.0
}
fn rise() -> f64 {
    6.0
}
fn tau() -> f64 {
    1800.0
}

impl Default for SessionSpec {
    fn default() -> Self {
        SessionSpec {
            speed_deg_s: speed(),
            dwell_s: dwell(),
            temp_start_c: temp0(),
            temp_rise_c: rise(),
            temp_tau_s: tau(),
            payload_kg: Vec::new(),
        }
    }
}

/// One effect to put into the recordings. Give either `magnitude` (in the
/// unit the analysis reports) or `size_x_noise` (the effect's RMS
/// displacement of T, or of the located point for sensor effects, in
/// multiples of the point noise).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectSpec {
    /// Catalogue name.
    pub effect: String,
    /// Joint (1-based) for joint effects.
    #[serde(default)]
    pub joint: Option<usize>,
    /// Sensor (1-based) for sensor effects.
    #[serde(default)]
    pub sensor: Option<usize>,
    /// Harmonic of `joint_periodic` (default 1).
    #[serde(default)]
    pub harmonic: Option<u32>,
    /// Phase of `joint_periodic` (deg): `A sin(h q + phase)`.
    #[serde(default)]
    pub phase_deg: Option<f64>,
    /// Direction of an `anchor_step`, `rig_step` or `rig_drift` translation
    /// (rig frame, normalised; default random).
    #[serde(default)]
    pub direction: Option<[f64; 3]>,
    /// When an `anchor_step` or `rig_step` happens, as a fraction of the
    /// session (default random in 0.2-0.8); other effects ignore it.
    #[serde(default)]
    pub at_fraction: Option<f64>,
    /// Magnitude in report units: compliance deg/(N*m), backlash deg (half
    /// dead band), periodic deg (amplitude), joint_scale ppm, thermal ppm/K, sensor_scale
    /// ppm, sensor_offset mm, sensor_drift mm/h, cable_sag mm/m^3, anchor_step mm, rig_step mm
    /// (translation; plus as many mrad of rotation about a random axis),
    /// rig_drift mm/h (likewise mrad/h).
    #[serde(default)]
    pub magnitude: Option<f64>,
    /// Size as a multiple of the point noise (overrides `magnitude`).
    #[serde(default)]
    pub size_x_noise: Option<f64>,
}

/// A generated dataset, in memory.
pub struct Simulated {
    /// Nominal robot (robot.json).
    pub robot: Robot,
    /// Rig (rig.json).
    pub rig: Rig,
    /// poses.csv text.
    pub poses_csv: String,
    /// Parsed poses.
    pub dataset: Dataset,
    /// truth.json.
    pub truth: serde_json::Value,
    /// The effects as put in (internal units).
    pub effects: Vec<EffectModel>,
    /// RMS 3-D error of a point multilaterated from the noisy strings (mm).
    pub point_noise_mm: f64,
    /// Per pose: point located from the noisy readings minus the point
    /// located from the exact ones (rig frame, mm).
    pub point_noise: Vec<Vector3<f64>>,
}

/// A built-in robot and its rig.
pub fn preset(name: &str) -> Option<(Robot, Rig, Vec<f64>)> {
    match name {
        "er3a" => Some((
            Robot::from_json(include_str!("../../tests/data/er3a_paper_like/robot.json")).ok()?,
            Rig::from_json(include_str!("../../tests/data/er3a_paper_like/rig.json")).ok()?,
            vec![0.0, 0.0, 0.0, 0.0, 45.0, 0.0],
        )),
        "ur5" => Some((
            Robot::from_json(include_str!("../../tests/data/ur5_geometric/robot.json")).ok()?,
            Rig::from_json(include_str!("../../tests/data/ur5_geometric/rig.json")).ok()?,
            vec![0.0, -90.0, 0.0, -90.0, 0.0, 0.0],
        )),
        "arm4_mdh" => {
            let j = |a: f64, al: f64, d: f64, lo: f64, hi: f64| JointSpec {
                a_mm: a,
                alpha_deg: al,
                d_mm: d,
                theta_offset_deg: 0.0,
                beta_deg: 0.0,
                q_min_deg: lo,
                q_max_deg: hi,
            };
            let lm = |m: f64, c: [f64; 3]| LinkMass {
                mass_kg: m,
                com_mm: c,
            };
            let robot = Robot {
                name: "4-axis arm, Craig MDH (drawcal preset)".into(),
                convention: Convention::Mdh,
                joints: vec![
                    j(0.0, 0.0, 300.0, -170.0, 170.0),
                    j(50.0, -90.0, 0.0, -100.0, 100.0),
                    j(350.0, 0.0, 0.0, -130.0, 130.0),
                    j(300.0, 0.0, 0.0, -120.0, 120.0),
                ],
                tool_point_mm: [100.0, 0.0, 0.0],
                links: Some(vec![
                    lm(8.0, [0.0, 0.0, -60.0]),
                    lm(5.0, [175.0, 0.0, 0.0]),
                    lm(3.0, [150.0, 0.0, 10.0]),
                    lm(1.0, [50.0, 0.0, 0.0]),
                ]),
                gravity_in_base: Some([0.0, 0.0, -9.81]),
            };
            let rig = Rig {
                anchors_mm: vec![
                    [0.0, 0.0, 0.0],
                    [0.0, 1000.0, 0.0],
                    [1200.0, 0.0, 0.0],
                    [1200.0, 1000.0, 0.0],
                ],
                anchor_names: Some(vec!["A".into(), "B".into(), "C".into(), "D".into()]),
                r_mm: 35.0,
                base_in_rig: Some(BasePose {
                    xyz_mm: [600.0, 500.0, -450.0],
                    rpy_deg: [0.0, 0.0, 0.0],
                }),
                sensor: Some(SensorSpec {
                    range_mm: Some(2000.0),
                    resolution_mm: Some(0.024),
                    linearity_pct_fs: Some(0.05),
                }),
                instrument: None,
            };
            Some((robot, rig, vec![0.0, -30.0, 60.0, 0.0]))
        }
        _ => None,
    }
}

/// The robot and rig of `spec`: its preset's, or the files the caller read
/// for the paths it names (`files`: robot.json, rig.json; the engine reads
/// no files).
fn load(spec: &Spec, files: SpecFiles) -> Result<(Robot, Rig, Vec<f64>, String)> {
    let rig_file = |files: &SpecFiles| match (&spec.rig, &files.rig) {
        (_, Some(rig)) => Ok(Some(rig.clone())),
        (Some(path), None) => Err(Error::field(
            "spec.rig",
            format!("{path}: a rig.json path, but its file was not read (the CLI reads it)"),
        )),
        (None, _) => Ok(None),
    };
    if let Some((robot, rig, home)) = preset(&spec.robot) {
        let rig = rig_file(&files)?.unwrap_or(rig);
        return Ok((robot, rig, home, spec.robot.clone()));
    }
    let Some(robot) = files.robot.clone() else {
        return Err(Error::field(
            "spec.robot",
            format!(
                "{:?} is not a preset (er3a, ur5, arm4_mdh); a robot.json path is read by the CLI",
                spec.robot
            ),
        ));
    };
    let Some(rig) = rig_file(&files)? else {
        return Err(Error::field(
            "spec.rig",
            "a robot.json path needs a rig.json path too",
        ));
    };
    let home = robot
        .joints
        .iter()
        .map(|j| 0.5 * (j.q_min_deg + j.q_max_deg))
        .collect();
    Ok((robot, rig, home, "file".into()))
}

/// The files a [`Spec`] names, read by the caller: the robot.json of a
/// `robot` that is not a preset, the rig.json of `rig` (a rig given here
/// replaces a preset's even when the spec names none).
#[derive(Debug, Clone, Default)]
pub struct SpecFiles {
    /// The robot `spec.robot` names (none for a preset).
    pub robot: Option<Robot>,
    /// The rig `spec.rig` names.
    pub rig: Option<Rig>,
}

/// Generate a dataset from a spec whose robot is a preset (and whose rig is
/// the preset's).
pub fn generate(spec: &Spec) -> Result<Simulated> {
    generate_with(spec, SpecFiles::default())
}

/// Generate a dataset from a spec and the files it names.
pub fn generate_with(spec: &Spec, files: SpecFiles) -> Result<Simulated> {
    let (robot, rig, home_deg, preset_name) = load(spec, files)?;
    let n = robot.dof();
    let m = rig.n_strings();
    if m < 3 {
        return Err(Error::field(
            "spec.rig",
            "the simulator makes string recordings: at least 3 anchors",
        ));
    }
    let mut rng = Rng::new(spec.seed);
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
    let mut truth_p = Params::nominal(&robot, &base, &rig, m);
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
    let chain = Chain::new(robot.convention, n, m);
    let anchors: Vec<Vector3<f64>> = (0..m).map(|k| rig.anchor(k)).collect();
    let range = rig.sensor.and_then(|s| s.range_mm).unwrap_or(2000.0);
    // Side of the anchor plane the nominal model puts T on (the analysis
    // locates with that hint; stay clear of the plane).
    let normal = (anchors[1] - anchors[0])
        .cross(&(anchors[2] - anchors[0]))
        .normalize();
    let nominal_guess = Params::nominal(&robot, &guess, &rig, m);
    let reach: f64 = robot
        .joints
        .iter()
        .map(|j| j.a_mm.abs() + j.d_mm.abs())
        .sum::<f64>()
        .max(100.0);

    // Sample poses.
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
    // A realistic tour: greedy nearest neighbour in joint space from home.
    let mut order = Vec::with_capacity(qs.len());
    let mut left: Vec<usize> = (0..qs.len()).collect();
    let mut cur = home_deg.clone();
    let dist = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    };
    while !left.is_empty() {
        let (pos, _) = left
            .iter()
            .enumerate()
            .map(|(p, &i)| (p, dist(&cur, &qs[i])))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("non-empty");
        let i = left.swap_remove(pos);
        cur = qs[i].clone();
        order.push(i);
    }
    let qs: Vec<Vec<f64>> = order.into_iter().map(|i| qs[i].clone()).collect();
    let ss = &spec.session;
    let mut time = Vec::with_capacity(qs.len());
    let mut temp = Vec::with_capacity(qs.len());
    let mut t = 0.0;
    let mut prev = home_deg.clone();
    for q in &qs {
        t += dist(&prev, q) / ss.speed_deg_s.max(1e-3) + ss.dwell_s * (0.8 + 0.4 * rng.uniform());
        prev = q.clone();
        time.push((t * 1000.0).round() / 1000.0);
        let tc = ss.temp_start_c + ss.temp_rise_c * (1.0 - (-t / ss.temp_tau_s.max(1.0)).exp());
        temp.push((tc * 1e4).round() / 1e4);
    }
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
    let true_t0: Vec<Vector3<f64>> = q_rad
        .iter()
        .map(|q| chain.point(&truth_p.values, q, OutputFrame::Rig).1)
        .collect();
    let (rb, _) = truth_p.base_rt();
    let make_ctx = |pts: &[Vector3<f64>]| {
        let inputs: Vec<PoseInput> = (0..qs.len())
            .map(|i| PoseInput {
                q_rad: &q_rad[i],
                time_s: Some(time[i]),
                temp_c: Some(temp[i]),
                payload_kg: payload[i],
                point_rig: pts[i],
            })
            .collect();
        Context::new(&robot, anchors.clone(), rig.r_mm, &rb, &inputs)
    };
    let ctx0 = make_ctx(&true_t0);
    let noise = &spec.noise;
    let eff_sigma = (noise.sigma_mm.powi(2) + noise.resolution_mm.powi(2) / 12.0).sqrt();
    let cov_traces: Vec<f64> = true_t0
        .iter()
        .map(|t| {
            let mut g = Matrix3::zeros();
            for a in &anchors {
                let u = (t - a).normalize();
                g += u * u.transpose();
            }
            g.try_inverse().map_or(0.0, |i| i.trace())
        })
        .collect();
    let point_noise_pred =
        eff_sigma * (cov_traces.iter().sum::<f64>() / cov_traces.len() as f64).sqrt();

    // Effects: coefficients from magnitudes or sizes.
    let mut effects = Vec::new();
    for (ei, es) in spec.effects.iter().enumerate() {
        let e = effect_model(es, &ctx0, &home_deg, &time, &mut rng)
            .map_err(|msg| Error::field(format!("spec.effects[{ei}]"), msg))?;
        let e = match es.size_x_noise {
            Some(size) => {
                let unit_rms = effect_rms(&chain, &truth_p.values, &ctx0, &q_rad, &anchors, &e);
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
    let mut buf = Basis::default();
    let true_t: Vec<Vector3<f64>> = (0..qs.len())
        .map(|i| {
            EffectProblem::model_point(&chain, &ctx0, &truth_p.values, &robot_eff, i, &q_rad[i]).0
        })
        .collect();
    let ctx1 = make_ctx(&true_t);
    let mut rows = Vec::new();
    let mut n_test = ((qs.len() as f64) * spec.test_fraction).round() as usize;
    n_test = n_test.min(qs.len().saturating_sub(3));
    let mut idx: Vec<usize> = (0..qs.len()).collect();
    rng.shuffle(&mut idx);
    let mut is_test = vec![false; qs.len()];
    for &i in &idx[..n_test] {
        is_test[i] = true;
    }
    let mut noise_sq = 0.0;
    let mut point_noise = Vec::with_capacity(qs.len());
    let mut header = vec!["pose".to_string()];
    header.extend((1..=n).map(|j| format!("q{j}_deg")));
    header.extend((1..=m).map(|k| format!("l{k}_mm")));
    header.extend(["time_s", "temp_c"].map(String::from));
    if !ss.payload_kg.is_empty() {
        header.push("payload_kg".into());
    }
    header.push("split".into());
    rows.push(header.join(","));
    for i in 0..qs.len() {
        let d = ctx1.apply(&sensor_eff, i, &mut buf);
        let mut readings = Vec::with_capacity(m);
        for (k, a) in anchors.iter().enumerate() {
            let l_true = (true_t[i] - a).norm() - rig.r_mm + d.dl[k];
            let mut v = l_true + noise.sigma_mm * rng.normal();
            if noise.resolution_mm > 0.0 {
                v = (v / noise.resolution_mm).round() * noise.resolution_mm;
            }
            readings.push(v);
        }
        // Point noise: the located point from these readings against the
        // located point from the exact (effect-including) readings.
        let exact: Vec<f64> = anchors
            .iter()
            .enumerate()
            .map(|(k, a)| (true_t[i] - a).norm() + d.dl[k])
            .collect();
        let noisy: Vec<f64> = readings.iter().map(|v| v + rig.r_mm).collect();
        if let (Ok(a), Ok(b)) = (
            crate::measure::locate(&anchors, &noisy, Some(&true_t[i])),
            crate::measure::locate(&anchors, &exact, Some(&true_t[i])),
        ) {
            noise_sq += (a.point - b.point).norm_squared();
            point_noise.push(a.point - b.point);
        } else {
            point_noise.push(Vector3::zeros());
        }
        let mut row = vec![format!("{}", i + 1)];
        row.extend(qs[i].iter().map(|v| format!("{v:.4}")));
        row.extend(readings.iter().map(|v| format!("{v:.6}")));
        row.push(format!("{:.3}", time[i]));
        row.push(format!("{:.4}", temp[i]));
        if let Some(p) = payload[i] {
            row.push(format!("{p}"));
        }
        row.push(if is_test[i] { "test" } else { "train" }.into());
        rows.push(row.join(","));
    }
    let poses_csv = rows.join("\n") + "\n";
    let dataset = Dataset::from_csv(poses_csv.as_bytes(), &robot, &rig)?;
    let point_noise_mm = (noise_sq / qs.len() as f64).sqrt();

    let true_robot = truth_p.to_robot(&robot, &format!("{} (true)", robot.name));
    let effects_json: Vec<serde_json::Value> = effects
        .iter()
        .map(|e| {
            let (mag, unit) = report_magnitude(e, &ctx0);
            let mut v = serde_json::json!({
                "effect": e.kind.name(),
                "magnitude": mag,
                "unit": unit,
                "description": e.kind.explanation(&ctx0),
                "effect_rms_mm": effect_rms(&chain, &truth_p.values, &ctx0, &q_rad, &anchors, e),
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
        .collect();
    let total_rms = {
        let mut s = 0.0;
        for i in 0..qs.len() {
            s += (true_t[i] - true_t0[i]).norm_squared();
        }
        (s / qs.len() as f64).sqrt()
    };
    let truth = serde_json::json!({
        "format": "drawcal-sim truth v1",
        "generator": "drawcal simulate",
        "robot_preset": preset_name,
        "deviations": devs,
        "true_robot": true_robot,
        "base_in_rig": base,
        "base_in_rig_guess": guess,
        "tool_point_mm": truth_p.tool(),
        "tool_point_nominal_mm": robot.tool_point_mm,
        "anchors_mm": rig.anchors_mm,
        "r_mm": rig.r_mm,
        "noise": {
            "sigma_mm": noise.sigma_mm,
            "resolution_mm": noise.resolution_mm,
            "effective_sigma_mm": eff_sigma,
            "model": "reading = round((l_true + N(0, sigma)) / resolution) * resolution"
        },
        "home_q_deg": home_deg,
        "effects": effects_json,
        "seed": spec.seed,
        "session": spec.session,
        "point_noise_mm": point_noise_mm,
        "effect_rms_mm": total_rms,
        "effect_rms_definition": "robot-side effects: RMS over poses of the displacement of the true T; sensor-side: of the point multilaterated from the strings",
        "true_points_mm": true_t.iter().map(|t| [t[0], t[1], t[2]]).collect::<Vec<_>>(),
    });
    Ok(Simulated {
        robot,
        rig,
        poses_csv,
        dataset,
        truth,
        effects,
        point_noise_mm,
        point_noise,
    })
}

/// Effect model from a spec entry, with its magnitude in internal units
/// (or unit size when only `size_x_noise` is given).
fn effect_model(
    es: &EffectSpec,
    ctx: &Context,
    home_deg: &[f64],
    time: &[f64],
    rng: &mut Rng,
) -> std::result::Result<EffectModel, String> {
    let (n, m) = (ctx.n_joints, ctx.anchors.len());
    let joint = || -> std::result::Result<usize, String> {
        match es.joint {
            Some(j) if (1..=n).contains(&j) => Ok(j - 1),
            _ => Err(format!("'{}' needs a joint in 1..={n}", es.effect)),
        }
    };
    let sensor = || -> std::result::Result<usize, String> {
        match es.sensor {
            Some(k) if (1..=m).contains(&k) => Ok(k - 1),
            _ => Err(format!("'{}' needs a sensor in 1..={m}", es.effect)),
        }
    };
    let mag = es.magnitude.unwrap_or(1.0);
    let rad = mag.to_radians();
    let (kind, coef) = match es.effect.as_str() {
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
        "thermal_expansion" => (
            Kind::ThermalExpansion {
                driver: ctx.thermal_driver,
                tau_h: None,
            },
            vec![mag * 1e-6],
        ),
        "sensor_scale" => (
            Kind::SensorScale {
                sensor_index: sensor()?,
            },
            vec![mag * 1e-6],
        ),
        "sensor_offset" => (
            Kind::SensorOffset {
                sensor_index: sensor()?,
            },
            vec![mag],
        ),
        "sensor_drift" => (
            Kind::SensorDrift {
                sensor_index: sensor()?,
            },
            vec![mag],
        ),
        "cable_sag" => (Kind::CableSag, vec![mag]),
        "anchor_step" => {
            let dir = match es.direction {
                Some(d) => Vector3::new(d[0], d[1], d[2]),
                None => Vector3::new(rng.normal(), rng.normal(), rng.normal()),
            };
            let dir = dir
                .try_normalize(1e-12)
                .ok_or("anchor_step direction is zero")?;
            let frac = es.at_fraction.unwrap_or_else(|| rng.range(0.2, 0.8));
            let last = time.last().copied().unwrap_or(0.0);
            (
                Kind::AnchorStep {
                    sensor_index: sensor()?,
                    t0_s: frac * last,
                },
                vec![mag * dir[0], mag * dir[1], mag * dir[2]],
            )
        }
        "rig_step" | "rig_drift" => {
            let unit = |v: Vector3<f64>| v.try_normalize(1e-12);
            let dir = match es.direction {
                Some(d) => Vector3::new(d[0], d[1], d[2]),
                None => Vector3::new(rng.normal(), rng.normal(), rng.normal()),
            };
            let dir = unit(dir).ok_or("rig motion direction is zero")?;
            let axis = unit(Vector3::new(rng.normal(), rng.normal(), rng.normal()))
                .unwrap_or(Vector3::z());
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
            if es.effect == "rig_step" {
                let frac = es.at_fraction.unwrap_or_else(|| rng.range(0.2, 0.8));
                let last = time.last().copied().unwrap_or(0.0);
                (Kind::RigStep { t0_s: frac * last }, coef)
            } else {
                (Kind::RigDrift, coef)
            }
        }
        other => return Err(format!("unknown effect '{other}'")),
    };
    Ok(EffectModel { kind, coef })
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
        Kind::AnchorStep { .. } => ((c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt(), "mm"),
        Kind::RigStep { .. } => (
            ctx.rigid_rms_mm(&e.kind, c, &(0..ctx.poses.len()).collect::<Vec<_>>()),
            "mm (RMS displacement of T after the move)",
        ),
        Kind::RigDrift => (
            ctx.rigid_rms_mm(&e.kind, c, &(0..ctx.poses.len()).collect::<Vec<_>>()),
            "mm (RMS displacement of T over the session)",
        ),
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
