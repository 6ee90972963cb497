//! `drawcal report --html` and the HTML renderer: the file holds the
//! report's numbers, its plots drew, and it references nothing outside.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

use drawcal::report::{ErrorStats, Report};
use drawcal::report_html::{self, PoseColumns};

const BIN: &str = env!("CARGO_BIN_EXE_drawcal");

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("drawcal-report-html-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Identify a shared dataset with the CLI and return the report path.
fn identify(dataset: &str, dir: &Path) -> PathBuf {
    let d = data(dataset);
    let out = dir.join("report.json");
    let st = Command::new(BIN)
        .args(["identify", "--robot"])
        .arg(d.join("robot.json"))
        .arg("--rig")
        .arg(d.join("rig.json"))
        .arg("--poses")
        .arg(d.join("poses.csv"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    out
}

fn run_report(report: &Path, html: &Path, poses: Option<&Path>) {
    let mut c = Command::new(BIN);
    c.arg("report").arg(report).arg("--html").arg(html);
    if let Some(p) = poses {
        c.arg("--poses").arg(p);
    }
    let st = c.output().unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
}

fn has_value(html: &str, v: f64, what: &str) {
    let full = format!("data-value=\"{v}\"");
    let shown = format!(">{v:.4}<");
    assert!(html.contains(&full), "{what}: {full} missing");
    assert!(html.contains(&shown), "{what}: {shown} missing");
}

fn has_stats(html: &str, e: &ErrorStats, what: &str) {
    has_value(html, e.rms_mm, &format!("{what} rms"));
    has_value(html, e.mean_mm, &format!("{what} mean"));
    has_value(html, e.max_mm, &format!("{what} max"));
    for (axis, a) in [("x", &e.x), ("y", &e.y), ("z", &e.z)] {
        has_value(html, a.max_abs_mm, &format!("{what} {axis} max"));
        has_value(html, a.mean_abs_mm, &format!("{what} {axis} mean"));
        has_value(html, a.rms_mm, &format!("{what} {axis} rms"));
    }
}

fn esc(s: &str) -> String {
    drawcal::report_html::svg::esc(s)
}

/// The SVG elements of the page, each with the number of points its series
/// drew (from `data-n`) and whether every non-empty series has a path.
fn plots(html: &str) -> Vec<(String, usize)> {
    let mut out = Vec::new();
    let mut rest = html;
    while let Some(i) = rest.find("<svg") {
        let end = rest[i..].find("</svg>").expect("closed svg") + i;
        let svg = &rest[i..end];
        let title = svg
            .split("<title>")
            .nth(1)
            .and_then(|t| t.split("</title>").next())
            .unwrap_or("")
            .to_string();
        let mut n = 0;
        for part in svg.split("<path class=\"series\"").skip(1) {
            let k: usize = part
                .split("data-n=\"")
                .nth(1)
                .and_then(|s| s.split('"').next())
                .and_then(|s| s.parse().ok())
                .expect("data-n");
            let d = part
                .split(" d=\"")
                .nth(1)
                .unwrap()
                .split('"')
                .next()
                .unwrap();
            assert_eq!(
                d.matches('M').count(),
                k,
                "{title}: path has not one dot per point"
            );
            n += k;
        }
        n += svg.matches("<rect class=\"bar\"").count();
        out.push((title, n));
        rest = &rest[end..];
    }
    out
}

fn assert_self_contained(html: &str) {
    let lower = html.to_lowercase();
    for bad in [
        "http://", "https://", "<script", "<link", " src=", "url(", "@import", "//cdn",
    ] {
        assert!(!lower.contains(bad), "the file references outside: {bad}");
    }
}

#[test]
fn cli_report_holds_the_numbers_and_draws_the_plots() {
    let dir = tmpdir("compliance");
    let report_path = identify("er3a_compliance_j2", &dir);
    let html_path = dir.join("out.html");
    let poses = data("er3a_compliance_j2").join("poses.csv");
    run_report(&report_path, &html_path, Some(&poses));
    let html = std::fs::read_to_string(&html_path).unwrap();
    let r: Report = serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();

    assert!(html.starts_with("<!DOCTYPE html>"));
    assert_self_contained(&html);
    // Tables 3/4: train and test, before and after, per axis and 3-D.
    has_stats(&html, &r.stats.train.before, "train before");
    has_stats(&html, &r.stats.train.after, "train after");
    has_stats(&html, &r.stats.test.before, "test before");
    has_stats(&html, &r.stats.test.after, "test after");
    if let Some(p) = &r.paper_stats {
        has_stats(&html, &p.test.after, "paper test after");
    }
    // Parameters with 1-sigma; the fixed list.
    assert!(!r.parameters.is_empty());
    for p in &r.parameters {
        assert!(
            html.contains(&format!("data-param=\"{}\"", esc(&p.name))),
            "{}",
            p.name
        );
        has_value(&html, p.value, &p.name);
        has_value(&html, p.sigma, &format!("{} sigma", p.name));
    }
    // The verdict first, with every reason; the free set with its reason.
    let v = drawcal::report::verdict::Verdict::read(&r);
    let at = html.find(r#"id="verdict""#).expect("verdict section");
    assert!(
        at < html.find(r#"id="summary""#).unwrap(),
        "verdict before the summary"
    );
    assert!(html.contains(&format!(r#"data-level="{}""#, v.level)));
    for reason in &v.reasons {
        assert!(html.contains(&esc(reason)), "{reason}");
    }
    let f = r.free_set.as_ref().expect("free set");
    assert!(html.contains(&format!(r#"data-chosen="{}""#, f.chosen)));
    assert!(html.contains(&esc(&f.reason)));
    assert!(!r.fixed.is_empty());
    for f in &r.fixed {
        assert!(html.contains(&format!("<td>{}</td>", esc(f))), "fixed {f}");
    }
    // Findings with evidence and held-out RMS before/after.
    assert!(
        !r.findings.is_empty(),
        "the compliance dataset has a finding"
    );
    for f in &r.findings {
        assert!(html.contains(&esc(&f.effect)));
        assert!(html.contains(&esc(&f.evidence)), "evidence of {}", f.effect);
        has_value(&html, f.test_rms_before_mm, "finding before");
        has_value(&html, f.test_rms_after_mm, "finding after");
        has_value(&html, f.magnitude, "finding magnitude");
    }

    // Each finding with the plot that is its evidence (train and test
    // points and the fitted effect, one dot each) and the held-out RMS
    // before and after it.
    let mut n_evidence = 0;
    for (i, f) in r.findings.iter().enumerate() {
        let fig = html
            .split(&format!("<figure class=\"evidence\" data-finding=\"{i}\""))
            .nth(1)
            .unwrap_or_else(|| panic!("no evidence figure for finding {i}"))
            .split("</figure>")
            .next()
            .unwrap();
        assert!(fig.contains(&format!(
            "class=\"rms-before\" data-value=\"{}\"",
            f.test_rms_before_mm
        )));
        assert!(fig.contains(&format!(
            "class=\"rms-after\" data-value=\"{}\"",
            f.test_rms_after_mm
        )));
        let ev = f
            .evidence_plot
            .as_ref()
            .unwrap_or_else(|| panic!("finding {i} ({}) has no evidence plot", f.effect));
        n_evidence += 1;
        let p = plots(fig);
        assert_eq!(p.len(), 1, "one plot in the figure of finding {i}");
        assert!(p[0].0.contains("held-out RMS"), "{}", p[0].0);
        assert_eq!(p[0].1, 2 * ev.points.len(), "{}", p[0].0);
        assert!(!ev.points.is_empty());
        assert!(fig.contains(&esc(&ev.x_label)), "{}", ev.x_label);
        if let Some(c) = ev.correlation {
            assert!(fig.contains(&format!("data-value=\"{c}\"")));
        }
    }
    assert!(
        n_evidence >= 1,
        "the compliance finding has its evidence plot"
    );
    // A report from before evidence plots still renders, and says so.
    let mut old = r.clone();
    old.findings.iter_mut().for_each(|f| f.evidence_plot = None);
    let old_html = report_html::render_fragment(&old, None);
    assert!(old_html.contains("the report predates evidence plots"));

    for n in &r.physics_notes {
        assert!(html.contains(&format!("<li>{}</li>", esc(n))), "note {n}");
    }
    // No warnings about this input: no warnings box; the physics analysis
    // ran.
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    assert!(warnings_box(&html).is_none());
    assert!(!html.contains("id=\"report-warnings\""));
    assert!(!html.contains("physics-not-run\""));

    // Plots: every one drew something; per pose holds every pose twice
    // (before and after) and the residual plots exist per joint angle.
    let plots = plots(&html);
    for (title, n) in &plots {
        assert!(*n > 0, "plot '{title}' is empty");
    }
    let per_pose = plots
        .iter()
        .find(|(t, _)| t == "3-D error per pose, before and after")
        .expect("per-pose plot");
    assert_eq!(per_pose.1, 2 * r.per_pose.len());
    let dof = r.nominal_robot.joints.len();
    for j in 1..=dof {
        let t = format!("3-D error after vs q{j}_deg");
        let p = plots
            .iter()
            .find(|(x, _)| *x == t)
            .unwrap_or_else(|| panic!("{t}"));
        assert_eq!(p.1, r.per_pose.len(), "{t}");
    }
    for t in ["3-D error after vs time_s", "3-D error after vs temp_c"] {
        assert!(plots.iter().any(|(x, _)| x == t), "{t}");
    }
    for k in 1..=4 {
        let t = format!("string {k} residual vs length");
        assert!(plots.iter().any(|(x, _)| *x == t), "{t}");
    }
    assert!(
        plots
            .iter()
            .any(|(t, _)| t.starts_with("RMS error per axis"))
    );
    assert!(
        plots
            .iter()
            .any(|(t, _)| t.starts_with("Held-out RMS before and after each finding"))
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The `unexplained` finding of the UR10 tracker session is drawn: its
/// plot (train, test and the running mean, one dot per point) along the
/// ordering that located the structure, captioned as a running mean, not
/// a fitted effect.
#[test]
fn the_unexplained_finding_is_drawn_with_its_running_mean() {
    let dir = tmpdir("unexplained");
    let report_path = identify("real_ur10_ipa_random", &dir);
    let html_path = dir.join("out.html");
    run_report(&report_path, &html_path, None);
    let html = std::fs::read_to_string(&html_path).unwrap();
    let r: Report = serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
    let (i, f) = r
        .findings
        .iter()
        .enumerate()
        .find(|(_, f)| f.effect == "unexplained")
        .expect("the UR10 tracker session leaves unexplained structure");
    let ev = f.evidence_plot.as_ref().expect("its evidence plot");
    assert!(!ev.points.is_empty());
    let fig = html
        .split(&format!("<figure class=\"evidence\" data-finding=\"{i}\""))
        .nth(1)
        .expect("the unexplained figure")
        .split("</figure>")
        .next()
        .unwrap();
    let p = plots(fig);
    assert_eq!(p.len(), 1, "one plot in the unexplained figure");
    assert_eq!(p[0].1, 2 * ev.points.len(), "{}", p[0].0);
    assert!(fig.contains(&format!("data-n=\"{}\"", ev.points.len())));
    assert!(fig.contains(&esc(&ev.x_label)), "{}", ev.x_label);
    assert!(fig.contains(&esc(&ev.y_label)));
    assert!(fig.contains("running mean"));
    assert!(!fig.contains("fitted effect"));
    assert!(fig.contains("residual on its dominant direction"));
    let c = ev.correlation.expect("a correlation");
    assert!(fig.contains(&format!("class=\"corr\" data-value=\"{c}\"")));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn without_poses_the_joint_plots_are_declared_missing_and_the_service_form_is_read() {
    let dir = tmpdir("plain");
    let report_path = identify("er3a_paper_like", &dir);
    let r: Report = serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
    // The service's answer, {calibration, report}, is read as well.
    let wrapped = dir.join("calibration.json");
    let v =
        serde_json::json!({"calibration": {"id": 1}, "report": serde_json::to_value(&r).unwrap()});
    std::fs::write(&wrapped, v.to_string()).unwrap();
    let html_path = dir.join("out.html");
    run_report(&wrapped, &html_path, None);
    let html = std::fs::read_to_string(&html_path).unwrap();
    assert_self_contained(&html);
    has_stats(&html, &r.stats.test.after, "test after");
    assert!(html.contains("Not available: the report holds no joint angles"));
    assert!(!html.contains("vs q1_deg"));
    assert!(html.contains("id=\"no-findings\"") == r.findings.is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_file_that_is_not_a_report_is_refused() {
    let dir = tmpdir("bad");
    let p = dir.join("x.json");
    std::fs::write(&p, "{\"format\": 1}").unwrap();
    let st = Command::new(BIN)
        .arg("report")
        .arg(&p)
        .arg("--html")
        .arg(dir.join("o.html"))
        .output()
        .unwrap();
    assert!(!st.status.success());
    assert!(String::from_utf8_lossy(&st.stderr).contains("not a drawcal report"));
    assert!(!dir.join("o.html").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn pose_columns_keep_numeric_columns_by_pose_id() {
    let csv = "pose,q1_deg,name,split,temp_c\np1,1.5,a,train,20\np2,-2,b,test,\n";
    let pc = PoseColumns::from_csv(csv.as_bytes()).unwrap();
    assert_eq!(pc.names, ["q1_deg", "temp_c"]);
    assert_eq!(pc.rows["p1"], vec![1.5, 20.0]);
    assert_eq!(pc.rows["p2"][0], -2.0);
    assert!(pc.rows["p2"][1].is_nan());
    assert!(PoseColumns::from_csv("a,b\n1,2\n".as_bytes()).is_err());
    // The renderer escapes text it is handed.
    assert_eq!(
        report_html::svg::esc("<a&\"'>"),
        "&lt;a&amp;&quot;&#39;&gt;"
    );
}

/// A dataset's poses.csv with every joint angle rewritten in radians.
fn in_radians(name: &str) -> String {
    common::q_columns_in_radians(
        &std::fs::read_to_string(data(name).join("poses.csv")).unwrap(),
        None,
    )
}

/// The box of the report's `warnings`, from its opening tag to its end.
fn warnings_box(html: &str) -> Option<&str> {
    let i = html.find(r#"<div class="report-warnings""#)?;
    let end = html[i..].find("</div>").expect("closed warnings box") + i;
    Some(&html[i..end])
}

/// Joint angles in radians: the report's warning is shown in a box at the
/// top of the HTML (before the summary), escaped; the physics analysis did
/// not run on a model that far off, and the HTML says so in the summary
/// and in the findings section instead of "no finding".
#[test]
fn warnings_and_a_physics_note_not_run_are_shown() {
    let dir = tmpdir("warnings");
    let poses = dir.join("poses.csv");
    std::fs::write(&poses, in_radians("er3a_paper_like")).unwrap();
    let d = data("er3a_paper_like");
    let report_path = dir.join("report.json");
    let st = Command::new(BIN)
        .args(["identify", "--robot"])
        .arg(d.join("robot.json"))
        .arg("--rig")
        .arg(d.join("rig.json"))
        .arg("--poses")
        .arg(&poses)
        .arg("--out")
        .arg(&report_path)
        // Refused without it.
        .arg("--force")
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let html_path = dir.join("out.html");
    run_report(&report_path, &html_path, Some(&poses));
    let html = std::fs::read_to_string(&html_path).unwrap();
    let r: Report = serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
    assert_self_contained(&html);

    assert!(!r.warnings.is_empty(), "radians are warned about");
    let b = warnings_box(&html).expect("the warnings box");
    assert!(
        html.find(r#"class="report-warnings""#) < html.find(r#"id="summary""#),
        "the warnings come before the summary"
    );
    for w in &r.warnings {
        assert!(b.contains(&format!("<li>{}</li>", esc(w))), "warning {w}");
    }
    assert_eq!(b.matches("<li>").count(), r.warnings.len());

    assert_eq!(r.physics, drawcal::report::PhysicsRun::GeometryMisses);
    let note = r
        .physics_notes
        .iter()
        .find(|n| n.starts_with(drawcal::report::PhysicsRun::NOTE_PREFIX))
        .expect("physics not run on a model this far off");
    assert!(r.findings.is_empty());
    assert!(html.contains(&format!(
        r#"<tr><th>physics analysis</th><td class="physics-not-run">{}</td></tr>"#,
        esc(note)
    )));
    assert!(html.contains(&format!(
        r#"<p id="physics-not-run" class="physics-not-run"><b>Physics analysis:</b> {}</p>"#,
        esc(note)
    )));
    assert!(
        !html.contains("id=\"no-findings\""),
        "a physics analysis that did not run found nothing is not 'no finding'"
    );

    // Text is escaped.
    let mut evil = r.clone();
    evil.warnings = vec!["<script>alert(1)</script> & \"q\"".into()];
    let h = report_html::render_fragment(&evil, None);
    let b = warnings_box(&h).unwrap();
    assert!(b.contains("<li>&lt;script&gt;alert(1)&lt;/script&gt; &amp; &quot;q&quot;</li>"));
    assert!(!h.contains("<script>"));

    // Physics switched off: its note is shown the same way.
    let mut off = r.clone();
    off.warnings.clear();
    off.physics_notes = vec!["not run (physics off)".into()];
    let h = report_html::render_fragment(&off, None);
    assert!(h.contains("<b>Physics analysis:</b> not run (physics off)</p>"));
    assert!(!h.contains("id=\"no-findings\""));
    // No warnings: no box (the CSS rule names the class, no element has it).
    assert!(warnings_box(&h).is_none());
    assert!(!h.contains("id=\"report-warnings\""));
    let _ = std::fs::remove_dir_all(&dir);
}
