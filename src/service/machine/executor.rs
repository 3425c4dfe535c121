//! The feature's loop as the service runs it: [`camloop_loop::FeatureMachine`] decides, and
//! this file carries out what it asks, in order: journal writes (through
//! [`FeatureLoop::record`]: the journal, the plant events, the store), rendering with the
//! share's numbering and provenance, the share's submit and delivery, the reject folder,
//! alarms, metrics and logs. Nothing here decides what the loop does next: every answer goes
//! back to the machine as an [`Input`].

use super::FeatureLoop;
use super::records::{self, keep_reject};
use crate::clock::now;
use crate::core::measure::RawMeasurement;
use crate::core::program::comment_text;
use crate::failpoint::crash_point;
use crate::share::{PushError, Submitted};
use camloop_loop::Input;
use camloop_loop::TableVersion;
use camloop_loop::machine::{Alarm, Effect, Finished, Metric, Program, RenderOrder};
use tracing::{error, warn};

impl FeatureLoop {
    /// Carries out the machine's effects until it has none; returns what its inputs came
    /// to. `raw` is the measurement being worked on, whose samples its records keep.
    pub(super) async fn run_machine(&mut self, raw: Option<&RawMeasurement>) -> Vec<Finished> {
        let mut finished = Vec::new();
        while let Some(effect) = self.machine.poll_effect() {
            let answer = match effect {
                Effect::Journal { ticket, records } => {
                    let records = records::pending(&self.name, &self.setup.name, records, raw);
                    // Journalled (durable) now; written to the store once, after the step.
                    Some(match self.journal_or_why(records) {
                        Ok(()) => Input::Journalled(ticket),
                        Err(reason) => Input::JournalFailed {
                            ticket,
                            fenced_out: self.journal.fenced_out(),
                            reason,
                        },
                    })
                }
                Effect::Render(order) => Some(self.render(*order)),
                Effect::Submit(record) => Some(self.submit(*record)),
                Effect::Deliver { version } => Some(self.deliver_to_share(version)),
                Effect::KeepReject { sha256, reason } => {
                    if let Some(raw) = raw {
                        warn!(machine = %self.name, lobe = %self.setup.name, origin = %raw.origin, reason = %reason, "measurement rejected");
                        let dir = self.share.config().state_dir.with_file_name("rejected");
                        if let Err(e) = keep_reject(&dir, raw, &sha256, &reason) {
                            error!(machine = %self.name, folder = %dir.display(), error = %e, "rejected measurement could not be kept");
                        }
                    }
                    None
                }
                Effect::Alarm(alarm) => {
                    self.alarm(alarm).await;
                    None
                }
                Effect::Metric(metric) => {
                    self.metric(metric);
                    None
                }
                Effect::Finished(f) => {
                    finished.push(f);
                    None
                }
            };
            if let Some(answer) = answer {
                self.machine.handle(answer);
            }
        }
        // The step's records (measurement, table, status, learning, events) go to the store
        // in one write, after its table is on the share: the store is history, not the
        // durability the step waits for (the journal is), so the part never waits on it
        // between its journal writes.
        self.flush_journal().await;
        finished
    }

    /// Renders a table for the share's next number with its provenance.
    fn render(&mut self, order: RenderOrder) -> Input<'static> {
        let version = self.share.history().next_version();
        let (table, planned) = match order.program {
            Program::Text { text, table_number } => {
                // A rollback's program, made for the plan in force when there is one.
                let va_speed_rpm = self
                    .plan
                    .pending_va_rpm
                    .filter(|_| self.setup.speed_plan.enabled);
                return Input::Rendered {
                    version,
                    table_number,
                    text,
                    va_speed_rpm,
                };
            }
            Program::Table { table, planned } => (table, planned),
        };
        if let Some(tables) = planned {
            self.keep_planned(&table, &order.next, *tables);
        }
        let learning = &order.learning;
        let mut settings = self.setup.program.clone();
        settings.table_number = self.share.next_table_number();
        settings.provenance = Some(self.provenance(version, order.parent, learning));
        settings.comment_lines = vec![
            comment_text(&format!("reason: {}", order.reason)),
            comment_text(&format!(
                "wheel radius {} mm, learning iteration {}",
                learning.wheel_radius_mm, learning.iteration
            )),
        ];
        match self.render_table(&table, &order.next, &settings) {
            Ok(text) => {
                crash_point("table_rendered");
                Input::Rendered {
                    version,
                    table_number: settings.table_number,
                    text,
                    va_speed_rpm: self.plan.pending_va_rpm,
                }
            }
            Err(e) => Input::RenderFailed {
                reason: format!("{e:#}"),
            },
        }
    }

    /// Submits a version whose record is durable.
    fn submit(&mut self, record: camloop_loop::record::TableRecord) -> Input<'static> {
        let version = record.version;
        let draft = super::delivery::Draft {
            text: record.program_text,
            table_number: record.table_number,
            learning: record.learning,
            reason: record.reason,
            measurement_id: record.measurement,
            rollback_of: record.rollback_of,
            at: record.at,
        };
        let request = match self.request(draft) {
            Ok(r) => r,
            Err(e) => {
                return Input::ShareFailed {
                    state: false,
                    reason: format!("{e:#}"),
                };
            }
        };
        match self.share.submit(request) {
            Ok(Submitted::Accepted { version: v }) => Input::Submitted {
                version: v,
                outcome: Ok(()),
            },
            Ok(Submitted::Refused { reason, .. }) => {
                error!(machine = %self.name, version = version.get(), reason = %reason, "table version refused by the share");
                Input::Submitted {
                    version,
                    outcome: Err(reason),
                }
            }
            Err(e) => Input::ShareFailed {
                state: true,
                reason: format!("{e:#}"),
            },
        }
    }

    /// Delivers the version just submitted.
    fn deliver_to_share(&mut self, version: TableVersion) -> Input<'static> {
        match self.share.deliver() {
            Ok(Some(p)) if p.version == version => Input::Delivered { version, at: now() },
            Err(PushError::Share { version: v, error }) => Input::ShareUnavailable {
                version: v,
                reason: error.to_string(),
                at: now(),
            },
            Ok(other) => Input::ShareFailed {
                state: false,
                reason: format!(
                    "the share delivered {:?} instead of the version just submitted, {version}",
                    other.map(|p| p.version)
                ),
            },
            Err(PushError::Refused { reason, .. }) => Input::ShareRefused { version, reason },
            Err(PushError::State(e)) => Input::ShareFailed {
                state: true,
                reason: format!("{e:#}"),
            },
        }
    }

    async fn alarm(&mut self, alarm: Alarm) {
        let lobe = &self.setup.name;
        match &alarm {
            Alarm::LearningReverted { reason } => {
                error!(machine = %self.name, lobe = %lobe, reason = %reason, "learning reverted and frozen: operator action needed");
            }
            Alarm::BlockedByGuard { reason, .. } => {
                error!(machine = %self.name, lobe = %lobe, reason = %reason, "blocked by a guard part after part: operator action needed");
            }
            Alarm::ShareUnavailable { reason } => {
                let in_force = self
                    .machine
                    .memory()
                    .in_force_version
                    .map_or(0, |v| v.get());
                error!(machine = %self.name, error = %reason, in_force, "controller share: table not delivered; learning holds on the table in force");
            }
            Alarm::DiskFull => {
                // Said once per outage, with its event ([`Self::disk_full_alarm`]).
                return self.disk_full_alarm(now()).await;
            }
        }
        self.metrics.update(&self.name, |m| m.alarms_total += 1);
    }

    fn metric(&mut self, metric: Metric) {
        let (machine, feature) = (self.name.clone(), self.setup.name.clone());
        match metric {
            Metric::MeasurementRejected => self
                .metrics
                .update(&machine, |m| m.measurements_rejected_total += 1),
            Metric::TableRefused => self
                .metrics
                .update(&machine, |m| m.tables_refused_total += 1),
            Metric::LearningHeld => self.metrics.update(&machine, |m| m.learning_held = 1),
            Metric::TablePushed { wheel_radius_mm } => self.on_delivered(wheel_radius_mm),
            Metric::ShareWaiting => self.metrics.update(&machine, |m| {
                m.share_waiting = 1;
                m.learning_held = 1;
            }),
            Metric::Blocked(status) => self
                .metrics
                .update_feature(&machine, &feature, |f| f.blocked_by_guard = status),
        }
    }
}
