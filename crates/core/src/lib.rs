//! The pure core: lift tables, exact wheel-centre geometry, curve-table fitting and program
//! rendering. No I/O, no clock, no logging: inputs arrive as values, failures leave as data.
//!
//! A crate of its own so the compiler holds that line: it depends on no I/O crate at all.

// No unwrap() in shipped code: bad input must become an error, not a panic (tests may).
#![warn(clippy::unwrap_used)]

pub mod analysis;
pub mod capability;
pub mod compensate;
pub mod cycle;
pub mod digest;
pub mod fit;
pub mod geometry;
pub mod harmonics;
pub mod ids;
pub mod learn;
pub mod levels;
pub mod lift;
pub mod measure;
pub mod names;
pub mod program;
pub mod setup;
pub mod smooth;
pub mod speed_plan;
pub mod spline;
pub mod svg;
pub mod table;
pub mod turn;
