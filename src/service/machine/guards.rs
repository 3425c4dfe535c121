//! The feature's status for the API and `/metrics`: what its memory says after a part or at
//! start (the guards' streaks and their alarms are the feature machine's, in the loop crate).

use super::FeatureLoop;
use crate::core::ids::PartId;
use crate::core::turn::Measured;
use camloop_loop::guards;

impl FeatureLoop {
    /// The feature's status after a part, for the API and `/metrics`.
    pub(super) fn publish_status(&self, part: &PartId, measured: &Measured) {
        let m = self.machine.memory();
        let blocked = guards::blocked_status(m.guard.as_ref());
        self.metrics
            .update_feature(&self.name, &self.setup.name, |f| {
                f.parts += 1;
                f.last_part = Some(part.clone());
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
        let m = self.machine.memory();
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
