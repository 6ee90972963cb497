//! Every kind of bad request gets a clear 4xx in the error shape and leaves
//! the stored data exactly as it was.

use serde_json::{Value, json};

use crate::helpers::{Options, TestApp, err_json, ok_json, read};

const DS: &str = "er3a_paper_like";

/// Send a bad request, check status, code and (optionally) field and row,
/// and check nothing stored changed.
async fn refused(
    app: &TestApp,
    req: reqwest::RequestBuilder,
    status: u16,
    code: &str,
    field: Option<&str>,
    row: Option<u64>,
) -> Value {
    let before = app.snapshot().await;
    let e = err_json(req.send().await.unwrap(), status, code).await;
    if let Some(f) = field {
        assert_eq!(e["field"], f, "field in {e}");
    }
    if let Some(r) = row {
        assert_eq!(e["row"], r, "row in {e}");
    }
    let after = app.snapshot().await;
    assert_eq!(before, after, "a refused request changed stored data: {e}");
    e
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_requests_are_refused_and_change_nothing() {
    let app = TestApp::spawn_with(
        "bad",
        Options {
            max_upload_bytes: 64 * 1024,
            ..Options::default()
        },
    )
    .await;
    let (model_id, robot_id, rig_id, sid) = app.setup(DS, "BAD-1").await;
    let c = &app.client;
    let poses = read(DS, "poses.csv");
    let lines: Vec<&str> = poses.lines().collect();
    let upload = |body: String| {
        c.post(app.url(&format!("/sessions/{sid}/poses")))
            .header("content-type", "text/csv")
            .body(body)
    };

    // A job on a session with no poses.
    let e = refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/jobs"))),
        422,
        "invalid_input",
        None,
        None,
    )
    .await;
    assert!(e["message"].as_str().unwrap().contains("no poses"));

    // Store half the poses so later bad uploads have something to leave alone.
    ok_json(upload(lines[..26].join("\n")).send().await.unwrap(), 200).await;

    // A typo in robot.json or rig.json is refused, naming the key and the
    // nearest one the format has; nothing is stored.
    let mut robot: Value = serde_json::from_str(&read(DS, "robot.json")).unwrap();
    robot["conventon"] = "mdh".into();
    let e = refused(
        &app,
        c.post(app.url("/models")).json(&robot),
        422,
        "invalid_input",
        Some("conventon"),
        None,
    )
    .await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("unknown key `conventon` (did you mean `convention`?)"),
        "{e}"
    );
    let mut rig: Value = serde_json::from_str(&read(DS, "rig.json")).unwrap();
    rig["sensor"] = json!({"rang_mm": 2000});
    let e = refused(
        &app,
        c.post(app.url("/rigs")).json(&rig),
        422,
        "invalid_input",
        Some("sensor.rang_mm"),
        None,
    )
    .await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("did you mean `range_mm`?"),
        "{e}"
    );

    // Malformed JSON, wrong types, unknown fields, missing fields.
    refused(
        &app,
        c.post(app.url("/robots"))
            .header("content-type", "application/json")
            .body("{\"serial_number\": "),
        400,
        "malformed_json",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/robots"))
            .json(&json!({"serial_number": "X", "model_id": "one"})),
        422,
        "invalid_input",
        Some("model_id"),
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/robots"))
            .json(&json!({"serial_number": "X", "model_id": model_id, "colour": "red"})),
        422,
        "invalid_input",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/robots"))
            .json(&json!({"model_id": model_id})),
        422,
        "invalid_input",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/robots"))
            .header("content-type", "text/plain")
            .body("{}"),
        415,
        "unsupported_media_type",
        None,
        None,
    )
    .await;
    // A duplicate serial number; an unknown model.
    refused(
        &app,
        c.post(app.url("/robots"))
            .json(&json!({"serial_number": "BAD-1", "model_id": model_id})),
        409,
        "conflict",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/robots"))
            .json(&json!({"serial_number": "NEW", "model_id": 4242})),
        422,
        "invalid_input",
        Some("model_id"),
        None,
    )
    .await;
    // robot.json and rig.json with bad values.
    let mut robot: Value = serde_json::from_str(&read(DS, "robot.json")).unwrap();
    robot["joints"][2]["a_mm"] = json!("wide");
    refused(
        &app,
        c.post(app.url("/models")).json(&robot),
        422,
        "invalid_input",
        Some("joints[2].a_mm"),
        None,
    )
    .await;
    robot["joints"][2]["a_mm"] = json!(60.0);
    robot["joints"][1]["q_min_deg"] = json!(500.0);
    refused(
        &app,
        c.post(app.url("/models")).json(&robot),
        422,
        "invalid_input",
        Some("joints[1].q_min_deg"),
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/rigs"))
            .json(&json!({"anchors_mm": [[0, 0, 0]], "r_mm": 35})),
        422,
        "invalid_input",
        None,
        None,
    )
    .await;
    // A key given twice in one pose object (JSON would keep the last).
    let twice = r#"[{"pose":"d","q1_deg":0,"q1_deg":5,"q2_deg":0,"q3_deg":0,"q4_deg":0,"q5_deg":0,"q6_deg":0,"l1_mm":800,"l2_mm":800,"l3_mm":800,"l4_mm":800}]"#;
    refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/poses")))
            .header("content-type", "application/json")
            .body(twice),
        422,
        "invalid_input",
        Some("q1_deg"),
        Some(1),
    )
    .await;
    // A number past f64.
    let e = refused(
        &app,
        c.post(app.url("/rigs"))
            .header("content-type", "application/json")
            .body(r#"{"anchors_mm": [[0, 0, 0], [0, 900, 0], [1e999, 0, 0]], "r_mm": 35}"#),
        422,
        "invalid_input",
        None,
        None,
    )
    .await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .starts_with("not a finite number"),
        "{e}"
    );
    // Two strings from one anchor; strings without r_mm; a negative r_mm.
    refused(
        &app,
        c.post(app.url("/rigs")).json(
            &json!({"anchors_mm": [[0, 0, 0], [0, 900, 0], [1200, 0, 0], [0, 0, 0]], "r_mm": 35}),
        ),
        422,
        "invalid_input",
        Some("anchors_mm[3]"),
        None,
    )
    .await;
    let e = refused(
        &app,
        c.post(app.url("/rigs"))
            .json(&json!({"anchors_mm": [[0, 0, 0], [0, 900, 0], [1200, 0, 0]]})),
        422,
        "invalid_input",
        Some("r_mm"),
        None,
    )
    .await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("missing field `r_mm`"),
        "{e}"
    );
    refused(
        &app,
        c.post(app.url("/rigs"))
            .json(&json!({"anchors_mm": [[0, 0, 0], [0, 900, 0], [1200, 0, 0]], "r_mm": -35})),
        422,
        "invalid_input",
        Some("r_mm"),
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/rigs"))
            .header("content-type", "application/json")
            .body("[1,2"),
        400,
        "malformed_json",
        None,
        None,
    )
    .await;
    // Sessions with unknown robot or rig.
    refused(
        &app,
        c.post(app.url("/sessions"))
            .json(&json!({"robot_id": 999, "rig_id": rig_id})),
        422,
        "invalid_input",
        Some("robot_id"),
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/sessions"))
            .json(&json!({"robot_id": robot_id, "rig_id": 999})),
        422,
        "invalid_input",
        Some("rig_id"),
        None,
    )
    .await;

    // Unknown ids in paths, and ids that are not ids.
    for path in [
        "/models/999",
        "/robots/999",
        "/rigs/999",
        "/sessions/999",
        "/jobs/999",
        "/calibrations/999",
        "/robots/999/accuracy",
        "/robots/999/activations",
        "/sessions/999/poses",
    ] {
        err_json(c.get(app.url(path)).send().await.unwrap(), 404, "not_found").await;
    }
    refused(
        &app,
        c.get(app.url("/robots/abc")),
        400,
        "bad_request",
        None,
        None,
    )
    .await;
    // `+1` is not the id 1.
    refused(
        &app,
        c.get(app.url("/sessions/+1")),
        400,
        "bad_request",
        None,
        None,
    )
    .await;

    // A NUL character in any text is refused naming the field (PostgreSQL
    // refuses it in text, SQLite would store it): a serial number, a
    // session name, a pose id, a filter.
    let nul = "A\u{0}B";
    refused(
        &app,
        c.post(app.url("/robots"))
            .json(&json!({"serial_number": nul, "model_id": model_id})),
        422,
        "invalid_input",
        Some("serial_number"),
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/sessions"))
            .json(&json!({"robot_id": robot_id, "rig_id": rig_id, "name": nul})),
        422,
        "invalid_input",
        Some("name"),
        None,
    )
    .await;
    let mut with_nul = lines[..1].to_vec();
    let row = lines[30].replacen(',', "\u{0},", 1);
    with_nul.push(&row);
    let e = refused(
        &app,
        upload(with_nul.join("\n")),
        422,
        "invalid_input",
        Some("pose"),
        Some(1),
    )
    .await;
    assert!(e["message"].as_str().unwrap().contains("NUL"), "{e}");
    // Other control characters alike: a line break or a bell in a serial
    // number (a forged line in a log or an export), a tab in a filter.
    for control in ["A\nB", "A\u{7}B", "A\u{9b}B"] {
        refused(
            &app,
            c.post(app.url("/robots"))
                .json(&json!({"serial_number": control, "model_id": model_id})),
            422,
            "invalid_input",
            Some("serial_number"),
            None,
        )
        .await;
    }
    refused(
        &app,
        c.get(app.url("/calibrations?site=plant%091")),
        422,
        "invalid_input",
        Some("site"),
        None,
    )
    .await;
    refused(
        &app,
        c.get(app.url("/calibrations?site=plant%001")),
        422,
        "invalid_input",
        Some("site"),
        None,
    )
    .await;
    refused(
        &app,
        upload(poses.clone())
            .try_clone()
            .unwrap()
            .url_replace(&app, "/sessions/999/poses"),
        404,
        "not_found",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/jobs/999/cancel")),
        404,
        "not_found",
        None,
        None,
    )
    .await;
    // Bad queries.
    refused(
        &app,
        c.get(app.url("/robots?limit=0")),
        422,
        "invalid_input",
        Some("limit"),
        None,
    )
    .await;
    refused(
        &app,
        c.get(app.url("/robots?limit=ten")),
        400,
        "bad_request",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.get(app.url("/calibrations?from=last-week")),
        422,
        "invalid_input",
        Some("from"),
        None,
    )
    .await;
    // A day that does not exist is refused, not silently rolled over.
    refused(
        &app,
        c.get(app.url("/calibrations?to=2026-02-30")),
        422,
        "invalid_input",
        Some("to"),
        None,
    )
    .await;
    refused(
        &app,
        c.get(app.url("/jobs?state=sleeping")),
        422,
        "invalid_input",
        Some("state"),
        None,
    )
    .await;

    // CSV uploads with a bad row: nothing of the upload is stored, and the
    // answer names row (1-based in the upload) and column.
    let header = lines[0];
    let mut bad = vec![header.to_string()];
    bad.extend(lines[26..30].iter().map(|s| s.to_string()));
    bad.push(lines[30].replacen(',', ",abc", 2).replacen(",abc", ",", 1)); // q2_deg becomes "abc..."
    refused(
        &app,
        upload(bad.join("\n")),
        422,
        "invalid_input",
        Some("q2_deg"),
        Some(5),
    )
    .await;
    // A missing joint column.
    let cut: Vec<String> = lines[26..28]
        .iter()
        .map(|l| {
            l.split(',')
                .enumerate()
                .filter(|(i, _)| *i != 6)
                .map(|(_, v)| v)
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect();
    let cut_header = header
        .split(',')
        .enumerate()
        .filter(|(i, _)| *i != 6)
        .map(|(_, v)| v)
        .collect::<Vec<_>>()
        .join(",");
    refused(
        &app,
        upload(format!("{cut_header}\n{}", cut.join("\n"))),
        422,
        "invalid_input",
        Some("header"),
        None,
    )
    .await;
    // A duplicate pose id already stored in an earlier batch.
    refused(
        &app,
        upload(format!("{header}\n{}\n{}", lines[27], lines[5])),
        422,
        "invalid_input",
        Some("pose"),
        Some(2),
    )
    .await;
    // Rows with a cell too few or too many, and text that is not UTF-8, in
    // a later batch: the row in this upload, no column, nothing stored (a
    // short row used to be padded with empty cells and accepted).
    let short = lines[30].rsplit_once(',').unwrap().0.to_string();
    let long = format!("{},extra", lines[30]);
    let batch = |last: &str| {
        let mut b = vec![header.to_string()];
        b.extend(lines[26..30].iter().map(|s| s.to_string()));
        b.push(last.to_string());
        b.join("\n")
    };
    for (last, cells) in [(&short, 13), (&long, 15)] {
        let e = refused(
            &app,
            upload(batch(last)),
            422,
            "invalid_input",
            None,
            Some(5),
        )
        .await;
        assert!(e.get("field").is_none(), "no one column is at fault: {e}");
        assert_eq!(
            e["message"],
            format!("{cells} cells where the header has 14 columns"),
            "{e}"
        );
    }
    let mut latin1 = format!("{header}\n{}\n", lines[26]).into_bytes();
    latin1.extend_from_slice(lines[27].replacen(',', ",\u{1}", 1).as_bytes());
    let at = latin1.iter().rposition(|&b| b == 1).unwrap();
    latin1[at] = 0xb0; // a Latin-1 degree sign
    let e = refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/poses")))
            .header("content-type", "text/csv")
            .body(latin1),
        422,
        "invalid_input",
        Some("q1_deg"),
        Some(2),
    )
    .await;
    assert!(e["message"].as_str().unwrap().contains("UTF-8"), "{e}");
    // A semicolon-separated export (decimal commas): told to use commas.
    let semi = [header, lines[26], lines[27]]
        .map(|l| l.replace(',', ";").replace('.', ","))
        .join("\n");
    let e = refused(
        &app,
        upload(semi),
        422,
        "invalid_input",
        Some("header"),
        None,
    )
    .await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("must be comma-separated"),
        "{e}"
    );
    // The same short row as the first upload of a new session (it used to
    // answer 500): 422 naming the row; the session stays empty.
    let fresh = ok_json(
        c.post(app.url("/sessions"))
            .json(&json!({"robot_id": robot_id, "rig_id": rig_id}))
            .send()
            .await
            .unwrap(),
        201,
    )
    .await;
    let fresh_id = fresh["id"].as_i64().unwrap();
    let e = refused(
        &app,
        c.post(app.url(&format!("/sessions/{fresh_id}/poses")))
            .header("content-type", "text/csv")
            .body(batch(&short)),
        422,
        "invalid_input",
        None,
        Some(5),
    )
    .await;
    assert_eq!(
        e["message"], "13 cells where the header has 14 columns",
        "{e}"
    );
    let s = ok_json(app.get(&format!("/sessions/{fresh_id}")).await, 200).await;
    assert_eq!(s["n_poses"], 0, "{s}");
    // Empty upload, wrong media type, JSON that is not an array, JSON with a nested value.
    refused(
        &app,
        upload(header.to_string()),
        422,
        "invalid_input",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/poses")))
            .header("content-type", "text/plain")
            .body(poses.clone()),
        415,
        "unsupported_media_type",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/poses")))
            .json(&json!({"pose": "x"})),
        422,
        "invalid_input",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/poses")))
            .json(&json!([{"pose": "x", "q1_deg": [1, 2]}])),
        422,
        "invalid_input",
        Some("q1_deg"),
        Some(1),
    )
    .await;
    // Oversized body (the limit here is 64 KiB).
    let big = format!(
        "{header}\n{}",
        lines[26..]
            .iter()
            .cycle()
            .take(2000)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
    assert!(big.len() > 64 * 1024);
    // (`connection: close`: the server answers 413 before reading the whole
    // body and drops the connection; the client must not pool it.)
    let e = refused(
        &app,
        upload(big).header("connection", "close"),
        413,
        "payload_too_large",
        None,
        None,
    )
    .await;
    // The answer says the limit and how to raise it.
    let m = e["message"].as_str().unwrap();
    assert!(
        m.contains("65536 bytes (64 KiB)")
            && m.contains("--max-upload-bytes")
            && m.contains("DRAWCAL_MAX_UPLOAD_BYTES")
            && m.contains("poses in several batches"),
        "{e}"
    );

    // Bad job options.
    refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/jobs")))
            .json(&json!({"holdout_fraction": 2.0})),
        422,
        "invalid_input",
        Some("holdout_fraction"),
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/jobs")))
            .json(&json!({"undetermined_z": -1.0})),
        422,
        "invalid_input",
        Some("undetermined_z"),
        None,
    )
    .await;
    // A smaller free set is not for the paper's one-step method; an
    // unknown set is refused.
    refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/jobs")))
            .json(&json!({"free_set": "offsets", "method": "paper"})),
        422,
        "invalid_input",
        Some("free_set"),
        None,
    )
    .await;
    let r = c
        .post(app.url(&format!("/sessions/{sid}/jobs")))
        .json(&json!({"free_set": "twists"}))
        .send()
        .await
        .unwrap();
    assert!(r.status().is_client_error(), "{}", r.status());
    // Held parameters must name this robot's joints, checked at once.
    for hold in ["j9.a", "base.x"] {
        refused(
            &app,
            c.post(app.url(&format!("/sessions/{sid}/jobs")))
                .json(&json!({"hold": [hold]})),
            422,
            "invalid_input",
            Some("hold"),
            None,
        )
        .await;
    }
    refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/jobs")))
            .json(&json!({"method": "magic"})),
        422,
        "invalid_input",
        Some("method"),
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/jobs")))
            .header("content-type", "application/json")
            .body("{"),
        400,
        "malformed_json",
        None,
        None,
    )
    .await;
    // An array is not the options object (serde alone took `[]`).
    let e = refused(
        &app,
        c.post(app.url(&format!("/sessions/{sid}/jobs")))
            .json(&json!([])),
        422,
        "invalid_input",
        None,
        None,
    )
    .await;
    assert!(
        e["message"].as_str().unwrap().contains("not an array"),
        "{e}"
    );

    // Activation and compensation without a calibration.
    refused(
        &app,
        c.post(app.url(&format!("/robots/{robot_id}/activate")))
            .json(&json!({"calibration_id": 77, "reason": "why not"})),
        422,
        "invalid_input",
        Some("calibration_id"),
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url(&format!("/robots/{robot_id}/activate")))
            .json(&json!({"calibration_id": 77, "by": "someone else", "reason": "r"})),
        422,
        "invalid_input",
        Some("by"),
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url(&format!("/robots/{robot_id}/rollback")))
            .json(&json!({"reason": "r"})),
        409,
        "conflict",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/compensate")).json(
            &json!({"robot_id": robot_id, "target": {"target": "t", "q_deg": [0, 0, 0, 0, 0, 0]}}),
        ),
        409,
        "conflict",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/compensate")).json(
            &json!({"robot_id": 999, "target": {"target": "t", "q_deg": [0, 0, 0, 0, 0, 0]}}),
        ),
        404,
        "not_found",
        None,
        None,
    )
    .await;
    refused(
        &app,
        c.post(app.url("/compensate"))
            .json(&json!({"robot_id": robot_id})),
        422,
        "invalid_input",
        Some("targets"),
        None,
    )
    .await;
    let many: Vec<Value> = (0..10_001)
        .map(|i| json!({"target": i.to_string(), "q_deg": [0, 0, 0, 0, 0, 0]}))
        .collect();
    let big_app_req = c
        .post(app.url("/compensate"))
        .header("connection", "close")
        .json(&json!({"robot_id": robot_id, "targets": many}));
    // (over 64 KiB: the body limit answers first; the advice fits the route)
    let e = refused(&app, big_app_req, 413, "payload_too_large", None, None).await;
    let m = e["message"].as_str().unwrap();
    assert!(m.contains("targets over several requests"), "{m}");

    // The session still holds exactly the first batch.
    let s = ok_json(app.get(&format!("/sessions/{sid}")).await, 200).await;
    assert_eq!(s["n_poses"], 25);
    assert_eq!(s["n_batches"], 1);
    app.stop().await;
}

trait UrlReplace {
    fn url_replace(self, app: &TestApp, path: &str) -> reqwest::RequestBuilder;
}

impl UrlReplace for reqwest::RequestBuilder {
    fn url_replace(self, app: &TestApp, path: &str) -> reqwest::RequestBuilder {
        let req = self.build().unwrap();
        let body = req
            .body()
            .and_then(|b| b.as_bytes())
            .map(|b| b.to_vec())
            .unwrap_or_default();
        let ct = req.headers().get("content-type").cloned();
        let mut r = app.client.post(app.url(path)).body(body);
        if let Some(ct) = ct {
            r = r.header("content-type", ct);
        }
        r
    }
}

/// A JSON file saved with a byte-order mark (Windows editors add one) is
/// read as the document it is, not refused as malformed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn json_with_a_byte_order_mark_is_read() {
    let app = TestApp::spawn("bom").await;
    let mut body = b"\xEF\xBB\xBF".to_vec();
    body.extend_from_slice(read(DS, "rig.json").as_bytes());
    let rig = ok_json(
        app.client
            .post(app.url("/rigs"))
            .header("content-type", "application/json")
            .body(body)
            .send()
            .await
            .unwrap(),
        201,
    )
    .await;
    assert_eq!(rig["n_strings"], 4, "{rig}");
    app.stop().await;
}

/// A rig stored by an earlier version that today's checks refuse (here a
/// negative `r_mm`, written straight into the store): uploads to its
/// session answer 409 naming the rig and what to do, not a 500.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stored_rig_that_no_longer_validates_is_a_conflict() {
    let app = TestApp::spawn("stalerig").await;
    let (_, robot_id, _, _) = app.setup(DS, "STALE-1").await;
    let store = drawcal::store::Store::connect(&app.db_url).await.unwrap();
    let bad = read(DS, "rig.json").replace("\"r_mm\": 35.0", "\"r_mm\": -35.0");
    assert!(bad.contains("-35.0"));
    let rig = store.create_rig("old rig", 4, &bad).await.unwrap();
    let session = ok_json(
        app.post_json(
            "/sessions",
            &json!({"robot_id": robot_id, "rig_id": rig.id}),
        )
        .await,
        201,
    )
    .await;
    let sid = session["id"].as_i64().unwrap();
    let e = err_json(
        app.post_raw(
            &format!("/sessions/{sid}/poses"),
            Some("text/csv"),
            read(DS, "poses.csv"),
        )
        .await,
        409,
        "conflict",
    )
    .await;
    let m = e["message"].as_str().unwrap();
    assert!(
        m.contains(&format!("stored rig {}", rig.id)) && m.contains("r_mm"),
        "{e}"
    );
    app.stop().await;
}

/// A stored rig or robot model gone stale under a session whose poses were
/// stored while it was valid: enqueueing a job answers 409 at once (not a
/// job that fails in the worker), and no job is stored.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_on_a_stale_rig_or_model_is_refused_when_enqueued() {
    for (what, file, from, to) in [
        ("rig", "rig.json", "\"r_mm\": 35.0", "\"r_mm\": -35.0"),
        (
            "robot model",
            "robot.json",
            "\"q_min_deg\": -170.0",
            "\"q_min_deg\": 200.0",
        ),
    ] {
        let app = TestApp::spawn("stalejob").await;
        let (model_id, _, rig_id, sid) = app.setup(DS, "STALE-2").await;
        ok_json(
            app.post_raw(
                &format!("/sessions/{sid}/poses"),
                Some("text/csv"),
                read(DS, "poses.csv"),
            )
            .await,
            200,
        )
        .await;
        let bad = read(DS, file).replacen(from, to, 1);
        assert_ne!(bad, read(DS, file));
        let (sql, id) = if what == "rig" {
            ("UPDATE rigs SET rig_json = $1 WHERE id = $2", rig_id)
        } else {
            (
                "UPDATE robot_models SET robot_json = $1 WHERE id = $2",
                model_id,
            )
        };
        let pool = sqlx::SqlitePool::connect(&app.db_url).await.unwrap();
        sqlx::query(sql)
            .bind(&bad)
            .bind(id)
            .execute(&pool)
            .await
            .unwrap();
        let e = err_json(
            app.post_json(&format!("/sessions/{sid}/jobs"), &json!({}))
                .await,
            409,
            "conflict",
        )
        .await;
        let m = e["message"].as_str().unwrap();
        assert!(m.contains(&format!("stored {what} {id}")), "{e}");
        let jobs = ok_json(app.get(&format!("/jobs?session_id={sid}")).await, 200).await;
        assert_eq!(jobs["total"], 0, "{jobs}");
        app.stop().await;
    }
}
