//! The calibration report as HTML: tables and inline SVG plots, no
//! JavaScript and no external files. Used by `drawcal report --html` (one
//! self-contained file) and by the service's
//! `GET /calibrations/{id}/report.html`, which the browser page shows.
//!
//! Every number comes from the [`Report`] (or, for the joint-angle axes of
//! the residual plots, from the poses file handed in as [`PoseColumns`]);
//! the only arithmetic here is the 3-D length of each pose's error vector
//! for the per-pose plots.

mod sections;
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
.drawcal-report .verdict{padding:8px 12px;margin:8px 0 12px;border:2px solid;border-left-width:8px}
.drawcal-report .verdict ul{margin:.3em 0 0;padding-left:1.4em}
.drawcal-report .verdict-green{color:#124d1e;background:#e6f6e9;border-color:#2e9e46}
.drawcal-report .verdict-amber{color:#5c3c00;background:#fff4d6;border-color:#e0a100}
.drawcal-report .verdict-red{color:#6b0f0f;background:#fde8e8;border-color:#c62828}
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
    sections::warnings(&mut o, r);
    // The answer to "is my result good?" before the evidence for it.
    sections::verdict(&mut o, r);
    // The physics analysis's note when it did not run (physics off, or a
    // geometric model too far off the data to fit effects on).
    let not_run = (!r.physics.ran())
        .then(|| {
            r.physics_notes
                .iter()
                .find(|n| n.starts_with(crate::report::PhysicsRun::NOTE_PREFIX))
        })
        .flatten();
    sections::summary(&mut o, r, not_run);
    sections::accuracy(&mut o, r);
    sections::per_pose(&mut o, r);
    sections::residual_vs(&mut o, r, poses);
    sections::findings(&mut o, r, not_run);
    sections::physics_notes(&mut o, r, not_run);
    sections::parameters(&mut o, r);
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
