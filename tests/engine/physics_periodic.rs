//! Errors periodic in their driver with many cycles over its range, which
//! no catalogue effect describes: neighbours in the driver agree only while
//! the period is long against their spacing, and a piecewise-linear
//! correction would need knots for every cycle.
//!
//! A string that reads wrong by a periodic function of its own length (a
//! drum's winding pitch, a spool's eccentricity): the analysis must locate
//! it on that string (with four strings on the string's own part of the
//! residual, with three on its whole residual), model it as a periodic
//! function of the length without a name, bring the held-out RMS near what
//! the same session without the error reaches, and find nothing on that
//! session. A joint whose angle is off by a non-integer harmonic of itself:
//! modelled periodically in its own angle, no catalogue harmonic named.

use crate::common;
use drawcal::model::{Dataset, Measurement, Rig};
use drawcal::physics::Kind;
use drawcal::physics::effects::{CorrectionDriver, CorrectionTarget};
use drawcal::physics::simulate;
use drawcal::report::Report;

/// The reading error (mm) of a string of length `l_mm`.
fn pitch_error(l_mm: f64, period_mm: f64) -> f64 {
    0.08 * (2.0 * std::f64::consts::PI * l_mm / period_mm + 0.6).sin()
}

fn simulated(seed: u64, rig: Option<&str>) -> simulate::Simulated {
    let spec: simulate::Spec = serde_json::from_value(serde_json::json!({
        "robot": "er3a", "rig": rig, "n_poses": 200, "seed": seed
    }))
    .unwrap();
    let rig = rig.map(|path| Rig::from_json(&std::fs::read_to_string(path).unwrap()).unwrap());
    let files = simulate::SpecFiles {
        rig,
        ..Default::default()
    };
    simulate::generate_with(&spec, files).unwrap()
}

/// `data` with string `s` (0-based) reading wrong by [`pitch_error`].
fn with_pitch(data: &Dataset, s: usize, period_mm: f64) -> Dataset {
    let mut out = data.clone();
    for p in &mut out.poses {
        if let Measurement::Strings(l) = &mut p.measurement {
            l[s] += pitch_error(l[s], period_mm);
        }
    }
    out
}

fn calibrate(sim: &simulate::Simulated, data: &Dataset) -> Report {
    common::identify_default(&sim.robot, &sim.rig, data)
}

/// The string's error is located on it, modelled periodically at about
/// its period, and the held-out RMS comes near the twin's.
fn located_and_modelled(sim: &simulate::Simulated, s: usize, period_mm: f64, side: &str) {
    let twin = calibrate(sim, &sim.dataset);
    let r = calibrate(sim, &with_pitch(&sim.dataset, s, period_mm));
    common::nothing_named(&r);
    let place = common::place_where(&r, |p| p.driver == "string" && p.sensor == Some(s + 1));
    assert_eq!(place.side, side);
    let c = common::data_driven_correction(&r);
    let Kind::DataDriven {
        target,
        target_index,
        driver,
        period,
        ..
    } = &c
    else {
        unreachable!()
    };
    assert_eq!(
        (*target, *target_index, *driver),
        (
            CorrectionTarget::StringReading,
            Some(s),
            CorrectionDriver::StringLength
        )
    );
    let p = period.expect("a periodic correction");
    assert!((p / period_mm - 1.0).abs() < 0.03, "period {p} mm");
    common::near_the_twin(&r, &twin, 1.15);
}

#[test]
fn a_periodic_error_of_a_string_is_located_and_modelled_with_four_strings() {
    located_and_modelled(&simulated(5, None), 1, 41.0, "sensor");
}

#[test]
fn a_periodic_error_of_a_string_is_located_and_modelled_with_three_strings() {
    located_and_modelled(
        &simulated(6, Some("tests/data/rigs/three_strings.json")),
        2,
        57.0,
        "strings",
    );
}

/// A joint whose angle is off by a sinusoid of a non-integer multiple of
/// itself (an intermediate gear stage turning 5.3 times per joint
/// revolution): no catalogue harmonic (whole multiples) describes it. The
/// analysis must model it as a periodic function of the joint's own angle
/// at about its period, and not name harmonics for it.
#[test]
fn a_non_integer_harmonic_of_a_joint_is_modelled_periodically_in_its_angle() {
    let h = 5.3;
    let sim = simulated(8, None);
    let twin = calibrate(&sim, &sim.dataset);
    // The joint sat at the recorded angle plus the error: recording the
    // true angle minus the error is the same session (the error evaluated
    // a few millidegrees away).
    let mut data = sim.dataset.clone();
    for p in &mut data.poses {
        p.q_rad[1] -= 0.02_f64.to_radians() * (h * p.q_rad[1] + 0.4).sin();
    }
    let r = calibrate(&sim, &data);
    common::nothing_named(&r);
    let c = common::data_driven_correction(&r);
    let Kind::DataDriven {
        target,
        target_index,
        driver_index,
        period,
        ..
    } = &c
    else {
        unreachable!()
    };
    assert_eq!(
        (*target, *target_index, *driver_index),
        (CorrectionTarget::JointAngle, Some(1), Some(1))
    );
    let p = period.expect("a periodic correction");
    let want = 2.0 * std::f64::consts::PI / h;
    assert!((p / want - 1.0).abs() < 0.03, "period {p} rad, want {want}");
    common::near_the_twin(&r, &twin, 1.15);
}
