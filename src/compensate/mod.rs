//! Compensation (in progress).
