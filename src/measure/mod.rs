//! Locating the tool point T from string readings: least-squares
//! multilateration with any number (3+) of anchors ([`multilateration`]) and
//! the paper's closed form for its four-anchor rig ([`closed_form`]); the
//! string noise estimated from the strings' redundancy.

pub mod closed_form;
pub mod multilateration;

pub use closed_form::{is_paper_mirror, paper_closed_form};
pub use multilateration::{Located, coplanar, locate, string_sigma};

/// A string's residual, predicted minus read (mm): the distance from T to
/// its anchor, less the sensor radius `r_mm` (the string leaves the drum at
/// its rim) and the string's zero offset, plus what modelled effects add
/// to the reading (`effect_mm`, 0 without), minus the reading. The one
/// formula every fit and report uses.
pub fn string_residual_mm(
    distance_mm: f64,
    r_mm: f64,
    offset_mm: f64,
    effect_mm: f64,
    reading_mm: f64,
) -> f64 {
    distance_mm - r_mm - offset_mm + effect_mm - reading_mm
}
