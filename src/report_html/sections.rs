//! The sections of the HTML report, in page order, each appending its
//! HTML to the page.

use std::fmt::Write;

use super::svg::{self, Series, esc};
use super::{
    BEFORE_TEST, PoseColumns, TEST, TRAIN, evidence_figure, finding_row, max_plot, num, opt_num,
    pose_series, stats_plot, stats_table,
};
use crate::model::Split;
use crate::report::Report;
use crate::report::verdict::Verdict;

/// The warnings about the input, if any, as an alert box.
pub(super) fn warnings(o: &mut String, r: &Report) {
    if !r.warnings.is_empty() {
        o.push_str(r#"<div class="report-warnings" id="report-warnings" role="alert"><b>Warning: the input looks wrong.</b> It was used as given; check it before trusting this calibration.<ul>"#);
        for w in &r.warnings {
            let _ = write!(o, "<li>{}</li>", esc(w));
        }
        o.push_str("</ul></div>");
    }
}

/// "Verdict": green, amber or red with every reason, and the extra poses
/// it suggests (their targets and what each parameter's 1-sigma becomes).
pub(super) fn verdict(o: &mut String, r: &Report) {
    let v = Verdict::read(r);
    let _ = write!(
        o,
        r#"<div class="verdict verdict-{l}" id="verdict" data-level="{l}"><b>Verdict: {L}</b><ul>"#,
        l = v.level,
        L = v.level.to_string().to_uppercase()
    );
    for reason in &v.reasons {
        let _ = write!(o, "<li>{}</li>", esc(reason));
    }
    o.push_str("</ul></div>");
    let Some(x) = r.extra_poses.as_ref().filter(|x| !x.poses.is_empty()) else {
        return;
    };
    o.push_str(r#"<h3 id="extra-poses">Extra poses to record</h3><table id="extra-parameters"><tr><th>parameter</th><th class="num">1-sigma now</th><th class="num">with the extra poses</th><th class="num">tolerance</th><th>unit</th></tr>"#);
    for p in &x.parameters {
        let _ = write!(
            o,
            "<tr><td>{}</td>{}{}{}<td>{}</td></tr>",
            esc(&p.name),
            opt_num(p.sigma_recorded),
            opt_num(p.sigma_with_extra),
            num(p.tolerance),
            esc(&p.unit)
        );
    }
    o.push_str(r#"</table><table id="extra-targets"><tr><th>target</th>"#);
    let dof = x.poses.first().map_or(0, |p| p.q_deg.len());
    for j in 1..=dof {
        let _ = write!(o, r#"<th class="num">q{j} (deg)</th>"#);
    }
    o.push_str("</tr>");
    for p in &x.poses {
        let _ = write!(o, "<tr><td>{}</td>", esc(&p.id));
        for q in &p.q_deg {
            let _ = write!(o, r#"<td class="num">{q:.3}</td>"#);
        }
        o.push_str("</tr>");
    }
    let _ = write!(o, "</table><p>{}</p>", esc(&x.criterion));
}

/// "Summary": method, split, held-out RMS, noise floor, solver,
/// identifiability, and why the physics analysis did not run (`not_run`).
pub(super) fn summary(o: &mut String, r: &Report, not_run: Option<&String>) {
    o.push_str(r#"<h2 id="summary">Summary</h2><table id="summary-table">"#);
    let row = |o: &mut String, k: &str, v: String| {
        let _ = write!(o, "<tr><th>{}</th><td>{}</td></tr>", esc(k), v);
    };
    row(o, "method", esc(&r.method));
    row(o, "robust loss", r.robust.to_string());
    row(
        o,
        "poses (train / test)",
        format!("{} / {}", r.stats.train.n, r.stats.test.n),
    );
    row(o, "split", esc(&r.split_source));
    let fmt_opt = |v: Option<f64>| v.map(|v| format!("{v:.4} mm")).unwrap_or("-".into());
    row(
        o,
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
    row(o, "noise floor (held-out)", fmt_opt(r.noise_floor_mm));
    row(
        o,
        "exact model from these train poses (held-out)",
        fmt_opt(r.expected_test_rms_mm),
    );
    row(o, "string noise (1σ)", fmt_opt(r.string_sigma_mm));
    row(
        o,
        "flange orientation from these data (1σ RMS angle)",
        r.flange_orientation_sigma_deg
            .map(|v| format!("{v:.3} deg"))
            .unwrap_or("-".into()),
    );
    row(
        o,
        "solver",
        format!(
            "{} iterations, {}, residual RMS {:.4} mm",
            r.convergence.iterations,
            esc(&r.convergence.termination),
            r.convergence.residual_rms_mm
        ),
    );
    row(
        o,
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
            o,
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
}

/// "Accuracy": the paper's Tables 3 and 4 for this calibration, their
/// plots, and the paper's one-step method on the same split if present.
pub(super) fn accuracy(o: &mut String, r: &Report) {
    o.push_str(r#"<h2 id="tables">Accuracy: the paper's Tables 3 and 4</h2>"#);
    o.push_str(r#"<p class="muted">Model T minus measured T in the robot base frame. Before: nominal joints with base pose and tool point fitted. After: calibrated model.</p>"#);
    stats_table(o, "stats-table", "This calibration", &r.stats);
    let _ = write!(
        o,
        r#"<div class="plots">{}{}</div>"#,
        stats_plot(&r.stats),
        max_plot(&r.stats)
    );
    if let Some(p) = &r.paper_stats {
        stats_table(
            o,
            "paper-stats-table",
            "The paper's one-step method, same split",
            p,
        );
    }
}

/// "Per-pose error": 3-D error per pose before and after, and the outlier
/// poses of a robust fit.
pub(super) fn per_pose(o: &mut String, r: &Report) {
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
}

/// "Residual against joint angles, time and temperature": plots against
/// the poses file's columns, or a note that the file was not given.
pub(super) fn residual_vs(o: &mut String, r: &Report, poses: Option<&PoseColumns>) {
    o.push_str(r#"<h2 id="residual-vs">Residual against joint angles, time and temperature</h2>"#);
    match poses {
        None => o.push_str(r#"<p class="muted">Not available: the report holds no joint angles. Pass the poses file (<code>drawcal report --poses poses.csv</code>) to plot the residual against each recorded variable.</p>"#),
        Some(pc) => {
            residual_vs_columns(o, r, pc);
            string_residuals(o, r, pc);
        }
    }
}

/// The 3-D error after against each recorded column of the poses file
/// (string lengths, split and source row aside).
fn residual_vs_columns(o: &mut String, r: &Report, pc: &PoseColumns) {
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
}

/// Each string's residual against its length, when the report holds
/// string residuals.
fn string_residuals(o: &mut String, r: &Report, pc: &PoseColumns) {
    // String residual per sensor against its length.
    let n_str = r
        .per_pose
        .iter()
        .filter_map(|p| p.strings_mm.as_ref().map(Vec::len))
        .max()
        .unwrap_or(0);
    if n_str > 0 {
        o.push_str(
            r#"<h3>String residual against string length, per sensor</h3><div class="plots">"#,
        );
        for k in 0..n_str {
            let col = format!("l{}_mm", k + 1);
            let Some(c) = pc.column(&col) else { continue };
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
            for p in &r.per_pose {
                let (Some(s), Some(v)) = (&p.strings_mm, pc.rows.get(&p.pose)) else {
                    continue;
                };
                let (Some(res), l) = (s.get(k), v[c]) else {
                    continue;
                };
                if p.split == Split::Test {
                    &mut te
                } else {
                    &mut tr
                }
                .points
                .push((l, *res));
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

/// "Physics beyond the geometric model": why the analysis did not run
/// (`not_run`), or the findings with their held-out RMS and evidence plots.
pub(super) fn findings(o: &mut String, r: &Report, not_run: Option<&String>) {
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
            finding_row(o, i, f);
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
            evidence_figure(o, i, f);
        }
        o.push_str("</div>");
    }
}

/// What the physics analysis saw: its notes, the "not run" one aside
/// (shown with the findings).
pub(super) fn physics_notes(o: &mut String, r: &Report, not_run: Option<&String>) {
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
}

/// "Parameters": each parameter with its deviation and 1 sigma, the fixed
/// ones, the deviations per joint, the tool point and the base.
pub(super) fn parameters(o: &mut String, r: &Report) {
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
    free_set(o, r);
    fixed(o, r);
    deviations(o, r);
}

/// Which identifiable parameters were freed and why, with each candidate
/// set's cross-validated RMS when the choice was made that way.
fn free_set(o: &mut String, r: &Report) {
    let Some(f) = &r.free_set else { return };
    let _ = write!(
        o,
        r#"<h3>Free set</h3><p id="free-set" data-chosen="{c}" data-how="{h}"><b>{c}</b> ({h}): {}</p>"#,
        esc(&f.reason),
        c = esc(&f.chosen),
        h = esc(&f.how)
    );
    if !f.candidates.is_empty() {
        let _ = write!(
            o,
            r#"<table id="free-set-table"><tr><th>set</th><th class="num">parameters freed</th><th class="num">RMS of the left-out train readings ({} folds, mm)</th></tr>"#,
            f.folds
        );
        for c in &f.candidates {
            let _ = write!(
                o,
                r#"<tr><td>{}</td><td class="num">{}</td>{}</tr>"#,
                esc(&c.name),
                c.n_free,
                num(c.cv_rms_mm)
            );
        }
        o.push_str("</table>");
    }
}

/// The parameters held at nominal as unidentifiable, with what each is
/// aliased with and why.
fn fixed(o: &mut String, r: &Report) {
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
}

/// The deviations per joint with their sigmas, then the tool point and the
/// base pose.
fn deviations(o: &mut String, r: &Report) {
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
}
