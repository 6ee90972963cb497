//! Warnings about the input: what does not stop an identification but
//! makes its result suspect. They go into the report's `warnings`, one
//! sentence each.
//!
//! Joint angles in radians in the `q*_deg` columns: poses.csv carries
//! degrees, and a file (or a row) written in radians still parses (its
//! numbers are inside any joint limits), so the calibration would run on
//! a robot that hardly moved. The numbers alone cannot tell: a positioner
//! may really move only a few degrees. So the suspicion (every angle within
//! ±2π) is only voiced when the measurements confirm it: the nominal model
//! with the angles read as radians follows the measured points of T
//! ([`Observations::measured`], located from the strings or as measured) far
//! better than with them read as degrees. Each reading is given its best
//! rigid placement of the robot base (a Kabsch fit, as the identification
//! starts from), so no base pose guess is needed.

use nalgebra::{Matrix3, Vector3};

use super::{Observations, rigid_fit};
use crate::kinematics::Params;
use crate::kinematics::chain::OutputFrame;
use crate::model::BasePose;

use crate::model::RADIANS_BOUND;

/// How many times closer to the measured points the nominal model must
/// come with the angles read as radians than read as degrees before they
/// are said to look like radians.
pub const RADIANS_FIT_RATIO: f64 = 4.0;

/// A single pose is only suspected when, read as degrees, it also sits
/// this many times the other poses' RMS from the nominal model.
pub const ROW_OUTLIER_RATIO: f64 = 3.0;

/// Most single poses described one by one; the rest are listed by id.
const MAX_POSES_NAMED: usize = 5;

/// Most pose ids listed after those.
const MAX_IDS_LISTED: usize = 20;

/// What the input check found.
#[derive(Debug, Default)]
pub struct InputCheck {
    /// The warnings, one sentence each, in the order found (empty when
    /// nothing is suspect).
    pub warnings: Vec<String>,
    /// Why every joint angle looks like radians, when it does: a
    /// calibration from such poses is refused unless forced
    /// ([`InputCheck::refusal`]).
    pub in_radians: Option<String>,
}

impl InputCheck {
    /// The error that refuses a calibration from poses in radians.
    pub fn refusal(evidence: &str) -> String {
        format!(
            "not calibrated: {evidence}; {DEGREES_ADVICE} (--force, or the job option \"force\": true, calibrates them as degrees anyway)"
        )
    }
}

/// What the user should do about angles in radians.
const DEGREES_ADVICE: &str =
    "poses.csv holds degrees (deg = rad × 180/π): convert the angles and identify again";

/// The input warnings of a session (see [`check_input`]).
pub fn input_warnings(obs: &Observations) -> Vec<String> {
    check_input(obs).warnings
}

/// Joint angles that look like radians, in one pass over the poses: the
/// whole file (a warning, and the evidence the pipeline refuses on), or
/// single poses among others that do not (warnings only).
pub fn check_input(obs: &Observations) -> InputCheck {
    let poses = &obs.data.poses;
    if poses.len() < 3 || obs.measured.len() != poses.len() {
        return InputCheck::default();
    }
    let nominal = Params::nominal(
        obs.robot,
        &BasePose {
            xyz_mm: [0.0; 3],
            rpy_deg: [0.0; 3],
        },
        obs.rig,
        obs.chain.layout.n_strings,
    );
    // T of the nominal model in its base frame, the angles read as degrees
    // (as parsed) or as radians (the file's numbers taken as radians).
    let point = |i: usize, as_radians: bool| -> Vector3<f64> {
        let q = &poses[i].q_rad;
        let q = if as_radians {
            file_numbers(q)
        } else {
            q.clone()
        };
        obs.chain.point(&nominal.values, &q, OutputFrame::Base).1
    };
    let within: Vec<bool> = poses.iter().map(|p| within_two_pi(&p.q_rad)).collect();
    if !within.iter().all(|&w| w) {
        return InputCheck {
            warnings: single_poses(obs, &point, &within),
            in_radians: None,
        };
    }
    match whole_file(obs, &point) {
        Some(evidence) => InputCheck {
            warnings: vec![format!(
                "{evidence}; {DEGREES_ADVICE}, this calibration is not to be trusted"
            )],
            in_radians: Some(evidence),
        },
        None => InputCheck::default(),
    }
}

/// The file's number for each joint angle (degrees, as the file holds it).
fn file_numbers(q_rad: &[f64]) -> Vec<f64> {
    q_rad.iter().map(|q| q.to_degrees()).collect()
}

/// Every angle of a pose within ±2π (in the file's numbers).
fn within_two_pi(q_rad: &[f64]) -> bool {
    q_rad.iter().all(|q| q.to_degrees().abs() <= RADIANS_BOUND)
}

/// The whole file within ±2π: do the measurements say radians?
fn whole_file(obs: &Observations, point: &dyn Fn(usize, bool) -> Vector3<f64>) -> Option<String> {
    let poses = &obs.data.poses;
    let all: Vec<usize> = (0..poses.len()).collect();
    let measured = &obs.measured;
    let fit = |as_radians: bool| {
        let a: Vec<Vector3<f64>> = all.iter().map(|&i| point(i, as_radians)).collect();
        let (r, t) = rigid_fit(&a, measured)?;
        Some(rms(&a, measured, &r, &t))
    };
    let (rms_deg_mm, rms_rad_mm) = (fit(false)?, fit(true)?);
    if !(rms_rad_mm.is_finite() && rms_deg_mm.is_finite())
        || rms_rad_mm * RADIANS_FIT_RATIO >= rms_deg_mm
    {
        return None;
    }
    let largest = poses
        .iter()
        .flat_map(|p| file_numbers(&p.q_rad))
        .fold(0.0_f64, |m, v| m.max(v.abs()));
    let limit_deg = obs.robot.joints.iter().fold(0.0_f64, |m, j| {
        m.max(j.q_min_deg.abs()).max(j.q_max_deg.abs())
    });
    Some(format!(
        "the joint angles look like radians, not degrees: every q*_deg value is within ±2π (largest |q| {largest:.3}) although the joint limits reach ±{limit_deg:.0} deg, and read as radians the nominal model follows the measured points to {rms_rad_mm:.2} mm RMS against {rms_deg_mm:.2} mm read as degrees"
    ))
}

/// Poses within ±2π among poses that are not: does each one's measurement
/// say radians?
fn single_poses(
    obs: &Observations,
    point: &dyn Fn(usize, bool) -> Vector3<f64>,
    within: &[bool],
) -> Vec<String> {
    let candidates: Vec<usize> = (0..within.len()).filter(|&i| within[i]).collect();
    let others: Vec<usize> = (0..within.len()).filter(|&i| !within[i]).collect();
    if candidates.is_empty() || others.len() < 3 {
        return vec![];
    }
    let a: Vec<Vector3<f64>> = others.iter().map(|&i| point(i, false)).collect();
    let b: Vec<Vector3<f64>> = others.iter().map(|&i| obs.measured[i]).collect();
    let Some((r, t)) = rigid_fit(&a, &b) else {
        return vec![];
    };
    let scale_mm = rms(&a, &b, &r, &t);
    let mut flagged = Vec::new();
    for &i in &candidates {
        let m = obs.measured[i];
        let e_deg_mm = (r * point(i, false) + t - m).norm();
        let e_rad_mm = (r * point(i, true) + t - m).norm();
        if e_rad_mm.is_finite()
            && e_deg_mm.is_finite()
            && e_rad_mm * RADIANS_FIT_RATIO < e_deg_mm
            && e_deg_mm > ROW_OUTLIER_RATIO * scale_mm
        {
            flagged.push((i, e_deg_mm, e_rad_mm));
        }
    }
    let mut out: Vec<String> = flagged
        .iter()
        .take(MAX_POSES_NAMED)
        .map(|&(i, e_deg_mm, e_rad_mm)| {
            format!(
                "pose {} (row {} after the header): its joint angles look like radians, not degrees: all within ±2π unlike the other poses', and read as radians the nominal model puts T {e_rad_mm:.2} mm from the measured point against {e_deg_mm:.2} mm read as degrees (the other poses: {scale_mm:.2} mm RMS); poses.csv holds degrees: correct the row (deg = rad × 180/π) or drop it",
                obs.data.poses[i].id,
                i + 1
            )
        })
        .collect();
    if flagged.len() > MAX_POSES_NAMED {
        let rest = &flagged[MAX_POSES_NAMED..];
        let ids: Vec<&str> = rest
            .iter()
            .take(MAX_IDS_LISTED)
            .map(|&(i, _, _)| obs.data.poses[i].id.as_str())
            .collect();
        out.push(format!(
            "{} more poses' joint angles look like radians in the same way: {}{}",
            rest.len(),
            ids.join(", "),
            if rest.len() > ids.len() { ", ..." } else { "" }
        ));
    }
    out
}

/// RMS of `|R a + t - b|` (mm).
fn rms(a: &[Vector3<f64>], b: &[Vector3<f64>], r: &Matrix3<f64>, t: &Vector3<f64>) -> f64 {
    let residuals: Vec<Vector3<f64>> = a.iter().zip(b).map(|(x, y)| r * x + t - y).collect();
    crate::stats::rms_norm(&residuals)
}
