//! The built binary as the Dockerfile runs it, and SIGKILL during a job.
//!
//! No Docker engine runs here, so the Dockerfile's runtime stage is read
//! (ENV, ENTRYPOINT + CMD, HEALTHCHECK) and the binary is started with the
//! same arguments and environment; only the volume (`/data` -> a temp dir)
//! and the published port are mapped, as `docker run -v -p` would.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use serde_json::{Value, json};

use crate::helpers::{fresh_dir, ok_json, read};

struct RuntimeStage {
    env: Vec<(String, String)>,
    argv: Vec<String>,
    healthcheck: Vec<String>,
    user: String,
    volume: String,
}

fn json_array(s: &str) -> Vec<String> {
    serde_json::from_str(s.trim())
        .unwrap_or_else(|e| panic!("not an exec-form JSON array ({e}): {s}"))
}

fn parse_dockerfile() -> RuntimeStage {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/Dockerfile"))
        .expect("Dockerfile");
    // Join continuation lines, drop comments, keep the last stage.
    let mut logical = Vec::new();
    let mut cur = String::new();
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with('#') && cur.is_empty() {
            continue;
        }
        if let Some(stripped) = t.strip_suffix('\\') {
            cur.push_str(stripped);
            cur.push(' ');
        } else {
            cur.push_str(t);
            if !cur.trim().is_empty() {
                logical.push(cur.trim().to_string());
            }
            cur.clear();
        }
    }
    let last_from = logical
        .iter()
        .rposition(|l| l.starts_with("FROM "))
        .expect("a FROM");
    assert!(last_from > 0, "multi-stage build expected");
    let stage = &logical[last_from..];
    let mut env = Vec::new();
    let (mut entry, mut cmd, mut hc, mut user, mut volume) =
        (vec![], vec![], vec![], String::new(), String::new());
    for l in stage {
        let (instr, rest) = l.split_once(' ').unwrap_or((l, ""));
        match instr {
            "ENV" => {
                for kv in rest.split_whitespace() {
                    let (k, v) = kv.split_once('=').expect("ENV key=value");
                    env.push((k.to_string(), v.to_string()));
                }
            }
            "ENTRYPOINT" => entry = json_array(rest),
            "CMD" => cmd = json_array(rest),
            "USER" => user = rest.trim().to_string(),
            "VOLUME" => volume = json_array(rest).remove(0),
            "HEALTHCHECK" => {
                let at = rest.find("CMD ").expect("HEALTHCHECK CMD");
                hc = json_array(&rest[at + 4..]);
            }
            _ => {}
        }
    }
    entry.extend(cmd);
    RuntimeStage {
        env,
        argv: entry,
        healthcheck: hc,
        user,
        volume,
    }
}

/// The binary under test: `DRAWCAL_BIN` if set (an installed build), else
/// this package's.
fn bin() -> String {
    std::env::var("DRAWCAL_BIN").unwrap_or_else(|_| env!("CARGO_BIN_EXE_drawcal").to_string())
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Start the built binary like the container would: `argv` from
/// ENTRYPOINT + CMD, the ENV, `/data` mapped to `data`, port mapped.
fn start(stage: &RuntimeStage, data: &Path, port: u16, extra_env: &[(&str, &str)]) -> Child {
    assert_eq!(stage.argv[0], "drawcal");
    let mut cmd = Command::new(bin());
    cmd.args(&stage.argv[1..]).env_clear().current_dir(data);
    for (k, v) in &stage.env {
        let v = v
            .replace(&stage.volume, &data.display().to_string())
            .replace("0.0.0.0:8080", &format!("127.0.0.1:{port}"));
        cmd.env(k, v);
    }
    // The first admin key, as a container is given it.
    cmd.env("DRAWCAL_ADMIN_KEY", crate::helpers::TEST_ADMIN_KEY);
    for (k, v) in extra_env {
        cmd.env(k, v);
    }
    cmd.stdout(Stdio::null()).stderr(Stdio::from(
        std::fs::File::create(data.join(format!("server-{port}.log"))).unwrap(),
    ));
    cmd.spawn().expect("start the drawcal binary")
}

async fn wait_ready(client: &reqwest::Client, base: &str, child: &mut Child) {
    for _ in 0..300 {
        if let Ok(r) = client.get(format!("{base}/ready")).send().await {
            if r.status() == 200 {
                return;
            }
        }
        if let Some(st) = child.try_wait().unwrap() {
            panic!("server exited early: {st}");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("server not ready");
}

fn signal(child: &Child, sig: &str) {
    let st = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn binary_runs_as_the_dockerfile_says() {
    let stage = parse_dockerfile();
    assert!(
        !stage.user.is_empty() && stage.user != "root",
        "runs as a non-root user"
    );
    assert!(
        stage
            .env
            .iter()
            .any(|(k, v)| k == "DATABASE_URL" && v.contains(&stage.volume)),
        "database on the volume"
    );
    let data = fresh_dir("docker");
    let port = free_port();
    let mut child = start(&stage, &data, port, &[]);
    let base = format!("http://127.0.0.1:{port}");
    let client = crate::helpers::client_with_key(crate::helpers::TEST_ADMIN_KEY);
    wait_ready(&client, &base, &mut child).await;
    // The HEALTHCHECK command itself, against the mapped port.
    let hc: Vec<String> = stage
        .healthcheck
        .iter()
        .map(|a| a.replace("/8080", &format!("/{port}")))
        .collect();
    let st = Command::new(&hc[0]).args(&hc[1..]).status().unwrap();
    assert!(st.success(), "HEALTHCHECK {hc:?} passes");
    // The database file is on the volume.
    assert!(data.join("drawcal.db").exists());
    let h: Value = client
        .get(format!("{base}/health"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(h["status"], "ok");
    // SIGTERM: graceful exit with status 0.
    signal(&child, "-TERM");
    let mut exited = None;
    for _ in 0..200 {
        if let Some(s) = child.try_wait().unwrap() {
            exited = Some(s);
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let s = exited.expect("exits after SIGTERM");
    assert!(s.success(), "graceful exit: {s}");
    let st = Command::new(&hc[0]).args(&hc[1..]).status().unwrap();
    assert!(
        !st.success(),
        "the health check fails when the server is down"
    );
}

/// `--runtime-threads` (here `DRAWCAL_RUNTIME_THREADS`) sets the async
/// runtime's worker threads: the start line gives the runtime's own count
/// of them (tokio's metrics, not the flag echoed).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn runtime_threads_flag_sets_the_runtime_and_is_printed() {
    let stage = parse_dockerfile();
    let client = crate::helpers::client_with_key(crate::helpers::TEST_ADMIN_KEY);
    for n in ["1", "3"] {
        let data = fresh_dir(&format!("runtime-threads-{n}"));
        let port = free_port();
        let mut child = start(&stage, &data, port, &[("DRAWCAL_RUNTIME_THREADS", n)]);
        wait_ready(&client, &format!("http://127.0.0.1:{port}"), &mut child).await;
        signal(&child, "-TERM");
        child.wait().unwrap();
        let log = std::fs::read_to_string(data.join(format!("server-{port}.log"))).unwrap();
        assert!(
            log.contains(&format!("runtime_threads={n} ")),
            "the start line gives the runtime's worker count: {log}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigkill_during_a_job_then_restart_completes_it() {
    let stage = parse_dockerfile();
    let data = fresh_dir("sigkill");
    let port = free_port();
    let extra = [("DRAWCAL_JOB_LEASE_SECS", "2")];
    let mut child = start(&stage, &data, port, &extra);
    let base = format!("http://127.0.0.1:{port}");
    let client = crate::helpers::client_with_key(crate::helpers::TEST_ADMIN_KEY);
    wait_ready(&client, &base, &mut child).await;

    let ds = "real_ur10_ipa_random";
    let post = |path: &str, ct: &str, body: String| {
        client
            .post(format!("{base}{path}"))
            .header("content-type", ct)
            .body(body)
            .send()
    };
    let model = ok_json(
        post("/models", "application/json", read(ds, "robot.json"))
            .await
            .unwrap(),
        201,
    )
    .await;
    let robot = ok_json(
        post(
            "/robots",
            "application/json",
            json!({"serial_number": "UR10-K", "model_id": model["id"]}).to_string(),
        )
        .await
        .unwrap(),
        201,
    )
    .await;
    let rig = ok_json(
        post("/rigs", "application/json", read(ds, "rig.json"))
            .await
            .unwrap(),
        201,
    )
    .await;
    let session = ok_json(
        post(
            "/sessions",
            "application/json",
            json!({"robot_id": robot["id"], "rig_id": rig["id"]}).to_string(),
        )
        .await
        .unwrap(),
        201,
    )
    .await;
    let sid = session["id"].as_i64().unwrap();
    let up = ok_json(
        post(
            &format!("/sessions/{sid}/poses"),
            "text/csv",
            read(ds, "poses.csv"),
        )
        .await
        .unwrap(),
        200,
    )
    .await;
    let n_poses = up["session"]["n_poses"].as_i64().unwrap();
    let job = ok_json(
        post(
            &format!("/sessions/{sid}/jobs"),
            "application/json",
            "{}".into(),
        )
        .await
        .unwrap(),
        202,
    )
    .await;
    let jid = job["id"].as_i64().unwrap();

    // Wait until a worker runs it, then SIGKILL the process.
    let mut running = false;
    for _ in 0..400 {
        let j: Value = client
            .get(format!("{base}/jobs/{jid}"))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        if j["state"] == "running" {
            running = true;
            break;
        }
        assert_eq!(
            j["state"], "queued",
            "the job must still be in progress when killed: {j}"
        );
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    assert!(running);
    signal(&child, "-KILL");
    let _ = child.wait();

    // Restart on the same volume: the lease expires, the job runs again and
    // completes; nothing stored is lost.
    let port2 = free_port();
    let mut child2 = start(&stage, &data, port2, &extra);
    let base2 = format!("http://127.0.0.1:{port2}");
    wait_ready(&client, &base2, &mut child2).await;
    let mut done = Value::Null;
    for _ in 0..6000 {
        let j: Value = client
            .get(format!("{base2}/jobs/{jid}"))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        if ["succeeded", "failed", "cancelled"].contains(&j["state"].as_str().unwrap()) {
            done = j;
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert_eq!(done["state"], "succeeded", "after restart: {done}");
    assert_eq!(
        (&done["attempts"], &done["interruptions"]),
        (&Value::from(0), &Value::from(1)),
        "the kill interrupted it once, which is not an attempt: {done}"
    );
    let s: Value = client
        .get(format!("{base2}/sessions/{sid}"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(s["n_poses"].as_i64().unwrap(), n_poses);
    let cal: Value = client
        .get(format!("{base2}/calibrations/{}", done["calibration_id"]))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(cal["calibration"]["version"], 1);
    let all: Value = client
        .get(format!("{base2}/calibrations"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(all["total"], 1, "exactly one calibration from the job");
    signal(&child2, "-TERM");
    assert!(child2.wait().unwrap().success());
}

/// The service walkthrough of docs/SERVICE.md, run as written against the
/// built binary on an empty database (only the port is changed).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn readme_walkthrough_works_as_written() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/SERVICE.md")).unwrap();
    let start = readme
        .find("<!-- SERVICE SECTION START")
        .expect("service section");
    let end = readme
        .find("<!-- SERVICE SECTION END -->")
        .expect("service section end");
    let section = &readme[start..end];
    let blocks: Vec<&str> = section
        .split("```sh\n")
        .skip(1)
        .map(|b| b.split("```").next().unwrap())
        .collect();
    assert!(blocks.len() >= 2, "a server block and a client block");
    assert_eq!(blocks[0].trim(), "cargo run --release -- serve");

    // The first block, from an empty directory (so ./drawcal.db is new).
    let dir = fresh_dir("readme");
    let port = free_port();
    let mut child = Command::new(bin())
        .arg("serve")
        .current_dir(&dir)
        .env_remove("DATABASE_URL")
        .env("DRAWCAL_LISTEN", format!("127.0.0.1:{port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::from(
            std::fs::File::create(dir.join("server.log")).unwrap(),
        ))
        .spawn()
        .unwrap();
    let client = crate::helpers::client_with_key(crate::helpers::TEST_ADMIN_KEY);
    wait_ready(&client, &format!("http://127.0.0.1:{port}"), &mut child).await;

    // The port, and the key made on this service's database with the
    // built binary (not a second release build).
    let script = blocks[1..]
        .join("\n")
        .replace(
            "BASE=http://127.0.0.1:8080",
            &format!("BASE=http://127.0.0.1:{port}"),
        )
        .replace(
            "cargo run --release -q -- keys create",
            &format!(
                "{} keys create --database sqlite://{}/drawcal.db",
                bin(),
                dir.display()
            ),
        );
    let out = tokio::task::spawn_blocking(move || {
        Command::new("bash")
            .args(["-euo", "pipefail", "-c", &script])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    signal(&child, "-TERM");
    let _ = child.wait();
    assert!(
        out.status.success(),
        "walkthrough failed: {stderr}\n{stdout}"
    );
    assert!(
        dir.join("drawcal.db").exists(),
        "the default database file was created"
    );
    assert!(stdout.contains("\"state\":\"succeeded\""), "{stdout}");
    // Both targets compensated, with the calibration that produced them.
    let comp_line = stdout
        .lines()
        .find(|l| l.contains("\"results\""))
        .expect("compensation answer");
    let comp: Value = serde_json::from_str(comp_line).unwrap();
    assert_eq!(comp["calibration_id"], 1);
    assert_eq!(comp["version"], 1);
    assert_eq!(comp["n_ok"], 2, "{comp}");
    assert!(
        stdout.contains("calibration_id,robot_id,serial_number"),
        "CSV export"
    );
}

/// The build stage copies everything the release build reads: the
/// manifest's targets and every file `include_str!`/`include_bytes!` pulls in.
#[test]
fn dockerfile_build_stage_copies_what_the_build_reads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("Dockerfile")).unwrap();
    let build_stage: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.starts_with("FROM "))
        .skip(1)
        .take_while(|l| !l.starts_with("FROM "))
        .collect();
    let copied: Vec<String> = build_stage
        .iter()
        .filter_map(|l| l.strip_prefix("COPY "))
        .filter(|l| !l.starts_with("--from"))
        .flat_map(|l| {
            let parts: Vec<&str> = l.split_whitespace().collect();
            parts[..parts.len() - 1]
                .iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
        })
        .collect();
    let is_copied = |rel: &str| {
        copied
            .iter()
            .any(|c| rel == c || rel.starts_with(&format!("{c}/")))
    };
    // Manifest targets.
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
    for line in manifest.lines() {
        if let Some(p) = line.trim().strip_prefix("path = ") {
            let p = p.trim_matches('"');
            assert!(
                is_copied(p),
                "Cargo.toml target {p} is not copied into the build stage"
            );
        }
    }
    for (name, dir) in [("bench", "benches")] {
        if manifest.contains(&format!("[[{name}]]")) {
            assert!(is_copied(dir), "{dir} not copied");
        }
    }
    assert!(is_copied("Cargo.lock") && is_copied("src/lib.rs") && is_copied("migrations/sqlite/x"));
    // Files embedded by the source.
    let mut stack = vec![root.join("src")];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            let src = std::fs::read_to_string(&p).unwrap_or_default();
            for mac in ["include_str!(\"", "include_bytes!(\""] {
                for (i, _) in src.match_indices(mac) {
                    let rest = &src[i + mac.len()..];
                    let rel = &rest[..rest.find('"').unwrap()];
                    let full = p.parent().unwrap().join(rel);
                    let mut norm = std::path::PathBuf::new();
                    for c in full.strip_prefix(root).unwrap().components() {
                        match c {
                            std::path::Component::ParentDir => {
                                norm.pop();
                            }
                            other => norm.push(other),
                        }
                    }
                    let norm = norm.to_string_lossy().to_string();
                    assert!(
                        is_copied(&norm),
                        "{} embeds {norm}, which the Dockerfile does not copy",
                        p.display()
                    );
                }
            }
        }
    }
}
