//! The loop's backlog: measurements a gauge source has handed over that are not yet
//! recorded (journalled, or rejected with their reason), per machine, with the time each was
//! received. It is what `/metrics` calls the lag and what turns `/healthz` "degraded" when
//! the service cannot keep up; nothing is dropped from it but by being recorded.

use crate::names::MachineName;
use std::collections::{HashMap, VecDeque};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Measurements received and not yet recorded, oldest first per machine.
#[derive(Debug, Default)]
pub struct Backlog {
    waiting: Mutex<HashMap<MachineName, VecDeque<Instant>>>,
}

/// The backlog at one moment.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Lag {
    /// Measurements received and not yet recorded, over every machine.
    pub waiting: usize,
    /// How long the oldest of them has waited (`None`: nothing waits).
    pub oldest: Option<Duration>,
}

impl Backlog {
    fn map(&self) -> std::sync::MutexGuard<'_, HashMap<MachineName, VecDeque<Instant>>> {
        // Every change is one push or pop: a panic elsewhere cannot leave it half-changed.
        self.waiting.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A measurement of `machine` was handed to its loop at `at`.
    pub fn received(&self, machine: &MachineName, at: Instant) {
        self.map().entry(machine.clone()).or_default().push_back(at);
    }

    /// The loop of `machine` has recorded its oldest waiting measurement (a machine handles
    /// its events in order, so the oldest is the one done).
    pub fn recorded(&self, machine: &MachineName) {
        if let Some(q) = self.map().get_mut(machine) {
            q.pop_front();
        }
    }

    /// The loop of `machine` stopped: what it had not taken stays with its source (a drop
    /// file in its inbox, a simulated part not ground), so it no longer waits here.
    pub fn forget(&self, machine: &MachineName) {
        self.map().remove(machine);
    }

    /// The backlog as of `now`.
    pub fn lag(&self, now: Instant) -> Lag {
        let map = self.map();
        Lag {
            waiting: map.values().map(VecDeque::len).sum(),
            oldest: map
                .values()
                .filter_map(|q| q.front())
                .min()
                .map(|t| now.saturating_duration_since(*t)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_oldest_waiting_measurement_over_every_machine_sets_the_lag() {
        let b = Backlog::default();
        let t0 = Instant::now();
        let (m1, m2): (MachineName, MachineName) = ("M1".parse().unwrap(), "M2".parse().unwrap());
        assert_eq!(b.lag(t0), Lag::default());
        b.received(&m1, t0);
        b.received(&m2, t0 + Duration::from_secs(1));
        b.received(&m1, t0 + Duration::from_secs(2));
        let now = t0 + Duration::from_secs(5);
        assert_eq!(
            b.lag(now),
            Lag {
                waiting: 3,
                oldest: Some(Duration::from_secs(5))
            }
        );
        // M1's first is recorded: M2's (received at 1 s) is now the oldest.
        b.recorded(&m1);
        assert_eq!(b.lag(now).oldest, Some(Duration::from_secs(4)));
        b.forget(&m2);
        assert_eq!(
            b.lag(now),
            Lag {
                waiting: 1,
                oldest: Some(Duration::from_secs(3))
            }
        );
        b.recorded(&m1);
        b.recorded(&m1);
        assert_eq!(b.lag(now), Lag::default());
    }
}
