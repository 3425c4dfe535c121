//! How many refused attempts the audit trail takes: every refused write and failed sign-in
//! is audited, but a client flooding refusals must not fill the disk. Each client gets at
//! most [`PER_CLIENT_PER_MINUTE`] rows a minute, and all clients together at most
//! [`TOTAL_PER_MINUTE`]; beyond that a refusal is only counted, and the client's next row
//! says how many of its refusals went unrecorded before it.
//!
//! Bound: [`TOTAL_PER_MINUTE`] rows a minute, 86 400 a day, about 26 MB a day at ~300 bytes
//! a row, whatever the flood. Kept in memory: at most [`MAX_CLIENTS`] clients are tracked
//! (a client whose minute has ended is forgotten first).

use jiff::{SignedDuration, Timestamp};
use std::collections::HashMap;
use std::sync::Mutex;

/// Rows one client may add a minute.
pub const PER_CLIENT_PER_MINUTE: u32 = 10;
/// Rows all clients together may add a minute.
pub const TOTAL_PER_MINUTE: u32 = 60;
/// Clients tracked at once.
pub const MAX_CLIENTS: usize = 4096;
const MINUTE: SignedDuration = SignedDuration::from_mins(1);

#[derive(Debug, Clone, Copy)]
struct Window {
    started: Timestamp,
    recorded: u32,
    /// Refusals not recorded since this client's last row.
    unrecorded: u64,
}

#[derive(Debug, Default)]
struct State {
    clients: HashMap<String, Window>,
    total: Option<Window>,
}

/// The audit trail's budget for refusals.
#[derive(Debug, Default)]
pub struct RefusalBudget {
    state: Mutex<State>,
}

/// Whether to audit a refusal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admit {
    /// Record it; this many refusals of the client went unrecorded before it.
    Record { unrecorded_before: u64 },
    /// Over budget: count it only.
    Skip,
}

fn fresh(w: Option<Window>, now: Timestamp) -> Window {
    match w {
        Some(w) if now.duration_since(w.started) < MINUTE => w,
        Some(w) => Window {
            started: now,
            recorded: 0,
            unrecorded: w.unrecorded,
        },
        None => Window {
            started: now,
            recorded: 0,
            unrecorded: 0,
        },
    }
}

impl RefusalBudget {
    /// One refusal of `client` at `now`.
    pub fn admit(&self, client: &str, now: Timestamp) -> Admit {
        let mut state = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let total = fresh(state.total, now);
        if state.clients.len() >= MAX_CLIENTS && !state.clients.contains_key(client) {
            state
                .clients
                .retain(|_, w| now.duration_since(w.started) < MINUTE);
            if state.clients.len() >= MAX_CLIENTS {
                // Every tracked client is within its minute: the newcomer shares the total.
                state.total = Some(total);
                return Self::untracked(&mut state);
            }
        }
        let mut mine = fresh(state.clients.get(client).copied(), now);
        state.total = Some(total);
        if mine.recorded >= PER_CLIENT_PER_MINUTE || total.recorded >= TOTAL_PER_MINUTE {
            mine.unrecorded += 1;
            state.clients.insert(client.to_string(), mine);
            return Admit::Skip;
        }
        let unrecorded_before = mine.unrecorded;
        mine.recorded += 1;
        mine.unrecorded = 0;
        state.clients.insert(client.to_string(), mine);
        if let Some(t) = state.total.as_mut() {
            t.recorded += 1;
        }
        Admit::Record { unrecorded_before }
    }

    /// A refusal of a client not tracked (too many are): within the total only.
    fn untracked(state: &mut State) -> Admit {
        match state.total.as_mut() {
            Some(t) if t.recorded < TOTAL_PER_MINUTE => {
                t.recorded += 1;
                Admit::Record {
                    unrecorded_before: 0,
                }
            }
            _ => Admit::Skip,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(s: i64) -> Timestamp {
        Timestamp::from_second(1_800_000_000 + s).unwrap()
    }

    #[test]
    fn a_client_gets_ten_rows_a_minute_and_then_hears_how_many_went_unrecorded() {
        let budget = RefusalBudget::default();
        let admitted = (0..25)
            .filter(|_| budget.admit("10.0.0.1", at(0)) != Admit::Skip)
            .count();
        assert_eq!(admitted, PER_CLIENT_PER_MINUTE as usize);
        // Another client is not held by the first one's flood.
        assert_eq!(
            budget.admit("10.0.0.2", at(1)),
            Admit::Record {
                unrecorded_before: 0
            }
        );
        assert_eq!(budget.admit("10.0.0.1", at(59)), Admit::Skip);
        assert_eq!(
            budget.admit("10.0.0.1", at(60)),
            Admit::Record {
                unrecorded_before: 16
            }
        );
    }

    #[test]
    fn all_clients_together_get_sixty_rows_a_minute() {
        let budget = RefusalBudget::default();
        let admitted = (0..200)
            .filter(|i| budget.admit(&format!("client-{i}"), at(0)) != Admit::Skip)
            .count();
        assert_eq!(admitted, TOTAL_PER_MINUTE as usize);
        let next_minute = budget.admit("client-0", at(60));
        assert_ne!(next_minute, Admit::Skip);
    }

    #[test]
    fn past_the_tracked_clients_newcomers_share_the_total_only() {
        let budget = RefusalBudget::default();
        for i in 0..MAX_CLIENTS {
            budget.admit(&format!("c{i}"), at(0));
        }
        // The total is spent: a new client within the minute is counted only.
        assert_eq!(budget.admit("newcomer", at(1)), Admit::Skip);
        // A minute on, the old windows are forgotten and the newcomer is tracked.
        assert_eq!(
            budget.admit("newcomer", at(61)),
            Admit::Record {
                unrecorded_before: 0
            }
        );
    }
}
