//! The browser page's server side: `/` and its script come from the
//! binary with no outside reference, and `GET /calibrations/{id}/report.html`
//! renders the stored report with the session's poses.

use crate::helpers;

use std::time::Duration;

use helpers::{TestApp, err_json, ok_json, read};

fn no_outside_reference(what: &str, text: &str) {
    let lower = text.to_lowercase();
    for bad in [
        "http://", "https://", "//cdn", "@import", "url(//", "url('//", "url(\"//",
    ] {
        assert!(!lower.contains(bad), "{what} references outside: {bad}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_is_served_from_the_binary() {
    let app = TestApp::spawn("ui-page").await;
    let r = app.get("/").await;
    assert_eq!(r.status(), 200);
    assert!(
        r.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with("text/html")
    );
    let html = r.text().await.unwrap();
    assert_eq!(html, drawcal::http::ui::INDEX_HTML);
    assert!(html.contains(r#"<script src="/ui/app.js"></script>"#));
    no_outside_reference("index.html", &html);
    let r = app.get("/ui/app.js").await;
    assert_eq!(r.status(), 200);
    assert!(
        r.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with("text/javascript")
    );
    let js = r.text().await.unwrap();
    no_outside_reference("app.js", &js);
    // The views the issue asks for, and the API routes they use.
    for needle in [
        "fleetView",
        "sessionView",
        "calibrationView",
        "compensateView",
        "/report.html",
        "/poses`, text, \"text/csv\"",
        "/jobs/${j.id}/cancel",
        "/activate",
        "/rollback",
        "\"/compensate\"",
    ] {
        assert!(js.contains(needle), "app.js lacks {needle}");
    }
    // The calibration view shows the report's `warnings` (as the API gave
    // them, escaped) in a styled box above activation, and drops the
    // embedded report's own copy of the box.
    for needle in [
        "function warningsHtml(warnings)",
        "if (!warnings || !warnings.length) return \"\";",
        "warnings.map(w => `<li>${esc(w)}</li>`)",
        "id=\"cal-warnings\"",
        "${warningsHtml(out.report && out.report.warnings)}\n    <fieldset><legend>${c.active ? \"Active for the robot\" : \"Activate for the robot\"}",
        "$(\"#report-warnings\", frag)",
    ] {
        assert!(js.contains(needle), "app.js lacks {needle}");
    }
    assert!(html.contains(".warnings{"), "index.html styles the box");
    // The page's routes are not API routes: unknown paths still answer the
    // API's 404.
    err_json(app.get("/ui/nope.js").await, 404, "not_found").await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn report_html_renders_the_stored_calibration() {
    let app = TestApp::spawn("ui-report").await;
    err_json(
        app.get("/calibrations/999999/report.html").await,
        404,
        "not_found",
    )
    .await;
    let ds = "er3a_compliance_j2";
    let (_, _, _, session) = app.setup(ds, "ER3A-UI").await;
    ok_json(
        app.post_raw(
            &format!("/sessions/{session}/poses"),
            Some("text/csv"),
            read(ds, "poses.csv"),
        )
        .await,
        200,
    )
    .await;
    let job = ok_json(
        app.post_raw(&format!("/sessions/{session}/jobs"), None, "")
            .await,
        202,
    )
    .await;
    let job = app
        .wait_job(job["id"].as_i64().unwrap(), Duration::from_secs(120))
        .await;
    assert_eq!(job["state"], "succeeded", "{job}");
    let cal = job["calibration_id"].as_i64().unwrap();
    let out = ok_json(app.get(&format!("/calibrations/{cal}")).await, 200).await;
    let report: drawcal::report::Report = serde_json::from_value(out["report"].clone()).unwrap();

    let r = app.get(&format!("/calibrations/{cal}/report.html")).await;
    assert_eq!(r.status(), 200);
    assert!(
        r.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with("text/html")
    );
    let html = r.text().await.unwrap();
    // The same HTML as the CLI renders from the same report and poses.
    let poses =
        drawcal::report_html::PoseColumns::from_csv(read(ds, "poses.csv").as_bytes()).unwrap();
    let title = format!("ER3A-UI calibration v1 (#{cal})");
    let expected = drawcal::report_html::render(&report, &title, Some(&poses));
    assert_eq!(html, expected);
    for v in [
        report.stats.test.before.rms_mm,
        report.stats.test.after.rms_mm,
        report.stats.train.after.x.max_abs_mm,
    ] {
        assert!(html.contains(&format!("data-value=\"{v}\"")), "{v}");
    }
    assert!(!report.findings.is_empty());
    assert!(html.contains("3-D error after vs q2_deg"));
    // Nothing looked wrong in this input: no warnings box.
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    assert!(!html.contains("id=\"report-warnings\""));
    no_outside_reference("report.html", &html);
    app.stop().await;
}

/// The Compensate view offers the run-time conditions `POST /compensate`
/// takes (temperature, payload, approach), sends each only when filled in,
/// and shows which ones the answer says were used (`temp_c_used`,
/// `payload_kg_used`, `approach_used`), as the answer gave them. A static
/// check of the script; the browser test runs it against the service.
#[test]
fn the_compensate_view_sends_the_conditions_and_shows_the_used_ones() {
    use drawcal::compensate::Approach;
    use drawcal::http::compensate::CompensateResponse;
    let js = drawcal::http::ui::APP_JS;
    let html = drawcal::http::ui::INDEX_HTML;
    for needle in [
        // The inputs; the approach's default sends nothing.
        "id=\"comp-temp\"",
        "id=\"comp-payload\"",
        "<select id=\"comp-approach\"><option value=\"\">default (not sent)</option>",
        // Sent only when filled in, under the API's names.
        "if (s === \"\") return undefined;",
        "if (temp !== undefined) req.temp_c = temp;",
        "if (payload !== undefined) req.payload_kg = payload;",
        "if ($(\"#comp-approach\").value) req.approach = $(\"#comp-approach\").value;",
        // The answer's *_used fields, rendered (null: not used).
        "used: r.temp_c_used",
        "used: r.payload_kg_used",
        "used: r.approach_used",
        "conds.filter(c => c.used != null)",
        "conds.filter(c => c.used == null)",
        "id=\"comp-used-${c.key}\" data-value=\"${c.used == null ? \"\" : esc(c.used)}\"",
        "${usedHtml(r, req)}",
        "Not used by this calibration",
        // Which conditions matter, from the selected calibration's findings.
        "x.parameters.driver === \"temperature\"",
        "of(\"thermal_expansion\")",
        "of(\"joint_compliance\")",
        "of(\"backlash\")",
        "api(\"GET\", `/calibrations/${calId}`)",
        "conditionHints(out.report)",
    ] {
        assert!(js.contains(needle), "app.js lacks {needle}");
    }
    // The select's values are the API's approach names.
    for a in Approach::ALL {
        let name = serde_json::to_value(a).unwrap();
        let name = name.as_str().unwrap();
        assert!(
            js.contains(&format!("<option value=\"{name}\">")),
            "no option {name}"
        );
        assert!(
            js.contains(&format!("{name}: ")),
            "APPROACH_TEXT lacks {name}"
        );
    }
    // The answer's field names are the ones the script reads.
    let answer = serde_json::to_value(CompensateResponse {
        robot_id: 1,
        calibration_id: 1,
        version: 1,
        temp_c_used: None,
        payload_kg_used: None,
        approach_used: None,
        n_ok: 0,
        results: vec![],
        warnings: vec![],
        notes: vec![],
    })
    .unwrap();
    for field in [
        "temp_c_used",
        "payload_kg_used",
        "approach_used",
        "warnings",
        "notes",
    ] {
        assert!(answer.get(field).is_some(), "the API answers {field}");
        assert!(js.contains(&format!("r.{field}")), "app.js reads {field}");
    }
    // The request's field names too: every condition is accepted by the
    // API's request type.
    let req: Result<drawcal::http::compensate::CompensateRequest, _> =
        serde_json::from_value(serde_json::json!({
            "robot_id": 1, "targets": [], "temp_c": 30.0, "payload_kg": 12.0,
            "approach": "in_order"
        }));
    assert!(req.is_ok(), "{req:?}");
    // A relevant condition is styled.
    assert!(html.contains(".cond[data-relevant=true]{"));
}
