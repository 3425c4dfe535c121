//! camloop: closed-loop compensation for X–C following grinding of cam lobes and crankpins.
//!
//! `core` is pure (geometry, measurement math, program rendering); everything that touches
//! files, buses or the clock lives outside it. `sim` is a simulated grinder and gauge (pure
//! as well, seeded) to run the loop and the demo without a machine.

// No unwrap() in shipped code: bad input must become an error, not a panic (tests may).
#![warn(clippy::unwrap_used)]

pub mod audit_seal;
pub mod auth;
pub mod cli;
pub mod clock;
pub mod cluster;
pub mod config;
/// The pure core (crate `camloop-core`) with the other machines' generators (crate
/// `camloop-generate`) under `core::generate`, where the rest of camloop and its users find
/// them.
pub mod core {
    pub use camloop_core::*;
    pub use camloop_generate as generate;
}
pub mod dfq;
/// SHA-256 digests as hex: the core's, so its ids and the edges' agree.
pub use camloop_core::digest;
pub mod failpoint;
pub mod private_fs;
/// Machine and feature names: the core's one rule, shared by config, API and store.
pub use camloop_core::names;
/// Gauge input: the crate `camloop-gauge`, with its I/O adapters.
pub use camloop_gauge as gauge;
pub mod quality;
pub mod recipe;
pub mod service;
pub mod share;
/// The simulated grinder, gauge and control: the crate `camloop-sim`.
pub use camloop_sim as sim;
/// The history store (SQLite or PostgreSQL): the crate `camloop-store`.
pub use camloop_store as store;
