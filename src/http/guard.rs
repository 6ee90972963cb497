//! Browser safety: what a web page elsewhere must not be able to do with
//! the service through its user's browser.
//!
//! - **Host** ([`BrowserPolicy::allowed_hosts`], `serve --allowed-host`):
//!   a request whose `Host` is not a name the service answers to is
//!   refused (421 `host_not_allowed`), so that a page on a hostile domain
//!   rebound to this address (DNS rebinding) gets nothing. `/health` and
//!   `/ready` answer any host: orchestrators probe them by address.
//! - **Origin**: a state-changing request (any method but GET, HEAD and
//!   OPTIONS) that a browser marks as coming from another origin is
//!   refused (403), unless that origin is configured (`--cors-origin`).
//!   API keys already keep such requests out (a browser cannot add
//!   `Authorization` to a cross-site request without a preflight that
//!   fails); this also holds with `--insecure-no-auth`.
//! - **Content types**: a state-changing request whose body is declared as
//!   anything but JSON or CSV is refused (415), so that an HTML form
//!   (`text/plain`, `application/x-www-form-urlencoded`,
//!   `multipart/form-data`) never reaches a handler.
//! - **CORS**: none unless `--cors-origin` names origins; then those
//!   origins, and only they, get CORS answers.
//! - **Headers on every answer**: a content security policy that forbids
//!   framing (`frame-ancestors 'none'`) and any script but the page's own,
//!   `X-Content-Type-Options: nosniff`, `X-Frame-Options: DENY` (older
//!   browsers) and `Referrer-Policy: no-referrer`.

use std::net::SocketAddr;
use std::sync::Arc;

use axum::extract::{Request, State};
use axum::http::header::{
    CONTENT_SECURITY_POLICY, CONTENT_TYPE, HOST, ORIGIN, REFERRER_POLICY, X_CONTENT_TYPE_OPTIONS,
    X_FRAME_OPTIONS,
};
use axum::http::{HeaderValue, Method};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::ApiError;

/// The content security policy of every answer: the page's own script and
/// the service's own requests only; inline styles (the report's plots carry
/// them) and `data:` images; never framed.
pub const CONTENT_SECURITY_POLICY_VALUE: &str = "default-src 'self'; script-src 'self'; \
     style-src 'self' 'unsafe-inline'; img-src 'self' data:; object-src 'none'; \
     base-uri 'none'; form-action 'self'; frame-ancestors 'none'";

/// Which hosts and origins the service answers browsers from.
#[derive(Debug, Clone, Default)]
pub struct BrowserPolicy {
    /// Host names (lower case, without a port; IPv6 addresses in brackets)
    /// the `Host` header may name; empty: any (`--allowed-host '*'`).
    pub allowed_hosts: Vec<String>,
    /// Origins (`https://mes.example:8443`) allowed to make cross-origin
    /// requests, with CORS answers; empty: none.
    pub cors_origins: Vec<String>,
}

impl BrowserPolicy {
    /// The policy for a service listening on `listen`: the hosts asked for
    /// (`*` alone: any), else the listen address and the loopback names.
    pub fn new(listen: SocketAddr, allowed_hosts: &[String], cors_origins: &[String]) -> Self {
        let allowed_hosts = if allowed_hosts.iter().any(|h| h == "*") {
            Vec::new()
        } else if allowed_hosts.is_empty() {
            let mut hosts: Vec<String> = ["localhost", "127.0.0.1", "[::1]"]
                .map(String::from)
                .to_vec();
            if !listen.ip().is_unspecified() {
                let own = host_of(&SocketAddr::new(listen.ip(), 0).to_string());
                if !hosts.contains(&own) {
                    hosts.push(own);
                }
            }
            hosts
        } else {
            allowed_hosts.iter().map(|h| normalize_host(h)).collect()
        };
        BrowserPolicy {
            allowed_hosts,
            cors_origins: cors_origins
                .iter()
                .map(|o| o.trim_end_matches('/').to_ascii_lowercase())
                .collect(),
        }
    }

    /// True when the `Host` header `host` (with or without its port) is one
    /// the service answers to.
    pub fn host_allowed(&self, host: &str) -> bool {
        self.allowed_hosts.is_empty() || self.allowed_hosts.contains(&host_of(host))
    }
}

/// A host as the policy compares it: lower case, an IPv6 address in
/// brackets (`::1` and `[::1]` alike).
fn normalize_host(h: &str) -> String {
    let h = h.trim().to_ascii_lowercase();
    if h.contains(':') && !h.starts_with('[') {
        format!("[{h}]")
    } else {
        h
    }
}

/// The host part of a `Host` header or an origin's authority, lower case,
/// without its port.
fn host_of(authority: &str) -> String {
    let a = authority.trim().to_ascii_lowercase();
    if a.starts_with('[') {
        return match a.find(']') {
            Some(end) => a[..=end].to_string(),
            None => a,
        };
    }
    match a.rsplit_once(':') {
        Some((host, port)) if port.bytes().all(|b| b.is_ascii_digit()) => host.to_string(),
        _ => a,
    }
}

/// The middleware: Host, Origin and content type checked (see the module
/// documentation), the security headers added to the answer.
pub async fn check(State(policy): State<Arc<BrowserPolicy>>, req: Request, next: Next) -> Response {
    let mut response = match refusal(&policy, &req) {
        Some(e) => e.into_response(),
        None => next.run(req).await,
    };
    let h = response.headers_mut();
    h.insert(
        CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CONTENT_SECURITY_POLICY_VALUE),
    );
    h.insert(X_CONTENT_TYPE_OPTIONS, HeaderValue::from_static("nosniff"));
    h.insert(X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(REFERRER_POLICY, HeaderValue::from_static("no-referrer"));
    response
}

/// Why `req` is refused before routing, if it is.
fn refusal(policy: &BrowserPolicy, req: &Request) -> Option<ApiError> {
    let path = req.uri().path();
    let header = |name| req.headers().get(name).and_then(|v| v.to_str().ok());
    // HTTP/1.1 requires Host; hyper puts an absolute URI's authority there.
    let host = header(HOST).or_else(|| req.uri().authority().map(|a| a.as_str()));
    if !matches!(path, "/health" | "/ready") {
        match host {
            Some(h) if policy.host_allowed(h) => {}
            Some(h) => {
                return Some(ApiError::HostNotAllowed(format!(
                    "this service does not answer to the host {h:?}: start it with \
                     --allowed-host NAME (environment DRAWCAL_ALLOWED_HOST) for each name \
                     clients use to reach it"
                )));
            }
            None => return Some(ApiError::BadRequest("no Host header".into())),
        }
    }
    if matches!(*req.method(), Method::GET | Method::HEAD | Method::OPTIONS) {
        return None;
    }
    if let Some(origin) = header(ORIGIN) {
        let o = origin.trim_end_matches('/').to_ascii_lowercase();
        let same_origin = match (o.split_once("://"), host) {
            (Some((_, authority)), Some(h)) => authority == h.to_ascii_lowercase(),
            _ => false,
        };
        if !same_origin && !policy.cors_origins.contains(&o) {
            return Some(ApiError::Forbidden(format!(
                "a request from the web page at {origin:?} (another origin) may not change \
                 anything here; to allow that origin, start the service with \
                 --cors-origin {origin}"
            )));
        }
    }
    let declared = header(CONTENT_TYPE)?;
    let media = declared
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    (!matches!(media.as_str(), "application/json" | "text/csv")).then(|| {
        ApiError::UnsupportedMediaType(format!(
            "a request that changes something takes application/json or text/csv bodies only \
             (each route documents which), got Content-Type {declared:?}"
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy(hosts: &[&str]) -> BrowserPolicy {
        let hosts: Vec<String> = hosts.iter().map(|s| s.to_string()).collect();
        BrowserPolicy::new("127.0.0.1:8080".parse().unwrap(), &hosts, &[])
    }

    #[test]
    fn hosts_compare_without_port_and_case() {
        let p = policy(&[]);
        for ok in [
            "localhost",
            "LOCALHOST:8080",
            "127.0.0.1:8080",
            "[::1]:8080",
        ] {
            assert!(p.host_allowed(ok), "{ok}");
        }
        for bad in [
            "evil.example",
            "evil.example:8080",
            "127.0.0.1.evil",
            "localhost.:80",
        ] {
            assert!(!p.host_allowed(bad), "{bad}");
        }
        let p = policy(&["Calib.Plant.example", "::1"]);
        assert!(p.host_allowed("calib.plant.example:443") && p.host_allowed("[::1]"));
        assert!(
            !p.host_allowed("localhost"),
            "the list replaces the default"
        );
        assert!(policy(&["*"]).host_allowed("anything"));
    }

    #[test]
    fn the_listen_address_is_allowed_by_default_unless_unspecified() {
        let p = BrowserPolicy::new("10.1.2.3:8080".parse().unwrap(), &[], &[]);
        assert!(p.host_allowed("10.1.2.3:8080"));
        let p = BrowserPolicy::new("0.0.0.0:8080".parse().unwrap(), &[], &[]);
        assert!(!p.host_allowed("0.0.0.0:8080") && p.host_allowed("localhost:8080"));
        let p = BrowserPolicy::new("[fe80::1]:8080".parse().unwrap(), &[], &[]);
        assert!(p.host_allowed("[fe80::1]:8080"));
    }
}
