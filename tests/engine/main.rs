//! The engine's and the CLI's tests: one binary (one link step) with a
//! module per concern. They run the numerical core on the datasets under
//! `tests/data` and on simulated recordings; `cli` runs the built binary.
//! The service's tests are the other binary, `tests/api`.

mod activation;
mod common;

mod architecture;
mod cli;
mod compensate_bound;
mod compensate_edited_report;
mod compensate_ik;
mod export;
mod fuzz_parsers;
mod fuzz_physics;
mod identify_datasets;
mod identify_freeset;
mod identify_rig;
mod identify_small;
mod identify_synthetic;
mod identify_warnings;
mod lm_minpack;
mod physics_analysis;
mod physics_backlash;
mod physics_base_tilt;
mod physics_compensation;
mod physics_derivatives;
mod physics_eval;
mod physics_evidence;
mod physics_honesty;
mod physics_in_time;
mod physics_joint_angle;
mod physics_link_bending;
mod physics_payload;
mod physics_periodic;
mod physics_rig;
mod physics_sensor_drift;
mod physics_string_direction;
mod physics_string_move;
mod physics_tool_compliance;
mod physics_workspace;
mod plan;
mod plan_effects;
mod report_html;
mod simulate_files;
mod urdf;
mod verdict;
