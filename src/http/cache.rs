//! What `POST /compensate` keeps between requests, and when it is dropped:
//! the built compensators (by calibration id) and the robots' active
//! calibration ids.
//!
//! - A compensator is built once per calibration and kept: calibrations
//!   are immutable, so an entry never goes stale.
//! - A robot's active calibration id is kept for
//!   [`super::ACTIVE_CACHE_TTL`], and dropped at once when this process
//!   activates or rolls back ([`CompensationCache::forget_active`]); a read
//!   that raced with such a change is not kept.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock};
use std::time::Instant;

use super::{ACTIVE_CACHE_TTL, ApiError, ApiResult};
use crate::compensate::Compensator;
use crate::report::Report;
use crate::store::Store;

/// A built compensator and what it came from.
pub struct Cached {
    /// The engine's compensator.
    pub compensator: Compensator,
    /// Calibration id.
    pub calibration_id: i64,
    /// Its version.
    pub version: i64,
    /// Its robot.
    pub robot_id: i64,
}

/// The compensation cache of a service (see the module documentation).
pub struct CompensationCache {
    /// Built compensators by calibration id.
    compensators: RwLock<HashMap<i64, Arc<Cached>>>,
    /// Robots' active calibration ids as last read, with when.
    active: RwLock<HashMap<i64, (Option<i64>, Instant)>>,
    /// Bumped by every activation and rollback through this process, so
    /// that a read of the active id that raced with one is not kept.
    activations: AtomicU64,
    /// The bound every compensator built here is given.
    max_joint_change_deg: f64,
}

impl CompensationCache {
    /// An empty cache whose compensators refuse a joint target's change
    /// beyond `max_joint_change_deg`.
    pub fn new(max_joint_change_deg: f64) -> Self {
        CompensationCache {
            compensators: RwLock::default(),
            active: RwLock::default(),
            activations: AtomicU64::default(),
            max_joint_change_deg,
        }
    }

    /// Drop the robot's active calibration id: this process activated
    /// another calibration or rolled back, and the next request must see it.
    pub fn forget_active(&self, robot_id: i64) {
        self.activations.fetch_add(1, Ordering::SeqCst);
        if let Ok(mut m) = self.active.write() {
            m.remove(&robot_id);
        }
    }

    /// The robot's active calibration id; not found if the robot does not
    /// exist.
    ///
    /// Kept per robot for [`ACTIVE_CACHE_TTL`]. When the entry has expired,
    /// the first request to see it re-reads the robot (one primary-key
    /// read) while concurrent requests keep using the old id until that
    /// read lands, so the database sees one read per robot per TTL, never
    /// a burst. An activation made through another replica on the same
    /// database is therefore seen within the TTL plus one read.
    pub async fn active_calibration(&self, store: &Store, robot_id: i64) -> ApiResult<Option<i64>> {
        let now = Instant::now();
        if let Some((active, at)) = self
            .active
            .read()
            .ok()
            .and_then(|m| m.get(&robot_id).copied())
        {
            if now.duration_since(at) < ACTIVE_CACHE_TTL {
                return Ok(active);
            }
            // Expired: claim the refresh (the entry looks fresh to the others
            // while this request reads the robot), unless another one has.
            let claimed = match self.active.write() {
                Ok(mut m) => match m.get_mut(&robot_id) {
                    Some(e) if now.duration_since(e.1) >= ACTIVE_CACHE_TTL => {
                        e.1 = now;
                        true
                    }
                    _ => false,
                },
                Err(_) => true,
            };
            if !claimed {
                return Ok(active);
            }
        }
        let read_at = Instant::now();
        let epoch = self.activations.load(Ordering::SeqCst);
        let robot = match store.get_robot(robot_id).await {
            Ok(r) => r,
            Err(e) => {
                if let Ok(mut m) = self.active.write() {
                    m.remove(&robot_id);
                }
                return Err(e.into());
            }
        };
        if let Ok(mut m) = self.active.write() {
            // Not if an activation through this process may have raced the read.
            if self.activations.load(Ordering::SeqCst) == epoch {
                m.insert(robot_id, (robot.active_calibration_id, read_at));
            } else {
                m.remove(&robot_id);
            }
        }
        Ok(robot.active_calibration_id)
    }

    /// The compensator of a calibration, from the cache or built (off the
    /// runtime) and kept.
    pub async fn compensator(&self, store: &Store, calibration_id: i64) -> ApiResult<Arc<Cached>> {
        if let Some(c) = self
            .compensators
            .read()
            .ok()
            .and_then(|m| m.get(&calibration_id).cloned())
        {
            return Ok(c);
        }
        let cal = store.get_calibration(calibration_id).await?;
        let text = store.calibration_report(calibration_id).await?;
        let bound = self.max_joint_change_deg;
        let built = tokio::task::spawn_blocking(move || -> ApiResult<Compensator> {
            let report = Report::from_json(&text)
                .map_err(|e| ApiError::Internal(format!("stored report: {e}")))?;
            let mut comp = Compensator::from_report(&report)
                .map_err(|e| ApiError::Internal(format!("compensator: {e}")))?;
            comp.max_joint_change_deg = bound;
            Ok(comp)
        })
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))??;
        let cached = Arc::new(Cached {
            compensator: built,
            calibration_id,
            version: cal.version,
            robot_id: cal.robot_id,
        });
        if let Ok(mut m) = self.compensators.write() {
            m.insert(calibration_id, cached.clone());
        }
        Ok(cached)
    }
}
