//! What happens to a feature between its parts, decided: a wheel dressing (the correction
//! moved by the loop's dressing policy, the radius believed, the newest correction's table
//! made again for it), a part ground but not gauged (the table moved on by the learned
//! drift), an engineer freezing or unfreezing learning, and the retry of a table waiting
//! for the share. Each ends like a part: a table order on its way, or a record of the
//! memory it leaves.

use super::table::{Program, TableOrder};
use super::{Effect, FeatureMachine, Finished, Input, Phase};
use crate::coast::{self, Coast};
use crate::dressing::{self, CorrectionMove, Dressing};
use camloop_core::compensate::{self, LobeLoop};
use camloop_core::ids::PartId;
use jiff::Timestamp;

/// A wheel dressing as the machine takes it.
#[derive(Debug)]
pub struct Dressed<'a> {
    /// The report, checked by [`dressing::check`], with the radius believed before.
    pub dressing: Dressing,
    /// The feature as it is ground with the dressed wheel.
    pub lobe: &'a LobeLoop<'a>,
    pub at: Timestamp,
}

/// What a dressing did to the feature, before its table's way (a [`Finished::Table`]
/// follows when a table was made).
#[derive(Debug, Clone, PartialEq)]
pub struct DressingDone {
    /// How the correction moved.
    pub moved: CorrectionMove,
    /// Why no table could be made for the dressed wheel (the table in force stays).
    pub no_table: Option<String>,
}

/// What a part ground but not gauged came to.
#[derive(Debug, Clone, PartialEq)]
pub enum NotGaugedDone {
    /// Noted as ground; its memory is written.
    Noted,
    /// The drift's table cannot be made: the table in force stays (nothing written).
    NoTable { reason: String },
    /// The drift's table is on its way: a [`Finished::Table`] follows.
    Table,
}

impl FeatureMachine {
    pub(super) fn on_dressed(&mut self, d: Dressed<'_>) {
        let limit_um = self.config.params.max_correction_um;
        let memory = &mut self.memory;
        let states = std::iter::once(&mut memory.learning)
            .chain(memory.waiting.as_mut().map(|w| &mut w.learning));
        let moved = dressing::move_correction(states, &d.dressing, limit_um);
        let radius_mm = d.dressing.new_radius_mm;
        memory.wheel_radius_mm = radius_mm;
        // The newest correction made (delivered or waiting) is made again: a dressing is not
        // a learning step.
        let next = memory.newest_learning().clone();
        match compensate::current_table(&next, d.lobe) {
            Ok(table) => {
                self.finish(Finished::Dressed(DressingDone {
                    moved,
                    no_table: None,
                }));
                let order = TableOrder {
                    program: Program::Table {
                        table: Box::new(table),
                        planned: None,
                    },
                    next: Box::new(next),
                    reason: format!("wheel dressed to {radius_mm} mm"),
                    measurement: None,
                    rollback_of: None,
                    learning: None,
                    at: d.at,
                };
                self.start_table(order, None);
            }
            Err(e) => self.finish(Finished::Dressed(DressingDone {
                moved,
                no_table: Some(e.to_string()),
            })),
        }
    }

    /// `part` is `None` when the gauge's text is no part id: the drift is anticipated all
    /// the same.
    pub(super) fn on_not_gauged(
        &mut self,
        part: Option<PartId>,
        lobe: &LobeLoop<'_>,
        at: Timestamp,
    ) {
        let name = part.as_ref().map_or("(no id)", PartId::as_str);
        let coasted = coast::coast(
            &self.memory.learning,
            self.memory.waiting.is_some(),
            name,
            lobe,
        );
        // Ground for this part: a resumed shaft does not grind it again.
        self.memory.last_part = part;
        match coasted {
            Coast::Noted => {
                let record = self.learning_record(at);
                self.close(vec![record], Finished::NotGauged(NotGaugedDone::Noted));
            }
            Coast::NoTable(e) => self.finish(Finished::NotGauged(NotGaugedDone::NoTable {
                reason: e.to_string(),
            })),
            Coast::Table {
                next,
                table,
                reason,
                ..
            } => {
                self.finish(Finished::NotGauged(NotGaugedDone::Table));
                let order = TableOrder {
                    program: Program::Table {
                        table,
                        planned: None,
                    },
                    next,
                    reason,
                    measurement: None,
                    rollback_of: None,
                    learning: None,
                    at,
                };
                self.start_table(order, None);
            }
        }
    }

    /// Freezes learning with `frozen` as the reason, or (`None`) lets it learn again from
    /// the correction in force with the recent errors forgotten, so the revert guard judges
    /// only parts ground after the decision.
    pub(super) fn on_freeze(&mut self, frozen: Option<String>, at: Timestamp) {
        let learning = &mut self.memory.learning;
        let before = learning.frozen.clone();
        if frozen.is_none() {
            learning.recent_max_error_um.clear();
        }
        learning.frozen = frozen;
        let record = self.learning_record(at);
        self.close(vec![record], Finished::Frozen { before });
    }

    /// Delivers the version waiting for the share, if one waits.
    pub(super) fn on_tick(&mut self) {
        let Some(version) = self.memory.waiting.as_ref().map(|w| w.version) else {
            return;
        };
        self.phase = Phase::Retrying(version);
        self.effects.push_back(Effect::Deliver { version });
    }

    /// The share's answer to a tick's delivery: in force once delivered, else still waiting.
    pub(super) fn on_retry_answer(&mut self, input: Input<'_>) {
        let Phase::Retrying(waiting) = std::mem::take(&mut self.phase) else {
            return;
        };
        let reason = match input {
            Input::Delivered { version, at } if version == waiting => {
                return self.delivered_on_retry(version, at);
            }
            Input::Delivered { version, .. } => {
                format!("the share delivered {version} while {waiting} waits")
            }
            Input::ShareUnavailable { reason, .. }
            | Input::ShareRefused { reason, .. }
            | Input::ShareFailed { reason, .. } => reason,
            other => {
                // Not an answer to the delivery: the retry stays in flight.
                self.phase = Phase::Retrying(waiting);
                return self.finish(Finished::Failed {
                    reason: format!("not an answer to a delivery: {other:?}"),
                });
            }
        };
        self.finish(Finished::StillWaiting {
            version: waiting,
            reason,
        });
    }
}
