//! Test harness: the real service on port 0 over a fresh SQLite file per
//! test, a reqwest client, and small helpers per endpoint.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use drawcal::http::{Service, ServiceConfig};
use drawcal::jobs::{JobConfig, JobFn, engine_job_fn};
use reqwest::{Client, Response, StatusCode};
use serde_json::{Value, json};

/// The admin key a test gives a binary it starts (`DRAWCAL_ADMIN_KEY`).
pub const TEST_ADMIN_KEY: &str = "dck_test_admin_key_0123456789abcdef0123456789";

/// A client that sends `key` as its bearer key on every request.
pub fn client_with_key(key: &str) -> Client {
    let mut headers = reqwest::header::HeaderMap::new();
    headers.insert(
        reqwest::header::AUTHORIZATION,
        reqwest::header::HeaderValue::from_str(&format!("Bearer {key}")).unwrap(),
    );
    Client::builder().default_headers(headers).build().unwrap()
}

pub fn data_dir(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

pub fn read(name: &str, file: &str) -> String {
    std::fs::read_to_string(data_dir(name).join(file)).expect("test data file")
}

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// A fresh directory for one test's database.
pub fn fresh_dir(tag: &str) -> PathBuf {
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "api-{tag}-{}-{n}-{}",
        std::process::id(),
        drawcal::store::now_ms()
    ));
    std::fs::create_dir_all(&dir).expect("create test dir");
    dir
}

pub struct TestApp {
    pub base: String,
    pub client: Client,
    pub db_url: String,
    /// The admin key `client` sends.
    pub admin_key: String,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    task: Option<tokio::task::JoinHandle<std::io::Result<()>>>,
}

pub struct Options {
    pub job_fn: JobFn,
    pub workers: usize,
    pub max_upload_bytes: usize,
    pub lease: Duration,
    pub grace: Duration,
    pub client_timeout: Duration,
    pub idle_timeout: Duration,
    pub max_joint_change_deg: f64,
    /// `--cors-origin`s.
    pub cors_origins: Vec<String>,
    /// Rates and the queue's bound.
    pub limits: drawcal::http::limits::LimitConfig,
    /// `--max-connections`.
    pub max_connections: Option<usize>,
    /// `--max-answer-bytes-in-flight`.
    pub max_answer_bytes_in_flight: u64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            job_fn: engine_job_fn(),
            workers: 1,
            max_upload_bytes: 2 * 1024 * 1024,
            lease: Duration::from_secs(15),
            grace: Duration::from_secs(10),
            client_timeout: Duration::from_secs(30),
            idle_timeout: Duration::from_secs(120),
            max_joint_change_deg: drawcal::compensate::DEFAULT_MAX_JOINT_CHANGE_DEG,
            cors_origins: Vec::new(),
            limits: Default::default(),
            max_connections: None,
            max_answer_bytes_in_flight: 1 << 30,
        }
    }
}

impl TestApp {
    pub async fn spawn(tag: &str) -> TestApp {
        Self::spawn_with(tag, Options::default()).await
    }

    pub async fn spawn_with(tag: &str, o: Options) -> TestApp {
        let dir = fresh_dir(tag);
        let db_url = format!("sqlite://{}", dir.join("drawcal.db").display());
        Self::spawn_on(&db_url, o).await
    }

    pub async fn spawn_on(db_url: &str, o: Options) -> TestApp {
        let cfg = ServiceConfig {
            listen: "127.0.0.1:0".parse().unwrap(),
            database_url: db_url.to_string(),
            max_upload_bytes: o.max_upload_bytes,
            client_timeout: o.client_timeout,
            idle_timeout: o.idle_timeout,
            max_joint_change_deg: o.max_joint_change_deg,
            insecure_no_auth: false,
            bootstrap_admin_key: None,
            allowed_hosts: Vec::new(),
            cors_origins: o.cors_origins.clone(),
            limits: o.limits,
            max_connections: o.max_connections,
            max_answer_bytes_in_flight: o.max_answer_bytes_in_flight,
            activation_bounds: Default::default(),
            jobs: JobConfig {
                workers: o.workers,
                lease: o.lease,
                poll: Duration::from_millis(100),
                shutdown_grace: o.grace,
                max_attempts: 3,
                max_interruptions: 10,
            },
        };
        let service = Service::start(&cfg, o.job_fn)
            .await
            .expect("service starts");
        // Every test client holds an admin key (the auth tests make their
        // own keys and clients); a restart on the same database makes
        // another.
        let store = &service.state().store;
        let n = store.list_keys().await.expect("keys").len();
        let name = match n {
            0 => "test-admin".to_string(),
            n => format!("test-admin-{n}"),
        };
        let admin = drawcal::http::keys::create(store, "test harness", &name, "admin", None, &[])
            .await
            .expect("an admin key");
        let base = format!("http://{}", service.addr);
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(service.run(async move {
            let _ = rx.await;
        }));
        TestApp {
            base,
            client: client_with_key(&admin.secret),
            admin_key: admin.secret,
            db_url: db_url.to_string(),
            shutdown: Some(tx),
            task: Some(task),
        }
    }

    /// Graceful shutdown, waiting for it to complete.
    pub async fn stop(mut self) {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        if let Some(t) = self.task.take() {
            t.await.expect("server task").expect("server ran");
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    pub async fn get(&self, path: &str) -> Response {
        self.client
            .get(self.url(path))
            .send()
            .await
            .expect("request")
    }

    pub async fn post_json(&self, path: &str, body: &Value) -> Response {
        self.client
            .post(self.url(path))
            .json(body)
            .send()
            .await
            .expect("request")
    }

    pub async fn post_raw(
        &self,
        path: &str,
        content_type: Option<&str>,
        body: impl Into<reqwest::Body>,
    ) -> Response {
        let mut r = self.client.post(self.url(path)).body(body);
        if let Some(ct) = content_type {
            r = r.header("content-type", ct);
        }
        r.send().await.expect("request")
    }

    /// Create model, robot, rig and session from a dataset; returns
    /// (model_id, robot_id, rig_id, session_id).
    pub async fn setup(&self, dataset: &str, serial: &str) -> (i64, i64, i64, i64) {
        self.setup_from(
            &read(dataset, "robot.json"),
            &read(dataset, "rig.json"),
            serial,
        )
        .await
    }

    /// [`TestApp::setup`] from the texts of robot.json and rig.json.
    pub async fn setup_from(
        &self,
        robot_json: &str,
        rig_json: &str,
        serial: &str,
    ) -> (i64, i64, i64, i64) {
        let model = ok_json(
            self.post_raw("/models", Some("application/json"), robot_json.to_string())
                .await,
            201,
        )
        .await;
        let robot = ok_json(
            self.post_json(
                "/robots",
                &json!({"serial_number": serial, "model_id": model["id"], "site": "plant-1", "line": "L2", "cell": "C7"}),
            )
            .await,
            201,
        )
        .await;
        let rig = ok_json(
            self.post_raw("/rigs", Some("application/json"), rig_json.to_string())
                .await,
            201,
        )
        .await;
        let session = ok_json(
            self.post_json(
                "/sessions",
                &json!({"robot_id": robot["id"], "rig_id": rig["id"], "name": "test"}),
            )
            .await,
            201,
        )
        .await;
        (
            model["id"].as_i64().unwrap(),
            robot["id"].as_i64().unwrap(),
            rig["id"].as_i64().unwrap(),
            session["id"].as_i64().unwrap(),
        )
    }

    /// Upload a poses CSV to a session (must be accepted); the answer.
    pub async fn upload_poses(&self, session: i64, poses_csv: String) -> Value {
        ok_json(
            self.post_raw(
                &format!("/sessions/{session}/poses"),
                Some("text/csv"),
                poses_csv,
            )
            .await,
            200,
        )
        .await
    }

    /// Upload poses.csv to a session and run its identification job to
    /// success; returns the finished job.
    pub async fn identify_session(&self, session: i64, poses_csv: String) -> Value {
        self.identify_session_with(session, poses_csv, &serde_json::json!({}))
            .await
    }

    /// [`Self::identify_session`] with job options.
    pub async fn identify_session_with(
        &self,
        session: i64,
        poses_csv: String,
        options: &Value,
    ) -> Value {
        self.upload_poses(session, poses_csv).await;
        let job = ok_json(
            self.post_raw(
                &format!("/sessions/{session}/jobs"),
                Some("application/json"),
                options.to_string(),
            )
            .await,
            202,
        )
        .await;
        let done = self
            .wait_job(job["id"].as_i64().unwrap(), Duration::from_secs(600))
            .await;
        assert_eq!(done["state"], "succeeded", "{done}");
        done
    }

    /// [`Self::identify_session`], then activate the result; returns the
    /// calibration id.
    pub async fn calibrate_and_activate(
        &self,
        robot: i64,
        session: i64,
        poses_csv: String,
        reason: &str,
    ) -> i64 {
        let done = self.identify_session(session, poses_csv).await;
        let cal = done["calibration_id"].as_i64().unwrap();
        ok_json(
            self.post_json(
                &format!("/robots/{robot}/activate"),
                &serde_json::json!({"calibration_id": cal, "reason": reason}),
            )
            .await,
            200,
        )
        .await;
        cal
    }

    /// Simulate a session from a `drawcal simulate` spec, create its model,
    /// robot (`serial`), rig and session through the API, calibrate it and
    /// activate the result; returns (robot_id, calibration_id, simulation).
    pub async fn calibrate_simulated(
        &self,
        spec: Value,
        serial: &str,
    ) -> (i64, i64, drawcal::physics::simulate::Simulated) {
        let spec: drawcal::physics::simulate::Spec = serde_json::from_value(spec).unwrap();
        let sim = drawcal::physics::simulate::generate(&spec).unwrap();
        let dir = fresh_dir("simulated-data");
        drawcal::cli::simulate::write(&sim, &dir).unwrap();
        let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap();
        let model = ok_json(
            self.post_raw("/models", Some("application/json"), read("robot.json"))
                .await,
            201,
        )
        .await;
        let robot = ok_json(
            self.post_json(
                "/robots",
                &json!({"serial_number": serial, "model_id": model["id"]}),
            )
            .await,
            201,
        )
        .await["id"]
            .as_i64()
            .unwrap();
        let rig = ok_json(
            self.post_raw("/rigs", Some("application/json"), read("rig.json"))
                .await,
            201,
        )
        .await;
        let session = ok_json(
            self.post_json(
                "/sessions",
                &json!({"robot_id": robot, "rig_id": rig["id"], "name": serial}),
            )
            .await,
            201,
        )
        .await["id"]
            .as_i64()
            .unwrap();
        let cal = self
            .calibrate_and_activate(robot, session, read("poses.csv"), serial)
            .await;
        (robot, cal, sim)
    }

    /// Poll a job until it ends (bounded by a generous number of polls).
    pub async fn wait_job(&self, job_id: i64, max_wait: Duration) -> Value {
        let polls = (max_wait.as_millis() / 100).max(1);
        for _ in 0..polls {
            let job = ok_json(self.get(&format!("/jobs/{job_id}")).await, 200).await;
            let state = job["state"].as_str().unwrap().to_string();
            if ["succeeded", "failed", "cancelled"].contains(&state.as_str()) {
                return job;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        panic!("job {job_id} did not end in time");
    }

    /// Everything stored, for before/after comparisons of bad requests.
    pub async fn snapshot(&self) -> Value {
        let mut all = serde_json::Map::new();
        for path in [
            "/models",
            "/robots",
            "/rigs",
            "/sessions",
            "/jobs",
            "/calibrations",
        ] {
            all.insert(
                path.into(),
                ok_json(self.get(&format!("{path}?limit=1000")).await, 200).await,
            );
        }
        let sessions = all["/sessions"]["items"].as_array().unwrap().clone();
        for s in sessions {
            let id = s["id"].as_i64().unwrap();
            let r = self.get(&format!("/sessions/{id}/poses")).await;
            all.insert(
                format!("/sessions/{id}/poses"),
                Value::String(r.text().await.unwrap()),
            );
        }
        let robots = all["/robots"]["items"].as_array().unwrap().clone();
        for r in robots {
            let id = r["id"].as_i64().unwrap();
            all.insert(
                format!("/robots/{id}/activations"),
                ok_json(self.get(&format!("/robots/{id}/activations")).await, 200).await,
            );
        }
        Value::Object(all)
    }
}

/// Assert the status and return the JSON body.
pub async fn ok_json(r: Response, status: u16) -> Value {
    let got = r.status();
    let text = r.text().await.expect("body");
    assert_eq!(
        got,
        StatusCode::from_u16(status).unwrap(),
        "unexpected status; body: {text}"
    );
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("not JSON ({e}): {text}"))
}

/// Assert an error answer: status, code, and the error body's shape.
pub async fn err_json(r: Response, status: u16, code: &str) -> Value {
    let v = ok_json(r, status).await;
    assert_eq!(v["error"], code, "error code: {v}");
    assert!(
        v["message"].as_str().is_some_and(|m| !m.is_empty()),
        "message: {v}"
    );
    for k in v.as_object().unwrap().keys() {
        assert!(
            ["error", "message", "field", "row"].contains(&k.as_str()),
            "unexpected key {k} in {v}"
        );
    }
    v
}

/// A stand-in engine for job-machinery tests: runs `steps` steps of
/// `step` each, reporting progress and honouring cancellation, then fails
/// with a recognisable message (it has no report to give).
pub fn slow_job_fn(
    steps: usize,
    step: Duration,
    started: Arc<std::sync::atomic::AtomicUsize>,
) -> JobFn {
    Arc::new(move |_input, progress| {
        started.fetch_add(1, Ordering::SeqCst);
        for i in 0..steps {
            if progress.cancelled() {
                return Err(drawcal::Error::Cancelled);
            }
            progress.update("stand-in", i as f64 / steps as f64);
            std::thread::sleep(step);
        }
        Err(drawcal::Error::Numerical("stand-in engine finished".into()))
    })
}

/// The compensated joints (deg) of result `k` of a `/compensate` answer.
pub fn q_at(answer: &Value, k: usize) -> Vec<f64> {
    answer["results"][k]["q_deg"]
        .as_array()
        .unwrap_or_else(|| panic!("{answer}"))
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect()
}
