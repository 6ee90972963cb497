//! Compensation.
