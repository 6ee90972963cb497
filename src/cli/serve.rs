//! `drawcal serve`: the HTTP service.

use std::net::SocketAddr;
use std::time::Duration;

use super::CliError;
use crate::http::{Service, ServiceConfig, shutdown_signal};
use crate::jobs::{JobConfig, engine_job_fn};

/// Flags of `drawcal serve`; each also reads an environment variable.
#[derive(Debug, Clone, clap::Args)]
pub struct ServeArgs {
    /// Address to listen on.
    #[arg(long, env = "DRAWCAL_LISTEN", default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// Database: `sqlite://PATH` (created and migrated at start) or
    /// `postgres://USER@HOST/DB`.
    #[arg(long, env = "DATABASE_URL", default_value = "sqlite://./drawcal.db")]
    pub database: String,
    /// Identification jobs run at once by this process.
    #[arg(long, env = "DRAWCAL_WORKERS", default_value_t = 1)]
    pub workers: usize,
    /// Largest request body accepted (bytes): pose uploads, compensation
    /// batches.
    #[arg(long, env = "DRAWCAL_MAX_UPLOAD_BYTES", default_value_t = 16 * 1024 * 1024)]
    pub max_upload_bytes: usize,
    /// Seconds a request body may stall before the request is answered 408
    /// (the whole body must arrive within ten times this). At most 86400.
    #[arg(long, env = "DRAWCAL_CLIENT_TIMEOUT_SECS", default_value_t = 30)]
    pub client_timeout_secs: u64,
    /// Seconds a connection may go without a complete request header
    /// before it is closed: idle keep-alive connections, and clients that
    /// send their headers too slowly. Longer than the 90 s idle time of
    /// common client connection pools, so that they drop a connection
    /// before the service does. At most 86400.
    #[arg(long, env = "DRAWCAL_IDLE_TIMEOUT_SECS", default_value_t = 120)]
    pub idle_timeout_secs: u64,
    /// Largest change of any joint (deg) a joint target's compensation may
    /// make; `/compensate` refuses a target that needs more
    /// (`joint_change`), saying which joint and how far.
    #[arg(long, env = "DRAWCAL_MAX_JOINT_CHANGE_DEG",
          default_value_t = crate::compensate::DEFAULT_MAX_JOINT_CHANGE_DEG,
          value_parser = super::max_joint_change_deg)]
    pub max_joint_change_deg: f64,
    /// Serve without API keys: every request acts as an admin. Refused
    /// unless --listen is a loopback address.
    #[arg(long)]
    pub insecure_no_auth: bool,
    /// A file holding the first admin key (the Docker image's way in; see
    /// `DRAWCAL_ADMIN_KEY` for the key itself): created on start if no key
    /// has it. At least 32 characters.
    #[arg(long, env = "DRAWCAL_ADMIN_KEY_FILE")]
    pub admin_key_file: Option<std::path::PathBuf>,
    /// A name clients reach the service by (repeat for several; `*`: any).
    /// Requests whose Host header names another are refused (DNS
    /// rebinding). Default: the --listen address, localhost, 127.0.0.1
    /// and `[::1]`; listening on 0.0.0.0 (a container), give the names.
    #[arg(
        long = "allowed-host",
        env = "DRAWCAL_ALLOWED_HOST",
        value_delimiter = ','
    )]
    pub allowed_hosts: Vec<String>,
    /// A web origin (`https://mes.example`) whose pages may call the API
    /// from a browser (repeat for several). Default: none, no CORS.
    #[arg(
        long = "cors-origin",
        env = "DRAWCAL_CORS_ORIGIN",
        value_delimiter = ','
    )]
    pub cors_origins: Vec<String>,
    /// Connections served at once; past it a new one is answered 503 and
    /// closed. Default: the descriptor limit (raised to its hard limit at
    /// start) less 128, at most 16384.
    #[arg(long, env = "DRAWCAL_MAX_CONNECTIONS",
          value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub max_connections: Option<u64>,
    /// Bytes that answers of 256 KiB or more (pose files, reports) may hold
    /// in memory together while their clients read them; past it such a
    /// request is answered 503 with Retry-After.
    #[arg(long, env = "DRAWCAL_MAX_ANSWER_BYTES_IN_FLIGHT", default_value_t = 512 * 1024 * 1024,
          value_parser = clap::value_parser!(u64).range(1024 * 1024..))]
    pub max_answer_bytes_in_flight: u64,
    /// Largest correction of a joint's alpha, theta offset or beta (deg) a
    /// calibration may make to be activated.
    #[arg(long, env = "DRAWCAL_MAX_ANGLE_CORRECTION_DEG", default_value_t = 2.0)]
    pub max_angle_correction_deg: f64,
    /// Largest correction of a joint's a or d (mm) a calibration may make
    /// to be activated.
    #[arg(long, env = "DRAWCAL_MAX_LENGTH_CORRECTION_MM", default_value_t = 10.0)]
    pub max_length_correction_mm: f64,
    /// Largest distance (mm) between robot.json's tool point and the
    /// calibrated one for a calibration to be activated.
    #[arg(long, env = "DRAWCAL_MAX_TOOL_CORRECTION_MM", default_value_t = 25.0)]
    pub max_tool_correction_mm: f64,
    /// Pose uploads one API key may make per minute (a burst of a minute's
    /// worth, then at that rate); past it 429 with Retry-After.
    #[arg(long, env = "DRAWCAL_MAX_UPLOADS_PER_MINUTE", default_value_t = 600,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub max_uploads_per_minute: u32,
    /// Identification jobs one API key may submit per minute; past it 429
    /// with Retry-After.
    #[arg(long, env = "DRAWCAL_MAX_JOBS_PER_MINUTE", default_value_t = 60,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub max_jobs_per_minute: u32,
    /// Jobs and plans that may wait in the queue (all replicas together);
    /// a submission past it is answered 429.
    #[arg(long, env = "DRAWCAL_MAX_QUEUED_JOBS", default_value_t = 1000,
          value_parser = clap::value_parser!(i64).range(1..))]
    pub max_queued_jobs: i64,
    /// Job lease (seconds): a job whose process died runs again this long
    /// after its last heartbeat.
    #[arg(long, env = "DRAWCAL_JOB_LEASE_SECS", default_value_t = 15)]
    pub job_lease_secs: u64,
    /// Runs of a job that may fail by themselves (the engine panicked, the
    /// database failed) before it is given up; a refusal of its data ends
    /// it at once.
    #[arg(long, env = "DRAWCAL_JOB_MAX_ATTEMPTS", default_value_t = 3)]
    pub job_max_attempts: i64,
    /// Times a job's worker may stop under it (a killed process, a lost
    /// lease) before the job is given up: restarts are not its attempts,
    /// but a job that crashes its process every time must still end.
    #[arg(long, env = "DRAWCAL_JOB_MAX_INTERRUPTIONS", default_value_t = 10)]
    pub job_max_interruptions: i64,
    /// Seconds open requests get to finish after a shutdown signal, and
    /// then a running job before it is handed back to the queue.
    #[arg(long, env = "DRAWCAL_SHUTDOWN_GRACE_SECS", default_value_t = 10)]
    pub shutdown_grace_secs: u64,
    /// Threads of the async runtime (HTTP I/O, the store, small inline
    /// compensations); numerical work has its own threads, one per core.
    /// Default: half the cores, at least one. Measured on 2 cores
    /// (BENCHMARKS.md, "Service load"): one runtime thread gives the same
    /// throughput as two and a p99 under half as long, because the compute
    /// threads and the clients keep the other core busy anyway.
    #[arg(long, env = "DRAWCAL_RUNTIME_THREADS", default_value_t = default_runtime_threads())]
    pub runtime_threads: usize,
    /// Log lines on stderr: `text` (key=value) or `json` (one object per
    /// line, for log collectors). Either way every line logged while a
    /// request is handled carries its request id.
    #[arg(long, env = "DRAWCAL_LOG_FORMAT", value_enum, default_value_t = LogFormat::Text)]
    pub log_format: LogFormat,
}

/// How log lines are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    /// `LEVEL span{request_id=...}: message key=value`, one per line.
    Text,
    /// One JSON object per line: `timestamp`, `level`, `fields.message`,
    /// the event's other fields, and `span`/`spans` with the request span's
    /// `request_id`, `method` and `uri`.
    Json,
}

impl std::fmt::Display for LogFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            LogFormat::Text => "text",
            LogFormat::Json => "json",
        })
    }
}

/// Half the cores available to this process, rounded up.
fn default_runtime_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get().div_ceil(2))
}

fn redact(url: &str) -> String {
    // postgres://user:password@host/db -> postgres://user:***@host/db
    match (url.find("://"), url.rfind('@')) {
        (Some(s), Some(at)) if at > s => {
            let cred = &url[s + 3..at];
            match cred.find(':') {
                Some(c) => format!("{}{}:***{}", &url[..s + 3], &cred[..c], &url[at..]),
                None => url.to_string(),
            }
        }
        _ => url.to_string(),
    }
}

/// Run the service until Ctrl-C or SIGTERM.
pub fn run(args: ServeArgs) -> Result<(), CliError> {
    let usage = |m: String| Err(CliError::Usage(m));
    if args.workers == 0 {
        return usage("--workers must be at least 1".into());
    }
    if args.runtime_threads == 0 {
        return usage("--runtime-threads must be at least 1".into());
    }
    let max = crate::http::MAX_TIMEOUT.as_secs();
    if !(1..=max).contains(&args.client_timeout_secs) {
        return usage(format!("--client-timeout-secs must be from 1 to {max}"));
    }
    if !(1..=max).contains(&args.idle_timeout_secs) {
        return usage(format!("--idle-timeout-secs must be from 1 to {max}"));
    }
    if args.job_lease_secs == 0 {
        return usage("--job-lease-secs must be at least 1".into());
    }
    for (flag, v) in [
        ("--max-angle-correction-deg", args.max_angle_correction_deg),
        ("--max-length-correction-mm", args.max_length_correction_mm),
        ("--max-tool-correction-mm", args.max_tool_correction_mm),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return usage(format!("{flag} must be a positive number, got {v}"));
        }
    }
    if !(1..=100).contains(&args.job_max_attempts) {
        return usage("--job-max-attempts must be from 1 to 100".into());
    }
    if !(1..=1000).contains(&args.job_max_interruptions) {
        return usage("--job-max-interruptions must be from 1 to 1000".into());
    }
    let admin_key = match (
        &args.admin_key_file,
        std::env::var("DRAWCAL_ADMIN_KEY").ok(),
    ) {
        (Some(path), _) => Some(
            std::fs::read_to_string(path)
                .map_err(|source| CliError::Io {
                    path: path.clone(),
                    source,
                })?
                .trim()
                .to_string(),
        ),
        (None, key) => key.map(|k| k.trim().to_string()),
    };
    init_tracing(args.log_format);
    let cfg = ServiceConfig {
        listen: args.listen,
        database_url: args.database.clone(),
        max_upload_bytes: args.max_upload_bytes,
        client_timeout: Duration::from_secs(args.client_timeout_secs),
        idle_timeout: Duration::from_secs(args.idle_timeout_secs),
        max_joint_change_deg: args.max_joint_change_deg,
        insecure_no_auth: args.insecure_no_auth,
        bootstrap_admin_key: admin_key,
        allowed_hosts: args.allowed_hosts.clone(),
        cors_origins: args.cors_origins.clone(),
        max_connections: args.max_connections.map(|n| n as usize),
        activation_bounds: crate::report::activation::ActivationBounds {
            angle_deg: args.max_angle_correction_deg,
            length_mm: args.max_length_correction_mm,
            tool_mm: args.max_tool_correction_mm,
        },
        max_answer_bytes_in_flight: args.max_answer_bytes_in_flight,
        limits: crate::http::limits::LimitConfig {
            uploads_per_minute: args.max_uploads_per_minute,
            jobs_per_minute: args.max_jobs_per_minute,
            max_queued_jobs: args.max_queued_jobs,
        },
        jobs: JobConfig {
            workers: args.workers,
            lease: Duration::from_secs(args.job_lease_secs),
            shutdown_grace: Duration::from_secs(args.shutdown_grace_secs),
            max_attempts: args.job_max_attempts,
            max_interruptions: args.job_max_interruptions,
            ..JobConfig::default()
        },
    };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .worker_threads(args.runtime_threads)
        .thread_name("drawcal-http")
        .build()
        .map_err(|e| CliError::Service(e.into()))?;
    // Through the log (not eprintln) so that JSON logs are JSON throughout;
    // the runtime's own count of its worker threads.
    tracing::info!(
        "drawcal serve: listen={} database={} workers={} runtime_threads={} max_upload_bytes={} client_timeout_secs={} idle_timeout_secs={} job_lease_secs={} job_max_attempts={} job_max_interruptions={} shutdown_grace_secs={} log_format={}",
        args.listen,
        redact(&args.database),
        args.workers,
        rt.metrics().num_workers(),
        args.max_upload_bytes,
        args.client_timeout_secs,
        args.idle_timeout_secs,
        args.job_lease_secs,
        args.job_max_attempts,
        args.job_max_interruptions,
        args.shutdown_grace_secs,
        args.log_format
    );
    rt.block_on(async move {
        let service = Service::start(&cfg, engine_job_fn())
            .await
            .map_err(CliError::Service)?;
        service
            .run(shutdown_signal())
            .await
            .map_err(|e| CliError::Service(e.into()))
    })
}

/// Structured logs (key=value text or JSON lines, with request and job
/// spans) to stderr; `RUST_LOG` filters (default `info,sqlx=warn`).
fn init_tracing(format: LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,sqlx=warn"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false);
    let _ = match format {
        LogFormat::Text => builder.try_init(),
        // The current span and the list of enclosing spans: the request
        // span (request_id, method, uri) is in every line of a request.
        LogFormat::Json => builder
            .json()
            .with_current_span(true)
            .with_span_list(true)
            .try_init(),
    };
}

#[cfg(test)]
mod tests {
    use super::redact;

    #[test]
    fn redacts_passwords() {
        assert_eq!(redact("postgres://u:secret@h/db"), "postgres://u:***@h/db");
        assert_eq!(redact("postgres://u@h/db"), "postgres://u@h/db");
        assert_eq!(redact("sqlite://./drawcal.db"), "sqlite://./drawcal.db");
    }
}
