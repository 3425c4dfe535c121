//! A part ground but not gauged, the shell's half: the feature's machine decides whether
//! the table moves on by the drift the loop has learned (the wheel wore all the same) and
//! delivers it; here the outcome is recorded and logged.

use super::FeatureLoop;
use crate::clock::now;
use camloop_loop::machine::{Finished, NotGaugedDone};
use camloop_loop::{Input, PartId};
use tracing::{debug, warn};

impl FeatureLoop {
    /// Notes the part as ground and moves the table on by one part of learned drift (not when
    /// there is none to anticipate, learning is frozen, or a table waits for the share).
    pub(super) async fn coast(&mut self, part: &str) {
        let lobe = self.setup.lobe_loop();
        self.machine.handle(Input::NotGauged {
            part: PartId::new(part).ok(),
            lobe: &lobe,
            at: now(),
        });
        let mut table = None;
        for f in self.run_machine(None).await {
            match f {
                Finished::NotGauged(NotGaugedDone::NoTable { reason }) => {
                    warn!(machine = %self.name, lobe = %self.setup.name, reason = %reason, "no table for the drift of a part not gauged: previous table stays in force");
                }
                Finished::Table(t) => table = Some(t),
                Finished::Failed { reason } => {
                    warn!(machine = %self.name, lobe = %self.setup.name, reason = %reason, "part not gauged not noted");
                }
                _ => {}
            }
        }
        let Some(done) = table else {
            return;
        };
        debug!(machine = %self.name, lobe = %self.setup.name, part, "part ground, not gauged: table moved on by the learned drift");
        match self.table_records(done) {
            Ok(mut records) => {
                records.push(self.learning_record(now()));
                self.record(records).await;
            }
            Err(e) => {
                warn!(machine = %self.name, error = %e, "table for a part not gauged not recorded")
            }
        }
    }
}
