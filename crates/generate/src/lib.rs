//! Generators for the other non-circular machines: turning contours (X–Z chords placed by
//! tolerance), turn-mill eccentric surfaces (X/Y/C) and ratio-coupled planing (X–A).
//!
//! Each generator checks its geometry, builds one [`ir::Program`] and reports what it
//! proved; [`dialect::Dialect`] writes that program for a control, as a loop the control
//! evaluates or fully expanded. Pure: values in, programs or typed refusals out.

// No unwrap() in shipped code: bad input must become an error, not a panic (tests may).
#![warn(clippy::unwrap_used)]

pub mod analytic;
pub mod chords;
pub mod contour;
pub mod contour_chain;
pub mod contour_file;
pub mod curve;
pub mod dialect;
pub mod ir;
pub mod open_spline;
pub mod param_curve;
pub mod planing;
pub mod profile;
pub mod safety;
pub mod setup;
pub mod turnmill;
