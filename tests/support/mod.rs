//! Shared test support for the geometry tests: the independent wheel-centre oracle and the
//! analytic test lobes it is checked on.
//!
//! Each integration-test crate includes this with `mod support;` and uses only part of it, so
//! dead-code warnings for the unused rest are expected and silenced here.

pub mod golden;
pub mod lobes;
pub mod oracle;
