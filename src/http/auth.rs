//! API keys and roles: every request but `/health`, `/ready` and the
//! browser page's own files needs `Authorization: Bearer <key>`.
//!
//! Roles are ordered, each holding the ones below it: `reader` (history,
//! results, reports: every GET), `operator` (`POST /compensate`),
//! `engineer` (models, rigs, robots, sessions, uploads, jobs: every other
//! write), `admin` (activation, rollback, keys, the audit log). A key is
//! random (`dck_` and 64 hex digits from the operating system's generator),
//! shown once, stored as its SHA-256 with its first characters for
//! telling keys apart. Missing, unknown, expired or revoked: 401; the
//! wrong role: 403. What a key does is recorded under its name
//! ([`Caller::name`]), never under a name the client sends.

use std::collections::HashMap;
use std::fmt;
use std::str::FromStr;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use axum::extract::{MatchedPath, Request, State};
use axum::http::Method;
use axum::middleware::Next;
use axum::response::Response;
use sha2::{Digest, Sha256};

use super::AppState;
use super::error::ApiError;
use crate::store::KeyRec;

/// How long a key read from the store is used without reading it again: a
/// revocation or expiry through this process takes effect at once (the
/// cache is emptied), through another replica within this time. The check
/// of a request then costs a hash and a map lookup, not a query.
pub const KEY_CACHE_TTL: Duration = Duration::from_secs(1);

/// Most keys (known or not) the cache holds: past it, it starts afresh, so
/// that a client trying random keys cannot grow it.
const KEY_CACHE_MAX: usize = 4096;

/// Keys by the SHA-256 of their secret, as last read (`None`: no such key).
#[derive(Debug, Default)]
pub struct KeyCache {
    entries: Mutex<HashMap<String, (Instant, Option<KeyRec>)>>,
}

impl KeyCache {
    /// The key with `hash`, from the cache if read within
    /// [`KEY_CACHE_TTL`], else from the store.
    async fn get(&self, app: &AppState, hash: String) -> Result<Option<KeyRec>, ApiError> {
        if let Some((at, key)) = self.lock().get(&hash) {
            if at.elapsed() < KEY_CACHE_TTL {
                return Ok(key.clone());
            }
        }
        let key = app.store.key_by_hash(&hash).await?;
        let mut entries = self.lock();
        if entries.len() >= KEY_CACHE_MAX {
            entries.clear();
        }
        entries.insert(hash, (Instant::now(), key.clone()));
        Ok(key)
    }

    /// Forget every key (after a key was created or revoked here).
    pub fn clear(&self) {
        self.lock().clear();
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, (Instant, Option<KeyRec>)>> {
        // A panic while holding the lock leaves a map that is still whole.
        self.entries.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Robots' sites, as read once: a robot's site is set when it is created and
/// no route changes it, so an entry never goes stale, and a key limited to
/// sites is checked without a query on every request (`POST /compensate`
/// from a floor client's site key, above all).
#[derive(Debug, Default)]
pub struct SiteCache {
    entries: std::sync::RwLock<HashMap<i64, Option<String>>>,
}

impl SiteCache {
    /// The site of the robot `robot_id` (`None`: at no site); not found if
    /// there is no such robot. Only robots that exist are kept, so the map
    /// grows with the fleet, never with what clients ask.
    /// `read` reads it from the store when it is not kept yet.
    pub async fn site<F, Fut>(&self, robot_id: i64, read: F) -> Result<Option<String>, ApiError>
    where
        F: FnOnce() -> Fut,
        Fut: std::future::Future<Output = Result<Option<String>, ApiError>>,
    {
        let known = self
            .entries
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .get(&robot_id)
            .cloned();
        if let Some(site) = known {
            return Ok(site);
        }
        let site = read().await?;
        self.entries
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .insert(robot_id, site.clone());
        Ok(site)
    }
}

/// What a key may do; each role holds the ones before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Role {
    /// History, results, reports (every GET).
    Reader,
    /// Floor clients: `POST /compensate`.
    Operator,
    /// Models, rigs, robots, sessions, uploads, jobs.
    Engineer,
    /// Activation, rollback, keys, the audit log.
    Admin,
}

impl Role {
    /// Every role, lowest first.
    pub const ALL: [Role; 4] = [Role::Reader, Role::Operator, Role::Engineer, Role::Admin];

    /// The role's name.
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Reader => "reader",
            Role::Operator => "operator",
            Role::Engineer => "engineer",
            Role::Admin => "admin",
        }
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Role {
    type Err = String;
    fn from_str(s: &str) -> Result<Role, String> {
        Role::ALL
            .into_iter()
            .find(|r| r.as_str() == s)
            .ok_or_else(|| format!("'{s}' is not a role (reader, operator, engineer, admin)"))
    }
}

/// Who is asking: the key's holder, as the middleware found it (handlers
/// take it as `Extension<Caller>`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Caller {
    /// The key's name: the actor recorded for what the request does.
    pub name: String,
    /// The key's role.
    pub role: Role,
    /// The sites the key is limited to (empty: every site): it reaches only
    /// the robots at them, and what belongs to those robots.
    pub sites: Vec<String>,
}

impl Caller {
    /// The caller of a service run with `--insecure-no-auth`.
    pub fn unauthenticated() -> Caller {
        Caller {
            name: "insecure-no-auth".into(),
            role: Role::Admin,
            sites: Vec::new(),
        }
    }

    /// Refused (403) unless the key reaches `site`, where `what` (`robot
    /// 7`) is.
    pub fn check_site(&self, what: &str, site: Option<&str>) -> Result<(), ApiError> {
        if self.sites.is_empty() || site.is_some_and(|s| self.sites.iter().any(|k| k == s)) {
            return Ok(());
        }
        Err(ApiError::Forbidden(format!(
            "the key '{}' is limited to the sites {}; {what} is {}",
            self.name,
            self.sites.join(", "),
            match site {
                Some(s) => format!("at the site {s:?}"),
                None => "at no site".to_string(),
            }
        )))
    }

    /// Refused (403) unless the key reaches the robot `robot_id` (its site
    /// looked up only for a key limited to sites, from [`SiteCache`]); an
    /// unknown robot is 404.
    pub async fn check_robot(&self, app: &AppState, robot_id: i64) -> Result<(), ApiError> {
        if self.sites.is_empty() {
            return Ok(());
        }
        let read = || async { Ok(app.store.get_robot(robot_id).await?.site) };
        let site = app.robot_sites.site(robot_id, read).await?;
        self.check_site(&format!("robot {robot_id}"), site.as_deref())
    }

    /// The site filter of a list for this key: the one asked if the key
    /// reaches it, the key's only site if none was asked; refused when the
    /// key has several sites and none was asked.
    pub fn site_filter(&self, asked: Option<String>) -> Result<Option<String>, ApiError> {
        match (asked, self.sites.as_slice()) {
            (asked, []) => Ok(asked),
            (Some(s), _) => self
                .check_site("the list asked", Some(&s))
                .map(|()| Some(s)),
            (None, [only]) => Ok(Some(only.clone())),
            (None, many) => Err(ApiError::Forbidden(format!(
                "the key '{}' is limited to the sites {}: give site= one of them",
                self.name,
                many.join(", ")
            ))),
        }
    }

    /// Refused (403) for a key limited to sites: lists that cannot be
    /// filtered by site (`what`).
    pub fn check_unlimited(&self, what: &str) -> Result<(), ApiError> {
        if self.sites.is_empty() {
            return Ok(());
        }
        Err(ApiError::Forbidden(format!(
            "the key '{}' is limited to sites, and {what} spans every site",
            self.name
        )))
    }
}

/// A new key: the secret to show once, its prefix and its hash.
pub struct NewSecret {
    /// The key itself (`dck_` and 64 hex digits).
    pub secret: String,
    /// Its first 12 characters.
    pub prefix: String,
    /// SHA-256 of the key (hex), what is stored.
    pub hash: String,
}

/// A fresh random key.
pub fn new_secret() -> Result<NewSecret, String> {
    let mut bytes = [0u8; 32];
    getrandom::fill(&mut bytes).map_err(|e| format!("no randomness for a key: {e}"))?;
    let secret = format!("dck_{}", hex(&bytes));
    Ok(NewSecret {
        prefix: secret[..12].to_string(),
        hash: hash(&secret),
        secret,
    })
}

/// SHA-256 of a key (hex): keys are long random strings, so a plain hash
/// (no salt, no stretching) is what lookup by hash needs and all a stolen
/// table gives away.
pub fn hash(secret: &str) -> String {
    hex(&Sha256::digest(secret.as_bytes()))
}

/// Lower-case hex: a table lookup per nibble, since every keyed request
/// hashes its key (a `format!` per byte made `hash` 23,600 instructions a
/// request under callgrind; 4,400 with the table).
fn hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut out = String::with_capacity(2 * bytes.len());
    for b in bytes {
        out.push(char::from(DIGITS[usize::from(b >> 4)]));
        out.push(char::from(DIGITS[usize::from(b & 0xf)]));
    }
    out
}

/// The role a route needs; `None` for the routes anyone may call.
pub fn required_role(method: &Method, path: &str) -> Option<Role> {
    match (method, path) {
        (&Method::GET, "/health" | "/ready") => None,
        (_, "/robots/{id}/activate" | "/robots/{id}/rollback" | "/audit") => Some(Role::Admin),
        (_, p) if p == "/keys" || p.starts_with("/keys/") => Some(Role::Admin),
        (&Method::POST, "/compensate") => Some(Role::Operator),
        (&Method::GET | &Method::HEAD, _) => Some(Role::Reader),
        _ => Some(Role::Engineer),
    }
}

/// The middleware: the key checked against the route's role, the caller
/// put in the request's extensions. Runs on matched API routes only (the
/// browser page's files and the fallbacks are public).
pub async fn require_key(
    State(app): State<AppState>,
    mut req: Request,
    next: Next,
) -> Result<Response, ApiError> {
    let path = req
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_string())
        .unwrap_or_else(|| req.uri().path().to_string());
    let Some(needed) = required_role(req.method(), &path) else {
        return Ok(next.run(req).await);
    };
    let caller = if app.insecure_no_auth {
        Caller::unauthenticated()
    } else {
        // The header copied out: a `&Request` held across the lookup
        // would make the future not `Send`.
        let header = req
            .headers()
            .get(axum::http::header::AUTHORIZATION)
            .map(|h| h.to_str().unwrap_or("").to_string());
        let caller = authenticate(&app, header).await?;
        if caller.role < needed {
            return Err(ApiError::Forbidden(format!(
                "the key '{}' has the role {}; {} {path} needs {needed}",
                caller.name,
                caller.role,
                req.method()
            )));
        }
        caller
    };
    req.extensions_mut().insert(caller);
    Ok(next.run(req).await)
}

/// The caller of a request's `Authorization` header, or why there is none.
async fn authenticate(app: &AppState, header: Option<String>) -> Result<Caller, ApiError> {
    let header = header.ok_or_else(|| {
        ApiError::Unauthorized("no API key: send Authorization: Bearer <key>".into())
    })?;
    let secret = header
        .strip_prefix("Bearer ")
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .ok_or_else(|| {
            ApiError::Unauthorized("the Authorization header is not `Bearer <key>`".into())
        })?;
    let unknown = || ApiError::Unauthorized("unknown API key".into());
    let key = app.keys.get(app, hash(secret)).await?.ok_or_else(unknown)?;
    if let Some(at) = &key.revoked_at {
        return Err(ApiError::Unauthorized(format!(
            "the key '{}' was revoked at {at}",
            key.name
        )));
    }
    if let Some(at) = key
        .expires_at
        .as_deref()
        .filter(|at| *at <= crate::store::now_rfc3339().as_str())
    {
        return Err(ApiError::Unauthorized(format!(
            "the key '{}' expired at {at}",
            key.name
        )));
    }
    let role = key.role.parse().map_err(ApiError::Internal)?;
    Ok(Caller {
        name: key.name,
        role,
        sites: key
            .sites
            .split(',')
            .filter(|s| !s.is_empty())
            .map(String::from)
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_by_route() {
        let r = |m: Method, p: &str| required_role(&m, p);
        assert_eq!(r(Method::GET, "/health"), None);
        assert_eq!(r(Method::GET, "/ready"), None);
        assert_eq!(r(Method::GET, "/calibrations"), Some(Role::Reader));
        assert_eq!(r(Method::POST, "/compensate"), Some(Role::Operator));
        assert_eq!(
            r(Method::POST, "/sessions/{id}/poses"),
            Some(Role::Engineer)
        );
        assert_eq!(r(Method::POST, "/jobs/{id}/cancel"), Some(Role::Engineer));
        assert_eq!(r(Method::POST, "/plans"), Some(Role::Engineer));
        assert_eq!(r(Method::GET, "/plans/{id}"), Some(Role::Reader));
        assert_eq!(
            r(Method::GET, "/plans/{id}/targets.csv"),
            Some(Role::Reader)
        );
        assert_eq!(r(Method::POST, "/robots/{id}/activate"), Some(Role::Admin));
        assert_eq!(r(Method::POST, "/robots/{id}/rollback"), Some(Role::Admin));
        assert_eq!(r(Method::GET, "/keys"), Some(Role::Admin));
        assert_eq!(r(Method::DELETE, "/keys/{id}"), Some(Role::Admin));
        assert_eq!(r(Method::GET, "/audit"), Some(Role::Admin));
        assert!(Role::Reader < Role::Operator && Role::Engineer < Role::Admin);
    }

    #[tokio::test]
    async fn a_robots_site_is_read_once() {
        let cache = SiteCache::default();
        let reads = std::sync::atomic::AtomicUsize::new(0);
        let read = |site: Option<&str>| {
            reads.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            let site = site.map(String::from);
            async move { Ok(site) }
        };
        for _ in 0..3 {
            let s = cache.site(7, || read(Some("plant-a"))).await.unwrap();
            assert_eq!(s.as_deref(), Some("plant-a"));
            assert_eq!(cache.site(8, || read(None)).await.unwrap(), None);
        }
        assert_eq!(reads.load(std::sync::atomic::Ordering::SeqCst), 2);
        // A robot that does not exist is not kept: asked again, read again.
        let missing = || async { Err(ApiError::NotFound("robot 9".into())) };
        assert!(cache.site(9, missing).await.is_err());
        assert!(cache.site(9, missing).await.is_err());
        assert!(cache.site(9, || read(Some("plant-b"))).await.is_ok());
        assert_eq!(reads.load(std::sync::atomic::Ordering::SeqCst), 3);
    }

    #[test]
    fn keys_are_random_and_stored_hashed() {
        let (a, b) = (new_secret().unwrap(), new_secret().unwrap());
        assert_ne!(a.secret, b.secret);
        assert!(a.secret.starts_with("dck_") && a.secret.len() == 68);
        assert!(a.secret.starts_with(&a.prefix));
        assert_eq!(a.hash, hash(&a.secret));
        assert!(!a.hash.contains(&a.secret[4..]));
        // SHA-256 of "abc".
        assert_eq!(
            hash("abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
