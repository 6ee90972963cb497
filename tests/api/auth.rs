//! API keys and roles as a client meets them: no key or a bad one is 401,
//! the wrong role 403 (both JSON errors); each role reaches its routes; the
//! actor recorded is the key's name, never one the client sends; revoked
//! and expired keys stop working; the audit log says who did what.

use serde_json::{Value, json};

use crate::helpers::{TestApp, client_with_key, err_json, ok_json, read};

const DS: &str = "er3a_paper_like";

async fn send(req: reqwest::RequestBuilder) -> reqwest::Response {
    req.send().await.unwrap()
}

/// A key of `role` made through the API by the harness's admin.
async fn key(app: &TestApp, name: &str, role: &str, expires_at: Option<&str>) -> (i64, String) {
    let mut body = json!({"name": name, "role": role});
    if let Some(at) = expires_at {
        body["expires_at"] = at.into();
    }
    let made = ok_json(app.post_json("/keys", &body).await, 201).await;
    assert!(made["key"].get("secret_hash").is_none(), "{made}");
    let secret = made["secret"].as_str().unwrap().to_string();
    assert!(secret.starts_with(made["key"]["prefix"].as_str().unwrap()));
    (made["key"]["id"].as_i64().unwrap(), secret)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_route_but_health_needs_a_key_of_the_right_role() {
    let app = TestApp::spawn("auth").await;
    let anon = reqwest::Client::new();
    // Health and readiness answer anyone; the page's files too.
    for path in ["/health", "/ready", "/", "/ui/app.js"] {
        let r = anon.get(app.url(path)).send().await.unwrap();
        assert_eq!(r.status(), 200, "{path}");
    }
    // No key, a malformed header, an unknown key: 401 in the error shape.
    let e = err_json(
        send(anon.get(app.url("/robots"))).await,
        401,
        "unauthorized",
    )
    .await;
    assert!(e["message"].as_str().unwrap().contains("Bearer"), "{e}");
    let r = anon
        .get(app.url("/robots"))
        .header("authorization", "Basic abc")
        .send()
        .await
        .unwrap();
    err_json(r, 401, "unauthorized").await;
    err_json(
        send(client_with_key("dck_nope").get(app.url("/robots"))).await,
        401,
        "unauthorized",
    )
    .await;

    let (_, robot, _, session) = app.setup(DS, "AUTH-1").await;
    let done = app.identify_session(session, read(DS, "poses.csv")).await;
    let cal = done["calibration_id"].as_i64().unwrap();

    let (_, reader) = key(&app, "mes-dashboard", "reader", None).await;
    let (_, operator) = key(&app, "floor-cell-7", "operator", None).await;
    let (_, engineer) = key(&app, "eve", "engineer", None).await;
    let (reader, operator, engineer) = (
        client_with_key(&reader),
        client_with_key(&operator),
        client_with_key(&engineer),
    );
    let target = json!({"robot_id": robot, "calibration_id": cal,
        "target": {"target": "t1", "q_deg": [10, -20, 30, 0, 40, 0]}});

    // reader: every GET, nothing else.
    ok_json(send(reader.get(app.url("/calibrations"))).await, 200).await;
    let e = err_json(
        send(reader.post(app.url("/compensate")).json(&target)).await,
        403,
        "forbidden",
    )
    .await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("'mes-dashboard' has the role reader")
            && e["message"].as_str().unwrap().contains("needs operator"),
        "{e}"
    );
    // operator: compensation, not the fleet's data.
    ok_json(
        send(operator.post(app.url("/compensate")).json(&target)).await,
        200,
    )
    .await;
    let robot_json: Value = serde_json::from_str(&read(DS, "robot.json")).unwrap();
    err_json(
        send(operator.post(app.url("/models")).json(&robot_json)).await,
        403,
        "forbidden",
    )
    .await;
    // Plans: an engineer's to make, anyone's to read.
    let plan = json!({"robot_id": robot, "rig_id": 1, "n_poses": 8, "candidates": 400});
    for c in [&reader, &operator] {
        err_json(
            send(c.post(app.url("/plans")).json(&plan)).await,
            403,
            "forbidden",
        )
        .await;
    }
    let plan = ok_json(
        send(engineer.post(app.url("/plans")).json(&plan)).await,
        202,
    )
    .await;
    let plan_url = app.url(&format!("/plans/{}", plan["id"]));
    ok_json(send(reader.get(&plan_url)).await, 200).await;
    // engineer: models, plans and jobs, not activation or keys.
    ok_json(
        send(engineer.post(app.url("/models")).json(&robot_json)).await,
        201,
    )
    .await;
    let activate = json!({"calibration_id": cal, "reason": "commissioning"});
    err_json(
        engineer
            .post(app.url(&format!("/robots/{robot}/activate")))
            .json(&activate)
            .send()
            .await
            .unwrap(),
        403,
        "forbidden",
    )
    .await;
    err_json(send(engineer.get(app.url("/keys"))).await, 403, "forbidden").await;

    // admin: activation, recorded under the key's name; a name sent by the
    // client is refused, not recorded.
    let e = err_json(
        app.post_json(
            &format!("/robots/{robot}/activate"),
            &json!({"calibration_id": cal, "by": "alice", "reason": "x"}),
        )
        .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "by", "{e}");
    let act = ok_json(
        app.post_json(&format!("/robots/{robot}/activate"), &activate)
            .await,
        200,
    )
    .await;
    assert_eq!(act["actor"], "test-admin", "{act}");

    // The audit log: who did what, newest first, JSON and CSV.
    let audit = ok_json(app.get("/audit").await, 200).await;
    let first = &audit["items"][0];
    assert_eq!(first["action"], "activate", "{audit}");
    assert_eq!(first["actor"], "test-admin");
    assert_eq!(first["target"], format!("robot {robot}"));
    let actions: Vec<&str> = audit["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["action"].as_str().unwrap())
        .collect();
    for a in ["create_key", "upload_poses", "enqueue_job"] {
        assert!(actions.contains(&a), "{a} in {actions:?}");
    }
    let csv = app.get("/audit?format=csv").await.text().await.unwrap();
    assert!(
        csv.starts_with("id,at,actor,action,target,detail\n"),
        "{csv}"
    );
    assert!(
        csv.contains(&format!(",test-admin,activate,robot {robot},")),
        "{csv}"
    );
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn revoked_and_expired_keys_stop_working() {
    let app = TestApp::spawn("authrevoke").await;
    let (id, secret) = key(&app, "temp", "reader", None).await;
    let client = client_with_key(&secret);
    ok_json(send(client.get(app.url("/robots"))).await, 200).await;
    let listed = ok_json(app.get("/keys").await, 200).await;
    assert!(
        listed
            .as_array()
            .unwrap()
            .iter()
            .all(|k| k.get("secret_hash").is_none() && !k.to_string().contains(&secret[4..])),
        "{listed}"
    );
    ok_json(
        app.post_json(&format!("/keys/{id}/revoke"), &json!({}))
            .await,
        200,
    )
    .await;
    let e = err_json(
        send(client.get(app.url("/robots"))).await,
        401,
        "unauthorized",
    )
    .await;
    assert!(e["message"].as_str().unwrap().contains("revoked"), "{e}");
    let (_, old) = key(&app, "old", "reader", Some("2020-01-01")).await;
    let e = err_json(
        send(client_with_key(&old).get(app.url("/robots"))).await,
        401,
        "unauthorized",
    )
    .await;
    assert!(e["message"].as_str().unwrap().contains("expired"), "{e}");
    // A taken name, an unknown role: refused.
    err_json(
        app.post_json("/keys", &json!({"name": "old", "role": "reader"}))
            .await,
        409,
        "conflict",
    )
    .await;
    let e = err_json(
        app.post_json("/keys", &json!({"name": "x", "role": "root"}))
            .await,
        422,
        "invalid_input",
    )
    .await;
    assert_eq!(e["field"], "role");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_auth_is_refused_beyond_the_loopback() {
    let cfg = drawcal::http::ServiceConfig {
        listen: "0.0.0.0:0".parse().unwrap(),
        database_url: format!(
            "sqlite://{}",
            crate::helpers::fresh_dir("noauth").join("d.db").display()
        ),
        max_upload_bytes: 1024,
        jobs: Default::default(),
        client_timeout: std::time::Duration::from_secs(5),
        idle_timeout: std::time::Duration::from_secs(5),
        max_joint_change_deg: 5.0,
        insecure_no_auth: true,
        bootstrap_admin_key: None,
        allowed_hosts: Vec::new(),
        cors_origins: Vec::new(),
        limits: Default::default(),
        max_connections: None,
        max_answer_bytes_in_flight: 1 << 30,
        activation_bounds: Default::default(),
    };
    let err = match drawcal::http::Service::start(&cfg, drawcal::jobs::engine_job_fn()).await {
        Ok(_) => panic!("served without keys on 0.0.0.0"),
        Err(e) => e.to_string(),
    };
    assert!(err.contains("loopback"), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_key_limited_to_a_site_reaches_only_that_sites_robots() {
    let app = TestApp::spawn("sites").await;
    // setup's robots are at plant-1; another at plant-2.
    let (model, here, _, sid) = app.setup(DS, "SITE-1").await;
    let there = ok_json(
        app.post_json(
            "/robots",
            &json!({"serial_number": "SITE-2", "model_id": model, "site": "plant-2"}),
        )
        .await,
        201,
    )
    .await["id"]
        .as_i64()
        .unwrap();
    let made = ok_json(
        app.post_json(
            "/keys",
            &json!({"name": "plant-1-eng", "role": "engineer", "sites": ["plant-1"]}),
        )
        .await,
        201,
    )
    .await;
    assert_eq!(made["key"]["sites"], "plant-1", "{made}");
    let eng = client_with_key(made["secret"].as_str().unwrap());
    let get = |path: String| send(eng.get(app.url(&path)));
    assert_eq!(get(format!("/robots/{here}")).await.status(), 200);
    assert_eq!(get(format!("/sessions/{sid}")).await.status(), 200);
    let e = err_json(get(format!("/robots/{there}")).await, 403, "forbidden").await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("limited to the sites plant-1; robot"),
        "{e}"
    );
    // Lists are the key's site's.
    let robots = ok_json(get("/robots".into()).await, 200).await;
    assert_eq!(robots["total"], 1, "{robots}");
    err_json(get("/robots?site=plant-2".into()).await, 403, "forbidden").await;
    err_json(get("/sessions".into()).await, 403, "forbidden").await;
    assert_eq!(
        get(format!("/sessions?robot_id={here}")).await.status(),
        200
    );
    // Nothing made at another site.
    let r = send(
        eng.post(app.url("/robots"))
            .json(&json!({"serial_number": "SITE-3", "model_id": model, "site": "plant-2"})),
    )
    .await;
    err_json(r, 403, "forbidden").await;
    let r = send(
        eng.post(app.url("/sessions"))
            .json(&json!({"robot_id": there, "rig_id": 1})),
    )
    .await;
    err_json(r, 403, "forbidden").await;
    // An admin key is never limited.
    let r = app
        .post_json(
            "/keys",
            &json!({"name": "a", "role": "admin", "sites": ["plant-1"]}),
        )
        .await;
    err_json(r, 422, "invalid_input").await;
    app.stop().await;
}
