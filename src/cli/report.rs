//! `drawcal report`: a calibration report as one self-contained HTML file.

use std::path::PathBuf;

use clap::Args;

use super::{CliError, core, read};
use crate::report::Report;
use crate::report_html::{self, PoseColumns};

/// Write a calibration report as one self-contained HTML file (tables and
/// inline SVG plots): `drawcal report report.json --html out.html`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// A report written by `drawcal identify --out` (or a calibration as
    /// `GET /calibrations/{id}` answers it, `{calibration, report}`).
    pub report: PathBuf,
    /// Where to write the HTML file.
    #[arg(long)]
    pub html: PathBuf,
    /// The poses.csv the report was identified from: adds the residual
    /// against each joint angle, time, temperature and string length.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// Title of the page (default: the report file's name).
    #[arg(long)]
    pub title: Option<String>,
}

/// Write the HTML report.
pub fn run(args: ReportArgs) -> Result<(), CliError> {
    let report = core(&args.report, Report::from_json(&read(&args.report)?))?;
    let poses = match &args.poses {
        None => None,
        Some(p) => {
            let f = std::fs::File::open(p).map_err(|source| CliError::Io {
                path: p.clone(),
                source,
            })?;
            Some(
                PoseColumns::from_csv(f)
                    .map_err(|m| CliError::Other(format!("{}: {m}", p.display())))?,
            )
        }
    };
    let title = args.title.clone().unwrap_or_else(|| {
        format!(
            "drawcal calibration report: {}",
            args.report
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        )
    });
    let html = report_html::render(&report, &title, poses.as_ref());
    std::fs::write(&args.html, html).map_err(|source| CliError::Io {
        path: args.html.clone(),
        source,
    })?;
    eprintln!("HTML report written to {}", args.html.display());
    Ok(())
}
