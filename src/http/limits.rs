//! Limits against abusive clients: per-key rates of pose uploads and job
//! submissions, and a bound on the job queue, each answered 429
//! `too_many_requests` with `Retry-After` and what the limit is.
//!
//! Rates are token buckets per key (a burst of a minute's worth, refilled
//! continuously), kept in this process: with several replicas a key gets
//! each replica's rate. The queue's bound is read from the store, so it
//! holds across replicas.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Instant;

use super::{ApiError, ApiResult, AppState};

/// What is limited per key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Action {
    /// `POST /sessions/{id}/poses`.
    Upload,
    /// `POST /sessions/{id}/jobs`.
    Job,
}

impl Action {
    fn describe(self) -> (&'static str, &'static str) {
        match self {
            Action::Upload => ("pose uploads", "--max-uploads-per-minute"),
            Action::Job => ("job submissions", "--max-jobs-per-minute"),
        }
    }
}

/// The limits (`serve` flags).
#[derive(Debug, Clone, Copy)]
pub struct LimitConfig {
    /// Pose uploads per key per minute.
    pub uploads_per_minute: u32,
    /// Job submissions per key per minute.
    pub jobs_per_minute: u32,
    /// Jobs queued (not yet running) across the service, beyond which a
    /// submission is refused.
    pub max_queued_jobs: i64,
}

impl Default for LimitConfig {
    fn default() -> Self {
        LimitConfig {
            uploads_per_minute: 600,
            jobs_per_minute: 60,
            max_queued_jobs: 1000,
        }
    }
}

/// The per-key buckets.
#[derive(Debug)]
pub struct Limits {
    /// The configured limits.
    pub config: LimitConfig,
    buckets: Mutex<HashMap<(String, Action), Bucket>>,
}

#[derive(Debug, Clone, Copy)]
struct Bucket {
    tokens: f64,
    at: Instant,
}

/// Most keys the buckets track; past it they start afresh (keys are made
/// by admins, so this is far above any real deployment).
const MAX_BUCKETS: usize = 100_000;

impl Limits {
    /// Limits with `config`, every bucket full.
    pub fn new(config: LimitConfig) -> Self {
        Limits {
            config,
            buckets: Mutex::new(HashMap::new()),
        }
    }

    /// Take one `action` for the key `key`, or say when to retry.
    pub fn take(&self, key: &str, action: Action) -> Result<(), ApiError> {
        self.take_at(key, action, Instant::now())
    }

    fn take_at(&self, key: &str, action: Action, now: Instant) -> Result<(), ApiError> {
        let per_minute = match action {
            Action::Upload => self.config.uploads_per_minute,
            Action::Job => self.config.jobs_per_minute,
        } as f64;
        let rate_per_s = per_minute / 60.0;
        let mut buckets = self.buckets.lock().unwrap_or_else(|e| e.into_inner());
        if buckets.len() >= MAX_BUCKETS {
            buckets.clear();
        }
        let b = buckets.entry((key.to_string(), action)).or_insert(Bucket {
            tokens: per_minute,
            at: now,
        });
        let elapsed = now.saturating_duration_since(b.at).as_secs_f64();
        b.tokens = (b.tokens + elapsed * rate_per_s).min(per_minute);
        b.at = now;
        if b.tokens >= 1.0 {
            b.tokens -= 1.0;
            return Ok(());
        }
        let (what, flag) = action.describe();
        let retry_after_s = ((1.0 - b.tokens) / rate_per_s).ceil().max(1.0) as u64;
        Err(ApiError::TooManyRequests {
            message: format!(
                "the key '{key}' is over its {per_minute} {what} a minute ({flag} of drawcal \
                 serve); retry in {retry_after_s} s"
            ),
            retry_after_s,
        })
    }

    /// Refuse a submission when `queued` jobs and plans already wait.
    pub fn check_queue(&self, queued: i64) -> Result<(), ApiError> {
        if queued < self.config.max_queued_jobs {
            return Ok(());
        }
        Err(ApiError::TooManyRequests {
            message: format!(
                "{queued} jobs and plans are already queued, the most the service takes \
                 (--max-queued-jobs); retry when some have run"
            ),
            retry_after_s: 30,
        })
    }
}

/// Refuse a job or plan submission when the queue is full: identification
/// jobs queued and plans waiting count together against
/// `--max-queued-jobs` (both wait for the same workers' time).
pub(super) async fn queue_has_room(app: &AppState) -> ApiResult<()> {
    let (_, queued_jobs) = app
        .store
        .list_jobs(
            None,
            Some("queued"),
            crate::store::Page {
                limit: 1,
                offset: 0,
            },
        )
        .await?;
    let queued_plans = app.store.count_queued_plans().await?;
    app.limits.check_queue(queued_jobs + queued_plans)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_bucket_allows_a_minutes_burst_then_refills_at_the_rate() {
        let l = Limits::new(LimitConfig {
            jobs_per_minute: 6,
            ..LimitConfig::default()
        });
        let t0 = Instant::now();
        for _ in 0..6 {
            l.take_at("k", Action::Job, t0).unwrap();
        }
        match l.take_at("k", Action::Job, t0) {
            Err(ApiError::TooManyRequests {
                retry_after_s,
                message,
            }) => {
                assert_eq!(retry_after_s, 10, "one job per 10 s");
                assert!(message.contains("'k'") && message.contains("--max-jobs-per-minute"));
            }
            other => panic!("{other:?}"),
        }
        // Another key and another action have their own buckets.
        l.take_at("other", Action::Job, t0).unwrap();
        l.take_at("k", Action::Upload, t0).unwrap();
        // Ten seconds later one more job.
        let t1 = t0 + Duration::from_secs(10);
        l.take_at("k", Action::Job, t1).unwrap();
        assert!(l.take_at("k", Action::Job, t1).is_err());
    }

    #[test]
    fn the_queue_is_bounded() {
        let l = Limits::new(LimitConfig {
            max_queued_jobs: 2,
            ..LimitConfig::default()
        });
        assert!(l.check_queue(1).is_ok());
        assert!(matches!(
            l.check_queue(2),
            Err(ApiError::TooManyRequests { .. })
        ));
    }
}
