//! Freezing and unfreezing a feature's learning by hand (an engineer's decision, through
//! the API), the shell's half: the feature's machine sets it and writes its memory (frozen,
//! the loop keeps the correction as it is and only measures; unfrozen, it learns again from
//! the correction in force, with the recent errors forgotten); here it is published.

use super::FeatureLoop;
use crate::clock::now;
use camloop_loop::Input;
use camloop_loop::machine::Finished;
use tracing::info;

impl FeatureLoop {
    /// Sets the learning's frozen reason (`None`: learning resumes) and keeps the state as
    /// every other change is kept (journal, then store). Returns the reason before.
    pub(crate) async fn set_frozen(&mut self, frozen: Option<String>) -> Option<String> {
        self.machine.handle(Input::Freeze { frozen, at: now() });
        let before = self
            .run_machine(None)
            .await
            .into_iter()
            .find_map(|f| match f {
                Finished::Frozen { before } => Some(before),
                _ => None,
            })
            .flatten();
        self.publish_start_status();
        info!(machine = %self.name, lobe = %self.setup.name, frozen = ?self.machine.memory().learning.frozen, "learning frozen state set by hand");
        before
    }
}
