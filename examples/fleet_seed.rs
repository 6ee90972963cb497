//! Fills an empty store with a fleet's calibration history, through the
//! store layer, for the fleet-scale figures of BENCHMARKS.md ("Fleet
//! scale"):
//!
//! ```sh
//! cargo run --release --example fleet_seed -- sqlite:///tmp/fleet.db
//! cargo run --release --example fleet_seed -- postgres://postgres@127.0.0.1:5432/fleet \
//!     --calibrations 100000 --robots 2000 --sites 20 --tasks 8
//! ```
//!
//! What is stored, and why it is representative:
//! - two robot models (the ER3A and the UR5 of `tests/data`), one rig, and
//!   `--robots` robots (serial `FLEET-00001`...) spread evenly over
//!   `--sites` sites (`site-00`...), five lines per site, one session each;
//! - `--calibrations` calibrations, round-robin over the robots (so each
//!   robot has versions 1..N/robots), each written as the service writes
//!   one: a job created, claimed and completed (`Store::create_job`,
//!   `claim_job`, `complete_job`);
//! - each report is a real engine report, computed at start from five
//!   datasets of `tests/data` (50 to 205 poses: 42 to 238 KB of JSON) and
//!   stored in turn, so the table holds what a fleet's would; the summary
//!   figures (held-out RMS before and after) are the report's, scaled per
//!   calibration by a seeded random factor, so that accuracy filters select
//!   a realistic fraction;
//! - the calibrations' `created_at` are then spread over two years (from
//!   2025-01-01, in id order, as the service would have written them), with
//!   one UPDATE: the service stamps "now", and date-range filters need a
//!   history that spans time.
//!
//! The database must be empty (a fresh SQLite file, or a PostgreSQL
//! database just created); the tool migrates it.
//!
//! `fleet_seed DATABASE_URL --explain` seeds nothing: it prints the
//! database's plans of the history queries the benchmark measures
//! (`Store::explain_calibrations`, and `Store::explain_calibration_export`
//! for the CSV exports and a robot's accuracy, which read every row);
//! `--time` instead times them through
//! the store (the database's part of a request, without HTTP).

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use futures_util::TryStreamExt;

use drawcal::identify::NoProgress;
use drawcal::jobs::summarize;
use drawcal::model::{Dataset, Rig, Robot};
use drawcal::pipeline;
use drawcal::store::{CalibrationFilter, NewCalibration, NewRobot, Page, Store};

/// Two years, the span the calibrations' dates are spread over.
const SPAN_S: i64 = 2 * 365 * 86_400;
/// 2025-01-01T00:00:00Z, the first calibration's date.
const START_EPOCH_S: i64 = 1_735_689_600;

struct Args {
    url: String,
    calibrations: usize,
    robots: usize,
    sites: usize,
    tasks: usize,
    explain: bool,
    time: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut it = std::env::args().skip(1);
    let mut a = Args {
        url: String::new(),
        calibrations: 100_000,
        robots: 2_000,
        sites: 20,
        tasks: 1,
        explain: false,
        time: false,
    };
    while let Some(arg) = it.next() {
        let mut num = |name: &str| -> Result<usize, String> {
            it.next()
                .and_then(|v| v.parse().ok())
                .filter(|&n: &usize| n > 0)
                .ok_or(format!("{name} needs a positive number"))
        };
        match arg.as_str() {
            "--calibrations" => a.calibrations = num("--calibrations")?,
            "--robots" => a.robots = num("--robots")?,
            "--sites" => a.sites = num("--sites")?,
            "--tasks" => a.tasks = num("--tasks")?,
            "--explain" => a.explain = true,
            "--time" => (a.explain, a.time) = (true, true),
            _ if arg.starts_with("--") => return Err(format!("unknown option {arg}")),
            _ => a.url = arg,
        }
    }
    if a.url.is_empty() {
        return Err(
            "usage: fleet_seed DATABASE_URL [--calibrations N] [--robots N] \
                    [--sites N] [--tasks N] | fleet_seed DATABASE_URL --explain|--time"
                .into(),
        );
    }
    Ok(a)
}

/// A real report of the engine on one dataset of `tests/data`.
fn engine_report(dir: &Path) -> NewCalibration {
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).expect("dataset file");
    let robot = Robot::from_json(&read("robot.json")).expect("robot.json");
    let rig = Rig::from_json(&read("rig.json")).expect("rig.json");
    let data = Dataset::from_csv(read("poses.csv").as_bytes(), &robot, &rig).expect("poses.csv");
    let report = pipeline::calibrate(
        &robot,
        &rig,
        &data,
        &pipeline::Options::default(),
        &NoProgress,
    )
    .expect("calibration");
    let json = serde_json::to_string(&report).expect("report json");
    summarize(&report, json)
}

/// splitmix64: a seeded, reproducible stream for the per-calibration figures.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

fn unit(seed: u64) -> f64 {
    (mix(seed) >> 11) as f64 / (1u64 << 53) as f64
}

/// Print the plans of the history queries that tests/api/load/fleet.sh
/// measures (the same filters, one site, robot and month each).
async fn explain(store: &Store, time: bool) -> Result<(), Box<dyn std::error::Error>> {
    let site = || Some("site-07".to_string());
    let month = |f: CalibrationFilter| CalibrationFilter {
        from: Some("2025-06-01T00:00:00.000Z".into()),
        to: Some("2025-06-28T23:59:59.999Z".into()),
        ..f
    };
    let page = |limit, offset| Page { limit, offset };
    let all = page(i64::MAX / 2, 0);
    let cases = [
        (
            "list_site: site, first page",
            CalibrationFilter {
                site: site(),
                ..Default::default()
            },
            page(50, 0),
        ),
        (
            "list_site_page: site, a page deep",
            CalibrationFilter {
                site: site(),
                ..Default::default()
            },
            page(100, 2500),
        ),
        (
            "list_site_line_month: site, line, a month",
            month(CalibrationFilter {
                site: site(),
                line: Some("L2".into()),
                ..Default::default()
            }),
            page(50, 0),
        ),
        (
            "list_site_rms: site, held-out RMS at most",
            CalibrationFilter {
                site: site(),
                max_test_rms_mm: Some(0.05),
                ..Default::default()
            },
            page(50, 0),
        ),
        (
            "list_month: a month, the whole fleet",
            month(CalibrationFilter::default()),
            page(50, 0),
        ),
        (
            "list_robot and accuracy: one robot",
            CalibrationFilter {
                robot_id: Some(777),
                ..Default::default()
            },
            all,
        ),
        (
            "csv_site_month: site and a month, every row",
            month(CalibrationFilter {
                site: site(),
                ..Default::default()
            }),
            all,
        ),
        (
            "csv_site: site, every row",
            CalibrationFilter {
                site: site(),
                ..Default::default()
            },
            all,
        ),
        (
            "no filter, first page",
            CalibrationFilter::default(),
            page(50, 0),
        ),
    ];
    for (name, filter, page) in cases {
        // Every row (a CSV export, a robot's accuracy): the export's
        // query, streamed; else a page and its count.
        let export = page.limit == all.limit;
        if time {
            // The store's part of a request, as the handler asks it, 20
            // times, one after the other.
            let mut ms = Vec::new();
            let mut rows = 0;
            for _ in 0..20 {
                let t = Instant::now();
                rows = if export {
                    let all: Vec<_> = store
                        .stream_calibrations(&filter)
                        .await
                        .try_collect()
                        .await?;
                    all.len()
                } else {
                    store.list_calibrations(&filter, page).await?.0.len()
                };
                ms.push(t.elapsed().as_secs_f64() * 1e3);
            }
            ms.sort_by(f64::total_cmp);
            println!(
                "{name}: {rows} rows, store median {:.2} ms, max {:.2} ms",
                ms[10], ms[19]
            );
            continue;
        }
        println!("#### {name}");
        let plan = if export {
            store.explain_calibration_export(&filter).await?
        } else {
            store.explain_calibrations(&filter, page).await?
        };
        for line in plan {
            println!("{line}");
        }
    }
    Ok(())
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a = parse_args()?;
    if a.explain {
        return explain(&Store::connect(&a.url).await?, a.time).await;
    }
    let t0 = Instant::now();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let reports: Vec<NewCalibration> = [
        "er3a_paper_like",
        "ur5_geometric",
        "er3a_compliance_j2",
        "xcheck_bump_j3",
        "real_positioner2ax_rosi",
    ]
    .iter()
    .map(|d| engine_report(&root.join(d)))
    .collect();
    let sizes: Vec<usize> = reports.iter().map(|r| r.report_json.len()).collect();
    eprintln!(
        "reports: {} real engine reports of {:?} bytes ({:.1} s)",
        reports.len(),
        sizes,
        t0.elapsed().as_secs_f64()
    );

    let store = Store::connect(&a.url).await?;
    let page = Page {
        limit: 1,
        offset: 0,
    };
    if store.list_models(page).await?.1 != 0 {
        return Err("the database is not empty: seed a fresh one".into());
    }
    let er3a = std::fs::read_to_string(root.join("er3a_paper_like/robot.json"))?;
    let ur5 = std::fs::read_to_string(root.join("ur5_geometric/robot.json"))?;
    let models = [
        store.create_model("ER3A", 6, &er3a).await?.id,
        store.create_model("UR5", 6, &ur5).await?.id,
    ];
    let rig_json = std::fs::read_to_string(root.join("er3a_paper_like/rig.json"))?;
    let rig = store.create_rig("fleet rig", 4, &rig_json).await?.id;
    let mut robots = Vec::with_capacity(a.robots);
    for i in 0..a.robots {
        let site = i * a.sites / a.robots;
        let robot = store
            .create_robot(&NewRobot {
                serial_number: format!("FLEET-{:05}", i + 1),
                model_id: models[i % 2],
                site: Some(format!("site-{site:02}")),
                line: Some(format!("L{}", i % 5 + 1)),
                cell: Some(format!("C{}", i % 10 + 1)),
            })
            .await?;
        let session = store
            .create_session(robot.id, rig, Some("fleet seed"))
            .await?;
        robots.push((robot.id, session.id));
    }
    eprintln!(
        "{} robots at {} sites ({:.1} s)",
        a.robots,
        a.sites,
        t0.elapsed().as_secs_f64()
    );

    // Each task queues a job, claims the oldest (perhaps another task's:
    // the calibration follows the claimed job's robot) and completes it.
    let next = Arc::new(AtomicUsize::new(0));
    let reports = Arc::new(reports);
    let robots = Arc::new(robots);
    let t_seed = Instant::now();
    let mut handles = Vec::new();
    for t in 0..a.tasks {
        let (store, next, reports, robots) =
            (store.clone(), next.clone(), reports.clone(), robots.clone());
        let n = a.calibrations;
        handles.push(tokio::spawn(async move {
            let worker = format!("fleet-seed-{t}");
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n {
                    return Ok::<(), drawcal::store::StoreError>(());
                }
                let (robot_id, session_id) = robots[i % robots.len()];
                store.create_job(session_id, robot_id, "{}", 3).await?;
                let Some(job) = store.claim_job(&worker, 600_000, 10).await? else {
                    continue;
                };
                let base = &reports[job.id as usize % reports.len()];
                let k = 0.5 + unit(job.id as u64);
                let cal = NewCalibration {
                    test_rms_before_mm: base.test_rms_before_mm.map(|x| x * k),
                    test_rms_after_mm: base.test_rms_after_mm.map(|x| x * k),
                    train_rms_after_mm: base.train_rms_after_mm.map(|x| x * k),
                    ..base.clone()
                };
                store.complete_job(job.id, &worker, &cal).await?;
                if i > 0 && i % 10_000 == 0 {
                    eprintln!(
                        "  {i} calibrations ({:.0}/s)",
                        i as f64 / t_seed.elapsed().as_secs_f64()
                    );
                }
            }
        }));
    }
    for h in handles {
        h.await??;
    }
    // A claim finds nothing when every queued job is locked by another
    // task's claim (`SKIP LOCKED`): such jobs are left queued; finish them.
    let worker = "fleet-seed-drain";
    while let Some(job) = store.claim_job(worker, 600_000, 10).await? {
        let cal = reports[job.id as usize % reports.len()].clone();
        store.complete_job(job.id, worker, &cal).await?;
    }
    let seeded_s = t_seed.elapsed().as_secs_f64();
    eprintln!(
        "{} calibrations in {seeded_s:.1} s ({:.0}/s)",
        a.calibrations,
        a.calibrations as f64 / seeded_s
    );
    store.close().await;

    // Dates spread over two years, in id order (one statement per backend).
    let step_s = (SPAN_S / a.calibrations as i64).max(1);
    if a.url.starts_with("sqlite:") {
        let pool = sqlx::SqlitePool::connect(&a.url).await?;
        sqlx::query(
            "UPDATE calibrations SET created_at = \
             strftime('%Y-%m-%dT%H:%M:%fZ', $1 + (id - 1) * $2, 'unixepoch')",
        )
        .bind(START_EPOCH_S)
        .bind(step_s)
        .execute(&pool)
        .await?;
        sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
            .execute(&pool)
            .await?;
        pool.close().await;
    } else {
        let pool = sqlx::PgPool::connect(&a.url).await?;
        sqlx::query(
            "UPDATE calibrations SET created_at = to_char(to_timestamp($1 + (id - 1) * $2) \
             AT TIME ZONE 'UTC', 'YYYY-MM-DD\"T\"HH24:MI:SS.MS\"Z\"')",
        )
        .bind(START_EPOCH_S as f64)
        .bind(step_s as f64)
        .execute(&pool)
        .await?;
        sqlx::query("VACUUM ANALYZE").execute(&pool).await?;
        pool.close().await;
    }
    eprintln!(
        "dates spread, one every {step_s} s from 2025-01-01; total {:.1} s",
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
