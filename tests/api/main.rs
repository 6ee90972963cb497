//! The service's integration tests: one binary (one link step) with a
//! module per concern. Every test starts the real service on port 0 over a
//! fresh SQLite file (the store conformance suite also runs on PostgreSQL).

// The engine tests' dataset helpers (the browser test reads a radians
// variant of a dataset through them).
#[allow(dead_code)]
#[path = "../engine/common.rs"]
mod common;

mod auth;
mod bad_requests;
mod browser_safety;
mod compensate_backlash;
mod compensate_bound;
mod compensate_csv;
mod compensate_payload;
mod compensate_thermal;
mod contract;
mod deploy;
mod e2e;
mod export;
mod helpers;
mod history_csv;
mod http_errors;
mod jobs;
mod limits;
mod logs;
mod openapi;
mod plans;
mod requires;
mod slow_clients;
mod store;
mod ui;
mod ui_browser;
