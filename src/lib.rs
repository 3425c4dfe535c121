//! camloop: closed-loop compensation for X–C following grinding of cam lobes and crankpins.
//!
//! `core` is pure (geometry, measurement math, program rendering); everything that touches
//! files, buses or the clock lives outside it.

pub mod cli;
pub mod core;
pub mod gauge;
