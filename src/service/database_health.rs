//! The database as a `/healthz` component: every [`PROBE_EVERY`] a `SELECT 1` within
//! [`PROBE_TIMEOUT`]; "ok" while it answers, "degraded" with the reason while it does not
//! (or while the service has no connection), so `/healthz` says the database is down within
//! a few seconds of the server going, not when the next write fails.

use super::health::State;
use super::machine::StoreHandle;
use super::metrics::Metrics;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

/// How often the database is asked.
pub const PROBE_EVERY: Duration = Duration::from_secs(2);
/// How long an answer may take before the database counts as down.
pub const PROBE_TIMEOUT: Duration = Duration::from_secs(2);
/// The component's name in `/healthz`.
pub const COMPONENT: &str = "database";

/// Probes until shutdown, setting the component each time.
pub(super) async fn watch(
    store: StoreHandle,
    metrics: Arc<Metrics>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut tick = tokio::time::interval(PROBE_EVERY);
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.changed() => return,
        }
        // A clone of the store (its pools are shared), so no lock is held while it answers.
        let current = store.read().await.clone();
        let (state, reason) = match current {
            None => (
                State::Degraded,
                Some("no connection: measurements wait in the journal".to_string()),
            ),
            Some(s) => match tokio::time::timeout(PROBE_TIMEOUT, s.ping()).await {
                Ok(Ok(())) => (State::Ok, None),
                Ok(Err(e)) => (State::Degraded, Some(format!("not answering: {e}"))),
                Err(_) => (
                    State::Degraded,
                    Some(format!("no answer within {} s", PROBE_TIMEOUT.as_secs())),
                ),
            },
        };
        metrics.health.set(COMPONENT, state, reason);
    }
}
