//! Gauge interfaces: CAN (live SocketCAN and candump logs, decoded from a DBC), a serial line
//! protocol, a watched drop folder of CSV files, and a reader for one measurement file.
//!
//! Each interface ends in the same value, [`camloop_core::measure::RawMeasurement`]: header,
//! samples in arrival order, origin. Codecs (frame decoder, line parsers, assembler) are pure
//! functions and state machines over bytes and lines; the adapters around them own the bus,
//! the port, the folder and the clock. Completeness checks and averaging belong to `core`.
//!
//! The adapters that need an async runtime or a bus (`can_bus`, `serial_port`,
//! `drop_folder`) are behind the `io` feature: without it this crate is the codecs and the
//! synchronous file readers, which the simulator and the tools use.

// No unwrap() in shipped code: bad input must become an error, not a panic (tests may).
#![warn(clippy::unwrap_used)]

pub mod assemble;
#[cfg(feature = "io")]
pub mod can_bus;
pub mod candump;
mod csv_fields;
pub mod csv_file;
pub mod dbc;
pub mod dressing;
#[cfg(feature = "io")]
pub mod drop_folder;
pub mod drop_names;
pub mod drop_reasons;
pub mod encode;
pub mod file;
pub mod frame;
pub mod serial;
#[cfg(feature = "io")]
pub mod serial_port;
pub mod signal;

pub use assemble::{Assembled, Assembler, AssemblyProblem, DiscardReason};
#[cfg(feature = "io")]
pub use can_bus::{CanBus, CanEvent, CanGauge, CanOpenError, CandumpReplay, FrameSource};
pub use candump::{CandumpIssue, CandumpReport, read_candump_measurements};
pub use csv_file::{Completeness, CsvError, CsvMeasurement, CsvParser, parse_measurement_csv};
pub use dbc::{DbcLoadError, GaugeDbc, GaugeSignalNames};
pub use dressing::{DressingError, DressingReport, read_dressing_file};
#[cfg(feature = "io")]
pub use drop_folder::{DropEvent, DropFolder, DropOptions, Settle, watch_drop_folder};
pub use drop_reasons::{DropFolderError, Rejection};
pub use encode::{EncodeError, candump_line, encode_measurement};
pub use file::{GaugeError, MeasurementFile, open_measurement_file, read_measurement_file};
pub use frame::{CanId, FrameError, GaugeFrame, GaugeStart};
pub use serial::{SerialDecoder, SerialEvent, SerialProblem, decode_serial_text};
#[cfg(feature = "io")]
pub use serial_port::{SerialGauge, SerialOpenError, open_serial_port};
