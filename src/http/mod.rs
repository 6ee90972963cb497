//! The HTTP service: an axum router around the store, the job pool and the
//! engine.
//!
//! - [`router`] builds the application for a [`AppState`]; [`openapi`] gives
//!   the OpenAPI document generated from the same handlers (utoipa), which is
//!   committed as `openapi.yaml` and checked by a test;
//! - [`Service::start`] connects the store, starts the job workers and binds
//!   the listener (port 0 works, for tests); [`Service::run`] serves until a
//!   shutdown future resolves, then drains requests and jobs.
//!
//! Error policy: handlers return [`error::ApiError`], mapped to a status and
//! the JSON error body in one place. Store errors convert into it; engine
//! input errors become 422 with `field` and `row`.

pub mod auth;
pub mod cache;
pub mod calibrations;
pub mod compensate;
pub mod compute;
pub mod conn;
pub mod contract;
pub mod documents;
pub mod error;
pub mod export;
pub mod extract;
pub mod guard;
pub mod keys;
pub mod limits;
pub mod ops;
pub mod plans;
pub mod resources;
pub mod sessions;
pub mod strict;
pub mod ui;

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use axum::Router;
use axum::http::{HeaderValue, Request};
use serde::{Deserialize, Serialize};
use tower_http::request_id::{
    MakeRequestId, PropagateRequestIdLayer, RequestId, SetRequestIdLayer,
};
use tower_http::trace::{DefaultOnResponse, TraceLayer};
use utoipa::{IntoParams, OpenApi, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::jobs::{JobConfig, JobFn, Jobs};
use crate::store::Store;
pub use error::{ApiError, ErrorBody};

/// Result alias for handlers.
pub type ApiResult<T> = Result<T, ApiError>;

/// Service settings (the `serve` flags).
#[derive(Debug, Clone)]
pub struct ServiceConfig {
    /// Address to listen on.
    pub listen: SocketAddr,
    /// `sqlite://PATH` or `postgres://...`.
    pub database_url: String,
    /// Largest accepted request body (bytes).
    pub max_upload_bytes: usize,
    /// Job pool settings.
    pub jobs: JobConfig,
    /// How long a request body may stall (`--client-timeout-secs`); the
    /// whole body must arrive within [`BODY_DEADLINE_FACTOR`] times this.
    /// A client past either is answered 408, so that slow or stalled
    /// clients cannot hold connections and buffers for ever.
    pub client_timeout: Duration,
    /// How long a connection may go without a complete request header
    /// (`--idle-timeout-secs`): a client sending its headers a byte at a
    /// time, or an idle keep-alive connection, is closed after it.
    pub idle_timeout: Duration,
    /// Largest change of any joint (deg) a joint target's compensation may
    /// make (`--max-joint-change-deg`): beyond it `/compensate` answers
    /// that target `joint_change` ([`crate::compensate::Compensator::max_joint_change_deg`]).
    pub max_joint_change_deg: f64,
    /// Serve without API keys (`--insecure-no-auth`): every request acts
    /// as an admin. Refused unless `listen` is a loopback address.
    pub insecure_no_auth: bool,
    /// An admin key to create on start if no key has it (`DRAWCAL_ADMIN_KEY`,
    /// `--admin-key-file`): how a fresh deployment gets its first key.
    pub bootstrap_admin_key: Option<String>,
    /// Names the `Host` header may give (`--allowed-host`; `*`: any);
    /// empty: the listen address and the loopback names
    /// ([`guard::BrowserPolicy::new`]).
    pub allowed_hosts: Vec<String>,
    /// Web origins allowed to call the API from a browser (`--cors-origin`);
    /// empty: none.
    pub cors_origins: Vec<String>,
    /// Per-key rates and the job queue's bound.
    pub limits: limits::LimitConfig,
    /// Connections served at once (`--max-connections`); `None`: under
    /// the descriptor limit ([`conn::default_max_connections`]).
    pub max_connections: Option<usize>,
    /// Bytes large answers may hold in memory together
    /// (`--max-answer-bytes-in-flight`, [`conn::AnswerBudget`]).
    pub max_answer_bytes_in_flight: u64,
    /// The largest corrections a calibration may make to be activated.
    pub activation_bounds: crate::report::activation::ActivationBounds,
}

/// The whole request body must arrive within this many client timeouts
/// (30 s by default: 5 minutes, 16 MiB at about 0.5 Mbit/s).
pub const BODY_DEADLINE_FACTOR: u32 = 10;

/// Longest client or idle timeout the service takes (a day): beyond it a
/// deadline would overflow the clock, and no client needs it.
pub const MAX_TIMEOUT: Duration = Duration::from_secs(86_400);

/// Largest batch `/compensate` accepts.
pub const MAX_COMPENSATE_TARGETS: usize = 10_000;

/// Shared state of the handlers.
pub struct App {
    /// The database.
    pub store: Store,
    /// The job pool (to wake it on enqueue).
    pub jobs: Jobs,
    /// The pose plans running or waiting in this process.
    pub plans: crate::jobs::plans::Plans,
    /// Built compensators and robots' active calibration ids, with the
    /// rules of when each is dropped.
    pub cache: cache::CompensationCache,
    /// Threads for request-path numerical work (one per core).
    pub compute: compute::ComputePool,
    /// No API keys asked ([`ServiceConfig::insecure_no_auth`]).
    pub insecure_no_auth: bool,
    /// Which hosts and origins browsers are answered from.
    pub browser: Arc<guard::BrowserPolicy>,
    /// API keys as last read ([`auth::KEY_CACHE_TTL`]).
    pub keys: auth::KeyCache,
    /// Robots' sites, for keys limited to sites.
    pub robot_sites: auth::SiteCache,
    /// Per-key rates and the job queue's bound.
    pub limits: limits::Limits,
    /// The largest corrections an activated calibration may make.
    pub activation_bounds: crate::report::activation::ActivationBounds,
}

/// Threads for request-path numerical work: the number of cores.
pub fn compute_threads() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

/// How long `/compensate` may use a robot's active calibration id without
/// reading it again. Activation through this process takes effect at once;
/// through another replica sharing the database, within this time.
pub const ACTIVE_CACHE_TTL: Duration = Duration::from_secs(1);

/// Handle to [`App`], cheap to clone.
#[derive(Clone)]
pub struct AppState(pub Arc<App>);

impl std::ops::Deref for AppState {
    type Target = App;
    fn deref(&self) -> &App {
        &self.0
    }
}

/// Pagination query parameters.
#[derive(Debug, Clone, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct PageParams {
    /// Items per page, 1..=1000 (default 50).
    #[param(minimum = 1, maximum = 1000)]
    pub limit: Option<i64>,
    /// Items to skip (default 0).
    #[param(minimum = 0, maximum = 9223372036854775807_i64)]
    pub offset: Option<i64>,
}

impl PageParams {
    /// Checked page.
    pub fn page(&self) -> ApiResult<crate::store::Page> {
        let limit = self.limit.unwrap_or(50);
        let offset = self.offset.unwrap_or(0);
        if !(1..=1000).contains(&limit) {
            return Err(ApiError::invalid("limit", "must be between 1 and 1000"));
        }
        if offset < 0 {
            return Err(ApiError::invalid("offset", "must not be negative"));
        }
        Ok(crate::store::Page { limit, offset })
    }
}

/// A page of a list.
#[derive(Debug, Serialize, ToSchema)]
pub struct Paged<T: ToSchema> {
    /// The items.
    pub items: Vec<T>,
    /// Items matching in all.
    pub total: i64,
    /// Page size used.
    pub limit: i64,
    /// Offset used.
    pub offset: i64,
}

impl<T: ToSchema> Paged<T> {
    fn new(items: Vec<T>, total: i64, page: crate::store::Page) -> Self {
        Paged {
            items,
            total,
            limit: page.limit,
            offset: page.offset,
        }
    }
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "drawcal service",
        description = "Robot kinematic calibration: pose plans, sessions, identification jobs, calibrations, activation, compensation and fleet history. Lengths in mm, angles in degrees. Every error answers `{error, message, field?, row?}`.",
        license(name = "MIT OR Apache-2.0")
    ),
    // Format and ExportFormatParam are referenced only by query
    // parameters, which utoipa does not collect schemas from; LengthMm's
    // schema is written by hand, which utoipa does not collect either.
    components(schemas(
        ErrorBody,
        calibrations::Format,
        export::ExportFormatParam,
        documents::LengthMm
    )),
    modifiers(&BearerKeys),
    security(("api_key" = []))
)]
struct ApiDoc;

/// Every route needs an API key (`/health` and `/ready` override it).
struct BearerKeys;

impl utoipa::Modify for BearerKeys {
    fn modify(&self, doc: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
        let scheme = SecurityScheme::Http(
            HttpBuilder::new()
                .scheme(HttpAuthScheme::Bearer)
                .description(Some(
                    "An API key (`drawcal keys create`, `POST /keys`); its role decides the routes: reader (GET), operator (POST /compensate), engineer (other writes), admin (activation, rollback, keys, audit)",
                ))
                .build(),
        );
        doc.components
            .get_or_insert_with(Default::default)
            .add_security_scheme("api_key", scheme);
    }
}

/// Routes and their documentation, from the same handler annotations.
fn api() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(ops::health))
        .routes(routes!(ops::ready))
        .routes(routes!(resources::create_model, resources::list_models))
        .routes(routes!(resources::get_model))
        .routes(routes!(resources::create_robot, resources::list_robots))
        .routes(routes!(resources::get_robot))
        .routes(routes!(resources::create_rig, resources::list_rigs))
        .routes(routes!(resources::get_rig))
        .routes(routes!(sessions::create_session, sessions::list_sessions))
        .routes(routes!(sessions::get_session))
        .routes(routes!(sessions::upload_poses, sessions::get_poses))
        .routes(routes!(sessions::enqueue_job))
        .routes(routes!(sessions::list_jobs))
        .routes(routes!(sessions::get_job))
        .routes(routes!(sessions::cancel_job))
        .routes(routes!(plans::create_plan))
        .routes(routes!(plans::get_plan))
        .routes(routes!(plans::get_plan_targets))
        .routes(routes!(calibrations::list_calibrations))
        .routes(routes!(calibrations::get_calibration))
        .routes(routes!(ui::calibration_report_html))
        .routes(routes!(export::export_calibration))
        .routes(routes!(calibrations::robot_accuracy))
        .routes(routes!(calibrations::activate))
        .routes(routes!(calibrations::rollback))
        .routes(routes!(calibrations::list_activations))
        .routes(routes!(compensate::compensate))
        .routes(routes!(keys::create_key, keys::list_keys))
        .routes(routes!(keys::revoke_key))
        .routes(routes!(keys::list_audit))
}

/// The OpenAPI document of the service.
pub fn openapi() -> utoipa::openapi::OpenApi {
    let mut doc = api().split_for_parts().1;
    declare_roles(&mut doc);
    contract::declare(&mut doc);
    doc
}

/// Each operation's role, from the rule the key check applies
/// ([`auth::required_role`]): `x-required-role` is `reader`, `operator`,
/// `engineer` or `admin` (a key with it or a higher role may call the
/// route), or `none` for the routes anyone may call.
fn declare_roles(doc: &mut utoipa::openapi::OpenApi) {
    use axum::http::Method;
    for (path, item) in doc.paths.paths.iter_mut() {
        let operations = [
            (Method::GET, &mut item.get),
            (Method::POST, &mut item.post),
            (Method::PUT, &mut item.put),
            (Method::PATCH, &mut item.patch),
            (Method::DELETE, &mut item.delete),
        ];
        for (method, op) in operations {
            let Some(op) = op else { continue };
            let role = auth::required_role(&method, path);
            op.extensions.get_or_insert_with(Default::default).insert(
                "x-required-role".into(),
                role.map_or("none", auth::Role::as_str).into(),
            );
            let Some(role) = role else { continue };
            for (status, description) in [
                (
                    "401",
                    "No API key, or one that is unknown, expired or revoked: error `unauthorized`"
                        .to_string(),
                ),
                (
                    "403",
                    format!(
                        "The key's role is below `{role}`, or the key is limited to sites this \
                         resource is not at: error `forbidden`"
                    ),
                ),
            ] {
                op.responses
                    .responses
                    .entry(status.into())
                    .or_insert_with(|| error_response(description).into());
            }
        }
    }
}

/// An answer documented as the error shape.
fn error_response(description: String) -> utoipa::openapi::Response {
    use utoipa::openapi::{ContentBuilder, Ref, ResponseBuilder};
    ResponseBuilder::new()
        .description(description)
        .content(
            "application/json",
            ContentBuilder::new()
                .schema(Some(Ref::from_schema_name("ErrorBody")))
                .build(),
        )
        .build()
}

/// The OpenAPI document as committed in `openapi.yaml`.
pub fn openapi_yaml() -> String {
    openapi()
        .to_yaml()
        .expect("the OpenAPI document serialises to YAML")
}

/// Request ids: a per-process counter with a process prefix.
#[derive(Clone)]
struct CounterId {
    prefix: Arc<str>,
    next: Arc<AtomicU64>,
}

impl MakeRequestId for CounterId {
    fn make_request_id<B>(&mut self, _: &Request<B>) -> Option<RequestId> {
        let n = self.next.fetch_add(1, Ordering::Relaxed);
        HeaderValue::from_str(&format!("{}-{n}", self.prefix))
            .ok()
            .map(RequestId::new)
    }
}

/// An `x-request-id` safe to log as it is: 1 to 64 letters, digits and
/// `.`, `_`, `:`, `-`.
fn is_plain_request_id(s: &str) -> bool {
    (1..=64).contains(&s.len())
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b".:_-".contains(&b))
}

/// The application, ready to serve; `budget` bounds what large answers
/// hold in memory together.
pub fn router(
    state: AppState,
    max_upload_bytes: usize,
    client_timeout: Duration,
    budget: conn::AnswerBudget,
) -> Router {
    let client_timeout = client_timeout.min(MAX_TIMEOUT);
    let (router, _) = api().split_for_parts();
    let ids = CounterId {
        prefix: format!("{:x}", crate::store::now_ms() & 0xff_ffff).into(),
        next: Arc::new(AtomicU64::new(1)),
    };
    // The key check runs on the API's matched routes (after routing, so it
    // sees the route's template); the page's own files and the fallbacks
    // are public.
    let router = router
        .route_layer(axum::middleware::from_fn_with_state(
            state.clone(),
            auth::require_key,
        ))
        .merge(ui::routes())
        .fallback(|| async { ApiError::NotFound("no such route".into()) })
        .method_not_allowed_fallback(|| async { ApiError::MethodNotAllowed })
        .layer(axum::Extension(extract::BodyPolicy {
            max_upload_bytes,
            idle_timeout: client_timeout,
            deadline: client_timeout * BODY_DEADLINE_FACTOR,
        }))
        .layer(axum::middleware::from_fn_with_state(budget, conn::budget))
        .layer(axum::middleware::from_fn_with_state(
            state.browser.clone(),
            guard::check,
        ));
    let router = match cors(&state.browser) {
        Some(layer) => router.layer(layer),
        None => router,
    };
    router
        .layer(PropagateRequestIdLayer::x_request_id())
        .layer(
            TraceLayer::new_for_http()
                .on_response(DefaultOnResponse::new().level(tracing::Level::INFO))
                .make_span_with(|req: &Request<_>| {
                // A client's own id is logged only when it cannot pass
                // for log syntax (`a method=DELETE`) or be a novel.
                let id = req
                    .headers()
                    .get("x-request-id")
                    .and_then(|v| v.to_str().ok())
                    .filter(|s| is_plain_request_id(s))
                    .unwrap_or("-");
                tracing::info_span!("request", request_id = %id, method = %req.method(), uri = %req.uri())
            }),
        )
        .layer(SetRequestIdLayer::x_request_id(ids))
        .with_state(state)
}

/// CORS answers for the configured origins only; none by default (then
/// a preflight is answered 405 like any OPTIONS request).
fn cors(policy: &guard::BrowserPolicy) -> Option<tower_http::cors::CorsLayer> {
    use axum::http::{Method, header};
    use tower_http::cors::{AllowOrigin, CorsLayer};
    if policy.cors_origins.is_empty() {
        return None;
    }
    let origins: Vec<HeaderValue> = policy
        .cors_origins
        .iter()
        .filter_map(|o| HeaderValue::from_str(o).ok())
        .collect();
    Some(
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(origins))
            .allow_methods([Method::GET, Method::POST])
            .allow_headers([header::AUTHORIZATION, header::CONTENT_TYPE, header::ACCEPT])
            .expose_headers([header::RETRY_AFTER, header::LOCATION])
            .max_age(Duration::from_secs(600)),
    )
}

/// A started service: store connected and migrated, workers running,
/// listener bound.
pub struct Service {
    /// The bound address (with the real port when 0 was asked).
    pub addr: SocketAddr,
    listener: tokio::net::TcpListener,
    state: AppState,
    max_upload_bytes: usize,
    client_timeout: Duration,
    idle_timeout: Duration,
    drain_timeout: Duration,
    max_connections: usize,
    budget: conn::AnswerBudget,
}

impl Service {
    /// Connect, migrate, start `cfg.jobs.workers` workers running `job_fn`,
    /// bind.
    pub async fn start(
        cfg: &ServiceConfig,
        job_fn: JobFn,
    ) -> Result<Service, Box<dyn std::error::Error + Send + Sync>> {
        if cfg.insecure_no_auth && !cfg.listen.ip().is_loopback() {
            return Err(format!(
                "--insecure-no-auth serves without API keys, so only on a loopback address \
                 (127.0.0.1, ::1), not {}",
                cfg.listen
            )
            .into());
        }
        let store = Store::connect(&cfg.database_url).await?;
        if let Some(secret) = &cfg.bootstrap_admin_key {
            keys::ensure_admin(&store, secret).await?;
        }
        let jobs = Jobs::start(store.clone(), cfg.jobs.clone(), job_fn);
        let descriptors = conn::raise_descriptor_limit();
        let max_connections = cfg
            .max_connections
            .unwrap_or_else(|| conn::default_max_connections(descriptors));
        tracing::info!(
            descriptor_limit = descriptors.unwrap_or(0),
            max_connections,
            "connections capped"
        );
        let listener = tokio::net::TcpListener::bind(cfg.listen).await?;
        if cfg.listen.ip().is_unspecified() && cfg.allowed_hosts.is_empty() {
            tracing::warn!(
                "listening on {} but answering only the hosts localhost, 127.0.0.1 and [::1]: \
                 give the names clients use with --allowed-host (DRAWCAL_ALLOWED_HOST)",
                cfg.listen
            );
        }
        let addr = listener.local_addr()?;
        let plans = crate::jobs::plans::Plans::new(store.clone(), cfg.jobs.workers, cfg.jobs.lease);
        let state = AppState(Arc::new(App {
            store,
            jobs,
            plans,
            cache: cache::CompensationCache::new(cfg.max_joint_change_deg),
            compute: compute::ComputePool::new(compute_threads()),
            insecure_no_auth: cfg.insecure_no_auth,
            keys: auth::KeyCache::default(),
            robot_sites: auth::SiteCache::default(),
            limits: limits::Limits::new(cfg.limits),
            activation_bounds: cfg.activation_bounds,
            browser: Arc::new(guard::BrowserPolicy::new(
                addr,
                &cfg.allowed_hosts,
                &cfg.cors_origins,
            )),
        }));
        Ok(Service {
            addr,
            listener,
            state,
            max_upload_bytes: cfg.max_upload_bytes,
            client_timeout: cfg.client_timeout,
            idle_timeout: cfg.idle_timeout.min(MAX_TIMEOUT),
            drain_timeout: cfg.jobs.shutdown_grace,
            max_connections,
            budget: conn::AnswerBudget::new(cfg.max_answer_bytes_in_flight),
        })
    }

    /// The handlers' state (tests use it to reach the store).
    pub fn state(&self) -> AppState {
        self.state.clone()
    }

    /// Serve until `shutdown` resolves; then finish in-flight requests
    /// (for at most the jobs' shutdown grace: a client that stopped reading
    /// its answer must not hold the shutdown up), let running jobs finish
    /// within their grace period (or hand them back to the queue), and
    /// close the database.
    pub async fn run(
        self,
        shutdown: impl std::future::Future<Output = ()> + Send + 'static,
    ) -> std::io::Result<()> {
        let app = router(
            self.state.clone(),
            self.max_upload_bytes,
            self.client_timeout,
            self.budget.clone(),
        );
        tracing::info!(addr = %self.addr, url = %format!("http://{}/", self.addr), "listening");
        serve_connections(
            self.listener,
            app,
            Timeouts {
                idle: self.idle_timeout,
                write: self.client_timeout.min(MAX_TIMEOUT),
                drain: self.drain_timeout,
            },
            self.max_connections,
            shutdown,
        )
        .await;
        tracing::info!("HTTP server stopped; stopping job workers");
        self.state.jobs.shutdown().await;
        self.state.plans.shutdown(self.drain_timeout).await;
        self.state.store.close().await;
        tracing::info!("shutdown complete");
        Ok(())
    }
}

/// Accept connections and serve `app` on each (HTTP/1.1) until `shutdown`
/// resolves; then stop accepting and give the open connections up to
/// `drain_timeout` to finish their requests.
///
/// Our own loop rather than `axum::serve`, which gives hyper no timer, so a
/// client could hold a connection open for ever by sending its headers a
/// byte at a time (or nothing at all); here hyper closes a connection whose
/// next request header has not all arrived within `idle_timeout`. That is
/// also hyper's keep-alive idle timeout, which is why it defaults longer
/// than the 90 s idle time of common client pools (reqwest, Go): a pool
/// must drop a connection before the server closes it under a request.
/// No HTTP upgrades (websockets): the service has none.
async fn serve_connections(
    listener: tokio::net::TcpListener,
    app: Router,
    timeouts: Timeouts,
    max_connections: usize,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) {
    let Timeouts {
        idle: idle_timeout,
        write: write_timeout,
        drain: drain_timeout,
    } = timeouts;
    let slots = Arc::new(tokio::sync::Semaphore::new(max_connections));
    use hyper_util::rt::{TokioIo, TokioTimer};
    use hyper_util::server::graceful::GracefulShutdown;
    use hyper_util::service::TowerToHyperService;

    let graceful = GracefulShutdown::new();
    let mut shutdown = std::pin::pin!(shutdown);
    loop {
        let accepted = tokio::select! {
            accepted = listener.accept() => accepted,
            () = &mut shutdown => break,
        };
        let (tcp, peer) = match accepted {
            Ok(conn) => conn,
            // The peer gave up before we took the connection: nothing to do.
            Err(e) if is_connection_error(&e) => continue,
            Err(e) => {
                // Out of file descriptors and the like: back off (and stay
                // stoppable) instead of spinning or stopping the service.
                tracing::error!(error = %e, "accept failed; retrying in 1 s");
                tokio::select! {
                    () = tokio::time::sleep(Duration::from_secs(1)) => continue,
                    () = &mut shutdown => break,
                }
            }
        };
        // An answer that leaves in more than one segment (a large batch, or
        // headers and body flushed apart) must not wait on Nagle for the
        // client's delayed ACK (up to 40 ms).
        let _ = tcp.set_nodelay(true);
        let Ok(slot) = slots.clone().try_acquire_owned() else {
            tracing::warn!(%peer, max_connections, "connection refused: at the cap");
            tokio::spawn(conn::refuse(tcp, max_connections));
            continue;
        };
        let io = conn::WriteTimeout::new(conn::JsonParseErrors::new(tcp), write_timeout);
        let conn = hyper::server::conn::http1::Builder::new()
            .timer(TokioTimer::new())
            .header_read_timeout(idle_timeout)
            .serve_connection(TokioIo::new(io), TowerToHyperService::new(app.clone()));
        let conn = graceful.watch(conn);
        tokio::spawn(async move {
            let _slot = slot;
            match conn.await {
                Ok(()) => {}
                Err(e) if e.is_timeout() => {
                    tracing::debug!(%peer, "connection closed: idle, or its request header too slow");
                }
                Err(e) => tracing::debug!(%peer, error = %e, "connection ended with an error"),
            }
        });
    }
    drop(listener);
    if tokio::time::timeout(drain_timeout, graceful.shutdown())
        .await
        .is_err()
    {
        // Their tasks end with the runtime.
        tracing::warn!(
            "connections still open {} s after the shutdown signal are dropped",
            drain_timeout.as_secs()
        );
    }
}

/// How long a connection may wait for its client.
struct Timeouts {
    /// Without a complete request header.
    idle: Duration,
    /// With an answer the client does not read.
    write: Duration,
    /// After the shutdown signal.
    drain: Duration,
}

/// Accept errors that concern one connection only.
fn is_connection_error(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::ConnectionRefused
            | std::io::ErrorKind::ConnectionAborted
            | std::io::ErrorKind::ConnectionReset
    )
}

/// Resolves on Ctrl-C or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {}
        _ = term => {}
    }
    tracing::info!("shutdown signal received");
}

/// Default lease if not configured.
pub const DEFAULT_LEASE: Duration = Duration::from_secs(15);

#[cfg(test)]
mod tests {
    #[test]
    fn only_plain_request_ids_are_logged_as_sent() {
        use super::is_plain_request_id as plain;
        assert!(plain("a1b2-3") && plain("mes.line-2:42_x"));
        for forged in ["", "a method=DELETE", "x\"y", "a\tb", &"x".repeat(65)] {
            assert!(!plain(forged), "{forged:?}");
        }
    }
}
