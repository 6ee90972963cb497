//! The handlers hold to what openapi.yaml declares (issue 21, item 6; the
//! schema-driven run is tests/api/schemathesis.sh): lengths are counted in
//! characters as JSON Schema counts them, control characters are refused in
//! query strings as in bodies (C1 too), an object is refused as an array
//! at any depth, and an integer may be written `1.0`.

use serde_json::{Value, json};

use crate::helpers::{TestApp, err_json, ok_json};

const DS: &str = "er3a_paper_like";

/// `maxLength` counts characters: a text of the limit in two-byte
/// characters is accepted, one more refused naming the field.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn text_limits_count_characters_not_bytes() {
    let app = TestApp::spawn("chars").await;
    let (model_id, robot_id, rig_id, _) = app.setup(DS, "CHARS-1").await;
    let e = |n: usize| "é".repeat(n);

    // serial_number and the tags: 100 characters (200 bytes) taken.
    let r = ok_json(
        app.post_json(
            "/robots",
            &json!({"serial_number": e(100), "model_id": model_id, "site": e(100), "line": e(100), "cell": e(100)}),
        )
        .await,
        201,
    )
    .await;
    assert_eq!(r["serial_number"], e(100));
    for (field, body) in [
        (
            "serial_number",
            json!({"serial_number": e(101), "model_id": model_id}),
        ),
        (
            "site",
            json!({"serial_number": "CHARS-2", "model_id": model_id, "site": e(101)}),
        ),
    ] {
        let v = err_json(app.post_json("/robots", &body).await, 422, "invalid_input").await;
        assert_eq!(v["field"], field, "{v}");
    }
    // A blank serial number is refused; the limit is on what is sent.
    for serial in ["   ".to_string(), format!("  {}", "a".repeat(99))] {
        let v = err_json(
            app.post_json(
                "/robots",
                &json!({"serial_number": serial, "model_id": model_id}),
            )
            .await,
            422,
            "invalid_input",
        )
        .await;
        assert_eq!(v["field"], "serial_number", "{v}");
    }

    // A session's name: 200 characters.
    ok_json(
        app.post_json(
            "/sessions",
            &json!({"robot_id": robot_id, "rig_id": rig_id, "name": e(200)}),
        )
        .await,
        201,
    )
    .await;
    let v = err_json(
        app.post_json(
            "/sessions",
            &json!({"robot_id": robot_id, "rig_id": rig_id, "name": e(201)}),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(v["field"], "name", "{v}");

    // A model's name in the query string: 200 characters.
    let robot_json = crate::helpers::read(DS, "robot.json");
    let name = |n: usize| "%C3%A9".repeat(n);
    ok_json(
        app.post_raw(
            &format!("/models?name={}", name(200)),
            Some("application/json"),
            robot_json.clone(),
        )
        .await,
        201,
    )
    .await;
    let v = err_json(
        app.post_raw(
            &format!("/models?name={}", name(201)),
            Some("application/json"),
            robot_json,
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(v["field"], "name", "{v}");

    // A key's name and sites: 100 characters as sent, not blank.
    let k = ok_json(
        app.post_json(
            "/keys",
            &json!({"name": e(100), "role": "reader", "sites": [e(100)]}),
        )
        .await,
        201,
    )
    .await;
    assert_eq!(k["key"]["name"], e(100));
    for (field, body) in [
        ("name", json!({"name": e(101), "role": "reader"})),
        (
            "name",
            json!({"name": format!(" {}", "k".repeat(100)), "role": "reader"}),
        ),
        ("name", json!({"name": " \u{3000} ", "role": "reader"})),
        (
            "sites",
            json!({"name": "k-sites", "role": "reader", "sites": [e(101)]}),
        ),
    ] {
        let v = err_json(app.post_json("/keys", &body).await, 422, "invalid_input").await;
        assert_eq!(v["field"], field, "{body}: {v}");
    }
    app.stop().await;
}

/// A C1 control character (U+0080-U+009F) in a query string is refused
/// as in a JSON body, naming the parameter; other non-ASCII text is not.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn c1_control_characters_in_query_strings_are_refused() {
    let app = TestApp::spawn("c1query").await;
    app.setup(DS, "C1-1").await;
    for (path, field) in [
        ("/robots?site=%C2%84", "site"),
        ("/calibrations?line=plant%C2%9F", "line"),
        ("/robots?site=plant-1&line=%c2%80", "line"),
        ("/calibrations?site=%00", "site"),
    ] {
        let v = err_json(app.get(path).await, 422, "invalid_input").await;
        assert_eq!(v["field"], field, "{path}: {v}");
        assert!(
            v["message"].as_str().unwrap().contains("control character"),
            "{v}"
        );
    }
    // No-break space (U+00A0, %C2%A0) and é are text.
    for path in ["/robots?site=plant%C2%A01", "/calibrations?site=%C3%A9"] {
        let v = ok_json(app.get(path).await, 200).await;
        assert_eq!(v["total"], 0, "{path}: {v}");
    }
    // A model's name (a stored text) too.
    let v = err_json(
        app.post_raw(
            "/models?name=a%C2%85b",
            Some("application/json"),
            crate::helpers::read(DS, "robot.json"),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(v["field"], "name", "{v}");
    app.stop().await;
}

/// serde reads a struct from an array (`["SN", 1]` as the fields in
/// order): a body documented as an object is refused as an array, and
/// nothing is stored.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn object_bodies_given_as_arrays_are_refused() {
    let app = TestApp::spawn("arrays").await;
    let (model_id, robot_id, _, _) = app.setup(DS, "ARR-1").await;
    let before = app.snapshot().await;
    let keys_before = ok_json(app.get("/keys").await, 200).await;
    for (path, body) in [
        ("/robots", json!(["ARR-2", model_id])),
        ("/models", json!([])),
        ("/rigs", json!([])),
        ("/keys", json!(["someone", "admin"])),
        ("/sessions", json!([robot_id, 1])),
        ("/compensate", json!([robot_id])),
        (
            &format!("/robots/{robot_id}/rollback") as &str,
            json!(["why"]),
        ),
    ] {
        let v: Value = err_json(app.post_json(path, &body).await, 422, "invalid_input").await;
        assert!(
            v["message"].as_str().unwrap().contains("not an array"),
            "{path}: {v}"
        );
    }
    // Nested: a rig's sensor, a compensation target, a plan's box.
    let rig = json!({"anchors_mm": [[0, 0, 0], [1500, 0, 0], [0, 1500, 0]], "r_mm": 35, "sensor": [null, null]});
    let v = err_json(app.post_json("/rigs", &rig).await, 422, "invalid_input").await;
    assert_eq!(v["field"], "sensor", "{v}");
    let target = json!({"robot_id": robot_id, "targets": [["t1", [0, 0, 0, 0, 0, 0]]]});
    let v = err_json(
        app.post_json("/compensate", &target).await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(v["field"], "targets[0]", "{v}");
    assert_eq!(app.snapshot().await, before);
    assert_eq!(ok_json(app.get("/keys").await, 200).await, keys_before);
    app.stop().await;
}

/// JSON Schema's `integer` is any number without a fraction (`1.0`): an
/// integer field takes it; `1.5` is still refused naming the field.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_integral_number_is_an_integer() {
    let app = TestApp::spawn("integral").await;
    let (_, robot_id, rig_id, _) = app.setup(DS, "INT-1").await;
    let s = ok_json(
        app.post_json(
            "/sessions",
            &json!({"robot_id": robot_id as f64, "rig_id": rig_id as f64}),
        )
        .await,
        201,
    )
    .await;
    assert_eq!(s["robot_id"], robot_id);
    let v = err_json(
        app.post_json(
            "/sessions",
            &json!({"robot_id": robot_id as f64 + 0.5, "rig_id": rig_id}),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(v["field"], "robot_id", "{v}");
    app.stop().await;
}

/// `limit` and `offset` are checked with `format=csv` too (the CSV has
/// every match, but the spec bounds them whatever the format).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn page_bounds_hold_for_csv_lists_too() {
    let app = TestApp::spawn("csvpage").await;
    for (path, field) in [
        ("/calibrations?format=csv&offset=-1", "offset"),
        ("/calibrations?format=csv&limit=0", "limit"),
        ("/audit?format=csv&offset=-34359738368", "offset"),
        ("/audit?format=csv&limit=1001", "limit"),
    ] {
        let v = err_json(app.get(path).await, 422, "invalid_input").await;
        assert_eq!(v["field"], field, "{path}: {v}");
    }
    for path in [
        "/calibrations?format=csv&limit=1000&offset=0",
        "/audit?format=csv",
    ] {
        let r = app.get(path).await;
        assert_eq!(r.status(), 200, "{path}");
    }
    app.stop().await;
}
