//! Store conformance: one suite, run against SQLite and PostgreSQL, each on
//! a fresh database; and the two migration folders in lockstep.

use std::collections::BTreeSet;
use std::time::Duration;

use futures_util::TryStreamExt;

use drawcal::store::{
    CalibrationFilter, NewCalibration, NewKey, NewRobot, Page, Store, StoreError,
};

use crate::helpers::{fresh_dir, read};

const PAGE: Page = Page {
    limit: 100,
    offset: 0,
};

fn cal(rms: f64) -> NewCalibration {
    NewCalibration {
        method: "lm".into(),
        n_poses: 50,
        n_test: 15,
        test_rms_before_mm: Some(rms * 10.0),
        test_rms_after_mm: Some(rms),
        train_rms_after_mm: Some(rms * 0.9),
        effects: "joint_compliance".into(),
        report_json: format!("{{\"rms\": {rms}}}"),
    }
}

/// Keys and the audit log: a taken name is a conflict; a key is found by
/// its hash and revoked; activations (above) and key changes write their
/// audit entry with themselves, newest first.
async fn keys_and_audit(store: &Store) {
    let new = |name: &str, hash: &str| NewKey {
        name: name.into(),
        role: "reader".into(),
        sites: String::new(),
        prefix: "dck_0123".into(),
        secret_hash: hash.into(),
        expires_at: None,
    };
    let k = store.create_key(&new("mes", "h1"), "ann").await.unwrap();
    assert!(matches!(
        store.create_key(&new("mes", "h2"), "ann").await,
        Err(StoreError::Conflict(_))
    ));
    assert_eq!(store.key_by_hash("h1").await.unwrap().unwrap().id, k.id);
    assert!(store.key_by_hash("h2").await.unwrap().is_none());
    let revoked = store.revoke_key(k.id, "bob").await.unwrap();
    assert!(revoked.revoked_at.is_some());
    assert!(matches!(
        store.revoke_key(9999, "bob").await,
        Err(StoreError::NotFound { .. })
    ));
    let (log, total) = store.list_audit(PAGE).await.unwrap();
    let seen: Vec<(&str, &str)> = log
        .iter()
        .map(|e| (e.actor.as_str(), e.action.as_str()))
        .collect();
    assert_eq!(
        seen,
        [
            ("bob", "revoke_key"),
            ("ann", "create_key"),
            ("cy", "rollback"),
            ("cy", "rollback"),
            ("bob", "activate"),
            ("ann", "activate"),
        ],
        "{log:?}"
    );
    assert_eq!(total, 6);
}

async fn suite(store: Store) {
    store.ping().await.unwrap();
    // Models, robots, rigs.
    let robot_json = read("er3a_paper_like", "robot.json");
    let m = store.create_model("ER3A", 6, &robot_json).await.unwrap();
    assert_eq!(store.get_model(m.id).await.unwrap().robot_json, robot_json);
    assert!(matches!(
        store.get_model(m.id + 100).await,
        Err(StoreError::NotFound { .. })
    ));
    let r1 = store
        .create_robot(&NewRobot {
            serial_number: "S1".into(),
            model_id: m.id,
            site: Some("A".into()),
            line: Some("L1".into()),
            cell: None,
        })
        .await
        .unwrap();
    let r2 = store
        .create_robot(&NewRobot {
            serial_number: "S2".into(),
            model_id: m.id,
            site: Some("B".into()),
            line: Some("L1".into()),
            cell: None,
        })
        .await
        .unwrap();
    let dup = store
        .create_robot(&NewRobot {
            serial_number: "S1".into(),
            model_id: m.id,
            site: None,
            line: None,
            cell: None,
        })
        .await;
    assert!(matches!(dup, Err(StoreError::Conflict(_))), "{dup:?}");
    let (robots, total) = store
        .list_robots(None, Some("A"), None, PAGE)
        .await
        .unwrap();
    assert_eq!((robots.len(), total), (1, 1));
    let (page, total) = store
        .list_robots(
            None,
            None,
            None,
            Page {
                limit: 1,
                offset: 1,
            },
        )
        .await
        .unwrap();
    assert_eq!((page[0].id, total), (r2.id, 2));
    let rig = store.create_rig("rig", 4, "{}").await.unwrap();
    assert_eq!(store.list_rigs(PAGE).await.unwrap().1, 1);

    // Sessions and pose batches with optimistic concurrency.
    let s = store
        .create_session(r1.id, rig.id, Some("s"))
        .await
        .unwrap();
    let s1 = store
        .append_poses(s.id, 0, "pose,q1_deg", "1,0\n2,1\n", 2)
        .await
        .unwrap();
    assert_eq!((s1.n_poses, s1.n_batches), (2, 1));
    let stale = store.append_poses(s.id, 0, "pose,q1_deg", "3,0\n", 1).await;
    assert!(matches!(stale, Err(StoreError::Conflict(_))), "{stale:?}");
    store
        .append_poses(s.id, 1, "pose,q1_deg", "3,0\n", 1)
        .await
        .unwrap();
    assert_eq!(
        store.pose_batches(s.id).await.unwrap(),
        vec!["1,0\n2,1\n".to_string(), "3,0\n".to_string()]
    );
    assert!(matches!(
        store.append_poses(9999, 0, "a", "b", 1).await,
        Err(StoreError::NotFound { .. })
    ));

    // Jobs: claim, heartbeat, lease expiry, completion, versions. Leases
    // are on the database's clock: short ones, and real waits.
    const MAX_INTERRUPTIONS: i64 = 2;
    let j1 = store.create_job(s.id, r1.id, "{}", 2).await.unwrap();
    let j2 = store.create_job(s.id, r1.id, "{}", 2).await.unwrap();
    let c1 = store
        .claim_job("w1", 60_000, MAX_INTERRUPTIONS)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        (c1.id, c1.state.as_str(), c1.attempts, c1.interruptions),
        (j1.id, "running", 0, 0)
    );
    let c2 = store
        .claim_job("w2", 200, MAX_INTERRUPTIONS)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(c2.id, j2.id, "a leased job is not claimed twice");
    assert!(
        store
            .claim_job("w3", 200, MAX_INTERRUPTIONS)
            .await
            .unwrap()
            .is_none()
    );
    assert_eq!(
        store
            .heartbeat(j1.id, "w1", 60_000, Some("lm"), 0.5)
            .await
            .unwrap(),
        Some(false)
    );
    assert_eq!(
        store
            .heartbeat(j1.id, "w9", 60_000, None, 0.5)
            .await
            .unwrap(),
        None
    );
    // w2's lease expires: w3 takes j2 over, an interruption and not an
    // attempt; w2 can no longer finish it.
    tokio::time::sleep(Duration::from_millis(300)).await;
    let c3 = store
        .claim_job("w3", 60_000, MAX_INTERRUPTIONS)
        .await
        .unwrap()
        .unwrap();
    assert_eq!((c3.id, c3.attempts, c3.interruptions), (j2.id, 0, 1));
    assert!(
        !store
            .finish_job(j2.id, "w2", "failed", Some("x"))
            .await
            .unwrap()
    );
    assert!(matches!(
        store.complete_job(j2.id, "w2", &cal(1.0)).await,
        Err(StoreError::Conflict(_))
    ));
    // Cancel: a running job is flagged and sees it at its heartbeat.
    let flagged = store.request_cancel(j1.id).await.unwrap();
    assert!(flagged.cancel_requested);
    assert_eq!(
        store
            .heartbeat(j1.id, "w1", 60_000, None, 0.6)
            .await
            .unwrap(),
        Some(true)
    );
    let a = store.complete_job(j2.id, "w3", &cal(0.2)).await.unwrap();
    assert_eq!((a.version, a.robot_id, a.active), (1, r1.id, false));
    assert!(
        store
            .finish_job(j1.id, "w1", "cancelled", None)
            .await
            .unwrap()
    );
    assert!(matches!(
        store.request_cancel(j1.id).await,
        Err(StoreError::Conflict(_))
    ));
    // After MAX_INTERRUPTIONS expired leases a job is given up, saying so;
    // interruptions are not attempts (j3 is allowed one failed run, and
    // is run again after its first interruption).
    let j3 = store.create_job(s.id, r1.id, "{}", 1).await.unwrap();
    store
        .claim_job("w4", 50, MAX_INTERRUPTIONS)
        .await
        .unwrap()
        .unwrap();
    tokio::time::sleep(Duration::from_millis(120)).await;
    let again = store
        .claim_job("w5", 50, MAX_INTERRUPTIONS)
        .await
        .unwrap()
        .unwrap();
    assert_eq!((again.id, again.interruptions), (j3.id, 1));
    tokio::time::sleep(Duration::from_millis(120)).await;
    assert!(
        store
            .claim_job("w6", 50, MAX_INTERRUPTIONS)
            .await
            .unwrap()
            .is_none()
    );
    let given_up = store.get_job(j3.id).await.unwrap();
    assert_eq!(
        (given_up.state.as_str(), given_up.interruptions),
        ("failed", 2)
    );
    let why = given_up.error.unwrap_or_default();
    assert!(why.contains("abandoned"), "{why}");
    // A run that fails by itself: queued again while attempts remain (a
    // failure that may not repeat), ended at once otherwise.
    let j5 = store.create_job(s.id, r1.id, "{}", 2).await.unwrap();
    store
        .claim_job("w8", 60_000, MAX_INTERRUPTIONS)
        .await
        .unwrap()
        .unwrap();
    let retried = store
        .fail_job(j5.id, "w8", "panicked", true)
        .await
        .unwrap()
        .unwrap();
    assert_eq!((retried.state.as_str(), retried.attempts), ("queued", 1));
    store
        .claim_job("w8", 60_000, MAX_INTERRUPTIONS)
        .await
        .unwrap()
        .unwrap();
    let ended = store
        .fail_job(j5.id, "w8", "panicked", true)
        .await
        .unwrap()
        .unwrap();
    assert_eq!((ended.state.as_str(), ended.attempts), ("failed", 2));
    assert!(
        store
            .fail_job(j5.id, "w8", "x", true)
            .await
            .unwrap()
            .is_none()
    );
    let j6 = store.create_job(s.id, r1.id, "{}", 3).await.unwrap();
    store
        .claim_job("w8", 60_000, MAX_INTERRUPTIONS)
        .await
        .unwrap()
        .unwrap();
    let refused = store
        .fail_job(j6.id, "w8", "bad poses", false)
        .await
        .unwrap()
        .unwrap();
    assert_eq!((refused.state.as_str(), refused.attempts), ("failed", 1));
    // Requeue at shutdown counts neither.
    let j4 = store.create_job(s.id, r1.id, "{}", 3).await.unwrap();
    store
        .claim_job("w6", 60_000, MAX_INTERRUPTIONS)
        .await
        .unwrap()
        .unwrap();
    assert!(store.requeue_job(j4.id, "w6").await.unwrap());
    let back = store.get_job(j4.id).await.unwrap();
    assert_eq!(
        (back.state.as_str(), back.attempts, back.interruptions),
        ("queued", 0, 0)
    );
    let again = store
        .claim_job("w7", 60_000, MAX_INTERRUPTIONS)
        .await
        .unwrap()
        .unwrap();
    let b = store.complete_job(again.id, "w7", &cal(0.1)).await.unwrap();
    assert_eq!(b.version, 2, "versions count per robot");
    assert_eq!(
        store.calibration_report(b.id).await.unwrap(),
        "{\"rms\": 0.1}"
    );
    let (_, jobs_total) = store
        .list_jobs(Some(s.id), Some("succeeded"), PAGE)
        .await
        .unwrap();
    assert_eq!(jobs_total, 2);

    // Activation history: activate a, activate b, roll back to a, roll back to none.
    assert!(matches!(
        store.previous_active(r1.id).await,
        Err(StoreError::Conflict(_))
    ));
    store
        .set_active(r1.id, Some(a.id), "activate", "ann", "first")
        .await
        .unwrap();
    assert!(matches!(
        store
            .set_active(r1.id, Some(a.id), "activate", "ann", "again")
            .await,
        Err(StoreError::Conflict(_))
    ));
    assert!(matches!(
        store
            .set_active(r2.id, Some(a.id), "activate", "ann", "wrong robot")
            .await,
        Err(StoreError::Conflict(_))
    ));
    store
        .set_active(r1.id, Some(b.id), "activate", "bob", "better")
        .await
        .unwrap();
    assert_eq!(store.get_calibration(b.id).await.unwrap().active, true);
    let prev = store.previous_active(r1.id).await.unwrap();
    assert_eq!(prev, Some(a.id));
    let rb = store
        .set_active(r1.id, prev, "rollback", "cy", "b is off")
        .await
        .unwrap();
    assert_eq!(
        (rb.calibration_id, rb.previous_calibration_id),
        (Some(a.id), Some(b.id))
    );
    assert_eq!(store.previous_active(r1.id).await.unwrap(), None);
    store
        .set_active(r1.id, None, "rollback", "cy", "back to nominal")
        .await
        .unwrap();
    assert!(matches!(
        store.previous_active(r1.id).await,
        Err(StoreError::Conflict(_))
    ));
    let (acts, n) = store.list_activations(r1.id, PAGE).await.unwrap();
    assert_eq!(n, 4);
    assert_eq!(acts[0].reason, "back to nominal", "newest first");
    assert_eq!(
        store.get_robot(r1.id).await.unwrap().active_calibration_id,
        None
    );

    // Fleet filters; the export (every row, streamed) has the page's rows.
    let f = |f: CalibrationFilter| {
        let store = store.clone();
        async move {
            let (items, total) = store.list_calibrations(&f, PAGE).await.unwrap();
            let streamed: Vec<_> = store
                .stream_calibrations(&f)
                .await
                .try_collect()
                .await
                .unwrap();
            let ids = |v: &[drawcal::store::CalibrationRec]| -> Vec<i64> {
                v.iter().map(|c| c.id).collect()
            };
            assert_eq!(ids(&streamed), ids(&items), "{f:?}");
            assert_eq!(
                format!("{streamed:?}"),
                format!("{items:?}"),
                "every column alike"
            );
            total
        }
    };
    assert_eq!(f(CalibrationFilter::default()).await, 2);
    assert_eq!(
        f(CalibrationFilter {
            robot_id: Some(r2.id),
            ..Default::default()
        })
        .await,
        0
    );
    assert_eq!(
        f(CalibrationFilter {
            model_id: Some(m.id),
            ..Default::default()
        })
        .await,
        2
    );
    assert_eq!(
        f(CalibrationFilter {
            site: Some("A".into()),
            line: Some("L1".into()),
            ..Default::default()
        })
        .await,
        2
    );
    assert_eq!(
        f(CalibrationFilter {
            site: Some("B".into()),
            ..Default::default()
        })
        .await,
        0
    );
    assert_eq!(
        f(CalibrationFilter {
            max_test_rms_mm: Some(0.15),
            ..Default::default()
        })
        .await,
        1
    );
    assert_eq!(
        f(CalibrationFilter {
            min_test_rms_mm: Some(0.15),
            ..Default::default()
        })
        .await,
        1
    );
    assert_eq!(
        f(CalibrationFilter {
            from: Some("2999-01-01T00:00:00.000Z".into()),
            ..Default::default()
        })
        .await,
        0
    );
    assert_eq!(
        f(CalibrationFilter {
            to: Some("2999-01-01T00:00:00.000Z".into()),
            ..Default::default()
        })
        .await,
        2
    );
    // Every filter at once (each bound in its place).
    let all = CalibrationFilter {
        robot_id: Some(r1.id),
        model_id: Some(m.id),
        site: Some("A".into()),
        line: Some("L1".into()),
        from: Some("2000-01-01T00:00:00.000Z".into()),
        to: Some("2999-01-01T00:00:00.000Z".into()),
        max_test_rms_mm: Some(0.15),
        min_test_rms_mm: Some(0.05),
    };
    let (items, total) = store.list_calibrations(&all, PAGE).await.unwrap();
    assert_eq!((items.len(), total), (1, 1));
    assert_eq!(items[0].id, b.id, "the calibration of RMS 0.1");
    plans(&store, m.id, r1.id, rig.id).await;
    keys_and_audit(&store).await;
    concurrent_claims(&store, s.id, r1.id).await;
    store.close().await;
}

/// Plans: queued with a lease, renewed, started and finished by their
/// runner only; one whose lease ran out reads as interrupted.
async fn plans(store: &Store, model: i64, robot: i64, rig: i64) {
    use drawcal::store::{NewPlan, PLAN_INTERRUPTED, PlanEnd};
    let new = |robot_id| NewPlan {
        model_id: model,
        robot_id,
        rig_id: rig,
        options: r#"{"n_poses":30}"#.into(),
        runner: "me".into(),
        created_by: "eve".into(),
    };
    let p = store.create_plan(&new(Some(robot)), 60_000).await.unwrap();
    assert_eq!((p.state.as_str(), p.robot_id), ("queued", Some(robot)));
    assert_eq!(store.count_queued_plans().await.unwrap(), 1);
    assert!(store.renew_plan(p.id, "me", 60_000).await.unwrap());
    assert!(!store.renew_plan(p.id, "other", 60_000).await.unwrap());
    assert!(!store.start_plan(p.id, "other", 60_000).await.unwrap());
    assert!(store.start_plan(p.id, "me", 60_000).await.unwrap());
    let running = store.get_plan(p.id).await.unwrap();
    assert_eq!(running.state, "running");
    assert!(running.started_at.is_some());
    assert_eq!(store.count_queued_plans().await.unwrap(), 0);
    let end = PlanEnd::Succeeded {
        plan_json: "{}".into(),
    };
    assert!(!store.finish_plan(p.id, "other", &end).await.unwrap());
    assert!(store.finish_plan(p.id, "me", &end).await.unwrap());
    let done = store.get_plan(p.id).await.unwrap();
    assert_eq!(done.state, "succeeded");
    assert_eq!(done.result.as_deref(), Some("{}"));
    assert!(done.finished_at.is_some() && done.runner.is_none());
    // Ended: neither renewed nor finished again.
    assert!(!store.renew_plan(p.id, "me", 60_000).await.unwrap());
    assert!(!store.finish_plan(p.id, "me", &end).await.unwrap());

    // A plan whose lease has run out (its process stopped): failed, once
    // read, and its runner can no longer store a result.
    let q = store.create_plan(&new(None), -1).await.unwrap();
    assert_eq!(q.robot_id, None);
    assert_eq!(store.count_queued_plans().await.unwrap(), 0, "not alive");
    let gone = store.get_plan(q.id).await.unwrap();
    assert_eq!(gone.state, "failed");
    assert_eq!(gone.error.as_deref(), Some(PLAN_INTERRUPTED));
    let failed = PlanEnd::Failed {
        error: "x".into(),
        field: Some("n_poses".into()),
    };
    assert!(!store.finish_plan(q.id, "me", &failed).await.unwrap());
    // A failure names its field.
    let f = store.create_plan(&new(None), 60_000).await.unwrap();
    assert!(store.finish_plan(f.id, "me", &failed).await.unwrap());
    let f = store.get_plan(f.id).await.unwrap();
    assert_eq!(
        (f.state.as_str(), f.error_field.as_deref()),
        ("failed", Some("n_poses"))
    );
    assert!(matches!(
        store.get_plan(f.id + 100).await,
        Err(StoreError::NotFound { .. })
    ));
}

/// Many workers claiming at once: every job is claimed exactly once.
async fn concurrent_claims(store: &Store, session: i64, robot: i64) {
    let mut ids = Vec::new();
    for _ in 0..24 {
        ids.push(store.create_job(session, robot, "{}", 3).await.unwrap().id);
    }
    let now = drawcal::store::now_ms();
    let mut tasks = Vec::new();
    for w in 0..6 {
        let store = store.clone();
        tasks.push(tokio::spawn(async move {
            let mut got = Vec::new();
            while let Some(j) = store
                .claim_job(&format!("c{w}"), now, 60_000)
                .await
                .unwrap()
            {
                got.push(j.id);
            }
            got
        }));
    }
    let mut claimed = Vec::new();
    for t in tasks {
        claimed.extend(t.await.unwrap());
    }
    claimed.sort();
    assert_eq!(claimed, ids, "each job claimed once, none lost");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn store_conformance_sqlite() {
    let dir = fresh_dir("store");
    let store = Store::connect(&format!("sqlite://{}", dir.join("s.db").display()))
        .await
        .unwrap();
    assert_eq!(store.backend(), "sqlite");
    suite(store).await;
}

/// The fleet history's filters by robot, site, line and date range, alone
/// or together (with the unindexed model and accuracy filters beside them
/// or not), never scan the calibrations: the page, its count and the CSV
/// export each use an index (BENCHMARKS.md, "Fleet scale", has the plans and the times at
/// 100,000 calibrations). SQLite's planner needs no statistics for this,
/// so an empty database shows the plan a full one gets. (A date bound
/// alone, `from` without `to`, may be a scan in id order that stops at the
/// page's last row: the planner's choice, 9 ms at 100,000.) The export
/// reads the matching ids first and then the rows in id order, sorting
/// nothing (`EXPORT_IDS_FIRST` in src/store/sqlite.rs says why).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn history_filters_use_indexes_sqlite() {
    let dir = fresh_dir("store-plans");
    let store = Store::connect(&format!("sqlite://{}", dir.join("s.db").display()))
        .await
        .unwrap();
    for mask in 1..16u32 {
        for extra in [false, true] {
            let on = |bit: u32| mask & (1 << bit) != 0;
            let f = CalibrationFilter {
                robot_id: on(0).then_some(7),
                site: on(1).then(|| "plant-1".to_string()),
                line: on(2).then(|| "L2".to_string()),
                from: on(3).then(|| "2026-01-01T00:00:00.000Z".to_string()),
                to: on(3).then(|| "2026-01-31T23:59:59.999Z".to_string()),
                model_id: extra.then_some(1),
                max_test_rms_mm: extra.then_some(0.5),
                min_test_rms_mm: None,
            };
            let mut plan = store.explain_calibrations(&f, PAGE).await.unwrap();
            let export = store.explain_calibration_export(&f).await.unwrap();
            // The export reads the ids first, then the rows in id order:
            // no whole rows sorted (nor anything else).
            assert!(
                export.iter().all(|l| !l.contains("TEMP B-TREE")),
                "{f:?} sorts its export: {export:#?}"
            );
            assert!(
                export.iter().any(|l| l
                    .trim_start()
                    .starts_with("SEARCH c USING INTEGER PRIMARY KEY")),
                "{f:?}: the export's rows not by id: {export:#?}"
            );
            plan.extend(export);
            let scans: Vec<&String> = plan
                .iter()
                .filter(|l| {
                    let l = l.trim_start();
                    l.starts_with("SCAN c") || l.starts_with("SCAN calibrations")
                })
                .collect();
            assert!(
                scans.is_empty(),
                "{f:?} scans the calibrations: {scans:?}\n{}",
                plan.join("\n")
            );
        }
    }
    // Without a filter the page reads the first rows in id order and stops.
    let plan = store
        .explain_calibrations(&CalibrationFilter::default(), PAGE)
        .await
        .unwrap();
    assert!(plan.iter().all(|l| !l.contains("TEMP B-TREE")), "{plan:?}");
    // Nor is the whole history's export sorted: it is the table's order.
    let plan = store
        .explain_calibration_export(&CalibrationFilter::default())
        .await
        .unwrap();
    assert!(plan.iter().all(|l| !l.contains("TEMP B-TREE")), "{plan:?}");
    store.close().await;
}

/// PostgreSQL at `DATABASE_URL_POSTGRES` (as `.ci/run` sets it; default
/// postgres://postgres@127.0.0.1:5432/test); a fresh database per run.
/// Fails when the server is down, unless `DRAWCAL_SKIP_POSTGRES` is set
/// (see `requires`).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn store_conformance_postgres() {
    let Some((admin, mut conn)) = crate::requires::postgres("store_conformance_postgres").await
    else {
        return;
    };
    let name = format!(
        "drawcal_t_{}_{}",
        std::process::id(),
        drawcal::store::now_ms()
    );
    sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}")))
        .execute(&mut conn)
        .await
        .unwrap();
    let base = admin.rsplit_once('/').unwrap().0;
    let store = Store::connect(&format!("{base}/{name}")).await.unwrap();
    assert_eq!(store.backend(), "postgres");
    suite(store).await;
    sqlx::query(sqlx::AssertSqlSafe(format!(
        "DROP DATABASE {name} WITH (FORCE)"
    )))
    .execute(&mut conn)
    .await
    .unwrap();
}

fn versions(dir: &str) -> BTreeSet<String> {
    std::fs::read_dir(format!("{}/migrations/{dir}", env!("CARGO_MANIFEST_DIR")))
        .unwrap()
        .map(|e| {
            e.unwrap()
                .file_name()
                .to_string_lossy()
                .split('_')
                .next()
                .unwrap()
                .to_string()
        })
        .collect()
}

#[test]
fn migrations_are_in_lockstep() {
    let (s, p) = (versions("sqlite"), versions("postgres"));
    assert!(!s.is_empty());
    assert_eq!(
        s, p,
        "migrations/sqlite and migrations/postgres must have the same versions"
    );
}

/// The whole service on PostgreSQL: upload, identification job, activation,
/// compensation (a fresh database).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn service_runs_on_postgres() {
    use crate::helpers::{Options, TestApp, ok_json};
    use serde_json::json;
    let Some((admin, mut conn)) = crate::requires::postgres("service_runs_on_postgres").await
    else {
        return;
    };
    let name = format!(
        "drawcal_app_{}_{}",
        std::process::id(),
        drawcal::store::now_ms()
    );
    sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}")))
        .execute(&mut conn)
        .await
        .unwrap();
    let url = format!("{}/{name}", admin.rsplit_once('/').unwrap().0);
    let app = TestApp::spawn_on(
        &url,
        Options {
            workers: 2,
            ..Options::default()
        },
    )
    .await;
    let ready = ok_json(app.get("/ready").await, 200).await;
    assert_eq!(ready["database"], "postgres");
    let ds = "er3a_paper_like";
    let (_, robot, _, sid) = app.setup(ds, "PG-1").await;
    app.upload_poses(sid, read(ds, "poses.csv")).await;
    let job = ok_json(
        app.post_raw(&format!("/sessions/{sid}/jobs"), None, "")
            .await,
        202,
    )
    .await;
    let done = app
        .wait_job(
            job["id"].as_i64().unwrap(),
            std::time::Duration::from_secs(600),
        )
        .await;
    assert_eq!(done["state"], "succeeded", "{done}");
    let cal = done["calibration_id"].as_i64().unwrap();
    ok_json(
        app.post_json(
            &format!("/robots/{robot}/activate"),
            &json!({"calibration_id": cal, "reason": "test"}),
        )
        .await,
        200,
    )
    .await;
    let out = ok_json(
        app.post_json("/compensate", &json!({"robot_id": robot, "target": {"target": "t", "q_deg": [10, -20, 30, 0, 40, 0]}})).await,
        200,
    )
    .await;
    assert_eq!(out["results"][0]["status"], "ok");
    let hist = ok_json(app.get("/calibrations?site=plant-1&format=json").await, 200).await;
    assert_eq!(hist["total"], 1);
    app.stop().await;
    sqlx::query(sqlx::AssertSqlSafe(format!(
        "DROP DATABASE {name} WITH (FORCE)"
    )))
    .execute(&mut conn)
    .await
    .unwrap();
}
