//! What a feature's loop remembers between parts: the loop crate's memory
//! ([`camloop_loop::memory`]), re-exported where the journal and the store have always found
//! it. Its serialized form is unchanged.

pub use camloop_loop::guards::{GuardKind, GuardStreak};
pub use camloop_loop::memory::{
    LoopMemory, MEMORY_SCHEMA, TableLearning, TableLearningSummary, WaitingTable,
};
