//! The `drawcal` binary: parse the command line and hand over to the CLI
//! layer.

use clap::Parser;

fn main() {
    let cli = drawcal::cli::Cli::parse();
    if let Err(e) = drawcal::cli::run(cli) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
