//! The history CSV's bytes, pinned: a few calibrations with awkward text
//! (quotes, commas, formula-like cells, non-ASCII, absent tags) and figures
//! (a tie of the fifth decimal, values just either side of one, absent
//! ones), exported through the service, compared byte for byte with the
//! CSV as the service wrote it before the export was made fast (the
//! expected figures are `{:.4}` of the exact binary values, worked out
//! independently). On SQLite, and on PostgreSQL when it is there: the two
//! read rows differently (SQLite through its C interface).

use drawcal::store::{NewCalibration, NewRobot, Store};

use crate::helpers::{Options, TestApp, ok_json, read};

/// No job workers: the test claims and completes its own jobs.
fn no_workers() -> Options {
    Options {
        workers: 0,
        ..Options::default()
    }
}

fn cal(
    before: Option<f64>,
    after: Option<f64>,
    train: Option<f64>,
    effects: &str,
) -> NewCalibration {
    NewCalibration {
        method: "lm".into(),
        n_poses: 50,
        n_test: 15,
        test_rms_before_mm: before,
        test_rms_after_mm: after,
        train_rms_after_mm: train,
        effects: effects.into(),
        report_json: "{}".into(),
    }
}

/// Seed the calibrations through the store (as a job's success writes
/// them), export them through the service, and compare.
async fn pinned_bytes(app: &TestApp) {
    let store = Store::connect(&app.db_url).await.unwrap();
    let model = store
        .create_model("ER3A", 6, &read("er3a_paper_like", "robot.json"))
        .await
        .unwrap();
    let rig = store
        .create_rig("rig", 4, &read("er3a_paper_like", "rig.json"))
        .await
        .unwrap();
    let robot =
        |serial: &str, site: Option<&str>, line: Option<&str>, cell: Option<&str>| NewRobot {
            serial_number: serial.into(),
            model_id: model.id,
            site: site.map(Into::into),
            line: line.map(Into::into),
            cell: cell.map(Into::into),
        };
    let r1 = store
        .create_robot(&robot(
            "=HYPERLINK(\"x\"),1",
            Some("-west"),
            Some("L 2;a"),
            None,
        ))
        .await
        .unwrap();
    let r2 = store
        .create_robot(&robot("Zürich 7", Some("plant \"B\""), None, Some("@c1")))
        .await
        .unwrap();
    // A robot whose rows are long (quoted, guarded, non-ASCII text), for
    // an export of several pieces (32 KB each): every row of it must come
    // whole and in order, across the pieces' edges.
    let long_serial = format!("={}", "x\"y,z ".repeat(40));
    let long_site = format!("-{}", "ü".repeat(60));
    let r3 = store
        .create_robot(&robot(
            &long_serial,
            Some(&long_site),
            Some("L\n3"),
            Some("+c"),
        ))
        .await
        .unwrap();
    let figures = [
        (
            cal(
                Some(0.03125),
                Some(1.5e-5),
                Some(12345.678_95),
                "joint_compliance,backlash",
            ),
            "0.0312,0.0000,12345.6789,joint_compliance;backlash",
        ),
        (
            cal(None, Some(0.00015), Some(2.0 / 3.0), ""),
            ",0.0001,0.6667,",
        ),
        (
            cal(Some(7.0), Some(0.99995), None, "thermal"),
            "7.0000,1.0000,,thermal",
        ),
        (
            cal(Some(4.99995), Some(0.00125), Some(0.0), ""),
            "5.0000,0.0013,0.0000,",
        ),
    ];
    let mut ids = Vec::new();
    for (r, c) in [
        (&r1, figures[0].0.clone()),
        (&r2, figures[1].0.clone()),
        (&r1, figures[2].0.clone()),
        (&r2, figures[3].0.clone()),
    ]
    .into_iter()
    .chain((0..LONG_ROWS).map(|i| (&r3, figures[i % 4].0.clone())))
    {
        let s = store.create_session(r.id, rig.id, None).await.unwrap();
        store.create_job(s.id, r.id, "{}", 3).await.unwrap();
        let job = store.claim_job("pin", 60_000, 10).await.unwrap().unwrap();
        let rec = store.complete_job(job.id, "pin", &c).await.unwrap();
        ids.push((rec.id, rec.robot_id, rec.session_id, rec.job_id));
    }
    store
        .set_active(r2.id, Some(ids[1].0), "activate", "t", "pin")
        .await
        .unwrap();
    store.close().await;

    // Only the dates are the store's own ("now"): taken from the JSON list.
    let list = ok_json(app.get("/calibrations?limit=1000").await, 200).await;
    let created: Vec<String> = list["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["created_at"].as_str().unwrap().to_string())
        .collect();
    let (m, rows) = (
        model.id,
        [
            "{id},{robot},\"'=HYPERLINK(\"\"x\"\"),1\",{m},'-west,L 2;a,,1,{created},lm,50,15,0.0312,0.0000,12345.6789,joint_compliance;backlash,false,{session},{job}",
            "{id},{robot},Zürich 7,{m},\"plant \"\"B\"\"\",,'@c1,1,{created},lm,50,15,,0.0001,0.6667,,true,{session},{job}",
            "{id},{robot},\"'=HYPERLINK(\"\"x\"\"),1\",{m},'-west,L 2;a,,2,{created},lm,50,15,7.0000,1.0000,,thermal,false,{session},{job}",
            "{id},{robot},Zürich 7,{m},\"plant \"\"B\"\"\",,'@c1,2,{created},lm,50,15,5.0000,0.0013,0.0000,,false,{session},{job}",
        ],
    );
    let header = String::from(
        "calibration_id,robot_id,serial_number,model_id,site,line,cell,version,created_at,\
         method,n_poses,n_test,test_rms_before_mm,test_rms_after_mm,train_rms_after_mm,\
         effects,active,session_id,job_id\n",
    );
    let long_row = format!(
        "{{id}},{{robot}},\"'={}\",{{m}},'{long_site},\"L\n3\",'+c,{{version}},{{created}},lm,50,15,{{figures}},false,{{session}},{{job}}",
        "x\"\"y,z ".repeat(40)
    );
    let rows: Vec<String> = rows
        .iter()
        .map(|r| r.to_string())
        .chain((0..LONG_ROWS).map(|i| {
            long_row
                .replace("{version}", &(i + 1).to_string())
                .replace("{figures}", figures[i % 4].1)
        }))
        .collect();
    // Each record, ended (a cell may hold a line break: no `lines()`).
    let body: Vec<String> = rows
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let (id, robot, session, job) = ids[i];
            row.replace("{id}", &id.to_string())
                .replace("{robot}", &robot.to_string())
                .replace("{m}", &m.to_string())
                .replace("{created}", &created[i])
                .replace("{session}", &session.to_string())
                .replace("{job}", &job.to_string())
                + "\n"
        })
        .collect();
    let want = header.clone() + &body.concat();
    assert!(want.len() > 3 * 32 * 1024, "{} bytes", want.len());
    let r = app.get("/calibrations?format=csv").await;
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-type"], "text/csv");
    assert_eq!(r.text().await.unwrap(), want);
    // A filtered export (the site filter's own statement) and a robot's
    // accuracy history: the same rows' bytes.
    let pick = |ks: &[usize]| -> String {
        let mut s = header.clone();
        for &k in ks {
            s += &body[k];
        }
        s
    };
    let site = app
        .get("/calibrations?format=csv&site=-west")
        .await
        .text()
        .await
        .unwrap();
    assert_eq!(site, pick(&[0, 2]));
    let acc = app
        .get(&format!("/robots/{}/accuracy?format=csv", r2.id))
        .await
        .text()
        .await
        .unwrap();
    assert_eq!(acc, pick(&[1, 3]));
    let long: Vec<usize> = (4..4 + LONG_ROWS).collect();
    let site = app
        .get(&format!(
            "/calibrations?format=csv&site={}",
            enc(&long_site)
        ))
        .await
        .text()
        .await
        .unwrap();
    assert_eq!(site, pick(&long));
    let acc = app
        .get(&format!("/robots/{}/accuracy?format=csv", r3.id))
        .await
        .text()
        .await
        .unwrap();
    assert_eq!(acc, pick(&long));
}

/// The long robot's calibrations: about 700 bytes a row, so the whole
/// export is more than three pieces.
const LONG_ROWS: usize = 200;

/// `s` percent-encoded for a query string.
fn enc(s: &str) -> String {
    s.bytes()
        .map(|b| {
            if b.is_ascii_alphanumeric() {
                (b as char).to_string()
            } else {
                format!("%{b:02X}")
            }
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn history_csv_bytes_are_pinned_sqlite() {
    let app = TestApp::spawn_with("history_csv", no_workers()).await;
    pinned_bytes(&app).await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn history_csv_bytes_are_pinned_postgres() {
    let Some((admin, mut conn)) =
        crate::requires::postgres("history_csv_bytes_are_pinned_postgres").await
    else {
        return;
    };
    let name = format!(
        "drawcal_csv_{}_{}",
        std::process::id(),
        drawcal::store::now_ms()
    );
    sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}")))
        .execute(&mut conn)
        .await
        .unwrap();
    let url = format!("{}/{name}", admin.rsplit_once('/').unwrap().0);
    let app = TestApp::spawn_on(&url, no_workers()).await;
    pinned_bytes(&app).await;
    app.stop().await;
    sqlx::query(sqlx::AssertSqlSafe(format!(
        "DROP DATABASE {name} WITH (FORCE)"
    )))
    .execute(&mut conn)
    .await
    .unwrap();
}
