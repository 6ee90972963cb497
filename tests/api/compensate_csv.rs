//! `POST /compensate` in the DATA_FORMAT CSV: targets.csv bodies and
//! compensated.csv answers (`Accept: text/csv`), equal to the JSON answers
//! and to the engine's own writer.

use drawcal::compensate::{Compensator, compensate_all, write_csv};
use drawcal::model::targets::targets_from_csv;
use drawcal::report::Report;
use serde_json::{Value, json};

use crate::helpers::{TestApp, err_json, ok_json, read};
use crate::openapi::validate_response;

/// A robot with an active calibration of er3a_paper_like: (robot, calibration).
async fn calibrated(app: &TestApp) -> (i64, i64) {
    let ds = "er3a_paper_like";
    let (_, robot, _, session) = app.setup(ds, "CSV-1").await;
    let cal = app
        .calibrate_and_activate(robot, session, read(ds, "poses.csv"), "csv")
        .await;
    (robot, cal)
}

const JOINT_TARGETS: &str = "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n\
    t1,10,-20,30,0,40,0\n\
    t2,-60,-10,45,90,-30,10\n\
    edge,10,-109.99,30,40,50,60\n";

async fn post(
    app: &TestApp,
    path: &str,
    content_type: &str,
    accept: Option<&str>,
    body: String,
) -> reqwest::Response {
    let mut r = app
        .client
        .post(app.url(path))
        .header("content-type", content_type)
        .body(body);
    if let Some(a) = accept {
        r = r.header("accept", a);
    }
    r.send().await.expect("request")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn csv_in_csv_out_equal_json_and_the_engine_writer() {
    let app = TestApp::spawn("compcsv").await;
    let (robot, cal) = calibrated(&app).await;

    // The same three targets as JSON, answered in JSON.
    let json_targets: Vec<Value> = JOINT_TARGETS
        .lines()
        .skip(1)
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            let q: Vec<f64> = c[1..].iter().map(|v| v.parse().unwrap()).collect();
            json!({"target": c[0], "q_deg": q})
        })
        .collect();
    let as_json = validate_response(
        "post",
        "/compensate",
        app.post_json(
            "/compensate",
            &json!({"robot_id": robot, "targets": json_targets}),
        )
        .await,
    )
    .await;
    assert_eq!(as_json["calibration_id"], cal);

    // targets.csv in, JSON out: the same answer.
    let r = post(
        &app,
        &format!("/compensate?robot_id={robot}"),
        "text/csv",
        None,
        JOINT_TARGETS.into(),
    )
    .await;
    let csv_in = validate_response("post", "/compensate", r).await;
    assert_eq!(csv_in, as_json);

    // JSON in, compensated.csv out.
    let r = app
        .client
        .post(app.url("/compensate"))
        .header("accept", "text/csv")
        .json(&json!({"robot_id": robot, "targets": json_targets}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-type"], "text/csv");
    assert_eq!(r.headers()["x-calibration-id"], cal.to_string().as_str());
    assert_eq!(r.headers()["x-calibration-version"], "1");
    let csv_out = r.text().await.unwrap();
    let lines: Vec<&str> = csv_out.lines().collect();
    assert_eq!(
        lines[0],
        "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,residual_mm,iterations,status,message"
    );
    assert_eq!(lines.len(), 4, "{csv_out}");
    for (line, res) in lines[1..]
        .iter()
        .zip(as_json["results"].as_array().unwrap())
    {
        let cells: Vec<&str> = line.splitn(11, ',').collect();
        assert_eq!(cells[0], res["target"].as_str().unwrap(), "order kept");
        assert_eq!(cells[9], res["status"].as_str().unwrap());
        match res["q_deg"].as_array() {
            Some(q) => {
                for (c, v) in cells[1..7].iter().zip(q) {
                    let c: f64 = c.parse().unwrap();
                    assert!((c - v.as_f64().unwrap()).abs() < 1e-6, "{line} vs {res}");
                }
            }
            None => assert!(cells[1..7].iter().all(|c| c.is_empty()), "{line}"),
        }
    }

    // Byte for byte what the engine's writer makes from the stored report
    // (the CLI's `drawcal compensate` output).
    let stored = ok_json(app.get(&format!("/calibrations/{cal}")).await, 200).await;
    let report: Report = serde_json::from_value(stored["report"].clone()).unwrap();
    let comp = Compensator::from_report(&report).unwrap();
    let targets = targets_from_csv(JOINT_TARGETS.as_bytes(), 6).unwrap();
    let mut engine = Vec::new();
    write_csv(&mut engine, 6, &compensate_all(&comp, &targets, false)).unwrap();
    assert_eq!(csv_out, String::from_utf8(engine).unwrap());

    // CSV in and out, Cartesian targets with the orientation held, the
    // calibration named in the query.
    let cart = "target,x_mm,y_mm,z_mm\nfar,10000,0,0\n";
    let r = post(
        &app,
        &format!("/compensate?robot_id={robot}&calibration_id={cal}&orientation=true"),
        "text/csv",
        Some("text/csv, application/json;q=0.5"),
        cart.into(),
    )
    .await;
    assert_eq!(r.status(), 200);
    let text = r.text().await.unwrap();
    assert!(
        text.lines().nth(1).unwrap().starts_with("far,,,,,,,,"),
        "{text}"
    );
    assert!(text.contains(",unreachable,"), "{text}");

    // JSON preferred (or anything else asked): JSON.
    for accept in ["application/json, text/csv", "*/*", "text/csv;q=0, */*"] {
        let r = post(
            &app,
            &format!("/compensate?robot_id={robot}"),
            "text/csv",
            Some(accept),
            JOINT_TARGETS.into(),
        )
        .await;
        assert_eq!(ok_json(r, 200).await, as_json, "Accept: {accept}");
    }
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_csv_targets_are_refused_in_json_naming_row_and_column() {
    let app = TestApp::spawn("compcsvbad").await;
    let (robot, _) = calibrated(&app).await;
    let before = app.snapshot().await;
    let url = format!("/compensate?robot_id={robot}");
    // A bad cell: 422 with row and column, in JSON even when CSV is asked.
    let e = err_json(
        post(
            &app,
            &url,
            "text/csv",
            Some("text/csv"),
            "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\na,1,2,3,4,5,6\nb,1,x,3,4,5,6\n"
                .into(),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "q2_deg");
    assert_eq!(e["row"], 2);
    // More than 10,000 rows: refused by the line count, before parsing.
    let mut big = String::from("target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n");
    for i in 0..10_001 {
        big.push_str(&format!("t{i},1,2,3,4,5,6\n"));
    }
    let e = err_json(
        post(&app, &url, "text/csv", None, big).await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "targets");
    assert!(e["message"].as_str().unwrap().contains("10001 rows"), "{e}");
    // Wrong number of joints for the robot.
    let e = err_json(
        post(
            &app,
            &url,
            "text/csv",
            None,
            "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg\na,1,2,3,4,5,6,7\n".into(),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "q7_deg");
    // Duplicate ids, a header only.
    let e = err_json(
        post(
            &app,
            &url,
            "text/csv",
            None,
            "target,x_mm,y_mm,z_mm\na,1,2,3\na,1,2,3\n".into(),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(
        (e["field"].as_str(), e["row"].as_i64()),
        (Some("target"), Some(2))
    );
    let e = err_json(
        post(
            &app,
            &url,
            "text/csv",
            None,
            "target,x_mm,y_mm,z_mm\n".into(),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "targets");
    // robot_id missing for CSV; query parameters with a JSON body.
    let e = err_json(
        post(
            &app,
            "/compensate",
            "text/csv",
            None,
            "target,x_mm,y_mm,z_mm\na,1,2,3\n".into(),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "robot_id");
    let e = err_json(
        post(
            &app,
            &url,
            "application/json",
            None,
            json!({"robot_id": robot, "target": {"target": "t", "q_deg": [0, 0, 0, 0, 0, 0]}})
                .to_string(),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "robot_id");
    // Unknown query parameter, unknown robot, neither CSV nor JSON.
    err_json(
        post(
            &app,
            &format!("/compensate?robot={robot}"),
            "text/csv",
            None,
            "target,x_mm,y_mm,z_mm\na,1,2,3\n".into(),
        )
        .await,
        400,
        "bad_request",
    )
    .await;
    err_json(
        post(
            &app,
            "/compensate?robot_id=999",
            "text/csv",
            None,
            "target,x_mm,y_mm,z_mm\na,1,2,3\n".into(),
        )
        .await,
        404,
        "not_found",
    )
    .await;
    err_json(
        post(&app, &url, "text/plain", None, "a,1,2,3".into()).await,
        415,
        "unsupported_media_type",
    )
    .await;
    assert_eq!(app.snapshot().await, before, "nothing changed");
    app.stop().await;
}

/// Joint targets that look like radians are compensated as degrees (the
/// contract) with a warning, in JSON `warnings` and as `X-Warning` on CSV;
/// targets in degrees get none.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn joint_targets_that_look_like_radians_are_warned_about() {
    let app = TestApp::spawn("comprad").await;
    let (robot, _) = calibrated(&app).await;
    let path = format!("/compensate?robot_id={robot}");
    let radians = "target,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n\
        a,0.1,0.5,1.2,-0.3,1.0,2.0\n\
        b,0.2,0.6,1.1,-0.2,0.9,2.1\n\
        c,0.3,0.4,1.3,-0.1,1.1,1.9\n";
    let r = post(&app, &path, "text/csv", None, radians.into()).await;
    assert_eq!(r.status(), 200);
    let v = validate_response("post", "/compensate", r).await;
    assert_eq!(v["n_ok"], 3, "{v}");
    let w = v["warnings"].as_array().unwrap();
    assert_eq!(w.len(), 1, "{v}");
    assert!(w[0].as_str().unwrap().contains("radians"), "{v}");
    let r = post(&app, &path, "text/csv", Some("text/csv"), radians.into()).await;
    assert_eq!(r.status(), 200);
    let h = r
        .headers()
        .get("x-warning")
        .expect("X-Warning")
        .to_str()
        .unwrap();
    assert!(h.contains("convert them to degrees"), "{h}");
    // Degrees: nothing to say.
    let r = post(&app, &path, "text/csv", None, JOINT_TARGETS.into()).await;
    assert_eq!(r.status(), 200);
    let v = validate_response("post", "/compensate", r).await;
    assert_eq!(v["warnings"], json!([]), "{v}");
    app.stop().await;
}
