//! Locating the tool point T from string readings: least-squares
//! multilateration with any number (3+) of anchors ([`multilateration`]) and
//! the paper's closed form for its four-anchor rig ([`closed_form`]); the
//! string noise estimated from the strings' redundancy.

pub mod closed_form;
pub mod multilateration;

pub use closed_form::{is_paper_mirror, paper_closed_form};
pub use multilateration::{Located, coplanar, locate, string_sigma};
