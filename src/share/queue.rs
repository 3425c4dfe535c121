//! The retry loop: a tokio task that owns a [`Share`], records queued requests, delivers the
//! newest waiting version, and retries with exponential backoff while the share (or the
//! state folder) fails, reporting alarms as [`ShareEvent`] values.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use super::error::PushError;
use super::store::{PushRequest, Share, Submitted};

/// Backoff between attempts while pushes fail: `initial_delay · 2^(n−1)` after the n-th
/// consecutive failure, at most `max_delay`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RetryPolicy {
    pub initial_delay: Duration,
    pub max_delay: Duration,
}

impl Default for RetryPolicy {
    /// 1 s, doubling up to 60 s.
    fn default() -> Self {
        Self {
            initial_delay: Duration::from_secs(1),
            max_delay: Duration::from_secs(60),
        }
    }
}

impl RetryPolicy {
    /// The wait after `failures` consecutive failures (≥ 1).
    pub fn delay(&self, failures: u32) -> Duration {
        let doublings = failures.saturating_sub(1).min(31);
        self.initial_delay
            .saturating_mul(1 << doublings)
            .min(self.max_delay)
    }
}

/// What the loop reports; the caller logs or stores it (an alarm is an operator matter).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ShareEvent {
    /// A version is on the share and verified.
    Pushed {
        version: u64,
        table_number: u32,
        paths: Vec<PathBuf>,
    },
    /// A request was recorded as refused and will never be pushed.
    Refused { version: u64, reason: String },
    /// The first failure after a success (or at start): the share or the state folder is
    /// unusable. `version` is the waiting version, if it was recorded.
    Alarm {
        version: Option<u64>,
        reason: String,
        retry_in: Duration,
    },
    /// A further failure while alarmed.
    Retrying {
        version: Option<u64>,
        reason: String,
        failures: u32,
        retry_in: Duration,
    },
    /// Pushing works again after an alarm; `version` is the one that went through.
    Recovered { version: u64 },
    /// Pushed, but removing old kept texts failed; retried after the next push.
    PruneFailed { reason: String },
}

/// Alarm bookkeeping, independent of time and I/O.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AlarmState {
    failures: u32,
}

impl AlarmState {
    /// Consecutive failures so far.
    pub fn failures(&self) -> u32 {
        self.failures
    }

    /// A failed attempt: the event to report and the wait before the next attempt.
    pub fn fail(
        &mut self,
        policy: &RetryPolicy,
        version: Option<u64>,
        reason: String,
    ) -> (ShareEvent, Duration) {
        self.failures = self.failures.saturating_add(1);
        let retry_in = policy.delay(self.failures);
        let event = if self.failures == 1 {
            ShareEvent::Alarm {
                version,
                reason,
                retry_in,
            }
        } else {
            ShareEvent::Retrying {
                version,
                reason,
                failures: self.failures,
                retry_in,
            }
        };
        (event, retry_in)
    }

    /// A successful attempt: `Recovered` if it ends an alarm.
    pub fn succeed(&mut self, version: u64) -> Option<ShareEvent> {
        let was_alarmed = self.failures > 0;
        self.failures = 0;
        was_alarmed.then_some(ShareEvent::Recovered { version })
    }
}

/// Queue of push requests into the running loop. Dropping it stops the loop after the
/// attempt in progress; waiting versions stay recorded and go at the next start.
#[derive(Debug, Clone)]
pub struct ShareQueue {
    tx: mpsc::UnboundedSender<PushRequest>,
}

/// The loop has stopped; the request was not taken.
#[derive(Debug, thiserror::Error)]
#[error("the share loop has stopped")]
pub struct QueueClosed(pub Box<PushRequest>);

impl ShareQueue {
    /// Queue a request. It is recorded at the next attempt (at once unless pushes are
    /// failing, then at the next retry); a newer request supersedes it if it has not been
    /// delivered by then.
    pub fn push(&self, request: PushRequest) -> Result<(), QueueClosed> {
        self.tx
            .send(request)
            .map_err(|e| QueueClosed(Box::new(e.0)))
    }
}

/// What the loop hands back when it stops.
#[derive(Debug)]
pub struct Stopped {
    pub share: Share,
    /// Requests that could not be recorded (state folder unusable) before the stop.
    pub unrecorded: Vec<PushRequest>,
}

/// Start the loop on the current tokio runtime. A version already waiting in `share` (from
/// an earlier run) is attempted at once. File-system work runs on the blocking pool.
pub fn spawn(
    share: Share,
    policy: RetryPolicy,
) -> (
    ShareQueue,
    mpsc::UnboundedReceiver<ShareEvent>,
    JoinHandle<Stopped>,
) {
    let (tx, rx) = mpsc::unbounded_channel();
    let (events_tx, events_rx) = mpsc::unbounded_channel();
    let handle = tokio::spawn(run(share, policy, rx, events_tx));
    (ShareQueue { tx }, events_rx, handle)
}

async fn run(
    share: Share,
    policy: RetryPolicy,
    mut requests: mpsc::UnboundedReceiver<PushRequest>,
    events: mpsc::UnboundedSender<ShareEvent>,
) -> Stopped {
    let mut share = Some(share);
    let mut unrecorded = VecDeque::new();
    let mut alarm = AlarmState::default();
    let mut next_attempt = share
        .as_ref()
        .and_then(|s| s.history().waiting())
        .map(|_| Instant::now());
    loop {
        let wake = next_attempt.unwrap_or_else(|| Instant::now() + Duration::from_secs(86_400));
        tokio::select! {
            biased;
            request = requests.recv() => match request {
                Some(request) => {
                    unrecorded.push_back(request);
                    while let Ok(more) = requests.try_recv() {
                        unrecorded.push_back(more);
                    }
                    // While failing, the new version goes at the scheduled retry.
                    next_attempt.get_or_insert_with(Instant::now);
                }
                None => break,
            },
            () = tokio::time::sleep_until(wake), if next_attempt.is_some() => {
                let Some(owned) = share.take() else { break };
                let (owned, queue, result) =
                    tokio::task::spawn_blocking(move || attempt(owned, unrecorded))
                        .await
                        .expect("a share attempt does not panic");
                share = Some(owned);
                unrecorded = queue;
                next_attempt = None;
                for event in result.events {
                    let _ = events.send(event);
                }
                match result.outcome {
                    Outcome::Idle => {}
                    Outcome::Pushed(version) => {
                        if let Some(event) = alarm.succeed(version) {
                            let _ = events.send(event);
                        }
                    }
                    Outcome::Failed { version, reason } => {
                        let (event, retry_in) = alarm.fail(&policy, version, reason);
                        let _ = events.send(event);
                        next_attempt = Some(Instant::now() + retry_in);
                    }
                }
            }
        }
    }
    Stopped {
        share: share.expect("the share is back after every attempt"),
        unrecorded: unrecorded.into(),
    }
}

enum Outcome {
    Idle,
    Pushed(u64),
    Failed {
        version: Option<u64>,
        reason: String,
    },
}

struct Attempt {
    events: Vec<ShareEvent>,
    outcome: Outcome,
}

/// Record every queued request in order, then deliver the newest waiting version.
fn attempt(
    mut share: Share,
    mut unrecorded: VecDeque<PushRequest>,
) -> (Share, VecDeque<PushRequest>, Attempt) {
    let mut events = Vec::new();
    while let Some(request) = unrecorded.front() {
        match share.submit(request.clone()) {
            Ok(Submitted::Accepted { .. }) => {}
            Ok(Submitted::Refused { version, reason }) => {
                events.push(ShareEvent::Refused { version, reason });
            }
            Err(e) => {
                let version = share.history().waiting().map(|v| v.record.version);
                let outcome = Outcome::Failed {
                    version,
                    reason: e.to_string(),
                };
                return (share, unrecorded, Attempt { events, outcome });
            }
        }
        unrecorded.pop_front();
    }
    let outcome = match share.deliver() {
        Ok(None) => Outcome::Idle,
        Ok(Some(pushed)) => {
            events.push(ShareEvent::Pushed {
                version: pushed.version,
                table_number: pushed.table_number,
                paths: pushed.paths,
            });
            if let Some(e) = pushed.prune_error {
                events.push(ShareEvent::PruneFailed {
                    reason: e.to_string(),
                });
            }
            Outcome::Pushed(pushed.version)
        }
        Err(PushError::Share { version, error }) => Outcome::Failed {
            version: Some(version),
            reason: error.to_string(),
        },
        Err(e) => Outcome::Failed {
            version: share.history().waiting().map(|v| v.record.version),
            reason: e.to_string(),
        },
    };
    (share, unrecorded, Attempt { events, outcome })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_from_the_initial_delay_up_to_the_maximum() {
        let policy = RetryPolicy {
            initial_delay: Duration::from_millis(500),
            max_delay: Duration::from_secs(5),
        };
        let delays_ms: Vec<u128> = (1..=7).map(|n| policy.delay(n).as_millis()).collect();
        assert_eq!(delays_ms, [500, 1000, 2000, 4000, 5000, 5000, 5000]);
        assert_eq!(policy.delay(u32::MAX), Duration::from_secs(5));
    }

    #[test]
    fn the_first_failure_alarms_later_ones_retry_and_success_recovers_once() {
        let policy = RetryPolicy::default();
        let mut alarm = AlarmState::default();
        assert_eq!(alarm.succeed(1), None);
        let (first, wait) = alarm.fail(&policy, Some(2), "share /x is missing".into());
        assert!(matches!(
            first,
            ShareEvent::Alarm {
                version: Some(2),
                ..
            }
        ));
        assert_eq!(wait, Duration::from_secs(1));
        let (second, wait) = alarm.fail(&policy, Some(2), "share /x is missing".into());
        assert!(matches!(second, ShareEvent::Retrying { failures: 2, .. }));
        assert_eq!(wait, Duration::from_secs(2));
        assert_eq!(alarm.succeed(2), Some(ShareEvent::Recovered { version: 2 }));
        assert_eq!(alarm.failures(), 0);
        assert_eq!(alarm.succeed(3), None);
    }
}
