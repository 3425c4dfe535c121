//! Freezing and unfreezing a feature's learning by hand (an engineer's decision, through
//! the API). Frozen, the loop keeps the correction as it is and only measures; unfrozen, it
//! learns again from the correction in force, with the recent errors forgotten so the
//! revert guard judges only parts ground after the decision.

use super::FeatureLoop;
use crate::clock::now;
use tracing::info;

impl FeatureLoop {
    /// Sets the learning's frozen reason (`None`: learning resumes) and keeps the state as
    /// every other change is kept (journal, then store). Returns the reason before.
    pub(crate) async fn set_frozen(&mut self, frozen: Option<String>) -> Option<String> {
        let learning = &mut self.machine.memory_mut().learning;
        let before = learning.frozen.clone();
        if frozen.is_none() {
            learning.recent_max_error_um.clear();
        }
        learning.frozen = frozen;
        let record = self.learning_record(now());
        self.record(vec![record]).await;
        self.publish_start_status();
        info!(machine = %self.name, lobe = %self.setup.name, frozen = ?self.machine.memory().learning.frozen, "learning frozen state set by hand");
        before
    }
}
