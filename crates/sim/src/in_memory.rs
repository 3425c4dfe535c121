//! camloop's loop as the simulated cell runs it: the same [`FeatureMachine`] the service
//! drives, with its effects carried out in memory. The journal is a list, the share numbers
//! versions from 1 and accepts and delivers every one at once (the cell's control couples a
//! table as soon as it is delivered), and time is the part's simulated time. So the cell
//! learns, guards, dresses and coasts by the service's policy, not a copy of it.

use camloop_core::ids::TableVersion;
use camloop_loop::machine::{Effect, FeatureConfig, Finished, RenderOrder};
use camloop_loop::{FeatureMachine, Input, LoopMemory};
use jiff::Timestamp;

/// What an input came to: what the machine finished with, and the table it rendered (the
/// one the cell's control now couples) if it made one.
#[derive(Debug, Default)]
pub(crate) struct Outcome {
    pub(crate) finished: Vec<Finished>,
    pub(crate) rendered: Option<RenderOrder>,
}

/// The feature's machine with its in-memory shell.
#[derive(Debug)]
pub(crate) struct InMemoryLoop {
    machine: FeatureMachine,
    /// The records the machine asked to keep, as many as a journal would hold.
    pub(crate) records_kept: usize,
    /// The number the share gives the next version.
    next_version: TableVersion,
}

impl InMemoryLoop {
    pub(crate) fn new(config: FeatureConfig, memory: LoopMemory) -> Self {
        Self {
            machine: FeatureMachine::new(config, memory),
            records_kept: 0,
            next_version: TableVersion::FIRST,
        }
    }

    pub(crate) fn memory(&self) -> &LoopMemory {
        self.machine.memory()
    }

    /// Hands `input` to the machine and carries out every effect it asks for.
    pub(crate) fn run(&mut self, input: Input<'_>, at: Timestamp) -> Outcome {
        self.machine.handle(input);
        let mut outcome = Outcome::default();
        while let Some(effect) = self.machine.poll_effect() {
            let answer = match effect {
                Effect::Render(order) => {
                    let version = self.next_version;
                    outcome.rendered = Some(*order);
                    Some(Input::Rendered {
                        version,
                        // The cell's control couples what it is handed; the number is the
                        // share's alternation, which the cell has no use for.
                        table_number: 1,
                        text: String::new(),
                        va_speed_rpm: None,
                    })
                }
                Effect::Journal { ticket, records } => {
                    self.records_kept += records.len();
                    Some(Input::Journalled(ticket))
                }
                Effect::Submit(record) => {
                    self.next_version = self.next_version.next();
                    Some(Input::Submitted {
                        version: record.version,
                        outcome: Ok(()),
                    })
                }
                Effect::Deliver { version } => Some(Input::Delivered { version, at }),
                Effect::Finished(f) => {
                    outcome.finished.push(f);
                    None
                }
                // Nothing to keep aside, nobody to alarm, no metrics in the cell.
                Effect::KeepReject { .. } | Effect::Alarm(_) | Effect::Metric(_) => None,
            };
            if let Some(answer) = answer {
                self.machine.handle(answer);
            }
        }
        outcome
    }
}
