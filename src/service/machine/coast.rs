//! A part ground but not gauged (the gauge's message was lost or refused, while the control
//! reported which feature it ground): nothing is learned, but the wheel wore all the same, so
//! the table moves on by the drift the loop has learned, as it would have after a measured
//! part. Without this, the feature's next part carries one part of drift more.

use super::FeatureLoop;
use crate::clock::now;
use crate::core::compensate;
use tracing::{debug, warn};

impl FeatureLoop {
    /// Notes the part as ground and moves the table on by one part of learned drift (not when
    /// there is none to anticipate, learning is frozen, or a table waits for the share).
    pub(super) async fn coast(&mut self, part: &str) {
        // Ground for this part: a resumed shaft does not grind it again.
        self.memory.last_part = Some(part.to_string());
        let learning = &self.memory.learning;
        let drift = learning.size_drift_um_per_part;
        if drift.abs() < 1e-3 || learning.frozen.is_some() || self.memory.waiting.is_some() {
            let record = self.learning_record(now());
            self.record(vec![record]).await;
            return;
        }
        let mut next = learning.clone();
        next.correction_um.iter_mut().for_each(|u| *u -= drift);
        crate::core::learn::quantise_correction(&mut next.correction_um, f64::INFINITY);
        let table = match compensate::current_table(&next, &self.lobe_loop()) {
            Ok(t) => t,
            Err(e) => {
                warn!(machine = %self.name, lobe = %self.setup.name, reason = %e, "no table for the drift of a part not gauged: previous table stays in force");
                return;
            }
        };
        let reason = format!("part {part} ground, not gauged: {drift:+.3} µm of drift anticipated");
        debug!(machine = %self.name, lobe = %self.setup.name, "{reason}");
        match self.deliver(&table, next, &reason, None).await {
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
