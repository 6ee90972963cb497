//! `drawcal simulate --spec spec.json --out DIR`: recordings from a robot,
//! a rig, deviations, noise and physical effects (spec in docs/PHYSICS.md).

use std::path::{Path, PathBuf};

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
}

/// Generate a dataset.
pub fn run(args: SimulateArgs) -> Result<(), Box<dyn std::error::Error>> {
    let text =
        std::fs::read_to_string(&args.spec).map_err(|e| format!("{}: {e}", args.spec.display()))?;
    let spec: simulate::Spec =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", args.spec.display()))?;
    let files = simulate::SpecFiles {
        robot: match simulate::preset(&spec.robot) {
            Some(_) => None,
            None => Some(Robot::from_json(&read_named(&spec.robot)?)?),
        },
        rig: match &spec.rig {
            Some(path) => Some(Rig::from_json(&read_named(path)?)?),
            None => None,
        },
    };
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

/// A file a spec names, its path in the error.
fn read_named(path: &str) -> crate::Result<String> {
    std::fs::read_to_string(path).map_err(|e| crate::Error::field(path, e.to_string()))
}

/// Write robot.json, rig.json, poses.csv and truth.json into `dir`.
pub fn write(sim: &Simulated, dir: &Path) -> crate::Result<()> {
    let io = |e: std::io::Error| crate::Error::field(dir.display().to_string(), e.to_string());
    std::fs::create_dir_all(dir).map_err(io)?;
    let json = |v: &dyn erased::Ser| v.to_pretty();
    std::fs::write(dir.join("robot.json"), json(&sim.robot)).map_err(io)?;
    std::fs::write(dir.join("rig.json"), json(&sim.rig)).map_err(io)?;
    std::fs::write(dir.join("poses.csv"), &sim.poses_csv).map_err(io)?;
    std::fs::write(dir.join("truth.json"), json(&sim.truth)).map_err(io)?;
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
