//! Identification.
