//! A machine rebuilt after a stop from what its journal kept, with the share's word on what
//! it holds: the newest memory (the measurements recorded after it still counted and known),
//! and a step the stop cut short finished. A part's step writes its table's record and the
//! memory with that table waiting in one write, so a step is cut short only between that
//! write and the table's status: the table is then submitted (when the share never heard of
//! it), delivered, or, when the share pushed it already, put in force.

use super::table::{Delivery, Program, TableOrder};
use super::{FeatureConfig, FeatureMachine, Finished, Phase};
use crate::memory::LoopMemory;
use crate::record::{Record, TableStatus};
use camloop_core::ids::TableVersion;
use jiff::Timestamp;

/// What the share holds for the feature, as its manifest says at start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShareView {
    /// The number the share gives the next version it accepts.
    pub next_version: TableVersion,
    /// The newest version it pushed (on the control).
    pub pushed: Option<TableVersion>,
}

impl FeatureMachine {
    /// The machine `records` (the feature's journal, oldest first) leave, `fallback` when
    /// they hold no memory; a step cut short is finished through the effects it queues.
    pub fn resume(
        config: FeatureConfig,
        records: &[Record],
        fallback: LoopMemory,
        share: ShareView,
        at: Timestamp,
    ) -> Self {
        let memory = LoopMemory::resume(records).unwrap_or(fallback);
        let mut machine = Self::new(config, memory);
        machine.finish_cut_short(records, share, at);
        machine
    }

    fn finish_cut_short(&mut self, records: &[Record], share: ShareView, at: Timestamp) {
        let Some(waiting) = self.memory.waiting.clone() else {
            return;
        };
        let v = waiting.version;
        if share.pushed == Some(v) {
            // Stopped between the push and its record (a step's, or a retry's): the share
            // is the authority.
            self.memory.delivered(v);
            let status = TableStatus::Pushed {
                note: "pushed to the share (its manifest, read at start)".into(),
            };
            let records = vec![
                Record::Status {
                    version: v,
                    status,
                    at,
                },
                self.learning_record(at),
            ];
            return self.close(records, Finished::Resumed);
        }
        // Settled as waiting: a table of a share outage, which the shell's retry delivers.
        let settled = records
            .iter()
            .any(|r| matches!(r, Record::Status { version, .. } if *version == v));
        let record = records.iter().rev().find_map(|r| match r {
            Record::Table(t) if t.version == v => Some(t.as_ref().clone()),
            _ => None,
        });
        let Some(record) = record.filter(|_| !settled) else {
            return;
        };
        let order = TableOrder {
            program: Program::Text {
                text: record.program_text.clone(),
                table_number: record.table_number,
            },
            next: Box::new(waiting.learning.clone()),
            reason: record.reason.clone(),
            measurement: record.measurement,
            rollback_of: record.rollback_of,
            learning: Some(record.learning.clone()),
            at: record.at,
        };
        let submitted = share.next_version > v;
        let d = Delivery::resumed(order, record, self.memory.clone(), submitted);
        self.effects.push_back(d.next_effect());
        self.phase = Phase::Table(Box::new(d));
    }
}
