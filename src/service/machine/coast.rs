//! A part ground but not gauged, the shell's half: the loop crate's [`coast`] decides
//! whether the table moves on by the drift the loop has learned (the wheel wore all the
//! same); here the part is noted, the table delivered and the outcome recorded and logged.

use super::FeatureLoop;
use crate::clock::now;
use camloop_loop::PartId;
use camloop_loop::coast::{self, Coast};
use tracing::{debug, warn};

impl FeatureLoop {
    /// Notes the part as ground and moves the table on by one part of learned drift (not when
    /// there is none to anticipate, learning is frozen, or a table waits for the share).
    pub(super) async fn coast(&mut self, part: &str) {
        // Ground for this part: a resumed shaft does not grind it again.
        self.machine.memory_mut().last_part = PartId::new(part).ok();
        let memory = self.machine.memory();
        let waiting = memory.waiting.is_some();
        let coasted = coast::coast(&memory.learning, waiting, part, &self.lobe_loop());
        let (next, table, reason) = match coasted {
            Coast::Noted => {
                let record = self.learning_record(now());
                self.record(vec![record]).await;
                return;
            }
            Coast::NoTable(e) => {
                warn!(machine = %self.name, lobe = %self.setup.name, reason = %e, "no table for the drift of a part not gauged: previous table stays in force");
                return;
            }
            Coast::Table {
                next,
                table,
                reason,
                ..
            } => (next, table, reason),
        };
        debug!(machine = %self.name, lobe = %self.setup.name, "{reason}");
        match self.deliver(&table, *next, &reason, None).await {
            Ok(mut records) => {
                records.push(self.learning_record(now()));
                self.record(records).await;
            }
            Err(e) => {
                warn!(machine = %self.name, error = format!("{e:#}"), "table for a part not gauged not recorded")
            }
        }
    }
}
