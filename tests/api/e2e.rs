//! The whole flow over real HTTP on a real SQLite file, checked against the
//! simulator's truth.

use std::time::Duration;

use nalgebra::{Matrix4, Vector3, Vector4};
use serde_json::{Value, json};

use crate::helpers::{TestApp, err_json, ok_json, read};
use crate::openapi::validate_response;

/// Forward kinematics of T, written here from DATA_FORMAT.md (independent
/// of the engine): `dh`: Rz(q+θ) Tz(d) Tx(a) Rx(α) Ry(β); `mdh`: Rx(α)
/// Ry(β) Tx(a) Rz(q+θ) Tz(d).
pub fn fk_point(robot: &Value, q_deg: &[f64], tool_mm: [f64; 3]) -> Vector3<f64> {
    let rz = |t: f64| {
        let (s, c) = t.sin_cos();
        Matrix4::new(c, -s, 0., 0., s, c, 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.)
    };
    let rx = |t: f64| {
        let (s, c) = t.sin_cos();
        Matrix4::new(1., 0., 0., 0., 0., c, -s, 0., 0., s, c, 0., 0., 0., 0., 1.)
    };
    let ry = |t: f64| {
        let (s, c) = t.sin_cos();
        Matrix4::new(c, 0., s, 0., 0., 1., 0., 0., -s, 0., c, 0., 0., 0., 0., 1.)
    };
    let tr = |x: f64, y: f64, z: f64| {
        Matrix4::new(1., 0., 0., x, 0., 1., 0., y, 0., 0., 1., z, 0., 0., 0., 1.)
    };
    let mdh = robot["convention"].as_str() == Some("mdh");
    let mut t = Matrix4::<f64>::identity();
    for (i, j) in robot["joints"].as_array().unwrap().iter().enumerate() {
        let g = |k: &str| j[k].as_f64().unwrap_or(0.0);
        let th = (q_deg[i] + g("theta_offset_deg")).to_radians();
        let (a, al, d, be) = (
            g("a_mm"),
            g("alpha_deg").to_radians(),
            g("d_mm"),
            g("beta_deg").to_radians(),
        );
        let link = if mdh {
            rx(al) * ry(be) * tr(a, 0., 0.) * rz(th) * tr(0., 0., d)
        } else {
            rz(th) * tr(0., 0., d) * tr(a, 0., 0.) * rx(al) * ry(be)
        };
        t *= link;
    }
    let p = t * Vector4::new(tool_mm[0], tool_mm[1], tool_mm[2], 1.0);
    Vector3::new(p[0], p[1], p[2])
}

/// A point of the robot base frame in the rig frame, for a base pose
/// `{xyz_mm, rpy_deg}` (Rz(yaw) Ry(pitch) Rx(roll), DATA_FORMAT.md).
fn to_rig(base: &Value, p: Vector3<f64>) -> Vector3<f64> {
    let [r, pi, y] = arr3(&base["rpy_deg"]).map(f64::to_radians);
    let rot = nalgebra::Rotation3::from_euler_angles(r, pi, y);
    rot * p + Vector3::from(arr3(&base["xyz_mm"]))
}

fn arr3(v: &Value) -> [f64; 3] {
    let a = v.as_array().unwrap();
    [
        a[0].as_f64().unwrap(),
        a[1].as_f64().unwrap(),
        a[2].as_f64().unwrap(),
    ]
}

fn pose_joints(csv_text: &str) -> Vec<(String, Vec<f64>)> {
    let mut rdr = csv::Reader::from_reader(csv_text.as_bytes());
    let h = rdr.headers().unwrap().clone();
    let qi: Vec<usize> = (1..=6)
        .map(|j| h.iter().position(|c| c == format!("q{j}_deg")).unwrap())
        .collect();
    rdr.records()
        .map(|r| {
            let r = r.unwrap();
            (
                r[0].to_string(),
                qi.iter().map(|&i| r[i].parse().unwrap()).collect(),
            )
        })
        .collect()
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn calibrate_activate_compensate_against_truth() {
    let app = TestApp::spawn("e2e").await;
    let ds = "er3a_paper_like";
    let (_model_id, robot_id, _rig_id, session_id) = app.setup(ds, "ER3A-0001").await;

    // Upload the dataset as CSV.
    let poses = read(ds, "poses.csv");
    let r = app
        .post_raw(
            &format!("/sessions/{session_id}/poses"),
            Some("text/csv"),
            poses.clone(),
        )
        .await;
    let request_id = r
        .headers()
        .get("x-request-id")
        .expect("a request id on every answer");
    assert!(!request_id.is_empty());
    let up = validate_response("post", "/sessions/{id}/poses", r).await;
    assert_eq!(up["added"], 50);
    assert_eq!(up["session"]["n_poses"], 50);

    // Compensating before any calibration is active is a clear conflict.
    err_json(
        app.post_json(
            "/compensate",
            &json!({"robot_id": robot_id, "target": {"target": "t", "q_deg": [0, 0, 0, 0, 0, 0]}}),
        )
        .await,
        409,
        "conflict",
    )
    .await;

    // Enqueue: 202 at once with the job and its URL.
    let r = app
        .post_raw(
            &format!("/sessions/{session_id}/jobs"),
            Some("application/json"),
            r#"{"seed": 7}"#,
        )
        .await;
    assert_eq!(r.status(), 202);
    let location = r.headers()["location"].to_str().unwrap().to_string();
    let job = validate_response("post", "/sessions/{id}/jobs", r).await;
    assert_eq!(location, format!("/jobs/{}", job["id"]));
    assert!(["queued", "running"].contains(&job["state"].as_str().unwrap()));
    let job_id = job["id"].as_i64().unwrap();
    let done = app.wait_job(job_id, Duration::from_secs(600)).await;
    assert_eq!(done["state"], "succeeded", "job: {done}");
    assert_eq!(done["progress"], 1.0);
    let cal_id = done["calibration_id"].as_i64().unwrap();
    validate_response(
        "get",
        "/jobs/{id}",
        app.get(&format!("/jobs/{job_id}")).await,
    )
    .await;

    // The calibration: the whole report, version 1, better than nominal on held-out poses.
    let cal = validate_response(
        "get",
        "/calibrations/{id}",
        app.get(&format!("/calibrations/{cal_id}")).await,
    )
    .await;
    assert_eq!(cal["calibration"]["version"], 1);
    assert_eq!(cal["calibration"]["robot_id"], robot_id);
    assert_eq!(cal["calibration"]["active"], false);
    let before = cal["report"]["stats"]["test"]["before"]["rms_mm"]
        .as_f64()
        .unwrap();
    let after = cal["report"]["stats"]["test"]["after"]["rms_mm"]
        .as_f64()
        .unwrap();
    assert!(after < before / 3.0, "held-out RMS {before} -> {after}");
    assert_eq!(
        cal["calibration"]["test_rms_after_mm"].as_f64().unwrap(),
        after
    );
    assert!(cal["report"]["calibrated_robot"]["joints"].is_array());

    // Activate (recorded with who and why).
    let act = validate_response(
        "post",
        "/robots/{id}/activate",
        app.post_json(
            &format!("/robots/{robot_id}/activate"),
            &json!({"calibration_id": cal_id, "reason": "first calibration"}),
        )
        .await,
    )
    .await;
    assert_eq!(act["calibration_id"], cal_id);
    assert_eq!(act["previous_calibration_id"], Value::Null);
    let acts = validate_response(
        "get",
        "/robots/{id}/activations",
        app.get(&format!("/robots/{robot_id}/activations")).await,
    )
    .await;
    assert_eq!(acts["total"], 1);
    // The actor is the key's name, never one the client sends.
    assert_eq!(acts["items"][0]["actor"], "test-admin");

    // Compensate every recorded pose's joints as nominal joint targets, plus
    // the nominal points as Cartesian targets, plus one unreachable point.
    let truth: Value = serde_json::from_str(&read(ds, "truth.json")).unwrap();
    let nominal: Value = serde_json::from_str(&read(ds, "robot.json")).unwrap();
    let true_robot = &truth["true_robot"];
    let true_tool = arr3(&truth["tool_point_mm"]);
    let nominal_tool = arr3(&nominal["tool_point_mm"]);
    let joints = pose_joints(&poses);
    let mut targets: Vec<Value> = joints
        .iter()
        .map(|(id, q)| json!({"target": format!("j{id}"), "q_deg": q}))
        .collect();
    for (id, q) in joints.iter().take(10) {
        let p = fk_point(&nominal, q, nominal_tool);
        targets.push(json!({"target": format!("c{id}"), "xyz_mm": [p.x, p.y, p.z]}));
    }
    targets.push(json!({"target": "far", "xyz_mm": [10000.0, 0.0, 0.0]}));
    let r = app
        .post_json(
            "/compensate",
            &json!({"robot_id": robot_id, "targets": targets}),
        )
        .await;
    let out = validate_response("post", "/compensate", r).await;
    assert_eq!(out["calibration_id"], cal_id);
    assert_eq!(out["version"], 1);
    let results = out["results"].as_array().unwrap();
    assert_eq!(results.len(), targets.len());
    let far = results.last().unwrap();
    assert_eq!(far["target"], "far");
    assert_eq!(far["status"], "unreachable", "{far}");
    assert!(far["q_deg"].is_null());

    // Where the true robot puts T, against where it should be. A drawstring
    // rig locates the base only together with the first joint (d1 and the
    // joint-1 offset are one with the base pose), so the base frame a
    // calibration can deliver is the identified one: targets are compared in
    // the rig frame, the true robot placed by its true base pose, the target
    // by the identified one (norms are the same in any frame).
    let base_true = &truth["base_in_rig"];
    let base_id = &cal["report"]["base_in_rig"];
    let mut err_nominal = Vec::new();
    let mut err_compensated = Vec::new();
    for ((t, res), (_, q_nom)) in targets
        .iter()
        .zip(results)
        .zip(joints.iter().chain(joints.iter().take(10)))
    {
        assert_eq!(t["target"], res["target"], "order kept");
        if res["status"] != "ok" {
            continue;
        }
        let wanted = to_rig(base_id, fk_point(&nominal, q_nom, nominal_tool));
        let q_c: Vec<f64> = res["q_deg"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        err_nominal
            .push((to_rig(base_true, fk_point(true_robot, q_nom, true_tool)) - wanted).norm());
        err_compensated
            .push((to_rig(base_true, fk_point(true_robot, &q_c, true_tool)) - wanted).norm());
    }
    assert!(
        err_compensated.len() >= 55,
        "most targets compensate ok: {}",
        err_compensated.len()
    );
    let (e_nom, e_comp) = (rms(&err_nominal), rms(&err_compensated));
    eprintln!(
        "true-robot error at nominal targets: nominal joints {e_nom:.3} mm RMS, compensated {e_comp:.3} mm RMS"
    );
    assert!(
        e_comp < 0.1 * e_nom,
        "compensation must bring the true robot much nearer: {e_nom} -> {e_comp}"
    );

    // One target alone, named calibration: same answer as in the batch.
    let (id0, q0) = &joints[0];
    let single = validate_response(
        "post",
        "/compensate",
        app.post_json(
            "/compensate",
            &json!({"robot_id": robot_id, "calibration_id": cal_id, "target": {"target": format!("j{id0}"), "q_deg": q0}}),
        )
        .await,
    )
    .await;
    assert_eq!(single["results"][0]["q_deg"], results[0]["q_deg"]);

    // Fleet history and accuracy over time, JSON and CSV.
    let hist = validate_response(
        "get",
        "/calibrations",
        app.get("/calibrations?site=plant-1&line=L2").await,
    )
    .await;
    assert_eq!(hist["total"], 1);
    assert_eq!(hist["items"][0]["active"], true);
    let none = ok_json(app.get("/calibrations?site=elsewhere").await, 200).await;
    assert_eq!(none["total"], 0);
    let tight = ok_json(
        app.get(&format!("/calibrations?max_test_rms_mm={}", after / 2.0))
            .await,
        200,
    )
    .await;
    assert_eq!(tight["total"], 0);
    let future = ok_json(app.get("/calibrations?from=2999-01-01").await, 200).await;
    assert_eq!(future["total"], 0);
    let acc = validate_response(
        "get",
        "/robots/{id}/accuracy",
        app.get(&format!("/robots/{robot_id}/accuracy")).await,
    )
    .await;
    assert_eq!(
        acc["history"][0]["test_rms_after_mm"].as_f64().unwrap(),
        after
    );
    // The effects found: a list in both answers (`[]` for none, never "").
    assert!(hist["items"][0]["effects"].is_array(), "{hist}");
    assert_eq!(acc["history"][0]["effects"], hist["items"][0]["effects"]);
    let csv_r = app.get("/calibrations?format=csv").await;
    assert_eq!(csv_r.headers()["content-type"], "text/csv");
    let csv_text = csv_r.text().await.unwrap();
    assert!(csv_text.starts_with("calibration_id,robot_id,serial_number"));
    assert_eq!(csv_text.lines().count(), 2);
    assert!(csv_text.contains("ER3A-0001"));

    // Roll back: to the nominal model (nothing was active before).
    let rb = ok_json(
        app.post_json(
            &format!("/robots/{robot_id}/rollback"),
            &json!({"reason": "check rollback"}),
        )
        .await,
        200,
    )
    .await;
    assert_eq!(rb["action"], "rollback");
    assert_eq!(rb["calibration_id"], Value::Null);
    assert_eq!(rb["previous_calibration_id"], cal_id);
    let robot = ok_json(app.get(&format!("/robots/{robot_id}")).await, 200).await;
    assert_eq!(robot["active_calibration_id"], Value::Null);
    err_json(
        app.post_json(
            &format!("/robots/{robot_id}/rollback"),
            &json!({"reason": "again"}),
        )
        .await,
        409,
        "conflict",
    )
    .await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn poses_in_json_and_csv_batches_are_one_session() {
    let app = TestApp::spawn("batches").await;
    let ds = "er3a_paper_like";
    let (_, _, _, sid) = app.setup(ds, "ER3A-0002").await;
    let poses = read(ds, "poses.csv");
    let mut lines = poses.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let rows: Vec<&str> = lines.collect();
    // First 20 rows as JSON objects (numbers as numbers, ids as strings).
    let json_rows: Vec<Value> = rows[..20]
        .iter()
        .map(|l| {
            let mut m = serde_json::Map::new();
            for (h, v) in header.iter().zip(l.split(',')) {
                let val = match v.parse::<f64>() {
                    Ok(x) if *h != "pose" => json!(x),
                    _ => json!(v),
                };
                m.insert(h.to_string(), val);
            }
            Value::Object(m)
        })
        .collect();
    let r = app
        .post_json(&format!("/sessions/{sid}/poses"), &Value::Array(json_rows))
        .await;
    let up = validate_response("post", "/sessions/{id}/poses", r).await;
    assert_eq!(up["added"], 20);
    // The rest as CSV with the columns in another order.
    let mut reordered = vec![header.iter().rev().cloned().collect::<Vec<_>>().join(",")];
    for l in &rows[20..] {
        reordered.push(l.split(',').rev().collect::<Vec<_>>().join(","));
    }
    let up = app.upload_poses(sid, reordered.join("\n")).await;
    assert_eq!(up["added"], 30);
    assert_eq!(up["session"]["n_poses"], 50);
    assert_eq!(up["session"]["n_batches"], 2);
    // Stored poses equal the file, value for value.
    let stored = app
        .get(&format!("/sessions/{sid}/poses"))
        .await
        .text()
        .await
        .unwrap();
    // Rows as column -> value maps (JSON objects carry no column order).
    let parse = |t: &str| -> Vec<std::collections::BTreeMap<String, String>> {
        let mut rdr = csv::Reader::from_reader(t.as_bytes());
        let h: Vec<String> = rdr.headers().unwrap().iter().map(str::to_string).collect();
        rdr.records()
            .map(|r| {
                let r = r.unwrap();
                h.iter()
                    .zip(r.iter())
                    .map(|(k, c)| {
                        (
                            k.clone(),
                            c.parse::<f64>()
                                .map(|x| format!("{x}"))
                                .unwrap_or_else(|_| c.to_string()),
                        )
                    })
                    .collect()
            })
            .collect()
    };
    assert_eq!(parse(&stored), parse(&poses));
    // A duplicate pose id across batches names the row of the new batch.
    let dup = format!("{}\n{}", header.join(","), rows[3]);
    let e = err_json(
        app.post_raw(&format!("/sessions/{sid}/poses"), Some("text/csv"), dup)
            .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["row"], 1, "{e}");
    assert_eq!(e["field"], "pose", "{e}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_calibration_with_a_correction_beyond_the_bounds_is_not_activated() {
    // Poses whose joint 2 was recorded 3 deg off (tampered, or another
    // robot's): the calibration takes it up as joint 2's offset, and fits
    // as well as the genuine one, but may not drive the robot.
    let app = TestApp::spawn("activation-bounds").await;
    let ds = "er3a_paper_like";
    let (_, robot, _, sid) = app.setup(ds, "BOUNDS-1").await;
    let poses = read(ds, "poses.csv");
    let mut lines = poses.lines();
    let mut shifted = format!("{}\n", lines.next().unwrap());
    for line in lines {
        let mut cells: Vec<String> = line.split(',').map(String::from).collect();
        let q2: f64 = cells[2].parse().unwrap();
        cells[2] = format!("{:.6}", q2 + 3.0);
        shifted.push_str(&cells.join(","));
        shifted.push('\n');
    }
    let done = app.identify_session(sid, shifted).await;
    let cal = done["calibration_id"].as_i64().unwrap();
    let r = app
        .post_json(
            &format!("/robots/{robot}/activate"),
            &json!({"calibration_id": cal, "reason": "try"}),
        )
        .await;
    let e = err_json(r, 422, "invalid_input").await;
    let m = e["message"].as_str().unwrap();
    assert!(
        m.contains("may not drive the robot")
            && m.contains("j2.theta is corrected by -3.")
            && m.contains("--max-angle-correction-deg"),
        "{m}"
    );
    assert_eq!(e["field"], "calibration_id");
    let r: Value = ok_json(app.get(&format!("/robots/{robot}")).await, 200).await;
    assert!(r["active_calibration_id"].is_null(), "{r}");
    app.stop().await;
}
