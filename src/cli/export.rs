//! `drawcal export report.json --format urdf|robot-json|csv|extra-targets
//! --out FILE`: the calibrated model (or the suggested extra poses) out of a
//! report (the core's `export`), and the
//! options that read a URDF wherever `--robot` takes a robot file.

use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};

use super::{CliError, core, read, to_stdout};
use crate::export::{self, ExportFormat};
use crate::model::urdf::{UrdfOptions, parse_xyz_mm, robot_from_text};
use crate::model::{Convention, Robot};
use crate::report::Report;

/// `--format` of `drawcal export`.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum FormatArg {
    /// The calibrated model as a URDF (world = the rig frame, tool0, tcp).
    Urdf,
    /// The calibrated robot.json.
    RobotJson,
    /// One row per parameter: nominal, calibrated, deviation, sigma.
    Csv,
    /// The extra poses the verdict suggests, as targets.csv.
    ExtraTargets,
}

/// Export a report's calibrated model:
/// `drawcal export report.json --format urdf --out calibrated.urdf`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// A report written by `drawcal identify --out` (or a calibration as
    /// `GET /calibrations/{id}` answers it).
    pub report: PathBuf,
    /// What to write.
    #[arg(long, value_enum)]
    pub format: FormatArg,
    /// Where to write it (stdout if absent).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Write the export.
pub fn run(a: ExportArgs) -> Result<(), CliError> {
    let report = core(&a.report, Report::from_json(&read(&a.report)?))?;
    let format = match a.format {
        FormatArg::Urdf => ExportFormat::Urdf,
        FormatArg::RobotJson => ExportFormat::RobotJson,
        FormatArg::Csv => ExportFormat::Csv,
        FormatArg::ExtraTargets => ExportFormat::ExtraTargets,
    };
    let text = core(&a.report, export::export(&report, format))?;
    match &a.out {
        None => to_stdout(&text),
        Some(p) => {
            std::fs::write(p, text).map_err(|source| CliError::Io {
                path: p.clone(),
                source,
            })?;
            eprintln!("{} written to {}", format.extension(), p.display());
        }
    }
    Ok(())
}

/// `--convention` for a URDF robot.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum ConventionArg {
    /// DH with Hayati's beta.
    Dh,
    /// Craig's modified DH.
    Mdh,
}

/// How a URDF given as `--robot` is read (ignored for robot.json).
#[derive(Debug, Clone, Default, Args)]
pub struct UrdfArgs {
    /// URDF robot: the link that carries the tool point T (default:
    /// `tool0`, else the only tip link).
    #[arg(long)]
    pub tool_link: Option<String>,
    /// URDF robot: T in the tool link's frame, mm (`0,0,100`; default 0,0,0).
    #[arg(long, allow_hyphen_values = true)]
    pub tool_xyz_mm: Option<String>,
    /// URDF robot: the robot's base frame (default: the URDF's root link).
    #[arg(long)]
    pub base_link: Option<String>,
    /// URDF robot: the convention to convert to (default: DH where exact,
    /// else MDH).
    #[arg(long, value_enum)]
    pub convention: Option<ConventionArg>,
}

impl UrdfArgs {
    fn options(&self) -> crate::Result<UrdfOptions> {
        Ok(UrdfOptions {
            tool_link: self.tool_link.clone(),
            tool_xyz_mm: match &self.tool_xyz_mm {
                Some(s) => parse_xyz_mm("--tool-xyz-mm", s)?,
                None => [0.0; 3],
            },
            base_link: self.base_link.clone(),
            convention: self.convention.map(|c| match c {
                ConventionArg::Dh => Convention::Dh,
                ConventionArg::Mdh => Convention::Mdh,
            }),
        })
    }
}

/// A robot file: a URDF (`.urdf`, or text starting with `<`) converted
/// with the URDF options, else robot.json.
pub(crate) fn read_robot(path: &Path, urdf: &UrdfArgs) -> Result<Robot, CliError> {
    let text = read(path)?;
    let is_urdf = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    let options = core(path, urdf.options())?;
    core(path, robot_from_text(&text, is_urdf, &options))
}
