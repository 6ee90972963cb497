//! `drawcal plan`: choose the poses of a calibration session (see
//! [`crate::plan`]), write them as targets.csv and the plan's report.

use std::path::PathBuf;

use super::export::{UrdfArgs, read_robot};
use super::{CliError, core, read};
use crate::model::Rig;
use crate::plan::{self, KeepOut, PlanOptions, Workspace};

/// Arguments of `drawcal plan`.
#[derive(Debug, Clone, clap::Args)]
pub struct PlanArgs {
    /// robot.json, or a URDF (`.urdf`; see the URDF options).
    #[arg(long)]
    pub robot: PathBuf,
    /// How a URDF robot is read.
    #[command(flatten)]
    pub urdf: UrdfArgs,
    /// rig.json (with `base_in_rig` for a string rig).
    #[arg(long)]
    pub rig: PathBuf,
    /// Poses to choose for the identification.
    #[arg(long, default_value_t = 30)]
    pub n: usize,
    /// Random check poses added and marked `test` (default max(5, N/4)).
    #[arg(long)]
    pub check: Option<usize>,
    /// A box the arm, the tool and the strings stay out of, robot base
    /// frame: `x0,y0,z0,x1,y1,z1` (mm); repeat for several.
    #[arg(long = "keep-out", allow_hyphen_values = true)]
    pub keep_out: Vec<String>,
    /// Floor height in the robot base frame (mm): joints, flange and T stay
    /// above it.
    #[arg(long, allow_hyphen_values = true)]
    pub floor_z_mm: Option<f64>,
    /// Effects the poses must also determine, comma-separated:
    /// joint_compliance, backlash, joint_scale, sensor_scale, cable_sag,
    /// base_tilt, link_bending (the last two need link masses).
    #[arg(long, value_delimiter = ',')]
    pub effects: Vec<String>,
    /// Valid candidate poses to choose from.
    #[arg(long, default_value_t = 10_000)]
    pub candidates: usize,
    /// Seed of the candidate draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Noise of one reading (mm; default 0.02 for strings with the
    /// resolution's quantisation, 0.03 per coordinate for a tracker).
    #[arg(long)]
    pub noise_mm: Option<f64>,
    /// Where the tour starts, `q1,...,qn` (deg; default all zero).
    #[arg(long, allow_hyphen_values = true, value_delimiter = ',')]
    pub home_deg: Option<Vec<f64>>,
    /// A payload at T (kg, more than 0, at most 5000) some poses carry,
    /// with joint_compliance among the effects: the plan chooses which,
    /// visits the unloaded ones first, and writes a payload_kg column.
    #[arg(long, allow_hyphen_values = true)]
    pub payload_kg: Option<f64>,
    /// Where to write the poses (targets.csv with a split column).
    #[arg(long)]
    pub out: PathBuf,
    /// Where to write the plan's report (JSON; default: next to --out,
    /// `<out>.plan.json`).
    #[arg(long)]
    pub report: Option<PathBuf>,
}

/// Plan, write, summarise.
pub fn run(a: PlanArgs) -> Result<(), CliError> {
    let robot = read_robot(&a.robot, &a.urdf)?;
    let rig = core(&a.rig, Rig::from_json(&read(&a.rig)?))?;
    let keep_out = a
        .keep_out
        .iter()
        .map(|s| KeepOut::parse("--keep-out", s))
        .collect::<crate::Result<Vec<_>>>()
        .map_err(|e| CliError::Usage(e.to_string()))?;
    let opts = PlanOptions {
        n_poses: a.n,
        n_check: a.check,
        workspace: Workspace {
            floor_z_mm: a.floor_z_mm,
            keep_out,
            ..Workspace::default()
        },
        effects: a.effects.clone(),
        candidates: a.candidates,
        seed: a.seed,
        noise_mm: a.noise_mm,
        home_deg: a.home_deg.clone(),
        payload_kg: a.payload_kg,
    };
    let plan = plan::plan(&robot, &rig, &opts)?;
    let report_path = a
        .report
        .clone()
        .unwrap_or_else(|| a.out.with_extension("plan.json"));
    let io = |path: &PathBuf| {
        let path = path.clone();
        move |source| CliError::Io { path, source }
    };
    std::fs::write(&a.out, plan.targets_csv()).map_err(io(&a.out))?;
    let json = serde_json::to_string_pretty(&plan.report).expect("a plan report serialises");
    std::fs::write(&report_path, json + "\n").map_err(io(&report_path))?;
    print!("{}", summary(&plan.report));
    println!(
        "wrote {} ({} poses to identify, {} check poses) and {}",
        a.out.display(),
        plan.report.n_poses,
        plan.report.n_check,
        report_path.display()
    );
    Ok(())
}

/// `0.1234 mm`, or words where the poses do not determine the model.
fn mm_or_undetermined(x_mm: f64) -> String {
    if x_mm.is_finite() {
        format!("{x_mm:.4} mm")
    } else {
        "not determined by these poses".into()
    }
}

/// The terminal summary of a plan.
pub fn summary(r: &plan::PlanReport) -> String {
    let mut s = String::new();
    s += &format!(
        "plan: {} poses from {} valid candidates ({} drawn)\n",
        r.n_poses, r.candidates_kept, r.candidates_drawn
    );
    if r.predicted.is_determined() && r.random.is_determined() {
        s += &format!(
            "predicted model error at random valid poses: {:.4} mm RMS (random poses: {:.4} mm, {:.2}x)\n",
            r.predicted.model_rms_mm,
            r.random.model_rms_mm,
            r.predicted.model_rms_mm / r.random.model_rms_mm
        );
    } else {
        s += &format!(
            "predicted model error at random valid poses: {} (random poses: {})\n",
            mm_or_undetermined(r.predicted.model_rms_mm),
            mm_or_undetermined(r.random.model_rms_mm)
        );
    }
    s += &format!(
        "predicted held-out RMS: {} (the located point's noise alone: {:.4} mm)\n",
        mm_or_undetermined(r.predicted.holdout_rms_mm),
        r.point_noise_rms_mm
    );
    let curve: Vec<String> = r
        .by_n
        .iter()
        .map(|p| match p.is_determined() {
            true => format!("{}: {:.4}", p.n_poses, p.model_rms_mm),
            false => format!("{}: not determined", p.n_poses),
        })
        .collect();
    s += &format!("model error by N (mm): {}\n", curve.join(", "));
    if let Some(worst) = r
        .parameters
        .iter()
        .filter(|p| p.unit == "mm" || p.unit == "deg")
        .max_by(|a, b| {
            let k = |p: &plan::PredictedParam| {
                if p.unit == "deg" {
                    p.sigma * 10.0
                } else {
                    p.sigma
                }
            };
            k(a).total_cmp(&k(b))
        })
    {
        s += &format!(
            "least determined parameter: {} (1-sigma {:.4} {})\n",
            worst.name, worst.sigma, worst.unit
        );
    }
    if !r.undetermined.is_empty() {
        let names: Vec<String> = r
            .undetermined
            .iter()
            .map(|f| match f.aliased_with.first() {
                Some(w) if w.starts_with('(') => format!("{} {w}", f.name),
                _ => format!("{} (moves T like {})", f.name, f.aliased_with.join(" + ")),
            })
            .collect();
        s += &format!("no poses on this rig can determine: {}\n", names.join("; "));
    }
    s += &backlash_summary(r);
    s += &payload_summary(r);
    for n in &r.notes {
        s += &format!("note: {n}\n");
    }
    s
}

/// The dead bands' predicted 1-sigma, with the shortest tour's beside.
fn backlash_summary(r: &plan::PlanReport) -> String {
    let Some(b) = &r.backlash else {
        return String::new();
    };
    let fmt = |v: Option<f64>| v.map_or("not determined".into(), |v| format!("{v:.4}"));
    let joints: Vec<String> = b
        .joints
        .iter()
        .map(|j| {
            format!(
                "j{} {} (shortest tour {})",
                j.joint,
                fmt(j.sigma_deg),
                fmt(j.sigma_shortest_deg)
            )
        })
        .collect();
    format!(
        "backlash 1-sigma (deg, half the dead band): {}; tour {:.0} deg, shortest {:.0} deg\n",
        joints.join(", "),
        r.tour_travel_deg,
        b.shortest_travel_deg
    )
}

/// Which poses carry the payload, and the compliance with and without it.
fn payload_summary(r: &plan::PlanReport) -> String {
    let Some(p) = &r.payload else {
        return String::new();
    };
    let joints: Vec<String> = p
        .compliance
        .iter()
        .map(|c| {
            format!(
                "j{} {:.3e} / {} {}",
                c.joint,
                c.sigma_with_payload,
                c.sigma_without_payload
                    .map_or("not determined".into(), |s| format!("{s:.3e}")),
                c.unit
            )
        })
        .collect();
    format!(
        "payload {} kg on {} of {} poses ({} change(s)); compliance 1-sigma with / without it: {}\n",
        p.payload_kg,
        p.loaded_poses,
        p.loaded_poses + p.unloaded_poses,
        p.payload_changes,
        joints.join(", ")
    )
}
