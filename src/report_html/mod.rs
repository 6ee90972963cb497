//! The calibration report as HTML: tables and inline SVG plots, no
//! JavaScript and no external files. Used by `drawcal report --html` (one
//! self-contained file) and by the service's
//! `GET /calibrations/{id}/report.html`, which the browser page shows.
//!
//! Every number comes from the [`Report`] (or, for the joint-angle axes of
//! the residual plots, from the poses file handed in as [`PoseColumns`]);
//! the only arithmetic here is the 3-D length of each pose's error vector
//! for the per-pose plots.

pub mod svg;

use std::collections::HashMap;
use std::fmt::Write;

use crate::model::Split;
use crate::report::{ErrorStats, Finding, Report, SplitStats, Stats};
use svg::{Series, esc};

/// Colours: before, after (train), after (test).
const GREY: &str = "#9aa0a6";
const BEFORE_TEST: &str = "#e8a33d";
const TRAIN: &str = "#1f77b4";
const TEST: &str = "#d62728";

/// Numeric columns of a poses.csv, by pose id, for residual plots against
/// joint angles, time, temperature and string lengths.
#[derive(Debug, Clone, Default)]
pub struct PoseColumns {
    /// Column names in file order (`q1_deg`, ..., `time_s`, `temp_c`,
    /// `l1_mm`...), the `pose` column excluded.
    pub names: Vec<String>,
    /// Pose id to its values (NaN where a cell is empty or not a number),
    /// in the order of `names`.
    pub rows: HashMap<String, Vec<f64>>,
}

impl PoseColumns {
    /// Read the numeric columns of a poses.csv (any CSV with a `pose`
    /// column). Columns with no numeric value at all are dropped.
    pub fn from_csv<R: std::io::Read>(r: R) -> Result<PoseColumns, String> {
        let mut rd = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_reader(r);
        let header: Vec<String> = rd
            .headers()
            .map_err(|e| e.to_string())?
            .iter()
            .map(str::to_string)
            .collect();
        let pose_col = header
            .iter()
            .position(|h| h == "pose")
            .ok_or("the poses file has no 'pose' column")?;
        let mut rows = Vec::new();
        for (i, rec) in rd.records().enumerate() {
            let rec = rec.map_err(|e| format!("row {}: {e}", i + 1))?;
            let id = rec.get(pose_col).unwrap_or("").to_string();
            let vals: Vec<f64> = (0..header.len())
                .map(|c| {
                    rec.get(c)
                        .and_then(|s| s.parse::<f64>().ok())
                        .unwrap_or(f64::NAN)
                })
                .collect();
            rows.push((id, vals));
        }
        let keep: Vec<usize> = (0..header.len())
            .filter(|&c| c != pose_col && rows.iter().any(|(_, v)| v[c].is_finite()))
            .collect();
        Ok(PoseColumns {
            names: keep.iter().map(|&c| header[c].clone()).collect(),
            rows: rows
                .into_iter()
                .map(|(id, v)| (id, keep.iter().map(|&c| v[c]).collect()))
                .collect(),
        })
    }

    fn column(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }
}

fn norm(v: &[f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// A number as shown (4 decimals) with its full value in `data-value`;
/// an unknown one (NaN: a sigma the data leave open) as "-".
fn num(v: f64) -> String {
    if v.is_finite() {
        format!(r#"<td class="num" data-value="{v}">{v:.4}</td>"#)
    } else {
        r#"<td class="num">-</td>"#.into()
    }
}

fn opt_num(v: Option<f64>) -> String {
    num(v.unwrap_or(f64::NAN))
}

const CSS: &str = r#"
.drawcal-report{font:14px/1.4 system-ui,sans-serif;color:#222;max-width:1200px}
.drawcal-report h2{margin-top:1.6em;border-bottom:1px solid #ccc}
.drawcal-report table{border-collapse:collapse;margin:.5em 0 1em}
.drawcal-report th,.drawcal-report td{border:1px solid #ccc;padding:2px 8px;text-align:left}
.drawcal-report td.num{text-align:right;font-variant-numeric:tabular-nums}
.drawcal-report th{background:#f3f3f3}
.drawcal-report .plots{display:flex;flex-wrap:wrap;gap:8px}
.drawcal-report svg.plot{max-width:100%;height:auto;border:1px solid #eee}
.drawcal-report .muted{color:#666}
.drawcal-report figure.evidence{margin:0;max-width:560px}
.drawcal-report figure.evidence figcaption{font-size:12px;color:#444}
.drawcal-report .report-warnings{color:#5c3c00;background:#fff4d6;border:2px solid #e0a100;border-left-width:8px;padding:8px 12px;margin:8px 0 12px}
.drawcal-report .report-warnings ul{margin:.3em 0 0;padding-left:1.4em}
.drawcal-report p.physics-not-run{color:#5c3c00;background:#fff8e6;border:1px solid #e0b84d;padding:6px 10px}
.drawcal-report td.physics-not-run{color:#5c3c00;background:#fff8e6}
"#;

fn stats_rows(out: &mut String, split: &str, model: &str, e: &ErrorStats) {
    for (axis, a) in [("x", &e.x), ("y", &e.y), ("z", &e.z)] {
        let _ = write!(
            out,
            r#"<tr data-split="{split}" data-model="{model}" data-axis="{axis}"><td>{split}</td><td>{model}</td><td>{axis}</td>{}{}{}</tr>"#,
            num(a.max_abs_mm),
            num(a.mean_abs_mm),
            num(a.rms_mm)
        );
    }
    let _ = write!(
        out,
        r#"<tr data-split="{split}" data-model="{model}" data-axis="3d"><td>{split}</td><td>{model}</td><td><b>3-D</b></td>{}{}{}</tr>"#,
        num(e.max_mm),
        num(e.mean_mm),
        num(e.rms_mm)
    );
}

fn stats_table(out: &mut String, id: &str, caption: &str, s: &Stats) {
    let _ = write!(
        out,
        r#"<table id="{id}"><caption>{}</caption><tr><th>split</th><th>model</th><th>axis</th><th>max |e| (mm)</th><th>mean |e| (mm)</th><th>RMS (mm)</th></tr>"#,
        esc(caption)
    );
    let parts: [(&str, &SplitStats); 2] = [("train", &s.train), ("test", &s.test)];
    for (name, sp) in parts {
        stats_rows(out, name, "before", &sp.before);
        stats_rows(out, name, "after", &sp.after);
    }
    out.push_str("</table>");
}

fn stats_plot(s: &Stats) -> String {
    axis_bars(s, "RMS error per axis (Tables 3/4)", "RMS (mm)", |e| {
        [e.x.rms_mm, e.y.rms_mm, e.z.rms_mm, e.rms_mm]
    })
}

fn max_plot(s: &Stats) -> String {
    axis_bars(s, "Max error per axis (Tables 3/4)", "max |e| (mm)", |e| {
        [e.x.max_abs_mm, e.y.max_abs_mm, e.z.max_abs_mm, e.max_mm]
    })
}

/// One figure per axis (x, y, z, 3-D) of train/test before/after bars.
fn axis_bars(s: &Stats, title: &str, y_label: &str, of: fn(&ErrorStats) -> [f64; 4]) -> String {
    let groups = ["x", "y", "z", "3-D"];
    let cols = [
        of(&s.train.before),
        of(&s.train.after),
        of(&s.test.before),
        of(&s.test.after),
    ];
    let values: Vec<Vec<f64>> = (0..4)
        .map(|g| cols.iter().map(|c| c[g]).collect())
        .collect();
    svg::bars(
        title,
        y_label,
        &groups,
        &[
            ("train before", GREY),
            ("train after", TRAIN),
            ("test before", BEFORE_TEST),
            ("test after", TEST),
        ],
        &values,
    )
}

/// Per-pose 3-D errors as four series (before/after x train/test) against
/// `x(pose index, pose id)`; poses where `x` gives None are skipped.
fn pose_series<'a>(
    r: &Report,
    x: impl Fn(usize, &str) -> Option<f64>,
    with_before: bool,
) -> Vec<Series<'a>> {
    let mut s = vec![
        Series {
            label: "train before",
            color: GREY,
            points: vec![],
            dot: 0.0,
        },
        Series {
            label: "test before",
            color: BEFORE_TEST,
            points: vec![],
            dot: 0.0,
        },
        Series {
            label: "train after",
            color: TRAIN,
            points: vec![],
            dot: 0.0,
        },
        Series {
            label: "test after",
            color: TEST,
            points: vec![],
            dot: 0.0,
        },
    ];
    for (i, p) in r.per_pose.iter().enumerate() {
        let Some(xv) = x(i, &p.pose) else { continue };
        let t = usize::from(p.split == Split::Test);
        s[t].points.push((xv, norm(&p.before_mm)));
        s[2 + t].points.push((xv, norm(&p.after_mm)));
    }
    if !with_before {
        s.drain(0..2);
    }
    s
}

fn finding_row(out: &mut String, i: usize, f: &Finding) {
    let target = match (f.joint, f.sensor) {
        (Some(j), _) => format!("joint {j}"),
        (None, Some(s)) => format!("sensor {s}"),
        _ => "-".into(),
    };
    let _ = write!(
        out,
        r#"<tr data-finding="{i}"><td>{}</td><td>{}</td>{}{}<td>{}</td><td>{}</td><td>{}</td>{}{}</tr>"#,
        esc(&f.effect),
        esc(&target),
        num(f.magnitude),
        num(f.sigma),
        esc(&f.unit),
        esc(&f.explanation),
        esc(&f.evidence),
        num(f.test_rms_before_mm),
        num(f.test_rms_after_mm),
    );
}

/// One finding's evidence plot (from the report's `evidence_plot`) with the
/// held-out RMS before and after it. The `unexplained` finding is labelled
/// as such: it has no fitted effect, its black dots are the running mean
/// the engine computed, and its held-out RMS is the same before and after.
fn evidence_figure(out: &mut String, i: usize, f: &Finding) {
    // `unexplained` has no fitted effect: its model is the running mean of
    // the residual along the ordering that located the structure.
    let unexplained = f.effect == "unexplained";
    let name = match (f.joint, f.sensor) {
        _ if unexplained => "unexplained structure".to_string(),
        (Some(j), _) => format!("{} j{j}", f.effect),
        (None, Some(s)) => format!("{} s{s}", f.effect),
        _ => f.effect.clone(),
    };
    let rms = format!(
        r#"held-out RMS <span class="rms-before" data-value="{b}">{b:.4}</span> → <span class="rms-after" data-value="{a}">{a:.4}</span> mm{}"#,
        if unexplained {
            " (nothing modelled: no effect of the catalogue explains it)"
        } else {
            ""
        },
        b = f.test_rms_before_mm,
        a = f.test_rms_after_mm
    );
    let Some(ev) = &f.evidence_plot else {
        let _ = write!(
            out,
            r#"<figure class="evidence" data-finding="{i}" data-effect="{}"><figcaption><b>{}</b>: {rms}; no evidence plot ({}).</figcaption></figure>"#,
            esc(&f.effect),
            esc(&name),
            if unexplained {
                "the report predates evidence plots of unexplained structure; see its evidence text"
            } else {
                "the report predates evidence plots"
            }
        );
        return;
    };
    let mut tr = Series {
        label: "train",
        color: TRAIN,
        points: vec![],
        dot: 0.0,
    };
    let mut te = Series {
        label: "test",
        color: TEST,
        points: vec![],
        dot: 0.0,
    };
    let model_name = if unexplained {
        "running mean"
    } else {
        "fitted effect"
    };
    let mut model = Series {
        label: model_name,
        color: "#000",
        points: vec![],
        dot: 2.0,
    };
    for p in &ev.points {
        if p.split == Split::Test {
            &mut te
        } else {
            &mut tr
        }
        .points
        .push((p.x, p.y));
        model.points.push((p.x, p.model));
    }
    let title = if unexplained {
        format!(
            "{name}: held-out RMS {:.4} mm, left unexplained",
            f.test_rms_after_mm
        )
    } else {
        format!(
            "{name}: held-out RMS {:.4} → {:.4} mm",
            f.test_rms_before_mm, f.test_rms_after_mm
        )
    };
    let plot = svg::scatter(
        &title,
        &format!("{} ({})", ev.x_label, ev.x_unit),
        &if unexplained {
            format!("residual on its dominant direction ({})", ev.y_unit)
        } else {
            format!("residual on the effect ({})", ev.y_unit)
        },
        &[tr, te, model],
    );
    let corr = match ev.correlation {
        Some(c) => format!(r#"<span class="corr" data-value="{c}">{c:.3}</span>"#),
        None => "-".into(),
    };
    let sub = if ev.stride > 1 {
        format!(
            "{} of {} points (one pose in {}, by visiting order)",
            ev.points.len(),
            ev.n_total,
            ev.stride
        )
    } else {
        format!("{} points", ev.points.len())
    };
    let _ = write!(
        out,
        r#"<figure class="evidence" data-finding="{i}" data-effect="{}" data-n="{n}">{plot}<figcaption><b>{}</b>: {rms}; correlation of residual and {model_name} {corr}; {sub}. y: {}.</figcaption></figure>"#,
        esc(&f.effect),
        esc(&name),
        esc(&ev.y_label),
        n = ev.points.len(),
    );
}

/// The report as an HTML fragment (a `<div class="drawcal-report">` with
/// its own `<style>`), to embed in a page.
pub fn render_fragment(r: &Report, poses: Option<&PoseColumns>) -> String {
    let mut o = String::with_capacity(64 * 1024 + r.per_pose.len() * 200);
    let _ = write!(o, r#"<div class="drawcal-report"><style>{CSS}</style>"#);

    // Warnings about the input, first: they say the rest may not be
    // trusted.
    if !r.warnings.is_empty() {
        o.push_str(r#"<div class="report-warnings" id="report-warnings" role="alert"><b>Warning: the input looks wrong.</b> It was used as given; check it before trusting this calibration.<ul>"#);
        for w in &r.warnings {
            let _ = write!(o, "<li>{}</li>", esc(w));
        }
        o.push_str("</ul></div>");
    }
    // The physics analysis's note when it did not run (physics off, or a
    // geometric model too far off the data to fit effects on).
    let not_run = (!r.physics.ran())
        .then(|| r.physics_notes.first())
        .flatten();

    // Summary.
    o.push_str(r#"<h2 id="summary">Summary</h2><table id="summary-table">"#);
    let row = |o: &mut String, k: &str, v: String| {
        let _ = write!(o, "<tr><th>{}</th><td>{}</td></tr>", esc(k), v);
    };
    row(&mut o, "method", esc(&r.method));
    row(&mut o, "robust loss", r.robust.to_string());
    row(
        &mut o,
        "poses (train / test)",
        format!("{} / {}", r.stats.train.n, r.stats.test.n),
    );
    row(&mut o, "split", esc(&r.split_source));
    let fmt_opt = |v: Option<f64>| v.map(|v| format!("{v:.4} mm")).unwrap_or("-".into());
    row(
        &mut o,
        "held-out 3-D RMS before → after",
        if r.stats.test.n == 0 {
            "- (no held-out poses)".to_string()
        } else {
            format!(
                r#"<span data-value="{}">{:.4}</span> → <span data-value="{}">{:.4}</span> mm"#,
                r.stats.test.before.rms_mm,
                r.stats.test.before.rms_mm,
                r.stats.test.after.rms_mm,
                r.stats.test.after.rms_mm
            )
        },
    );
    row(&mut o, "noise floor (held-out)", fmt_opt(r.noise_floor_mm));
    row(
        &mut o,
        "exact model from these train poses (held-out)",
        fmt_opt(r.expected_test_rms_mm),
    );
    row(&mut o, "string noise (1σ)", fmt_opt(r.string_sigma_mm));
    row(
        &mut o,
        "flange orientation from these data (1σ RMS angle)",
        r.flange_orientation_sigma_deg
            .map(|v| format!("{v:.3} deg"))
            .unwrap_or("-".into()),
    );
    row(
        &mut o,
        "solver",
        format!(
            "{} iterations, {}, residual RMS {:.4} mm",
            r.convergence.iterations,
            esc(&r.convergence.termination),
            r.convergence.residual_rms_mm
        ),
    );
    row(
        &mut o,
        "identifiability",
        format!(
            "{} of {} parameters identified, condition number {:.0}",
            r.identifiability.n_identified,
            r.identifiability.n_candidates,
            r.identifiability.condition_number
        ),
    );
    if let Some(c) = &r.closed_form_vs_lsq {
        row(
            &mut o,
            "paper closed form vs least squares",
            format!(
                "{} poses, RMS {:.4} mm, max {:.4} mm{}",
                c.n,
                c.rms_mm,
                c.max_mm,
                esc(&c.mirrored_note())
            ),
        );
    }
    if let Some(n) = not_run {
        let _ = write!(
            o,
            r#"<tr><th>physics analysis</th><td class="physics-not-run">{}</td></tr>"#,
            esc(n)
        );
    }
    o.push_str("</table>");

    // Tables 3/4.
    o.push_str(r#"<h2 id="tables">Accuracy: the paper's Tables 3 and 4</h2>"#);
    o.push_str(r#"<p class="muted">Model T minus measured T in the robot base frame. Before: nominal joints with base pose and tool point fitted. After: calibrated model.</p>"#);
    stats_table(&mut o, "stats-table", "This calibration", &r.stats);
    let _ = write!(
        o,
        r#"<div class="plots">{}{}</div>"#,
        stats_plot(&r.stats),
        max_plot(&r.stats)
    );
    if let Some(p) = &r.paper_stats {
        stats_table(
            &mut o,
            "paper-stats-table",
            "The paper's one-step method, same split",
            p,
        );
    }

    // Per pose.
    o.push_str(r#"<h2 id="per-pose">Per-pose error</h2><div class="plots">"#);
    let idx = |i: usize, _: &str| Some((i + 1) as f64);
    o.push_str(&svg::scatter(
        "3-D error per pose, before and after",
        "pose (order in the file)",
        "|e| (mm)",
        &pose_series(r, idx, true),
    ));
    o.push_str(&svg::scatter(
        "3-D error per pose, after",
        "pose (order in the file)",
        "|e| (mm)",
        &pose_series(r, idx, false),
    ));
    o.push_str("</div>");
    if !r.outliers.is_empty() {
        o.push_str(r#"<table id="outliers"><caption>Outlier poses (robust loss)</caption><tr><th>pose</th><th>residual (mm)</th><th>score</th></tr>"#);
        for ol in &r.outliers {
            let _ = write!(
                o,
                "<tr><td>{}</td>{}{}</tr>",
                esc(&ol.pose),
                num(ol.residual_mm),
                num(ol.score)
            );
        }
        o.push_str("</table>");
    }

    // Residual against the recorded variables.
    o.push_str(r#"<h2 id="residual-vs">Residual against joint angles, time and temperature</h2>"#);
    match poses {
        None => o.push_str(r#"<p class="muted">Not available: the report holds no joint angles. Pass the poses file (<code>drawcal report --poses poses.csv</code>) to plot the residual against each recorded variable.</p>"#),
        Some(pc) => {
            o.push_str(r#"<div class="plots">"#);
            let mut drawn = 0;
            for (c, name) in pc.names.iter().enumerate() {
                if name == "split" || name == "src_row" || name.starts_with('l') && name.ends_with("_mm") {
                    continue;
                }
                let x = |_: usize, id: &str| pc.rows.get(id).map(|v| v[c]).filter(|v| v.is_finite());
                let s = pose_series(r, x, false);
                if s.iter().all(|s| s.points.is_empty()) {
                    continue;
                }
                drawn += 1;
                o.push_str(&svg::scatter(
                    &format!("3-D error after vs {name}"),
                    name,
                    "|e| (mm)",
                    &s,
                ));
            }
            o.push_str("</div>");
            if drawn == 0 {
                o.push_str(r#"<p class="muted">No pose of the file matches the report's pose ids.</p>"#);
            }
            // String residual per sensor against its length.
            let n_str = r
                .per_pose
                .iter()
                .filter_map(|p| p.strings_mm.as_ref().map(Vec::len))
                .max()
                .unwrap_or(0);
            if n_str > 0 {
                o.push_str(r#"<h3>String residual against string length, per sensor</h3><div class="plots">"#);
                for k in 0..n_str {
                    let col = format!("l{}_mm", k + 1);
                    let Some(c) = pc.column(&col) else { continue };
                    let mut tr = Series { label: "train", color: TRAIN, points: vec![], dot: 0.0 };
                    let mut te = Series { label: "test", color: TEST, points: vec![], dot: 0.0 };
                    for p in &r.per_pose {
                        let (Some(s), Some(v)) = (&p.strings_mm, pc.rows.get(&p.pose)) else { continue };
                        let (Some(res), l) = (s.get(k), v[c]) else { continue };
                        if p.split == Split::Test { &mut te } else { &mut tr }.points.push((l, *res));
                    }
                    o.push_str(&svg::scatter(
                        &format!("string {} residual vs length", k + 1),
                        &col,
                        "residual (mm)",
                        &[tr, te],
                    ));
                }
                o.push_str("</div>");
            }
        }
    }

    // Findings.
    o.push_str(r#"<h2 id="findings">Physics beyond the geometric model</h2>"#);
    if let Some(n) = not_run {
        let _ = write!(
            o,
            r#"<p id="physics-not-run" class="physics-not-run"><b>Physics analysis:</b> {}</p>"#,
            esc(n)
        );
    }
    if r.findings.is_empty() {
        if not_run.is_none() {
            o.push_str(
                r#"<p id="no-findings">No finding: the geometric model explains the data.</p>"#,
            );
        }
    } else {
        o.push_str(r#"<table id="findings-table"><tr><th>effect</th><th>on</th><th>magnitude</th><th>1σ</th><th>unit</th><th>physics</th><th>evidence</th><th>held-out RMS before (mm)</th><th>held-out RMS after (mm)</th></tr>"#);
        for (i, f) in r.findings.iter().enumerate() {
            finding_row(&mut o, i, f);
        }
        o.push_str(r#"</table><div class="plots">"#);
        let groups: Vec<String> = r
            .findings
            .iter()
            .map(|f| match f.joint {
                Some(j) => format!("{} j{j}", f.effect),
                None => f.effect.clone(),
            })
            .collect();
        let g: Vec<&str> = groups.iter().map(String::as_str).collect();
        let values: Vec<Vec<f64>> = r
            .findings
            .iter()
            .map(|f| vec![f.test_rms_before_mm, f.test_rms_after_mm])
            .collect();
        o.push_str(&svg::bars(
            "Held-out RMS before and after each finding",
            "RMS (mm)",
            &g,
            &[("before", BEFORE_TEST), ("after", TEST)],
            &values,
        ));
        o.push_str("</div>");
        o.push_str(r#"<h3 id="evidence">Evidence of each finding</h3><p class="muted">Per pose, the residual with the effect left out of the fitted model, on the effect's own signature (robot side: the error along the displacement the effect causes; sensor side: the string's reading error), against what drives the effect; black: the fitted effect along the same direction. Where the effect is real the points follow it. An <b>unexplained</b> finding has no fitted effect: its plot is the final model's error along the residuals' dominant direction against the ordering that located the structure (a joint angle, time, temperature), and in black the running mean of its train neighbours along that ordering.</p><div class="plots">"#);
        for (i, f) in r.findings.iter().enumerate() {
            evidence_figure(&mut o, i, f);
        }
        o.push_str("</div>");
    }

    // The other notes (the "not run" one is shown above).
    let notes: Vec<&String> = r
        .physics_notes
        .iter()
        .filter(|n| Some(*n) != not_run)
        .collect();
    if !notes.is_empty() {
        o.push_str(r#"<h3>What the physics analysis saw</h3><ul id="physics-notes">"#);
        for n in notes {
            let _ = write!(o, "<li>{}</li>", esc(n));
        }
        o.push_str("</ul>");
    }

    // Parameters.
    o.push_str(r#"<h2 id="parameters">Parameters (1σ)</h2><p class="muted">deviation: the calibrated value minus the nominal one for the joints; for the base pose and the tool point, minus the "before" fit (nominal joints, base and tool fitted), since their nominal values are only starting guesses.</p><table id="parameters-table"><tr><th>name</th><th>value</th><th>deviation</th><th>1σ</th><th>unit</th><th>|deviation| / σ</th></tr>"#);
    for p in &r.parameters {
        let ratio = if p.sigma > 0.0 {
            format!("{:.1}", p.deviation.abs() / p.sigma)
        } else {
            "-".into()
        };
        let _ = write!(
            o,
            r#"<tr data-param="{n}"><td>{n}</td>{}{}{}<td>{}</td><td class="num">{ratio}</td></tr>"#,
            num(p.value),
            num(p.deviation),
            num(p.sigma),
            esc(&p.unit),
            n = esc(&p.name),
        );
    }
    o.push_str("</table>");
    o.push_str(r#"<h3>Fixed as unidentifiable (held at nominal)</h3>"#);
    if r.identifiability.fixed.is_empty() && r.fixed.is_empty() {
        o.push_str(r#"<p id="fixed-none">None.</p>"#);
    } else {
        o.push_str(
            r#"<table id="fixed-table"><tr><th>parameter</th><th>aliased with</th><th>why</th></tr>"#,
        );
        for name in &r.fixed {
            let f = r.identifiability.fixed.iter().find(|f| &f.name == name);
            let _ = write!(
                o,
                "<tr><td>{}</td><td>{}</td><td>{}</td></tr>",
                esc(name),
                esc(&f.map(|f| f.aliased_with.join(", ")).unwrap_or_default()),
                esc(f.map_or("", |f| f.reason.heading()))
            );
        }
        o.push_str("</table>");
    }
    o.push_str(r#"<h3>Deviations per joint</h3><table id="deviations-table"><tr><th>joint</th><th>a (mm)</th><th>1σ</th><th>α (deg)</th><th>1σ</th><th>d (mm)</th><th>1σ</th><th>θ offset (deg)</th><th>1σ</th><th>β (deg)</th><th>1σ</th></tr>"#);
    for d in &r.deviations {
        let _ = write!(
            o,
            "<tr><td>{}</td>{}{}{}{}{}{}{}{}{}{}</tr>",
            d.joint,
            num(d.a_mm),
            opt_num(d.a_mm_sigma),
            num(d.alpha_deg),
            opt_num(d.alpha_deg_sigma),
            num(d.d_mm),
            opt_num(d.d_mm_sigma),
            num(d.theta_offset_deg),
            opt_num(d.theta_offset_deg_sigma),
            num(d.beta_deg),
            opt_num(d.beta_deg_sigma),
        );
    }
    o.push_str("</table>");
    let _ = write!(
        o,
        r#"<p>Tool point in the flange frame: {} mm. Base in the rig frame: xyz {} mm, rpy {} deg.</p>"#,
        r.tool_point_mm
            .iter()
            .map(|v| format!("{v:.4}"))
            .collect::<Vec<_>>()
            .join(", "),
        r.base_in_rig
            .xyz_mm
            .iter()
            .map(|v| format!("{v:.4}"))
            .collect::<Vec<_>>()
            .join(", "),
        r.base_in_rig
            .rpy_deg
            .iter()
            .map(|v| format!("{v:.4}"))
            .collect::<Vec<_>>()
            .join(", "),
    );
    o.push_str("</div>");
    o
}

/// The report as one self-contained HTML document (inline CSS and SVG, no
/// script, no external reference).
pub fn render(r: &Report, title: &str, poses: Option<&PoseColumns>) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{t}</title><meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"></head><body style=\"margin:16px\"><h1 style=\"font:bold 20px system-ui,sans-serif\">{t}</h1>{}</body></html>\n",
        render_fragment(r, poses),
        t = esc(title)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_numbers_show_as_a_dash() {
        assert_eq!(num(f64::NAN), r#"<td class="num">-</td>"#);
        assert_eq!(opt_num(None), r#"<td class="num">-</td>"#);
        assert_eq!(num(1.5), r#"<td class="num" data-value="1.5">1.5000</td>"#);
    }
}
