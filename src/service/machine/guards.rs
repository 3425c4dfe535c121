//! Guards acting part after part: a streak of refusals or limited steps by the same guard
//! becomes one alarm (said once, not per part), and the feature's status for the API and
//! `/metrics`.

use super::super::journal::{EventKind, Pending};
use super::FeatureLoop;
use super::memory::{GuardKind, GuardStreak};
use super::records::event;
use crate::core::turn::Measured;
use crate::store::EventLevel;
use tracing::{error, info};

impl FeatureLoop {
    /// A guard refused or limited part `part`; returns how many parts in a row it has. At
    /// `learning.blocked_alarm_after_parts` in a row, one alarm event with the reason and
    /// what the operator can do.
    pub(super) fn guard_acted(
        &mut self,
        kind: GuardKind,
        reason: &str,
        part: u64,
        at_ms: jiff::Timestamp,
        records: &mut Vec<Pending>,
    ) -> u32 {
        let streak = match self.memory.guard.take() {
            Some(s) if s.kind == kind => GuardStreak {
                parts: s.parts + 1,
                reason: reason.to_string(),
                ..s
            },
            _ => GuardStreak {
                kind,
                parts: 1,
                reason: reason.to_string(),
                alarmed: false,
            },
        };
        let in_a_row = streak.parts;
        let alarm_now = !streak.alarmed && in_a_row >= self.setup.params.blocked_alarm_after_parts;
        self.memory.guard = Some(GuardStreak {
            alarmed: streak.alarmed || alarm_now,
            ..streak
        });
        if alarm_now {
            let message = format!(
                "{} part {part}: blocked by a guard on {in_a_row} parts in a row: {reason}; {}",
                self.setup.name,
                kind.advice()
            );
            error!(machine = %self.name, lobe = %self.setup.name, guard = ?kind, reason = %reason, "blocked by a guard part after part: operator action needed");
            self.metrics.update(&self.name, |m| m.alarms_total += 1);
            records.push(event(
                &self.name,
                at_ms,
                EventLevel::Error,
                EventKind::BlockedByGuard,
                message.clone(),
            ));
            let (machine, feature) = (self.name.clone(), self.setup.name.clone());
            self.metrics
                .update_feature(&machine, &feature, |f| f.blocked_by_guard = Some(message));
        }
        in_a_row
    }

    /// A part learned from with no guard acting ends a streak (and its alarm).
    pub(super) fn guard_cleared(
        &mut self,
        part: u64,
        at_ms: jiff::Timestamp,
        records: &mut Vec<Pending>,
    ) {
        let Some(streak) = self.memory.guard.take() else {
            return;
        };
        if streak.alarmed {
            let message = format!(
                "{} part {part}: learned from again; the {:?} guard no longer blocks",
                self.setup.name, streak.kind
            );
            info!(machine = %self.name, lobe = %self.setup.name, "guard no longer blocks: alarm cleared");
            records.push(event(
                &self.name,
                at_ms,
                EventLevel::Info,
                EventKind::GuardCleared,
                message,
            ));
        }
        let (machine, feature) = (self.name.clone(), self.setup.name.clone());
        self.metrics
            .update_feature(&machine, &feature, |f| f.blocked_by_guard = None);
    }

    /// The feature's status after a part, for the API and `/metrics`.
    pub(super) fn publish_status(&self, part: &str, measured: &Measured) {
        let m = &self.memory;
        let blocked = m
            .guard
            .as_ref()
            .filter(|g| g.alarmed)
            .map(|g| format!("{} parts in a row: {}", g.parts, g.reason));
        self.metrics
            .update_feature(&self.name, &self.setup.name, |f| {
                f.parts += 1;
                f.last_part = Some(part.to_string());
                f.last_max_error_um = Some(measured.max_error_um);
                f.last_profile_error_um = Some(measured.max_profile_error_um);
                f.last_timing_error_deg = Some(measured.timing_error_deg);
                f.last_size_error_um = Some(measured.report.base_radius_error_um);
                f.last_pass = Some(measured.report.verdict.pass);
                f.in_force_version = m.in_force_version;
                f.waiting_version = m.waiting.as_ref().map(|w| w.version);
                f.frozen = m.learning.frozen.clone();
                f.blocked_by_guard = blocked;
            });
    }

    /// The status before any part: what the memory says (after a restart, a standing alarm
    /// stands again).
    pub(super) fn publish_start_status(&self) {
        let m = &self.memory;
        let blocked = m
            .guard
            .as_ref()
            .filter(|g| g.alarmed)
            .map(|g| format!("{} parts in a row: {}", g.parts, g.reason));
        self.metrics
            .update_feature(&self.name, &self.setup.name, |f| {
                f.in_force_version = m.in_force_version;
                f.waiting_version = m.waiting.as_ref().map(|w| w.version);
                f.frozen = m.learning.frozen.clone();
                f.blocked_by_guard = blocked;
            });
    }
}
