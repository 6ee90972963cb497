//! `drawcal evaluate`: the blind sweep of simulated datasets with concealed
//! effects, printing the confusion table recorded in EVAL.md.

use super::{CliError, core, read};
use crate::pipeline::evaluate::{self, Sweep};

/// Arguments of `drawcal evaluate`.
#[derive(Debug, Clone, clap::Args)]
pub struct EvaluateArgs {
    /// Robot presets, comma separated.
    #[arg(long, default_value = "er3a,ur5,arm4_mdh", value_delimiter = ',')]
    pub robots: Vec<String>,
    /// rig.json to simulate every robot with (default: each preset's own
    /// 4-string rig); e.g. a 3- or 5-string rig.
    #[arg(long)]
    pub rig: Option<std::path::PathBuf>,
    /// Effect sizes in multiples of the point noise (0 = effect-free).
    #[arg(long, default_value = "0,1,2,3,5,10", value_delimiter = ',')]
    pub sizes: Vec<f64>,
    /// Datasets per robot and size.
    #[arg(long, default_value_t = 20)]
    pub per_cell: usize,
    /// Probability of a second concealed effect.
    #[arg(long, default_value_t = 0.3)]
    pub two_effects: f64,
    /// Poses per dataset.
    #[arg(long, default_value_t = 80)]
    pub poses: usize,
    /// Master seed.
    #[arg(long, default_value_t = 2024)]
    pub seed: u64,
    /// Print every dataset's outcome.
    #[arg(long)]
    pub verbose: bool,
}

/// Run the sweep and print the table.
pub fn run(args: EvaluateArgs) -> Result<(), CliError> {
    let cfg = Sweep {
        robots: args.robots,
        rig: match &args.rig {
            Some(path) => Some(core(path, crate::model::Rig::from_json(&read(path)?))?),
            None => None,
        },
        sizes: args.sizes,
        per_cell: args.per_cell,
        two_effects: args.two_effects,
        n_poses: args.poses,
        seed: args.seed,
    };
    let verbose = args.verbose;
    let outcomes = evaluate::sweep(&cfg, |o| {
        if verbose {
            println!(
                "{} seed {} size {}: truth {:?} found {:?} test geo {:.4} final {:.4} floor {:.4} ({:.0} ms) worse3d {}",
                o.robot,
                o.seed,
                o.size_x_noise,
                o.truth,
                o.found,
                o.test_geometric_mm,
                o.test_final_mm,
                o.test_floor_mm,
                1e3 * o.seconds,
                o.worse_3d
            );
        }
    })?;
    print!("{}", evaluate::table(&outcomes));
    Ok(())
}
