//! Guards acting part after part, the shell's half: the loop crate's [`guards`] decides the
//! streaks and their alarms; here they become events, logs, `/metrics` and the feature's
//! status for the API.

use super::super::journal::{EventKind, Pending};
use super::FeatureLoop;
use super::memory::GuardKind;
use super::records::event;
use crate::core::turn::Measured;
use crate::store::EventLevel;
use camloop_loop::guards;
use tracing::{error, info};

impl FeatureLoop {
    /// A guard refused or limited part `part`; returns how many parts in a row it has. At
    /// `learning.blocked_alarm_after_parts` in a row, one alarm event with the reason and
    /// what the operator can do ([`guards::acted`] decides).
    pub(super) fn guard_acted(
        &mut self,
        kind: GuardKind,
        reason: &str,
        part: u64,
        at_ms: jiff::Timestamp,
        records: &mut Vec<Pending>,
    ) -> u32 {
        let acted = guards::acted(
            self.memory.guard.take(),
            kind,
            reason,
            part,
            &self.setup.name,
            self.setup.params.blocked_alarm_after_parts,
        );
        let in_a_row = acted.streak.parts;
        self.memory.guard = Some(acted.streak);
        if let Some(message) = acted.alarm {
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
        if let Some(message) = guards::cleared(Some(streak), part, &self.setup.name) {
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
        let blocked = guards::blocked_status(m.guard.as_ref());
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
        let blocked = guards::blocked_status(m.guard.as_ref());
        self.metrics
            .update_feature(&self.name, &self.setup.name, |f| {
                f.in_force_version = m.in_force_version;
                f.waiting_version = m.waiting.as_ref().map(|w| w.version);
                f.frozen = m.learning.frozen.clone();
                f.blocked_by_guard = blocked;
            });
    }
}
