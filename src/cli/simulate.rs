//! `drawcal simulate --spec spec.json --out DIR`: recordings from a robot,
//! a rig, deviations, noise and physical effects (spec in the README).

use std::path::PathBuf;

use crate::physics::simulate;

/// Arguments of `drawcal simulate`.
#[derive(Debug, Clone, clap::Args)]
pub struct SimulateArgs {
    /// Simulation spec (JSON, see the README's physics section).
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
    let sim = simulate::generate(&spec)?;
    simulate::write(&sim, &args.out)?;
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
