//! The conditions a compensation runs under: the temperature (for a
//! thermal expansion driven by it), the payload at T (for a joint
//! compliance) and the direction the joints arrive from (for a backlash).
//!
//! [`Conditions`] is what was asked; [`Applied`] is the compensator moved
//! to them, with what was used ([`ConditionsUsed`]: none where the
//! calibration has no effect the condition acts on) and the [`Note`]s on
//! what was asked and not used, or not asked and defaulted. The command
//! line and the service both go through it, so that they apply, default
//! and refuse the conditions alike; each names them its own way
//! ([`ConditionNames`]).

use std::borrow::Cow;
use std::sync::{Arc, OnceLock};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::model::{MAX_PAYLOAD_KG, Target};
use crate::report::Report;

use super::{Compensated, Compensator, compensate_all, compensate_in_order};

/// Lowest and highest temperature (°C) a compensation is asked for.
pub const TEMP_C_RANGE: (f64, f64) = (-50.0, 150.0);

/// A run-time temperature (°C) checked: finite and within
/// [`TEMP_C_RANGE`]; the error names `field`.
pub fn check_temp_c(field: &str, temp_c: f64) -> Result<f64> {
    let (lo, hi) = TEMP_C_RANGE;
    if temp_c.is_finite() && (lo..=hi).contains(&temp_c) {
        Ok(temp_c)
    } else {
        Err(Error::field(
            field,
            format!("a temperature in degrees C from {lo} to {hi}, got {temp_c}"),
        ))
    }
}

/// A run-time payload (kg) checked: finite, from 0 to [`MAX_PAYLOAD_KG`];
/// the error names `field`.
pub fn check_payload_kg(field: &str, payload_kg: f64) -> Result<f64> {
    if payload_kg.is_finite() && (0.0..=MAX_PAYLOAD_KG).contains(&payload_kg) {
        Ok(payload_kg)
    } else {
        Err(Error::field(
            field,
            format!("a payload in kg from 0 to {MAX_PAYLOAD_KG}, got {payload_kg}"),
        ))
    }
}

/// Thermal expansion driven by the temperature, as the analysis accepted it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ThermalInfo {
    /// Growth of every nominal a and d per kelvin (1/K).
    pub coef_per_k: f64,
    /// The temperature the calibrated geometry holds at (°C): the first
    /// pose's of the calibration session.
    pub reference_temp_c: f64,
}

/// What a compensator needs to move its geometry to a temperature.
#[derive(Debug)]
pub(super) struct Thermal {
    pub(super) info: ThermalInfo,
    /// `(parameter index, nominal value)` of the lengths that grow
    /// ([`crate::physics::effects::nominal_lengths`]).
    pub(super) lengths: Vec<(usize, f64)>,
    /// Calibrated parameters at the reference temperature.
    pub(super) reference_values: Vec<f64>,
}

/// The temperature-driven thermal expansion a report's findings accepted
/// (with the reference temperature that reports since it was recorded
/// carry), if any.
pub(super) fn thermal_of(report: &Report) -> Option<ThermalInfo> {
    use crate::physics::effects::{Kind, ThermalDriver};
    report.findings.iter().find_map(|f| {
        let p = f.effect_parameters()?;
        let e = &p.model;
        if !matches!(
            e.kind,
            Kind::ThermalExpansion {
                driver: ThermalDriver::Temperature,
                ..
            }
        ) {
            return None;
        }
        let coef_per_k = *e.coef.first()?;
        let reference_temp_c = p.reference_temp_c?;
        (coef_per_k.is_finite() && reference_temp_c.is_finite()).then_some(ThermalInfo {
            coef_per_k,
            reference_temp_c,
        })
    })
}

/// True when the report accepted a thermal expansion driven by time or by
/// the row order (not compensated: see the module documentation).
pub fn has_time_thermal(report: &Report) -> bool {
    use crate::physics::effects::{Kind, ThermalDriver};
    crate::physics::effects_of(&report.findings)
        .iter()
        .any(|e| {
            matches!(
                e.kind,
                Kind::ThermalExpansion {
                    driver: ThermalDriver::Time | ThermalDriver::Order,
                    ..
                }
            )
        })
}

impl Compensator {
    /// The accepted temperature-driven thermal expansion, if any.
    pub fn thermal(&self) -> Option<ThermalInfo> {
        self.thermal.as_ref().map(|t| t.info)
    }

    /// The temperature (°C) this compensator compensates at: `None` without
    /// a temperature-driven thermal effect.
    pub fn temperature_c(&self) -> Option<f64> {
        self.temp_c
    }

    /// True when the calibration accepted a backlash: the joints to send
    /// then depend on the direction each joint arrives from
    /// ([`Compensator::with_approach`]; default: every joint moving in +q).
    pub fn has_backlash(&self) -> bool {
        self.joint_effects
            .as_ref()
            .is_some_and(|e| e.has_backlash())
    }

    /// This compensator with every joint arriving from `direction` (+1:
    /// moving in +q, -1: in -q; one per joint). Without a backlash, an
    /// unchanged copy.
    pub fn with_approach(&self, direction: &[f64]) -> Compensator {
        let mut c = self.clone();
        if let Some(e) = self.joint_effects.as_ref().filter(|e| e.has_backlash()) {
            c.joint_effects = Some(Arc::new(e.with_approach(direction)));
        }
        c
    }

    /// The payload (kg at T) this compensator compensates with, when the
    /// accepted effects depend on it (a compliance): the one given to
    /// [`Compensator::with_payload_kg`], else the calibration session's
    /// (`Some(0.0)` when it recorded none). `None` when the payload does
    /// not matter.
    pub fn payload_kg(&self) -> Option<f64> {
        self.joint_effects
            .as_ref()
            .filter(|e| e.payload_matters())
            .map(|e| e.payload_kg().unwrap_or(0.0))
    }

    /// This compensator with the robot carrying `payload_kg` at T: a
    /// compliant joint deflects under the payload's gravity torque too.
    /// When the payload does not matter ([`Compensator::payload_kg`] is
    /// `None`), an unchanged copy.
    pub fn with_payload_kg(&self, payload_kg: f64) -> Compensator {
        let mut c = self.clone();
        if self.payload_kg().is_some()
            && let Some(e) = &self.joint_effects
        {
            c.joint_effects = Some(Arc::new(e.with_payload_kg(payload_kg)));
        }
        c
    }

    /// This compensator with the robot at `temp_c` (°C): every nominal a
    /// and d of the calibrated geometry grows by `k · (temp_c - T_ref)`
    /// times its nominal value. Without a temperature-driven thermal
    /// effect, an unchanged copy. A clone of the parameter vectors; no
    /// other work (the calibrated arm's reach, which the lengths change, is
    /// worked out again when first needed).
    pub fn at_temperature(&self, temp_c: f64) -> Compensator {
        let mut c = self.clone();
        if let Some(t) = &self.thermal {
            let m = t.info.coef_per_k * (temp_c - t.info.reference_temp_c);
            c.calibrated.values.copy_from_slice(&t.reference_values);
            for &(i, v) in &t.lengths {
                c.calibrated.values[i] += m * v;
            }
            c.reach_calibrated = OnceLock::new();
            c.temp_c = Some(temp_c);
        }
        c
    }
}

/// How the joints arrive at the targets, for a calibration with a backlash
/// (where a joint stops depends on the side it comes from).
///
/// Serde spells it in snake case (`in_order`), as the API and the command
/// line do (which also takes `in-order`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Approach {
    /// Every joint moving in +q (the default; most teach programs finish
    /// so).
    Positive,
    /// Every joint moving in -q.
    Negative,
    /// The robot visits the targets in the given order: each joint arrives
    /// from the previous target's compensated joints
    /// ([`compensate_in_order`]).
    InOrder,
}

impl Approach {
    /// Every approach, in the order the layers list them.
    pub const ALL: [Approach; 3] = [Approach::Positive, Approach::Negative, Approach::InOrder];
}

/// The conditions a compensation is asked to run under. `None`: not asked,
/// the calibration's own (its reference temperature, its session's
/// payload, every joint arriving in +q).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Conditions {
    /// Temperature the robot runs at (°C).
    pub temp_c: Option<f64>,
    /// Payload the robot carries at T (kg).
    pub payload_kg: Option<f64>,
    /// How the joints arrive at the targets.
    pub approach: Option<Approach>,
}

/// How a layer names the conditions in its errors and notes (`--temp-c` on
/// the command line, `temp_c` in the API).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConditionNames {
    /// The temperature's name.
    pub temp_c: &'static str,
    /// The payload's name.
    pub payload_kg: &'static str,
    /// The approach's name.
    pub approach: &'static str,
}

/// What was used of the conditions: `None` where the calibration has no
/// effect the condition acts on (it does not matter then).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConditionsUsed {
    /// Temperature (°C) the calibrated geometry was taken at: the one
    /// asked, else the calibration's reference temperature, with a thermal
    /// expansion driven by the temperature.
    pub temp_c_used: Option<f64>,
    /// Payload (kg at T) the joint compliance was evaluated with: the one
    /// asked, else the calibration session's, with a compliance that
    /// depends on it.
    pub payload_kg_used: Option<f64>,
    /// How the joints were taken to arrive: the approach asked, else
    /// positive, with a backlash.
    pub approach_used: Option<Approach>,
}

/// What a note says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoteKind {
    /// A condition was asked for that the calibration has no effect for.
    NotUsed,
    /// An effect depends on a condition that was not asked for: the
    /// calibration's own is used.
    Defaulted,
    /// An accepted effect is left out of compensation (a thermal expansion
    /// driven by time or row order).
    LeftOut,
    /// A condition asked for was applied, and how.
    Applied,
}

/// One sentence on the conditions, for the user.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Note {
    /// What it says.
    pub kind: NoteKind,
    /// The sentence, naming the conditions as the layer does.
    pub text: String,
}

impl Conditions {
    /// Each condition asked checked (the temperature, then the payload):
    /// finite and within range. The error names the condition as `names`
    /// does. For a layer that refuses a bad value before it looks the
    /// calibration up; [`Conditions::apply`] checks again.
    pub fn check(&self, names: ConditionNames) -> Result<()> {
        if let Some(t) = self.temp_c {
            check_temp_c(names.temp_c, t)?;
        }
        if let Some(p) = self.payload_kg {
            check_payload_kg(names.payload_kg, p)?;
        }
        Ok(())
    }

    /// `comp` moved to these conditions: the temperature, the payload and
    /// the approach in turn ([`Applied`]'s steps).
    pub fn apply<'a>(&self, comp: &'a Compensator, names: ConditionNames) -> Result<Applied<'a>> {
        let mut applied = Applied::new(comp, names);
        applied.temperature(self.temp_c)?;
        applied.payload(self.payload_kg)?;
        applied.approach(self.approach);
        Ok(applied)
    }
}

/// A compensator moved to the conditions asked, with what was used of
/// them and the notes on them.
///
/// Built one condition at a time, each step once and in this order:
/// [`Applied::temperature`], [`Applied::payload`], [`Applied::approach`]
/// ([`Conditions::apply`] takes all three). Each step answers the notes it
/// made, so that a layer can say them as they come (the command line says
/// what it made of the temperature before it refuses a bad payload). The
/// compensator is copied only when a condition changes its answers.
#[derive(Debug, Clone)]
pub struct Applied<'a> {
    compensator: Cow<'a, Compensator>,
    names: ConditionNames,
    asked: Conditions,
    notes: Vec<Note>,
}

impl<'a> Applied<'a> {
    /// `comp` as it is, nothing asked yet.
    pub fn new(comp: &'a Compensator, names: ConditionNames) -> Self {
        Applied {
            compensator: Cow::Borrowed(comp),
            names,
            asked: Conditions::default(),
            notes: Vec::new(),
        }
    }

    fn note(&mut self, kind: NoteKind, text: String) {
        self.notes.push(Note { kind, text });
    }

    /// The temperature asked, checked, and applied when the calibration has
    /// a thermal expansion driven by the temperature; the notes it made
    /// (also that a thermal expansion driven by time is left out, asked or
    /// not).
    pub fn temperature(&mut self, temp_c: Option<f64>) -> Result<&[Note]> {
        if let Some(t) = temp_c {
            check_temp_c(self.names.temp_c, t)?;
        }
        self.asked.temp_c = temp_c;
        let from = self.notes.len();
        let name = self.names.temp_c;
        if self.compensator.time_thermal {
            self.note(
                NoteKind::LeftOut,
                "the calibration's thermal expansion is driven by time or row order (no \
                 temperature was recorded in its session); it cannot be compensated at run \
                 time and is left out"
                    .into(),
            );
        }
        match (self.compensator.thermal(), temp_c) {
            (Some(th), None) => self.note(
                NoteKind::Defaulted,
                format!(
                    "the calibration models thermal expansion ({:.2} ppm/K); compensating at its \
                     reference temperature {:.2} C. Give {name} with the temperature the robot \
                     runs at",
                    th.coef_per_k * 1e6,
                    th.reference_temp_c
                ),
            ),
            (Some(th), Some(t)) => {
                self.note(
                    NoteKind::Applied,
                    format!(
                        "compensating at {t:.2} C (thermal expansion {:.2} ppm/K from the \
                         reference {:.2} C)",
                        th.coef_per_k * 1e6,
                        th.reference_temp_c
                    ),
                );
                self.compensator = Cow::Owned(self.compensator.at_temperature(t));
            }
            (None, Some(_)) => self.note(
                NoteKind::NotUsed,
                format!(
                    "{name} is not used: the calibration has no thermal expansion driven by the \
                     temperature"
                ),
            ),
            (None, None) => {}
        }
        Ok(&self.notes[from..])
    }

    /// The payload asked, checked, and applied when the calibration has an
    /// effect that depends on it (a joint's compliance, a base tilt, a
    /// bending link, a compliant tool); the notes it made.
    pub fn payload(&mut self, payload_kg: Option<f64>) -> Result<&[Note]> {
        if let Some(p) = payload_kg {
            check_payload_kg(self.names.payload_kg, p)?;
        }
        self.asked.payload_kg = payload_kg;
        let from = self.notes.len();
        let name = self.names.payload_kg;
        match (self.compensator.payload_kg(), payload_kg) {
            (Some(reference), None) => self.note(
                NoteKind::Defaulted,
                format!(
                    "the calibration models an effect of the payload (a joint's compliance, a \
                     base tilt, a bending link or a compliant tool); compensating with the \
                     calibration session's payload {reference} kg. Give {name} with the payload \
                     the robot carries"
                ),
            ),
            (Some(_), Some(p)) => {
                self.note(
                    NoteKind::Applied,
                    format!("compensating with a payload of {p} kg at T"),
                );
                self.compensator = Cow::Owned(self.compensator.with_payload_kg(p));
            }
            (None, Some(_)) => self.note(
                NoteKind::NotUsed,
                format!(
                    "{name} is not used: the calibration has no effect that depends on the \
                     payload (a joint's compliance, a base tilt, a bending link or a compliant \
                     tool)"
                ),
            ),
            (None, None) => {}
        }
        Ok(&self.notes[from..])
    }

    /// The approach asked, applied when the calibration has a backlash
    /// (`in_order` is applied by [`Applied::compensate`], from target to
    /// target); the notes it made. Asking for the default, positive, of a
    /// calibration without a backlash is no note: the command line always
    /// asks for it.
    pub fn approach(&mut self, approach: Option<Approach>) -> &[Note] {
        self.asked.approach = approach;
        let from = self.notes.len();
        if self.compensator.has_backlash() {
            if approach == Some(Approach::Negative) {
                let negative = vec![-1.0; self.compensator.dof()];
                self.compensator = Cow::Owned(self.compensator.with_approach(&negative));
            }
        } else if approach.is_some_and(|a| a != Approach::Positive) {
            let name = self.names.approach;
            self.note(
                NoteKind::NotUsed,
                format!("{name} is not used: the calibration has no backlash"),
            );
        }
        &self.notes[from..]
    }

    /// What was asked.
    pub fn asked(&self) -> &Conditions {
        &self.asked
    }

    /// What was used of it.
    pub fn used(&self) -> ConditionsUsed {
        let c = self.compensator();
        ConditionsUsed {
            temp_c_used: c.temperature_c(),
            payload_kg_used: c.payload_kg(),
            approach_used: c
                .has_backlash()
                .then(|| self.asked.approach.unwrap_or(Approach::Positive)),
        }
    }

    /// Every note so far, in the order made.
    pub fn notes(&self) -> &[Note] {
        &self.notes
    }

    /// The compensator under these conditions.
    pub fn compensator(&self) -> &Compensator {
        &self.compensator
    }

    /// True when the targets are to be compensated in the order the robot
    /// visits them ([`compensate_in_order`]): `in_order` asked of a
    /// calibration with a backlash (without one, the order changes
    /// nothing).
    pub fn in_order(&self) -> bool {
        self.used().approach_used == Some(Approach::InOrder)
    }

    /// Compensate `targets` under these conditions: in order when
    /// [`Applied::in_order`], else each on its own ([`compensate_all`]).
    pub fn compensate(&self, targets: &[Target], orientation: bool) -> Vec<Compensated> {
        if self.in_order() {
            compensate_in_order(self.compensator(), targets, orientation)
        } else {
            compensate_all(self.compensator(), targets, orientation)
        }
    }

    /// The compensator these conditions made, when they changed it
    /// (`None`: the one given to [`Applied::new`] serves as it is), for a
    /// caller that must own it (to hand it to another thread).
    pub fn into_changed(self) -> Option<Compensator> {
        match self.compensator {
            Cow::Owned(c) => Some(c),
            Cow::Borrowed(_) => None,
        }
    }
}
