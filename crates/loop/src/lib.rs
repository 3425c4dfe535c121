//! camloop's loop as a pure state machine, in the shape of quinn-proto's `Connection`: the
//! service hands it what happened (a measurement, a command, a completed write) and carries
//! out the effects it asks for (journal, submit, deliver, publish). It reads no clock, touches
//! no file and logs nothing, so every decision the loop makes is testable without I/O.

pub mod coast;
pub mod dressing;
pub mod guards;
pub mod in_process;
pub mod machine;
pub mod memory;
pub mod record;

pub use camloop_core::ids::{BadPartId, PartId, TableVersion, VersionOutOfRange};
pub use camloop_core::names::{FeatureName, MachineName};

pub mod command;

pub use command::{CommandError, CommandOutcome, MachineCommand};
pub mod event;
pub mod unix_ms;

pub use event::{MACHINE_LEVEL, PlantEvent};
pub use machine::{Effect, FeatureMachine, Input};
pub use memory::LoopMemory;
