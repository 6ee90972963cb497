//! Blind evaluation: simulate datasets with concealed effects (or none),
//! run the geometric identification and the analysis without the truth,
//! then score the findings against the truth.

use crate::identify::{self, IdentifyOptions, NoProgress, Observations};
use crate::model::Rig;
use crate::physics::simulate::{self, EffectSpec, Spec, SpecFiles};
use crate::physics::{self, Kind};
use crate::rng::Rng;

/// The effects drawn at random.
pub const CATALOGUE: [&str; 12] = [
    "joint_compliance",
    "backlash",
    "joint_periodic",
    "joint_scale",
    "thermal_expansion",
    "sensor_scale",
    "sensor_offset",
    "sensor_drift",
    "cable_sag",
    "anchor_step",
    "rig_step",
    "rig_drift",
];

/// What one dataset held and what the analysis said.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Robot preset.
    pub robot: String,
    /// Seed of the dataset.
    pub seed: u64,
    /// Size of the concealed effects (multiples of the point noise; 0 for
    /// none).
    pub size_x_noise: f64,
    /// Concealed effects: (name, joint or sensor, 1-based).
    pub truth: Vec<(String, Option<usize>)>,
    /// Findings: (name, joint or sensor).
    pub found: Vec<(String, Option<usize>)>,
    /// Held-out RMS of the geometric model (mm).
    pub test_geometric_mm: f64,
    /// Held-out RMS of the final model (mm).
    pub test_final_mm: f64,
    /// Held-out RMS of the located points' own noise (noisy against exact
    /// readings): the noise floor of this dataset (mm).
    pub test_floor_mm: f64,
    /// Analysis time (s).
    pub seconds: f64,
    /// Named findings whose held-out 3-D RMS went up when modelled (the
    /// gate is on the held-out readings).
    pub worse_3d: usize,
}

/// Slot of an effect: its name, with the harmonic for a periodic joint
/// error (a third harmonic named as a first is not right), and which joint
/// or sensor (1-based).
fn slot(
    name: &str,
    harmonic: Option<u64>,
    joint: Option<usize>,
    sensor: Option<usize>,
) -> (String, Option<usize>) {
    let name = match harmonic {
        Some(h) if name == "joint_periodic" => format!("{name}_{h}x"),
        _ => name.to_string(),
    };
    (name, joint.or(sensor))
}

/// Joints worth putting a joint effect on: T is at least 20 mm off the
/// joint's axis (a wrist roll turning the tool point about itself moves
/// nothing, and is not identifiable from T alone).
pub fn movable_joints(robot: &crate::model::Robot) -> Vec<usize> {
    use crate::kinematics::Params;
    use crate::kinematics::chain::{Chain, OutputFrame};
    let p = Params::of_robot(robot);
    let chain = Chain::new(robot.convention, robot.dof(), 0);
    let q: Vec<f64> = robot
        .joints
        .iter()
        .map(|j| (0.5 * (j.q_min_deg + j.q_max_deg)).to_radians() + 0.3)
        .collect();
    let (_, t) = chain.point(&p.values, &q, OutputFrame::Base);
    chain
        .joint_axes(&p.values, &q, OutputFrame::Base)
        .iter()
        .enumerate()
        .filter(|(_, (z, o))| z.cross(&(t - o)).norm() > 20.0)
        .map(|(j, _)| j + 1)
        .collect()
}

/// Draw one random effect for a robot with `n_strings` strings.
pub fn draw_effect(rng: &mut Rng, joints: &[usize], n_strings: usize, size: f64) -> EffectSpec {
    // Only what the arm and the rig can carry: joint effects need a joint
    // that moves T, string effects need strings (tracker points have none).
    let applicable: Vec<&str> = CATALOGUE
        .iter()
        .copied()
        .filter(|&e| match e {
            "joint_compliance" | "backlash" | "joint_periodic" | "joint_scale" => {
                !joints.is_empty()
            }
            "sensor_scale" | "sensor_offset" | "sensor_drift" | "anchor_step" | "cable_sag" => {
                n_strings > 0
            }
            _ => true,
        })
        .collect();
    let name = applicable[(rng.uniform() * applicable.len() as f64) as usize % applicable.len()];
    let pick = |rng: &mut Rng, v: &[usize]| v[(rng.uniform() * v.len() as f64) as usize % v.len()];
    let sensors: Vec<usize> = (1..=n_strings).collect();
    let (joint, sensor) = match name {
        "joint_compliance" | "backlash" | "joint_periodic" | "joint_scale" => {
            (Some(pick(rng, joints)), None)
        }
        "sensor_scale" | "sensor_offset" | "sensor_drift" | "anchor_step" => {
            (None, Some(pick(rng, &sensors)))
        }
        _ => (None, None),
    };
    // Every harmonic the analysis tries, equally often.
    let harmonic = (name == "joint_periodic").then(|| {
        let h: Vec<usize> = (1..=physics::analyse::MAX_HARMONIC as usize).collect();
        pick(rng, &h) as u32
    });
    EffectSpec {
        effect: name.into(),
        joint,
        sensor,
        harmonic,
        phase_deg: None,
        direction: None,
        at_fraction: None,
        magnitude: None,
        size_x_noise: Some(size),
    }
}

/// Simulate one dataset and analyse it blind.
pub fn run_case(
    robot: &str,
    rig: Option<&Rig>,
    seed: u64,
    effects: Vec<EffectSpec>,
    size: f64,
    n_poses: usize,
) -> crate::Result<Outcome> {
    let spec = Spec {
        robot: robot.into(),
        rig: None,
        n_poses,
        test_fraction: 0.3,
        seed,
        deviations: Default::default(),
        base_in_rig: None,
        noise: Default::default(),
        session: Default::default(),
        effects,
    };
    let sim = simulate::generate_with(
        &spec,
        SpecFiles {
            robot: None,
            rig: rig.cloned(),
            poses: None,
        },
    )?;
    let truth: Vec<(String, Option<usize>)> = sim
        .effects
        .iter()
        .map(|e| {
            let harmonic = match e.kind {
                Kind::JointPeriodic { harmonic, .. } => Some(u64::from(harmonic)),
                _ => None,
            };
            slot(
                e.kind.name(),
                harmonic,
                e.kind.joint().map(|j| j + 1),
                e.kind.sensor().map(|k| k + 1),
            )
        })
        .collect();
    let opts = IdentifyOptions::default();
    let obs = Observations::new(&sim.robot, &sim.rig, &sim.dataset, &opts)?;
    let geo = identify::geometric(&obs, &opts, &NoProgress)?;
    let t = std::time::Instant::now();
    let mut analysis = physics::analyse(&obs, &geo, &NoProgress)?;
    // As the pipeline does: a constant anchor error proposed in place of
    // the findings is a finding of its own (a false alarm where the
    // simulation put none).
    let rig_proposed = super::propose_rig_anchors(&obs, &geo, &mut analysis).is_some();
    let seconds = t.elapsed().as_secs_f64();
    let rms = crate::stats::rms_norm;
    let test_geometric_mm = rms(&obs.errors(&geo.after.values, &obs.test));
    let test_final_mm = rms(&analysis.test_errors);
    // The floor: the located points' own noise on the test poses.
    let floor: Vec<nalgebra::Vector3<f64>> = obs.test.iter().map(|&i| sim.point_noise[i]).collect();
    let found = analysis
        .findings
        .iter()
        .map(|f| {
            let harmonic = match f.effect_model().map(|e| &e.kind) {
                Some(Kind::JointPeriodic { harmonic, .. }) => Some(u64::from(*harmonic)),
                _ => None,
            };
            slot(&f.effect, harmonic, f.joint, f.sensor)
        })
        .chain(rig_proposed.then(|| slot("rig_anchors", None, None, None)))
        .collect();
    let worse_3d = analysis
        .findings
        .iter()
        .filter(|f| f.effect != "unexplained" && f.test_rms_after_mm > f.test_rms_before_mm)
        .count();
    Ok(Outcome {
        worse_3d,
        robot: robot.into(),
        seed,
        size_x_noise: size,
        truth,
        found,
        test_geometric_mm,
        test_final_mm,
        test_floor_mm: rms(&floor),
        seconds,
    })
}

/// Sweep settings.
#[derive(Debug, Clone)]
pub struct Sweep {
    /// Robot presets.
    pub robots: Vec<String>,
    /// The rig for every robot (default: each preset's own 4-string rig).
    pub rig: Option<Rig>,
    /// Effect sizes (multiples of the point noise); 0 means effect-free.
    pub sizes: Vec<f64>,
    /// Datasets per robot and size.
    pub per_cell: usize,
    /// Probability of a second effect.
    pub two_effects: f64,
    /// Poses per dataset.
    pub n_poses: usize,
    /// Master seed.
    pub seed: u64,
}

/// Run a sweep; `on_case` sees every outcome as it comes.
pub fn sweep(cfg: &Sweep, mut on_case: impl FnMut(&Outcome)) -> crate::Result<Vec<Outcome>> {
    let mut out = Vec::new();
    let mut rng = Rng::new(cfg.seed);
    for robot in &cfg.robots {
        let Some((r, preset_rig, _)) = simulate::preset(robot) else {
            continue;
        };
        let rig = cfg.rig.clone().unwrap_or(preset_rig);
        let joints = movable_joints(&r);
        for &size in &cfg.sizes {
            let mut done = 0;
            let mut attempts = 0;
            while done < cfg.per_cell && attempts < 5 * cfg.per_cell {
                attempts += 1;
                let seed = rng.next_u64() % 1_000_000;
                let mut effects = Vec::new();
                if size > 0.0 {
                    effects.push(draw_effect(&mut rng, &joints, rig.n_strings(), size));
                    if rng.uniform() < cfg.two_effects {
                        let e2 = draw_effect(&mut rng, &joints, rig.n_strings(), size);
                        if e2.effect != effects[0].effect {
                            effects.push(e2);
                        }
                    }
                }
                // Effects that cannot move anything on a robot (compliance
                // of a vertical axis) are redrawn.
                if let Ok(o) = run_case(robot, cfg.rig.as_ref(), seed, effects, size, cfg.n_poses) {
                    on_case(&o);
                    out.push(o);
                    done += 1;
                }
            }
        }
    }
    Ok(out)
}

/// Per-effect tallies.
#[derive(Debug, Clone, Default)]
pub struct Tally {
    /// Named with the right joint/sensor.
    pub right: usize,
    /// Right effect, wrong joint/sensor.
    pub wrong_place: usize,
    /// Not found.
    pub missed: usize,
    /// Reported where it was not.
    pub false_alarm: usize,
}

/// Headline figures of a sweep.
#[derive(Debug, Clone, Default)]
pub struct Summary {
    /// Effects at size >= 3x noise named correctly / their number.
    pub named_at_3x: (usize, usize),
    /// Effect-free datasets with any finding / their number.
    pub false_alarm_free: (usize, usize),
    /// Median final/floor held-out RMS over datasets with effects >= 3x
    /// where every effect was named.
    pub median_ratio_final_floor: f64,
    /// Median fraction of the gap (geometric - floor) closed, same datasets.
    pub median_gap_closed: f64,
    /// Median geometric/floor ratio on effect-free datasets.
    pub median_ratio_free: f64,
}

/// Score outcomes: per-effect tallies (by size bucket) and the headline.
pub fn score(outcomes: &[Outcome]) -> (Vec<(String, f64, Tally)>, Summary) {
    let mut tallies: Vec<(String, f64, Tally)> = Vec::new();
    let mut get = |name: &str, size: f64| -> usize {
        match tallies.iter().position(|(n, s, _)| n == name && *s == size) {
            Some(i) => i,
            None => {
                tallies.push((name.into(), size, Tally::default()));
                tallies.len() - 1
            }
        }
    };
    let mut sum = Summary::default();
    let (mut ratios, mut gaps, mut free) = (vec![], vec![], vec![]);
    let mut tally_updates = Vec::new();
    for o in outcomes {
        let mut all_right = true;
        for t in &o.truth {
            let i = get(&t.0, o.size_x_noise);
            let right = o.found.contains(t);
            let same_name = o.found.iter().any(|f| f.0 == t.0);
            tally_updates.push((
                i,
                if right {
                    0
                } else if same_name {
                    1
                } else {
                    2
                },
            ));
            if o.size_x_noise >= 3.0 {
                sum.named_at_3x.1 += 1;
                if right {
                    sum.named_at_3x.0 += 1;
                }
            }
            all_right &= right;
        }
        for f in &o.found {
            let matches = o.truth.iter().any(|t| t.0 == f.0);
            if !matches {
                let i = get(&f.0, o.size_x_noise);
                tally_updates.push((i, 3));
            }
        }
        if o.truth.is_empty() {
            sum.false_alarm_free.1 += 1;
            if !o.found.is_empty() {
                sum.false_alarm_free.0 += 1;
            }
            free.push(o.test_geometric_mm / o.test_floor_mm);
        } else if o.size_x_noise >= 3.0 && all_right {
            ratios.push(o.test_final_mm / o.test_floor_mm);
            let gap = o.test_geometric_mm - o.test_floor_mm;
            if gap > 0.0 {
                gaps.push((o.test_geometric_mm - o.test_final_mm) / gap);
            }
        }
    }
    for (i, kind) in tally_updates {
        let t = &mut tallies[i].2;
        match kind {
            0 => t.right += 1,
            1 => t.wrong_place += 1,
            2 => t.missed += 1,
            _ => t.false_alarm += 1,
        }
    }
    tallies.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    sum.median_ratio_final_floor = crate::stats::median(&ratios);
    sum.median_gap_closed = crate::stats::median(&gaps);
    sum.median_ratio_free = crate::stats::median(&free);
    (tallies, sum)
}

/// The confusion table and headline as text.
pub fn table(outcomes: &[Outcome]) -> String {
    let (tallies, s) = score(outcomes);
    let mut out = String::new();
    out.push_str(
        "| effect | size (x point noise) | right | wrong place | missed | false alarm |\n",
    );
    out.push_str("|---|---|---|---|---|---|\n");
    for (name, size, t) in &tallies {
        out.push_str(&format!(
            "| {name} | {size} | {} | {} | {} | {} |\n",
            t.right, t.wrong_place, t.missed, t.false_alarm
        ));
    }
    let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
    out.push_str(&format!(
        "\nnamed correctly at >= 3x noise: {}/{} ({:.1}%)\nfalse alarms on effect-free datasets: {}/{} ({:.1}%)\nmedian held-out RMS final/floor (effects >= 3x, all named): {:.3}\nmedian fraction of the gap to the floor closed: {:.3}\nmedian held-out RMS geometric/floor on effect-free data: {:.3}\ndatasets: {}\n",
        s.named_at_3x.0,
        s.named_at_3x.1,
        pct(s.named_at_3x.0, s.named_at_3x.1),
        s.false_alarm_free.0,
        s.false_alarm_free.1,
        pct(s.false_alarm_free.0, s.false_alarm_free.1),
        s.median_ratio_final_floor,
        s.median_gap_closed,
        s.median_ratio_free,
        outcomes.len()
    ));
    out
}
