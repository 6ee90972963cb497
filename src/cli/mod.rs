//! The `drawcal` command line: a thin layer over the core that reads files,
//! prints summaries and writes results.

mod error;
pub mod evaluate;
pub mod export;
pub mod keys;
pub mod plan;
pub mod report;
pub mod serve;
pub mod simulate;
pub mod summary;

use std::fs::File;
use std::path::{Path, PathBuf};

use clap::builder::PossibleValue;
use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::Vector3;

use crate::compensate::{Applied, Approach, Compensator, ConditionNames, Note, NoteKind};
use crate::identify::freeset::FreeSet;
use crate::identify::{self, IdentifyOptions, Method, Progress};
use crate::measure;
use crate::model::compensated::{Compensated, CompensationStatus, write_csv};
use crate::model::{Dataset, Rig, targets::targets_from_csv};
use crate::pipeline;
use crate::report::{ClosedFormComparison, Report};
pub use error::CliError;

/// A text file, without the byte-order mark some Windows editors put at
/// the start (JSON parsers refuse it; the CSV reader skips it anyway).
pub(crate) fn read(path: &Path) -> Result<String, CliError> {
    std::fs::read_to_string(path)
        .map(|t| match t.strip_prefix('\u{feff}') {
            Some(rest) => rest.to_string(),
            None => t,
        })
        .map_err(|source| CliError::Io {
            path: path.into(),
            source,
        })
}

/// Text to stdout; a reader that went away (`drawcal identify | head`)
/// ends the output quietly instead of the panic `print!` gives.
fn to_stdout(text: &str) {
    use std::io::Write;
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
}

/// A core result, its error blamed on the file `path`.
pub(crate) fn core<T>(path: &Path, r: crate::Result<T>) -> Result<T, CliError> {
    r.map_err(|source| CliError::Core {
        path: path.into(),
        source,
    })
}

/// drawcal: robot calibration from drawstring sensors (or trackers).
#[derive(Debug, Parser)]
#[command(name = "drawcal", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Identify the kinematic parameters from recorded poses.
    Identify(IdentifyArgs),
    /// Compensate targets with a calibration.
    Compensate(CompensateArgs),
    /// Locate the tool point from string readings.
    Locate(LocateArgs),
    /// Run the HTTP service.
    Serve(serve::ServeArgs),
    /// API keys of the service: create (printed once), list, revoke.
    Keys(keys::KeysArgs),
    /// Choose the poses of a calibration session (targets.csv and a report).
    Plan(plan::PlanArgs),
    /// Simulate a recording from a spec (robot, rig, deviations, effects).
    Simulate(simulate::SimulateArgs),
    /// Blind evaluation of the physics analysis on simulated datasets.
    Evaluate(evaluate::EvaluateArgs),
    Report(report::ReportArgs),
    /// A report's calibrated model as URDF, robot.json or a CSV of deviations.
    Export(export::ExportArgs),
}

/// Identification method on the command line.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum MethodArg {
    /// Levenberg-Marquardt on the raw readings (default).
    Lm,
    /// The paper's linearised one-step method.
    Paper,
}

/// `--approach`: the core's [`Approach`], spelt as the API spells it
/// (`in_order`; `in-order` is accepted too), with the help said in the
/// command line's terms (the targets' file order).
impl ValueEnum for Approach {
    fn value_variants<'a>() -> &'a [Self] {
        &Approach::ALL
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        Some(match self {
            Approach::Positive => PossibleValue::new("positive")
                .help("Every joint moving in +q (most teach programs finish so)"),
            Approach::Negative => PossibleValue::new("negative").help("Every joint moving in -q"),
            Approach::InOrder => PossibleValue::new("in_order").alias("in-order").help(
                "The robot visits the targets in file order: each joint arrives from the \
                 previous target's compensated joints",
            ),
        })
    }
}

/// `--free`: which identifiable parameters the geometric fit frees.
#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum FreeArg {
    /// Cross-validation on the train poses chooses, when they are few;
    /// every identifiable parameter otherwise (default).
    Auto,
    /// Every identifiable parameter (drawcal before the choice existed).
    All,
    /// The joint offsets, link lengths and link offsets (θ, a, d).
    Lengths,
    /// The joint offsets (θ) alone.
    Offsets,
}

impl From<FreeArg> for FreeSet {
    fn from(a: FreeArg) -> FreeSet {
        match a {
            FreeArg::Auto => FreeSet::Auto,
            FreeArg::All => FreeSet::All,
            FreeArg::Lengths => FreeSet::Lengths,
            FreeArg::Offsets => FreeSet::Offsets,
        }
    }
}

/// On or off.
#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum Switch {
    /// Enabled.
    On,
    /// Disabled.
    Off,
}

/// `drawcal identify`.
#[derive(Debug, Args)]
pub struct IdentifyArgs {
    /// Nominal robot model (robot.json, or a URDF: `.urdf` or XML text,
    /// read with the `--tool-link`, `--tool-xyz-mm`, `--base-link` and
    /// `--convention` options).
    #[arg(long)]
    pub robot: PathBuf,
    /// How a URDF `--robot` is read.
    #[command(flatten)]
    pub urdf: export::UrdfArgs,
    /// Measuring rig (rig.json).
    #[arg(long)]
    pub rig: PathBuf,
    /// Recorded poses (poses.csv).
    #[arg(long)]
    pub poses: PathBuf,
    /// Identification method.
    #[arg(long, value_enum, default_value = "lm")]
    pub method: MethodArg,
    /// Where to write the JSON report.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Robust loss: down-weight and flag outlier poses.
    #[arg(long)]
    pub robust: bool,
    /// The physics analysis after the geometric identification.
    #[arg(long, value_enum, default_value = "on")]
    pub physics: Switch,
    /// Hold half of the held-out poses back from every decision of the
    /// physics analysis and report the final model's error on them apart
    /// (`stats.confirmation`); off (the default) lets the analysis read
    /// them all: twice the poses behind each held-out gate, at the cost of
    /// a figure about 1.5 % optimistic where effects were kept (EVAL.md).
    #[arg(long, value_enum, default_value = "off")]
    pub confirm_half: Switch,
    /// Fraction of poses held out when the file has no split column, from 0
    /// (none: no held-out figures) to 0.9.
    #[arg(long, default_value_t = 0.3, value_parser = holdout_fraction)]
    pub holdout: f64,
    /// Seed of the hold-out choice.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also identify each string's zero offset.
    #[arg(long)]
    pub string_offsets: bool,
    /// Calibrate even when every joint angle looks like radians (refused
    /// otherwise: poses.csv holds degrees).
    #[arg(long)]
    pub force: bool,
    /// Print the summary's detail too: every candidate effect not kept and
    /// why, each finding's explanation and evidence, which parameter is
    /// aliased with which, the paper's closed form against least squares.
    #[arg(long, short = 'v')]
    pub verbose: bool,
    /// Identifiability tolerance: a parameter whose scaled Jacobian column
    /// lies within this sine of the span of those kept is held at nominal
    /// (from 1e-9 to 0.5).
    #[arg(long, default_value_t = identify::identifiability::DEFAULT_TOLERANCE,
          value_parser = identifiability_tolerance)]
    pub identifiability_tolerance: f64,
    /// Deviation (sigmas) under which a nearly aliased joint parameter is
    /// held at nominal as undetermined; 0 keeps them all free.
    #[arg(long, default_value_t = identify::identifiability::UNDETERMINED_Z,
          value_parser = undetermined_z)]
    pub undetermined_z: f64,
    /// Parameters to hold at nominal whatever the data say, comma
    /// separated report names (`--hold j5.a,j5.d`).
    #[arg(long, value_delimiter = ',')]
    pub hold: Vec<String>,
    /// Which identifiable joint parameters to free (the base pose, the
    /// tool point and the sensor parameters always are): `auto` chooses
    /// by cross-validation on the train poses when they are few.
    #[arg(long, value_enum, default_value = "auto")]
    pub free: FreeArg,
    /// Also identify the rig's anchor coordinates (four strings or more),
    /// less the rigid motion the base pose takes; the report gets each
    /// anchor's correction and `calibrated_rig`, the rig.json of the next
    /// session.
    #[arg(long)]
    pub rig_anchors: bool,
    /// Where to write the calibrated rig (rig.json form) found with
    /// --rig-anchors.
    #[arg(long, requires = "rig_anchors")]
    pub out_rig: Option<PathBuf>,
}

/// `drawcal compensate`.
#[derive(Debug, Args)]
pub struct CompensateArgs {
    /// A report written by `drawcal identify`.
    #[arg(long)]
    pub calibration: PathBuf,
    /// Targets (targets.csv).
    #[arg(long)]
    pub targets: PathBuf,
    /// Where to write compensated.csv (stdout if absent).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also hold the flange orientation (nominal for joint targets).
    #[arg(long)]
    pub orientation: bool,
    /// Temperature the robot runs at (°C, -50 to 150), for a calibration
    /// whose physics analysis accepted thermal expansion driven by the
    /// temperature (default: the calibration session's reference
    /// temperature, i.e. the geometry as calibrated).
    #[arg(long, allow_negative_numbers = true)]
    pub temp_c: Option<f64>,
    /// Payload the robot carries at T (kg, 0 to 5000), for a calibration
    /// whose physics analysis accepted a joint compliance (default: the
    /// calibration session's median payload, 0 if it recorded none).
    /// A negative one reaches the range check, which names it.
    #[arg(long, allow_negative_numbers = true)]
    pub payload_kg: Option<f64>,
    /// How the joints arrive at the targets, for a calibration whose
    /// physics analysis accepted a backlash (ignored otherwise).
    #[arg(long, value_enum, default_value = "positive")]
    pub approach: Approach,
    /// Largest change of any joint (deg) a joint target's compensation may
    /// make; a target that needs more is refused (`joint_change`), saying
    /// which joint and how far.
    #[arg(long, default_value_t = crate::compensate::DEFAULT_MAX_JOINT_CHANGE_DEG,
          value_parser = max_joint_change_deg)]
    pub max_joint_change_deg: f64,
}

/// `drawcal locate`.
#[derive(Debug, Args)]
pub struct LocateArgs {
    /// Measuring rig (rig.json).
    #[arg(long)]
    pub rig: PathBuf,
    /// Poses with string readings (poses.csv; joint columns are ignored
    /// without --robot).
    #[arg(long)]
    pub poses: PathBuf,
    /// Nominal robot (robot.json): with the rig's `base_in_rig` guess and the
    /// joint columns it picks, for anchors in one plane, which side of the
    /// plane each point is on (without it every point is put on the side
    /// of the anchors' normal).
    #[arg(long)]
    pub robot: Option<PathBuf>,
    /// How a URDF `--robot` is read.
    #[command(flatten)]
    pub urdf: export::UrdfArgs,
    /// Where to write the located points CSV (stdout if absent).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
struct Bar(ProgressBar);

impl Progress for Bar {
    fn update(&self, stage: &str, fraction: f64) {
        self.0.set_message(stage.to_string());
        self.0.set_position((fraction * 100.0) as u64);
    }
}

/// Run a parsed command line.
pub fn run(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::Identify(a) => run_identify(a),
        Command::Compensate(a) => run_compensate(a),
        Command::Locate(a) => run_locate(a),
        Command::Serve(a) => serve::run(a),
        Command::Keys(a) => keys::run(a),
        Command::Plan(a) => plan::run(a),
        Command::Simulate(a) => simulate::run(a),
        Command::Evaluate(a) => evaluate::run(a),
        Command::Report(a) => report::run(a),
        Command::Export(a) => export::run(a),
    }
}

fn run_identify(a: IdentifyArgs) -> Result<(), CliError> {
    let robot = export::read_robot(&a.robot, &a.urdf)?;
    let rig = core(&a.rig, Rig::from_json(&read(&a.rig)?))?;
    let file = File::open(&a.poses).map_err(|source| CliError::Io {
        path: a.poses.clone(),
        source,
    })?;
    let data = core(&a.poses, Dataset::from_csv(file, &robot, &rig))?;
    let opts = IdentifyOptions {
        method: match a.method {
            MethodArg::Lm => Method::Lm,
            MethodArg::Paper => Method::Paper,
        },
        robust: a.robust,
        holdout_fraction: a.holdout,
        seed: a.seed,
        identify_string_offsets: a.string_offsets,
        identifiability_tolerance: a.identifiability_tolerance,
        undetermined_z: a.undetermined_z,
        hold: a.hold.clone(),
        rig_anchors: a.rig_anchors,
        free_set: a.free.into(),
    };
    // What --rig-anchors cannot do is the option's fault, not the files'.
    if a.rig_anchors {
        let why = identify::rig::refusal(data.n_strings).or_else(|| {
            (opts.method == Method::Paper).then(|| {
                "the paper's method identifies the robot alone; use --method lm".to_string()
            })
        });
        if let Some(why) = why {
            return Err(CliError::Usage(format!("--rig-anchors: {why}")));
        }
    }
    let bar = ProgressBar::new(100);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{bar:30}] {pos}%")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    // A bad --hold is the command line's fault, not the poses file's.
    let layout = crate::kinematics::Layout {
        n_joints: robot.dof(),
        n_strings: rig.n_strings(),
    };
    core(Path::new("--hold"), identify::held(layout, &opts))?;
    let report = core(
        &a.poses,
        pipeline::calibrate(
            &robot,
            &rig,
            &data,
            &pipeline::Options {
                identify: opts,
                physics: a.physics == Switch::On,
                force: a.force,
                confirm_half: a.confirm_half == Switch::On,
            },
            &Bar(bar.clone()),
        ),
    )?;
    bar.finish_and_clear();
    // In the summary too, but a summary sent to a file must not hide them.
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    to_stdout(&summary::render(
        &report,
        &summary::Input {
            robot: &robot,
            n_poses: data.poses.len(),
            n_strings: data.n_strings,
            ignored_columns: &data.ignored_columns,
        },
        a.verbose,
    ));
    if let Some(out) = &a.out {
        let text = serde_json::to_string_pretty(&report).map_err(CliError::Json)?;
        std::fs::write(out, text).map_err(|source| CliError::Io {
            path: out.clone(),
            source,
        })?;
        to_stdout(&format!("report written to {}\n", out.display()));
    }
    if let (Some(out), Some(rig)) = (&a.out_rig, &report.calibrated_rig) {
        let text = serde_json::to_string_pretty(rig).map_err(CliError::Json)?;
        std::fs::write(out, text + "\n").map_err(|source| CliError::Io {
            path: out.clone(),
            source,
        })?;
        to_stdout(&format!("calibrated rig written to {}\n", out.display()));
    }
    Ok(())
}

/// How the command line names the compensation conditions in its errors
/// and notes: by its options.
const CONDITION_NAMES: ConditionNames = ConditionNames {
    temp_c: "--temp-c",
    payload_kg: "--payload-kg",
    approach: "--approach",
};

fn run_compensate(a: CompensateArgs) -> Result<(), CliError> {
    let report = core(&a.calibration, Report::from_json(&read(&a.calibration)?))?;
    let mut comp = core(&a.calibration, Compensator::from_report(&report))?;
    comp.max_joint_change_deg = a.max_joint_change_deg;
    // One condition at a time, each said as it is taken: what was made of
    // the temperature is said before a bad --payload-kg is refused, and the
    // approach after what is said of the targets.
    let bad = CliError::Engine;
    let mut applied = Applied::new(&comp, CONDITION_NAMES);
    say(applied.temperature(a.temp_c).map_err(bad)?);
    say(applied.payload(a.payload_kg).map_err(bad)?);
    let file = File::open(&a.targets).map_err(|source| CliError::Io {
        path: a.targets.clone(),
        source,
    })?;
    let targets = core(&a.targets, targets_from_csv(file, comp.dof()))?;
    if let Some(w) = crate::model::targets::radians_warning(&targets, comp.dof()) {
        eprintln!("WARNING: {}: {w}", a.targets.display());
    }
    if let (true, Some(o)) = (a.orientation, report.flange_orientation_sigma_deg) {
        eprintln!(
            "note: the flange orientation is held to the calibrated model's; the calibration's \
             data determine that orientation to {o:.3} deg (RMS rotation angle, 1 sigma, \
             before undetermined parameters were held), with every parameter held at nominal \
             (among them those position data never see) taken as exact"
        );
    }
    say(applied.approach(Some(a.approach)));
    let rows = applied.compensate(&targets, a.orientation);
    write_compensated(a.out.as_deref(), comp.dof(), &rows)
}

/// The notes on the compensation conditions, on stderr: what was applied
/// as it is, anything else as a note.
fn say(notes: &[Note]) {
    for n in notes {
        match n.kind {
            NoteKind::Applied => eprintln!("{}", n.text),
            _ => eprintln!("note: {}", n.text),
        }
    }
}

/// compensated.csv to `out` (with a count on stderr), or to stdout.
fn write_compensated(out: Option<&Path>, dof: usize, rows: &[Compensated]) -> Result<(), CliError> {
    let failed = rows
        .iter()
        .filter(|r| r.status != CompensationStatus::Ok)
        .count();
    match out {
        Some(out) => {
            let f = File::create(out).map_err(|source| CliError::Io {
                path: out.into(),
                source,
            })?;
            write_csv(f, dof, rows).map_err(|source| CliError::Io {
                path: out.into(),
                source,
            })?;
            eprintln!(
                "{} targets compensated, {} failed; written to {}",
                rows.len() - failed,
                failed,
                out.display()
            );
        }
        None => write_csv(std::io::stdout(), dof, rows).map_err(|source| CliError::Io {
            path: "stdout".into(),
            source,
        })?,
    }
    Ok(())
}

/// A pose's id and string readings (mm), and the point the nominal model
/// puts T at, when known (which side of a plane of anchors it is on).
type LocateInput = (Vec<(String, Vec<f64>)>, Vec<Option<Vector3<f64>>>);

fn run_locate(a: LocateArgs) -> Result<(), CliError> {
    let rig = core(&a.rig, Rig::from_json(&read(&a.rig)?))?;
    let anchors: Vec<_> = (0..rig.n_strings()).map(|k| rig.anchor(k)).collect();
    let (readings, hints) = locate_input(&a, &rig, &anchors)?;
    let mut located = Vec::with_capacity(readings.len());
    let mut w = csv::Writer::from_writer(Vec::new());
    let _ = w.write_record([
        "pose",
        "x_mm",
        "y_mm",
        "z_mm",
        "consistency_rms_mm",
        "closed_form_distance_mm",
    ]);
    let mut cf = Vec::new();
    let mut mirrored = 0;
    for ((id, l), hint) in readings.iter().zip(&hints) {
        let dist: Vec<f64> = l.iter().map(|v| v + rig.r_mm).collect();
        let loc = core(&a.poses, measure::locate(&anchors, &dist, hint.as_ref()))?;
        let cf_point = if anchors.len() >= 4 {
            measure::paper_closed_form(&anchors, l[0], l[2], l[3], rig.r_mm).ok()
        } else {
            None
        };
        let d_cf = cf_point.map(|p| (p - loc.point).norm());
        if let (Some(d), Some(p)) = (d_cf, cf_point) {
            cf.push(d);
            if measure::is_paper_mirror(&anchors, &p, &loc.point) {
                mirrored += 1;
            }
        }
        let _ = w.write_record([
            id.clone(),
            format!("{:.4}", loc.point.x),
            format!("{:.4}", loc.point.y),
            format!("{:.4}", loc.point.z),
            format!("{:.5}", loc.consistency_rms_mm()),
            d_cf.map(|d| format!("{d:.5}")).unwrap_or_default(),
        ]);
        located.push(loc);
    }
    let bytes = w.into_inner().map_err(|e| CliError::Other(e.to_string()))?;
    match &a.out {
        Some(out) => std::fs::write(out, &bytes).map_err(|source| CliError::Io {
            path: out.clone(),
            source,
        })?,
        None => to_stdout(&String::from_utf8_lossy(&bytes)),
    }
    eprintln!(
        "{} poses located by least squares from {} strings",
        located.len(),
        anchors.len()
    );
    if let Some(s) = measure::string_sigma(&located) {
        eprintln!("string noise from the redundancy: {s:.4} mm (1 sigma)");
    }
    if let Some(c) = ClosedFormComparison::from_distances(&cf, mirrored) {
        let bad = cf.iter().filter(|d| **d > 1.0).count();
        eprintln!(
            "paper closed form vs least squares: RMS {:.4} mm, max {:.4} mm, {bad} pose{} more \
             than 1 mm apart{} ({})",
            c.rms_mm,
            c.max_mm,
            if bad == 1 { "" } else { "s" },
            c.mirrored_note(),
            ClosedFormComparison::WHY
        );
    }
    Ok(())
}

/// What `locate` locates: the readings of poses.csv, with the nominal
/// model's points when `--robot` is given. A rig without strings is
/// refused by name (its poses.csv holds measured points already).
fn locate_input(
    a: &LocateArgs,
    rig: &Rig,
    anchors: &[Vector3<f64>],
) -> Result<LocateInput, CliError> {
    if rig.n_strings() == 0 {
        // A tracker, CMM or camera rig: poses.csv has the points already.
        return Err(CliError::Core {
            path: a.rig.clone(),
            source: crate::Error::field(
                "anchors_mm",
                "the rig has no strings: its poses.csv gives T's measured points \
                 (x_mm, y_mm, z_mm) already, so there is nothing to locate \
                 (identify takes them as they are)",
            ),
        });
    }
    let file = File::open(&a.poses).map_err(|source| CliError::Io {
        path: a.poses.clone(),
        source,
    })?;
    match &a.robot {
        Some(path) => {
            let robot = export::read_robot(path, &a.urdf)?;
            if rig.base_in_rig.is_none() {
                return Err(CliError::Core {
                    path: a.rig.clone(),
                    source: crate::Error::field(
                        "base_in_rig",
                        "--robot needs the rig's guess of where the robot base is",
                    ),
                });
            }
            let data = core(&a.poses, Dataset::from_csv(file, &robot, rig))?;
            let hints = identify::nominal_points(&robot, rig, &data);
            let readings = data
                .poses
                .into_iter()
                .map(|p| match p.measurement {
                    crate::model::Measurement::Strings(l) => Ok((p.id, l)),
                    crate::model::Measurement::Point(_) => Err(CliError::Core {
                        path: a.poses.clone(),
                        source: crate::Error::field("l1_mm", "no string readings to locate from"),
                    }),
                })
                .collect::<Result<Vec<_>, _>>()?;
            Ok((readings, hints))
        }
        None => {
            let readings = core(
                &a.poses,
                crate::model::dataset::string_readings_from_csv(file, rig),
            )?;
            if measure::coplanar(anchors) {
                eprintln!(
                    "note: the anchors lie in one plane, so each point has a mirror image across it; every point is put on the side of the anchors' normal (give --robot to choose each point's side from the nominal model)"
                );
            }
            let n = readings.len();
            Ok((readings, vec![None; n]))
        }
    }
}

/// A number within `range`, refused rather than clamped; `what` names the
/// unit in the message.
fn in_range(
    s: &str,
    range: std::ops::RangeInclusive<f64>,
    what: &str,
) -> std::result::Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && range.contains(&v) {
        Ok(v)
    } else {
        Err(format!(
            "{s}: {what} from {} to {}",
            range.start(),
            range.end()
        ))
    }
}

/// `--identifiability-tolerance`: a sine from 1e-9 to 0.5.
fn identifiability_tolerance(s: &str) -> std::result::Result<f64, String> {
    in_range(s, 1e-9..=0.5, "a sine")
}

/// `--undetermined-z`: sigmas from 0 to 100.
fn undetermined_z(s: &str) -> std::result::Result<f64, String> {
    in_range(s, 0.0..=100.0, "sigmas")
}

/// `--max-joint-change-deg`: degrees, from 0 to 360.
pub(crate) fn max_joint_change_deg(s: &str) -> std::result::Result<f64, String> {
    in_range(s, 0.0..=360.0, "degrees")
}

/// `--holdout`: a fraction from 0 to 0.9 (at least a tenth of the poses
/// must train).
fn holdout_fraction(s: &str) -> std::result::Result<f64, String> {
    in_range(s, 0.0..=0.9, "a fraction")
}
