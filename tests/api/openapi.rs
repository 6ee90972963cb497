//! openapi.yaml against the router and against real responses.

use std::collections::BTreeSet;

use serde_json::Value;

use crate::helpers::TestApp;

fn spec() -> Value {
    serde_json::to_value(drawcal::http::openapi()).expect("spec to JSON")
}

/// The committed file is what the handlers generate. Regenerate with
/// `UPDATE_OPENAPI=1 cargo test --test api openapi`.
#[test]
fn committed_openapi_yaml_matches_the_router() {
    let generated = drawcal::http::openapi_yaml();
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/openapi.yaml");
    if std::env::var_os("UPDATE_OPENAPI").is_some() {
        std::fs::write(path, &generated).expect("write openapi.yaml");
    }
    let committed = std::fs::read_to_string(path).expect("openapi.yaml at the top level");
    assert!(
        committed == generated,
        "openapi.yaml is stale: regenerate with UPDATE_OPENAPI=1 cargo test --test api openapi"
    );
}

/// Every `$ref` of the spec resolves, as a JSON pointer into the document
/// (a generated client fails on one that does not).
#[test]
fn every_reference_resolves() {
    fn refs<'a>(v: &'a Value, out: &mut Vec<&'a str>) {
        match v {
            Value::Object(m) => {
                if let Some(Value::String(r)) = m.get("$ref") {
                    out.push(r);
                }
                m.values().for_each(|x| refs(x, out));
            }
            Value::Array(a) => a.iter().for_each(|x| refs(x, out)),
            _ => {}
        }
    }
    let spec = spec();
    let mut all = Vec::new();
    refs(&spec, &mut all);
    assert!(!all.is_empty());
    let dangling: BTreeSet<&str> = all
        .into_iter()
        .filter(|r| {
            r.strip_prefix('#')
                .and_then(|p| spec.pointer(&p.replace("~1", "/").replace("~0", "~")))
                .is_none()
        })
        .collect();
    assert!(dangling.is_empty(), "undefined: {dangling:?}");
}

/// The document has the structure OpenAPI 3.1 requires, and what this
/// service promises of it: every path parameter declared, required and
/// typed; every parameter with a name, a place and a schema; every body
/// with a content type; every answer described, its errors in the error
/// shape; operation ids unique; security naming the bearer scheme; each
/// operation's role declared (`x-required-role`) and the public ones
/// without security.
#[test]
fn the_spec_is_structurally_valid() {
    let spec = spec();
    let mut problems = Vec::new();
    assert!(
        spec["openapi"]
            .as_str()
            .is_some_and(|v| v.starts_with("3.1.")),
        "{}",
        spec["openapi"]
    );
    assert!(spec["info"]["title"].is_string() && spec["info"]["version"].is_string());
    let scheme = &spec["components"]["securitySchemes"]["api_key"];
    assert_eq!(scheme["type"], "http", "{scheme}");
    assert_eq!(scheme["scheme"], "bearer", "{scheme}");
    assert_eq!(spec["security"], serde_json::json!([{"api_key": []}]));
    let mut ids = BTreeSet::new();
    for (path, item) in spec["paths"].as_object().expect("paths") {
        assert!(path.starts_with('/'), "{path}");
        let templated: BTreeSet<&str> = path
            .split('/')
            .filter_map(|seg| seg.strip_prefix('{').and_then(|s| s.strip_suffix('}')))
            .collect();
        for (method, op) in item.as_object().unwrap() {
            let at = format!("{method} {path}");
            if !["get", "post", "put", "patch", "delete"].contains(&method.as_str()) {
                problems.push(format!("{at}: not an operation"));
                continue;
            }
            match op["operationId"].as_str() {
                Some(id) if ids.insert(id.to_string()) => {}
                other => problems.push(format!("{at}: operationId {other:?} missing or repeated")),
            }
            let mut in_path = BTreeSet::new();
            for p in op["parameters"].as_array().into_iter().flatten() {
                let (Some(name), Some(place)) = (p["name"].as_str(), p["in"].as_str()) else {
                    problems.push(format!("{at}: parameter without name or in: {p}"));
                    continue;
                };
                if !["path", "query", "header", "cookie"].contains(&place) {
                    problems.push(format!("{at}: parameter {name} in {place}"));
                }
                if !p["schema"].is_object() {
                    problems.push(format!("{at}: parameter {name} without a schema"));
                }
                if place == "path" {
                    in_path.insert(name);
                    if p["required"] != true {
                        problems.push(format!("{at}: path parameter {name} not required"));
                    }
                }
            }
            if in_path != templated {
                problems.push(format!(
                    "{at}: path parameters {in_path:?} for {templated:?}"
                ));
            }
            if let Some(body) = op.get("requestBody") {
                let content = body["content"].as_object();
                if content.is_none_or(|c| c.is_empty()) {
                    problems.push(format!("{at}: request body without content"));
                }
                for (ct, media) in content.into_iter().flatten() {
                    if !media["schema"].is_object() {
                        problems.push(format!("{at}: request body {ct} without a schema"));
                    }
                }
            }
            let responses = op["responses"].as_object();
            if responses.is_none_or(|r| r.is_empty()) {
                problems.push(format!("{at}: no responses"));
            }
            for (status, resp) in responses.into_iter().flatten() {
                if !(status.len() == 3
                    && status.parse::<u16>().is_ok_and(|s| (100..600).contains(&s)))
                {
                    problems.push(format!("{at}: status {status}"));
                }
                if !resp["description"].is_string() {
                    problems.push(format!("{at} {status}: no description"));
                }
                if status.starts_with('4') || status.starts_with('5') {
                    let schema = &resp["content"]["application/json"]["schema"];
                    if schema["$ref"] != "#/components/schemas/ErrorBody" {
                        problems.push(format!("{at} {status}: not the error shape: {schema}"));
                    }
                }
            }
            let role = op["x-required-role"].as_str();
            let public = role == Some("none");
            match role {
                Some("none" | "reader" | "operator" | "engineer" | "admin") => {}
                other => problems.push(format!("{at}: x-required-role {other:?}")),
            }
            if public != (op["security"] == serde_json::json!([{}])) {
                problems.push(format!(
                    "{at}: role {role:?} but security {}",
                    op["security"]
                ));
            }
            if !public && !op["responses"]["401"].is_object() {
                problems.push(format!("{at}: needs a key but documents no 401"));
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

fn resolve<'a>(spec: &'a Value, schema: &'a Value) -> &'a Value {
    match schema.get("$ref").and_then(Value::as_str) {
        Some(r) => {
            let name = r.trim_start_matches("#/components/schemas/");
            resolve(spec, &spec["components"]["schemas"][name])
        }
        None => schema,
    }
}

fn type_ok(t: &str, v: &Value) -> bool {
    match t {
        "null" => v.is_null(),
        "boolean" => v.is_boolean(),
        "integer" => v.is_i64() || v.is_u64(),
        "number" => v.is_number(),
        "string" => v.is_string(),
        "array" => v.is_array(),
        "object" => v.is_object(),
        _ => true,
    }
}

/// Validate `v` against an OpenAPI 3.1 schema (the subset utoipa emits:
/// $ref, type (string or list), properties, required, items, enum, allOf,
/// oneOf, anyOf, additionalProperties). Returns the first violation.
pub fn check(spec: &Value, schema: &Value, v: &Value, at: &str) -> Result<(), String> {
    let s = resolve(spec, schema);
    if let Some(all) = s.get("allOf").and_then(Value::as_array) {
        for sub in all {
            check(spec, sub, v, at)?;
        }
    }
    for key in ["oneOf", "anyOf"] {
        if let Some(alts) = s.get(key).and_then(Value::as_array) {
            let ok = alts
                .iter()
                .filter(|a| check(spec, a, v, at).is_ok())
                .count();
            if ok == 0 || (key == "oneOf" && ok > 1) {
                return Err(format!("{at}: {ok} alternatives of {key} match {v}"));
            }
        }
    }
    match s.get("type") {
        Some(Value::String(t)) if !type_ok(t, v) => {
            return Err(format!("{at}: expected {t}, got {v}"));
        }
        Some(Value::Array(ts)) if !ts.iter().any(|t| type_ok(t.as_str().unwrap_or(""), v)) => {
            return Err(format!("{at}: expected one of {ts:?}, got {v}"));
        }
        _ => {}
    }
    if let Some(e) = s.get("enum").and_then(Value::as_array) {
        if !e.contains(v) {
            return Err(format!("{at}: {v} not in {e:?}"));
        }
    }
    if let Value::Object(map) = v {
        let props = s.get("properties").and_then(Value::as_object);
        if let Some(req) = s.get("required").and_then(Value::as_array) {
            for r in req {
                let r = r.as_str().unwrap();
                if !map.contains_key(r) {
                    return Err(format!("{at}: missing required '{r}'"));
                }
            }
        }
        if let Some(props) = props {
            for (k, val) in map {
                match props.get(k) {
                    Some(ps) => check(spec, ps, val, &format!("{at}.{k}"))?,
                    None if s.get("additionalProperties") == Some(&Value::Bool(false)) => {
                        return Err(format!("{at}: undocumented property '{k}'"));
                    }
                    None if s.get("additionalProperties").is_none() && s.get("allOf").is_none() => {
                        return Err(format!("{at}: undocumented property '{k}'"));
                    }
                    None => {}
                }
            }
        }
    }
    if let (Value::Array(items), Some(is)) = (v, s.get("items")) {
        for (i, it) in items.iter().enumerate() {
            check(spec, is, it, &format!("{at}[{i}]"))?;
        }
    }
    Ok(())
}

/// `POST /compensate` with a JSON body: the answer, checked against
/// openapi.yaml (a 200 expected).
pub async fn compensate(app: &crate::helpers::TestApp, body: &Value) -> Value {
    validate_response(
        "post",
        "/compensate",
        app.post_json("/compensate", body).await,
    )
    .await
}

/// Check a live response against the spec's schema for its route and
/// status, and return the JSON body.
pub async fn validate_response(method: &str, path: &str, r: reqwest::Response) -> Value {
    let status = r.status().as_u16().to_string();
    let text = r.text().await.expect("body");
    let body: Value = serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("{method} {path}: not JSON ({e}): {text}"));
    let spec = spec();
    let op = &spec["paths"][path][method];
    assert!(op.is_object(), "{method} {path} is not in the spec");
    let resp = &op["responses"][&status];
    assert!(
        resp.is_object(),
        "{method} {path}: status {status} is not documented; body {text}"
    );
    let schema = &resp["content"]["application/json"]["schema"];
    assert!(
        schema.is_object(),
        "{method} {path} {status}: no JSON schema documented"
    );
    if let Err(e) = check(&spec, schema, &body, "$") {
        panic!("{method} {path} {status}: response does not match its schema: {e}\nbody: {text}");
    }
    body
}

/// Every documented route answers (no 404 "no such route", no 405), and
/// routes that are not documented do not exist.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_documented_route_exists_and_nothing_else() {
    let app = TestApp::spawn("routes").await;
    let spec = spec();
    let mut documented = BTreeSet::new();
    for (path, item) in spec["paths"].as_object().unwrap() {
        for method in item.as_object().unwrap().keys() {
            if !["get", "post", "put", "patch", "delete"].contains(&method.as_str()) {
                continue;
            }
            documented.insert((method.clone(), path.clone()));
            let url = app.url(&path.replace("{id}", "999999"));
            let req = match method.as_str() {
                "get" => app.client.get(url),
                "post" => app
                    .client
                    .post(url)
                    .header("content-type", "application/json")
                    .body("{}"),
                m => panic!("unexpected method {m}"),
            };
            let r = req.send().await.unwrap();
            let st = r.status().as_u16();
            let body: Value = r.json().await.unwrap_or(Value::Null);
            assert_ne!(st, 405, "{method} {path}: 405");
            assert!(
                !(st == 404 && body["message"] == "no such route"),
                "{method} {path}: documented but not routed"
            );
            // Every answer is documented, error or not.
            let st_s = st.to_string();
            assert!(
                spec["paths"][path][method]["responses"][&st_s].is_object(),
                "{method} {path}: answered {st} which is not documented ({body})"
            );
        }
    }
    assert!(
        documented.len() >= 25,
        "{} operations documented",
        documented.len()
    );
    // Methods and paths outside the spec are refused in the error shape.
    for (method, path, status) in [
        ("delete", "/robots", 405),
        ("put", "/compensate", 405),
        ("get", "/compensate", 405),
        ("get", "/nope", 404),
        ("get", "/robots/1/nope", 404),
    ] {
        assert!(!documented.contains(&(method.to_string(), path.to_string())));
        let r = app
            .client
            .request(
                reqwest::Method::from_bytes(method.to_uppercase().as_bytes()).unwrap(),
                app.url(path),
            )
            .send()
            .await
            .unwrap();
        assert_eq!(r.status().as_u16(), status, "{method} {path}");
        let v: Value = r.json().await.unwrap();
        assert!(v["error"].is_string(), "{v}");
    }
    app.stop().await;
}

/// Every schema a request body or parameter uses, `$ref`s followed, with
/// the path it was reached by.
fn request_schemas(spec: &Value) -> Vec<(String, Value)> {
    fn walk(
        spec: &Value,
        s: &Value,
        at: String,
        seen: &mut BTreeSet<String>,
        out: &mut Vec<(String, Value)>,
    ) {
        if let Some(r) = s["$ref"].as_str() {
            if seen.insert(r.to_string()) {
                let name = r.trim_start_matches("#/components/schemas/");
                walk(
                    spec,
                    &spec["components"]["schemas"][name],
                    format!("{at}->{name}"),
                    seen,
                    out,
                );
            }
            return;
        }
        out.push((at.clone(), s.clone()));
        for (k, p) in s["properties"].as_object().into_iter().flatten() {
            walk(spec, p, format!("{at}.{k}"), seen, out);
        }
        for key in ["items", "additionalProperties"] {
            if s[key].is_object() {
                walk(spec, &s[key], format!("{at}[{key}]"), seen, out);
            }
        }
        for key in ["oneOf", "anyOf", "allOf"] {
            for (i, x) in s[key].as_array().into_iter().flatten().enumerate() {
                walk(spec, x, format!("{at}.{key}[{i}]"), seen, out);
            }
        }
    }
    let mut out = Vec::new();
    for (path, item) in spec["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            let mut seen = BTreeSet::new();
            for p in op["parameters"].as_array().into_iter().flatten() {
                walk(
                    spec,
                    &p["schema"],
                    format!("{method} {path} ?{}", p["name"]),
                    &mut seen,
                    &mut out,
                );
            }
            let json = &op["requestBody"]["content"]["application/json"]["schema"];
            if json.is_object() {
                walk(
                    spec,
                    json,
                    format!("{method} {path} body"),
                    &mut seen,
                    &mut out,
                );
            }
        }
    }
    out
}

fn has_type(s: &Value, t: &str) -> bool {
    s["type"] == t
        || s["type"]
            .as_array()
            .is_some_and(|ts| ts.iter().any(|x| x == t))
}

/// What every handler enforces on input is declared (src/http/contract.rs):
/// every request text has a pattern (no control characters) or an enum,
/// every object that takes other keys constrains their names, every
/// integer has bounds within what serde reads (i64, u64), every path id
/// starts at 1, and a route with a query string or a body documents the
/// extractors' 400 and 422 (and 408, 413, 415 with a body).
#[test]
fn what_the_handlers_enforce_on_every_request_is_declared() {
    let spec = spec();
    let mut problems = Vec::new();
    let schemas = request_schemas(&spec);
    assert!(schemas.len() > 100, "{} request schemas", schemas.len());
    for (at, s) in &schemas {
        if has_type(s, "string") && !s["pattern"].is_string() && !s["enum"].is_array() {
            problems.push(format!("{at}: text without a pattern"));
        }
        let extras = s["additionalProperties"] != false;
        if has_type(s, "object") && extras && !s["propertyNames"]["pattern"].is_string() {
            problems.push(format!("{at}: object taking any key name"));
        }
        if has_type(s, "integer") {
            let min = s["minimum"].as_f64().or(s["exclusiveMinimum"].as_f64());
            let max = s["maximum"].as_f64().or(s["exclusiveMaximum"].as_f64());
            if !(min.is_some_and(|m| m >= i64::MIN as f64)
                && max.is_some_and(|m| m <= u64::MAX as f64))
            {
                problems.push(format!("{at}: integer without bounds ({s})"));
            }
        }
    }
    for (path, item) in spec["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            let at = format!("{method} {path}");
            let params = op["parameters"].as_array().cloned().unwrap_or_default();
            for p in params
                .iter()
                .filter(|p| p["in"] == "path" && p["name"] == "id")
            {
                if p["schema"]["minimum"] != 1 || p["schema"]["maximum"] != i64::MAX {
                    problems.push(format!("{at}: path id {}", p["schema"]));
                }
            }
            let query = params.iter().any(|p| p["in"] == "query");
            let body = op["requestBody"].is_object();
            let mut needed = Vec::new();
            if query || body {
                needed.extend(["400", "422"]);
            }
            if body {
                needed.extend(["408", "413", "415"]);
            }
            for status in needed {
                if !op["responses"][status].is_object() {
                    problems.push(format!("{at}: {status} not documented"));
                }
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The declared patterns accept exactly what the handlers take: text
/// without a control character (`char::is_control`), not blank once
/// trimmed, a date or UTC time as `normalize_bound` reads it.
#[test]
fn the_declared_patterns_say_what_the_handlers_check() {
    use drawcal::http::contract::{
        DATE_OR_TIME_PATTERN, NON_BLANK_PATTERN, SITE_PATTERN, TEXT_PATTERN,
    };
    use drawcal::store::time::normalize_bound;
    let text = regex::Regex::new(TEXT_PATTERN).unwrap();
    let non_blank = regex::Regex::new(NON_BLANK_PATTERN).unwrap();
    let site = regex::Regex::new(SITE_PATTERN).unwrap();
    for c in (0u32..0x3100).filter_map(char::from_u32) {
        for s in [format!("a{c}b"), c.to_string(), format!(" {c} ")] {
            let control = s.chars().any(char::is_control);
            let blank = s.trim().is_empty();
            assert_eq!(text.is_match(&s), !control, "{s:?}");
            assert_eq!(non_blank.is_match(&s), !control && !blank, "{s:?}");
            assert_eq!(
                site.is_match(&s),
                !control && !blank && !s.contains(','),
                "{s:?}"
            );
        }
    }
    assert!(text.is_match("") && !non_blank.is_match(""));
    let date = regex::Regex::new(DATE_OR_TIME_PATTERN).unwrap();
    let mut n = 0;
    for y in [0, 4, 100, 400, 1900, 1999, 2000, 2023, 2024, 2100, 9999] {
        for m in 0..=13 {
            for d in 0..=32 {
                let day = format!("{y:04}-{m:02}-{d:02}");
                for s in [
                    day.clone(),
                    format!("{day}T00:00:00Z"),
                    format!("{day}T23:59:59.999Z"),
                    format!("{day}T12:30:00.5Z"),
                    format!("{day}T24:00:00Z"),
                    format!("{day}T12:60:00Z"),
                    format!("{day}T12:00:00.Z"),
                    format!("{day}T12:00:00"),
                    format!("{day}T12:00Z"),
                    format!("{day} "),
                ] {
                    let takes = normalize_bound(&s, false).is_some();
                    assert_eq!(date.is_match(&s), takes, "{s}");
                    n += takes as usize;
                }
            }
        }
    }
    assert!(n > 10_000, "{n} accepted");
    for s in [
        "",
        "2024-1-01",
        "20240101",
        "2024-01-01T12:00:00+01:00",
        "x2024-01-01",
    ] {
        assert!(
            !date.is_match(s) && normalize_bound(s, false).is_none(),
            "{s}"
        );
    }
}

/// robot.json and rig.json as the data sets have them are what the spec's
/// RobotJson and RigJson describe (keys, types, required keys), and the
/// engine reads every one: the schemas mirror the engine's files.
#[test]
fn the_data_sets_match_the_robot_json_and_rig_json_schemas() {
    let spec = spec();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let mut files = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let d = entry.unwrap().path();
        for (file, schema) in [("robot.json", "RobotJson"), ("rig.json", "RigJson")] {
            if d.join(file).is_file() {
                files.push((d.join(file), schema));
            }
        }
        for rig in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = rig.path();
            if d.ends_with("rigs") && p.extension().is_some_and(|e| e == "json") {
                files.push((p, "RigJson"));
            }
        }
    }
    assert!(files.len() >= 18, "{files:?}");
    for (path, schema) in files {
        let text = std::fs::read_to_string(&path).unwrap();
        let v: Value = serde_json::from_str(&text).unwrap();
        let reference = serde_json::json!({"$ref": format!("#/components/schemas/{schema}")});
        if let Err(e) = check(&spec, &reference, &v, "$") {
            panic!("{}: {e}", path.display());
        }
        let read = match schema {
            "RobotJson" => drawcal::model::Robot::from_json(&text).map(|_| ()),
            _ => drawcal::model::Rig::from_json(&text).map(|_| ()),
        };
        assert!(read.is_ok(), "{}: {read:?}", path.display());
    }
}
