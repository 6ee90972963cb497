//! `drawcal simulate --spec spec.json --out DIR`: recordings from a robot,
//! a rig, deviations, noise and physical effects (spec in docs/PHYSICS.md).

use std::path::{Path, PathBuf};

use super::{CliError, core, read};
use crate::model::{Rig, Robot};
use crate::physics::simulate::{self, Simulated};

/// Arguments of `drawcal simulate`.
#[derive(Debug, Clone, clap::Args)]
pub struct SimulateArgs {
    /// Simulation spec (JSON, see docs/PHYSICS.md).
    #[arg(long)]
    pub spec: PathBuf,
    /// Output folder: robot.json, rig.json, poses.csv, truth.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Record these joint targets, in this order (a plan's targets.csv:
    /// `target,q1_deg..qn_deg[,payload_kg][,split]`), instead of drawing
    /// the spec's `n_poses`; their ids, payload and split go into
    /// poses.csv, and each pose is simulated carrying its payload.
    #[arg(long)]
    pub targets: Option<PathBuf>,
}

/// Generate a dataset.
pub fn run(args: SimulateArgs) -> Result<(), CliError> {
    let spec: simulate::Spec =
        serde_json::from_str(&read(&args.spec)?).map_err(|source| CliError::Parse {
            path: args.spec.clone(),
            source,
        })?;
    // The files the spec names, read here: the engine reads none.
    let named = |path: &str| -> Result<(PathBuf, String), CliError> {
        let path = PathBuf::from(path);
        let text = read(&path)?;
        Ok((path, text))
    };
    let files = simulate::SpecFiles {
        robot: match simulate::preset(&spec.robot) {
            Some(_) => None,
            None => {
                let (path, text) = named(&spec.robot)?;
                Some(core(&path, Robot::from_json(&text))?)
            }
        },
        rig: match &spec.rig {
            Some(rig) => {
                let (path, text) = named(rig)?;
                Some(core(&path, Rig::from_json(&text))?)
            }
            None => None,
        },
        poses: None,
    };
    let mut files = files;
    if let Some(path) = &args.targets {
        let dof = match &files.robot {
            Some(r) => r.dof(),
            None => simulate::preset(&spec.robot).map_or(0, |(r, _, _)| r.dof()),
        };
        let text = read(path)?;
        let targets = core(path, crate::model::targets_from_csv(text.as_bytes(), dof))?;
        let split = core(path, crate::model::target_splits(text.as_bytes()))?;
        let payload = core(path, crate::model::target_payloads(text.as_bytes()))?;
        let mut given = Vec::with_capacity(targets.len());
        for (r, t) in targets.into_iter().enumerate() {
            let crate::model::TargetKind::Joints { q_deg } = t.kind else {
                return Err(CliError::Usage(format!(
                    "{}: row {}: simulate records joint targets (q1_deg..), not Cartesian ones",
                    path.display(),
                    r + 1
                )));
            };
            given.push(simulate::GivenPose {
                id: t.target,
                q_deg,
                test: split.as_ref().map(|s| s[r]),
                payload_kg: payload.as_ref().map(|p| p[r]),
            });
        }
        files.poses = Some(given);
    }
    let sim = simulate::generate_with(&spec, files)?;
    write(&sim, &args.out)?;
    println!(
        "wrote {} poses to {} (point noise {:.4} mm, {} effect(s))",
        sim.dataset.poses.len(),
        args.out.display(),
        sim.point_noise_mm,
        sim.effects.len()
    );
    for e in sim.truth["effects"].as_array().into_iter().flatten() {
        println!(
            "  {} {} magnitude {:.6} {} (RMS {:.4} mm)",
            e["effect"].as_str().unwrap_or(""),
            e.get("joint")
                .map(|j| format!("joint {j}"))
                .or_else(|| e.get("sensor").map(|k| format!("sensor {k}")))
                .unwrap_or_default(),
            e["magnitude"].as_f64().unwrap_or(f64::NAN),
            e["unit"].as_str().unwrap_or(""),
            e["effect_rms_mm"].as_f64().unwrap_or(f64::NAN)
        );
    }
    Ok(())
}

/// Write robot.json, rig.json, poses.csv and truth.json into `dir`.
pub fn write(sim: &Simulated, dir: &Path) -> Result<(), CliError> {
    let io = |path: PathBuf| move |source| CliError::Io { path, source };
    std::fs::create_dir_all(dir).map_err(io(dir.into()))?;
    let json = |v: &dyn erased::Ser| v.to_pretty();
    for (name, text) in [
        ("robot.json", json(&sim.robot)),
        ("rig.json", json(&sim.rig)),
        ("poses.csv", sim.poses_csv.clone()),
        ("truth.json", json(&sim.truth)),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, text).map_err(io(path.clone()))?;
    }
    Ok(())
}

mod erased {
    /// Pretty JSON of anything serialisable, behind a trait object.
    pub trait Ser {
        fn to_pretty(&self) -> String;
    }
    impl<T: serde::Serialize> Ser for T {
        fn to_pretty(&self) -> String {
            serde_json::to_string_pretty(self).unwrap_or_default() + "\n"
        }
    }
}
