//! The loop's backlog: measurements a gauge source has handed over that are not yet
//! recorded (journalled, or rejected with their reason), per machine, with the time each was
//! received. It is what `/metrics` calls the lag and what turns `/healthz` "degraded" when
//! the service cannot keep up; nothing is dropped from it but by being recorded.

use crate::names::MachineName;
use std::collections::{HashMap, VecDeque};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Measurements received and not yet recorded, oldest first per machine, and how long
/// those done took.
#[derive(Debug, Default)]
pub struct Backlog {
    waiting: Mutex<HashMap<MachineName, VecDeque<Instant>>>,
    /// From received to done (its table durable on the share, or its record kept).
    pub done: PartSeconds,
}

/// Upper bounds of the buckets of [`PartSeconds`], seconds: fine below the 2 s goal, coarse
/// past it.
pub const PART_SECONDS_BUCKETS: [f64; 14] = [
    0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0, 30.0,
];

/// A histogram of the seconds from a measurement received to its part done: the
/// measurement journalled and analysed, and the table it made rendered and durable on the
/// share (the part's whole way through the loop, the queue in front of it included).
#[derive(Debug, Default)]
pub struct PartSeconds {
    counts: Mutex<PartCounts>,
}

/// The histogram's counts: per bucket (not cumulative; `+Inf` last), their sum, and the sum
/// of the seconds.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PartCounts {
    pub buckets: [u64; PART_SECONDS_BUCKETS.len() + 1],
    pub count: u64,
    pub sum_s: f64,
}

impl PartSeconds {
    /// One part done `took` after its measurement was received.
    pub fn observe(&self, took: Duration) {
        let s = took.as_secs_f64();
        let k = PART_SECONDS_BUCKETS
            .iter()
            .position(|le| s <= *le)
            .unwrap_or(PART_SECONDS_BUCKETS.len());
        let mut c = self.counts.lock().unwrap_or_else(|p| p.into_inner());
        c.buckets[k] += 1;
        c.count += 1;
        c.sum_s += s;
    }

    /// The counts so far.
    pub fn counts(&self) -> PartCounts {
        self.counts
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }
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
        self.recorded_at(machine, Instant::now());
    }

    /// [`Self::recorded`] at `now`: the time since it was received goes to [`Self::done`].
    pub fn recorded_at(&self, machine: &MachineName, now: Instant) {
        let received = self.map().get_mut(machine).and_then(VecDeque::pop_front);
        if let Some(at) = received {
            self.done.observe(now.saturating_duration_since(at));
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

    /// Each measurement done lands in the bucket of its time from received to done, the
    /// bounds inclusive as Prometheus reads `le`; one past the last bound goes to `+Inf`.
    #[test]
    fn each_part_done_is_counted_in_the_bucket_of_its_time() {
        let b = Backlog::default();
        let m: MachineName = "M1".parse().unwrap();
        let t0 = Instant::now();
        for offset_ms in [0, 1000, 3000] {
            b.received(&m, t0 + Duration::from_millis(offset_ms));
        }
        // Done at 2 s, 2.3 s and 33.5 s: 2 s, 1.3 s and 30.5 s after they came in.
        b.recorded_at(&m, t0 + Duration::from_secs(2));
        b.recorded_at(&m, t0 + Duration::from_millis(2300));
        b.recorded_at(&m, t0 + Duration::from_millis(33_500));
        // A machine with nothing waiting counts nothing.
        b.recorded_at(&m, t0 + Duration::from_secs(40));
        let c = b.done.counts();
        let bucket = |le: f64| PART_SECONDS_BUCKETS.iter().position(|b| *b == le).unwrap();
        let mut want = [0u64; PART_SECONDS_BUCKETS.len() + 1];
        want[bucket(2.0)] = 1;
        want[bucket(1.5)] = 1;
        want[PART_SECONDS_BUCKETS.len()] = 1;
        assert_eq!(c.buckets, want);
        assert_eq!(c.count, 3);
        assert!((c.sum_s - 33.8).abs() < 1e-9, "{}", c.sum_s);
    }
}
