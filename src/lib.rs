//! camloop: closed-loop compensation for X–C following grinding of cam lobes and crankpins.
//!
//! `core` is pure (geometry, measurement math, program rendering); everything that touches
//! files, buses or the clock lives outside it. `sim` is a simulated grinder and gauge (pure
//! as well, seeded) to run the loop and the demo without a machine.

// No unwrap() in shipped code: bad input must become an error, not a panic (tests may).
#![warn(clippy::unwrap_used)]

pub mod cli;
pub mod clock;
pub mod cluster;
pub mod config;
pub mod core;
pub mod dfq;
pub mod digest;
pub mod failpoint;
pub mod gauge;
pub mod names;
pub mod recipe;
pub mod service;
pub mod share;
pub mod sim;
pub mod store;
