//! Gauge interfaces: CAN (live SocketCAN and candump logs, decoded from a DBC), a serial line
//! protocol, a watched drop folder of CSV files, and a reader for one measurement file.
//!
//! Each interface ends in the same value, [`crate::core::measure::RawMeasurement`]: header,
//! samples in arrival order, origin. Codecs (frame decoder, line parsers, assembler) are pure
//! functions and state machines over bytes and lines; the adapters around them own the bus,
//! the port, the folder and the clock. Completeness checks and averaging belong to `core`.

pub mod assemble;
pub mod candump;
pub mod dbc;
pub mod frame;
pub mod signal;

pub use assemble::{Assembled, Assembler, AssemblyProblem, DiscardReason};
pub use candump::{CandumpIssue, CandumpReport, read_candump_measurements};
pub use dbc::{DbcLoadError, GaugeDbc, GaugeSignalNames};
pub use frame::{CanId, FrameError, GaugeFrame, GaugeStart};
