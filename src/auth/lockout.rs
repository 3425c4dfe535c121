//! The lockout: failed password sign-ins counted per (user, client), failed tokens per
//! address, and the rule that makes counting and checking one step.
//!
//! - A password attempt first takes a slot ([`Lockout::begin_password`]) under the same lock
//!   that counts failures; failures plus attempts still being checked may not pass
//!   [`LOCKOUT_FAILURES`]. So 60 attempts sent at once check at most 5 passwords: the rest
//!   are refused before any hash runs, and the right password sent among them is refused
//!   too once 5 wrong ones are counted.
//! - Password failures lock only that user from that client: someone guessing `ann`'s
//!   password from one address locks neither `ann` elsewhere nor anyone else there.
//! - Tokens are 256-bit random values, so a valid token is never refused because of
//!   failures; wrong tokens from one address lock that address's wrong tokens (429 without
//!   a look-up), which only slows a scan.
//!
//! Kept in memory: a restart forgets it (an attacker who can restart the service has no
//! need to guess). A record lives while it holds a failure in the window, a lock or an
//! attempt; every failure took one argon2 hash, which bounds how fast records can be made.

use jiff::{SignedDuration, Timestamp};
use std::collections::HashMap;
use std::fmt;
use std::net::IpAddr;
use std::sync::Mutex;

/// Failures within [`LOCKOUT_WINDOW`] that lock.
pub const LOCKOUT_FAILURES: usize = 5;
/// The window failures are counted in, and how long a lock lasts: 15 minutes.
pub const LOCKOUT_WINDOW: SignedDuration = SignedDuration::from_mins(15);
/// The longest user name kept in a record: a longer name is not a user, and counting it by
/// its first characters still counts it.
const NAME_CHARS: usize = 64;

/// Where a password attempt comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Client {
    /// An HTTP client's address.
    Address(IpAddr),
    /// Any OPC UA client: the OPC UA stack tells the server neither its peer's address nor
    /// its certificate, so OPC UA attempts share one client, apart from every HTTP one.
    OpcUa,
}

impl fmt::Display for Client {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Client::Address(a) => write!(f, "{a}"),
            Client::OpcUa => f.write_str("opc.tcp"),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq, Hash)]
enum Key {
    Password { user: String, client: Client },
    Token(IpAddr),
}

#[derive(Debug, Default)]
struct Record {
    /// Times of failures within the window.
    failures: Vec<Timestamp>,
    /// Attempts taken and not yet found right or wrong.
    in_flight: usize,
    /// Locked until this time.
    locked_until: Option<Timestamp>,
}

impl Record {
    fn locked(&self, now: Timestamp) -> Option<Timestamp> {
        self.locked_until.filter(|&u| u > now)
    }

    fn forget_old(&mut self, now: Timestamp) {
        self.failures.retain(|t| recent(*t, now));
    }

    /// Counts one failure at `now`; whether it locked now.
    fn fail(&mut self, now: Timestamp) -> bool {
        self.forget_old(now);
        self.failures.push(now);
        if self.locked(now).is_none() && self.failures.len() >= LOCKOUT_FAILURES {
            // Saturates at jiff's last instant rather than failing: a lock all the same.
            let until = now.saturating_add(LOCKOUT_WINDOW);
            self.locked_until = Some(until.unwrap_or(Timestamp::MAX));
            self.failures.clear();
            return true;
        }
        false
    }

    fn live(&self, now: Timestamp) -> bool {
        self.in_flight > 0
            || self.locked(now).is_some()
            || self.failures.iter().any(|t| recent(*t, now))
    }
}

fn recent(t: Timestamp, now: Timestamp) -> bool {
    now.duration_since(t) < LOCKOUT_WINDOW
}

/// Failed sign-ins per (user, client) and failed tokens per address: [`LOCKOUT_FAILURES`]
/// within [`LOCKOUT_WINDOW`] lock for [`LOCKOUT_WINDOW`].
#[derive(Debug, Default)]
pub struct Lockout {
    records: Mutex<HashMap<Key, Record>>,
}

/// A failure counted: whether it locked now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Counted {
    pub locked_now: bool,
}

/// Why a password attempt may not be checked now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// Locked until then.
    Locked { until: Timestamp },
    /// The attempts being checked would lock if they all failed: this one waits its turn.
    Busy,
}

/// One password attempt that holds a slot until it is found right or wrong; dropped
/// unfinished (the check could not be made), it gives the slot back uncounted.
#[derive(Debug)]
pub struct Attempt<'a> {
    lockout: &'a Lockout,
    key: Key,
    open: bool,
}

impl Attempt<'_> {
    /// The password was wrong (or the user unknown or disabled): counted at `now`.
    pub fn failed(mut self, now: Timestamp) -> Counted {
        self.open = false;
        let locked_now = self.lockout.with(&self.key, |r| {
            r.in_flight = r.in_flight.saturating_sub(1);
            r.fail(now)
        });
        Counted { locked_now }
    }

    /// The password was right: the earlier failures of this user from this client go.
    pub fn succeeded(mut self) {
        self.open = false;
        self.lockout.with(&self.key, |r| {
            r.in_flight = r.in_flight.saturating_sub(1);
            r.failures.clear();
        });
    }
}

impl Drop for Attempt<'_> {
    fn drop(&mut self) {
        if self.open {
            self.lockout
                .with(&self.key, |r| r.in_flight = r.in_flight.saturating_sub(1));
        }
    }
}

impl Lockout {
    fn with<T>(&self, key: &Key, f: impl FnOnce(&mut Record) -> T) -> T {
        let mut records = self.records.lock().unwrap_or_else(|p| p.into_inner());
        f(records.entry(key.clone()).or_default())
    }

    /// Takes a slot for checking `user`'s password from `client` at `now`, in one step with
    /// the count: refused while locked, or while failures and attempts in flight already
    /// reach [`LOCKOUT_FAILURES`].
    pub fn begin_password(
        &self,
        user: &str,
        client: Client,
        now: Timestamp,
    ) -> Result<Attempt<'_>, Refused> {
        let user: String = user.chars().take(NAME_CHARS).collect();
        let key = Key::Password { user, client };
        let mut records = self.records.lock().unwrap_or_else(|p| p.into_inner());
        // Old records go, so a scan of many names or addresses does not grow the map for ever.
        records.retain(|_, r| r.live(now));
        let r = records.entry(key.clone()).or_default();
        if let Some(until) = r.locked(now) {
            return Err(Refused::Locked { until });
        }
        r.forget_old(now);
        if r.failures.len() + r.in_flight >= LOCKOUT_FAILURES {
            return Err(Refused::Busy);
        }
        r.in_flight += 1;
        Ok(Attempt {
            lockout: self,
            key,
            open: true,
        })
    }

    /// Until when wrong tokens from `address` are refused unchecked, if they are at `now`.
    pub fn token_locked_until(&self, address: IpAddr, now: Timestamp) -> Option<Timestamp> {
        let records = self.records.lock().unwrap_or_else(|p| p.into_inner());
        records.get(&Key::Token(address))?.locked(now)
    }

    /// Counts one wrong token from `address` at `now`.
    pub fn fail_token(&self, address: IpAddr, now: Timestamp) -> Counted {
        let mut records = self.records.lock().unwrap_or_else(|p| p.into_inner());
        records.retain(|_, r| r.live(now));
        let locked_now = records.entry(Key::Token(address)).or_default().fail(now);
        Counted { locked_now }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(ms: i64) -> Timestamp {
        Timestamp::from_millisecond(1_000_000 + ms).unwrap()
    }

    fn at(a: &str) -> Client {
        Client::Address(a.parse().unwrap())
    }

    #[test]
    fn attempts_taken_at_once_check_at_most_five_passwords() {
        let l = Lockout::default();
        let a = at("10.0.0.1");
        // 60 attempts arrive before any is checked: five get a slot, the rest wait.
        let taken: Vec<_> = (0..60)
            .filter_map(|_| l.begin_password("ann", a, t(0)).ok())
            .collect();
        assert_eq!(taken.len(), LOCKOUT_FAILURES);
        assert_eq!(l.begin_password("ann", a, t(0)).unwrap_err(), Refused::Busy);
        let locked: Vec<bool> = taken
            .into_iter()
            .map(|x| x.failed(t(1)).locked_now)
            .collect();
        assert_eq!(locked, [false, false, false, false, true]);
        // The right password, sent after them, is refused: ann is locked from there.
        let until = t(1) + LOCKOUT_WINDOW;
        assert_eq!(
            l.begin_password("ann", a, t(2)).unwrap_err(),
            Refused::Locked { until }
        );
        assert!(
            l.begin_password("ann", a, until).is_ok(),
            "15 minutes later"
        );
    }

    #[test]
    fn a_lock_holds_one_user_from_one_client_only() {
        let l = Lockout::default();
        let (a, b) = (at("10.0.0.1"), at("10.0.0.2"));
        for i in 0..5 {
            l.begin_password("ann", a, t(i)).unwrap().failed(t(i));
        }
        assert!(l.begin_password("ann", a, t(6)).is_err());
        assert!(l.begin_password("ann", b, t(6)).is_ok(), "ann elsewhere");
        assert!(l.begin_password("bob", a, t(6)).is_ok(), "bob from there");
        assert!(
            l.begin_password("ann", Client::OpcUa, t(6)).is_ok(),
            "ann on OPC UA"
        );
        // Nor does it touch tokens from that address.
        let ip: IpAddr = "10.0.0.1".parse().unwrap();
        assert_eq!(l.token_locked_until(ip, t(6)), None);
    }

    #[test]
    fn an_unfinished_attempt_gives_its_slot_back_and_a_right_one_clears_the_count() {
        let l = Lockout::default();
        let a = at("10.0.0.1");
        for _ in 0..10 {
            drop(l.begin_password("ann", a, t(0)).unwrap());
        }
        for i in 0..4 {
            l.begin_password("ann", a, t(i)).unwrap().failed(t(i));
        }
        l.begin_password("ann", a, t(5)).unwrap().succeeded();
        for i in 0..4 {
            let c = l
                .begin_password("ann", a, t(6 + i))
                .unwrap()
                .failed(t(6 + i));
            assert!(!c.locked_now, "failure {i} after the right password");
        }
    }

    #[test]
    fn failures_spread_over_more_than_the_window_never_lock() {
        let l = Lockout::default();
        let a = at("10.0.0.2");
        let ip: IpAddr = "10.0.0.2".parse().unwrap();
        for i in 0..10 {
            let now = t(0) + (LOCKOUT_WINDOW / 4 + SignedDuration::from_millis(1)) * i;
            assert!(
                !l.begin_password("cy", a, now)
                    .unwrap()
                    .failed(now)
                    .locked_now
            );
            assert!(!l.fail_token(ip, now).locked_now, "token failure {i}");
        }
    }

    #[test]
    fn five_wrong_tokens_lock_that_address_s_wrong_tokens() {
        let l = Lockout::default();
        let (a, b): (IpAddr, IpAddr) = ("10.0.0.1".parse().unwrap(), "10.0.0.2".parse().unwrap());
        for i in 0..4 {
            assert!(!l.fail_token(a, t(i)).locked_now);
        }
        assert!(l.fail_token(a, t(4)).locked_now);
        assert_eq!(l.token_locked_until(a, t(5)), Some(t(4) + LOCKOUT_WINDOW));
        assert_eq!(l.token_locked_until(b, t(5)), None);
        assert!(l.begin_password("ann", Client::Address(a), t(5)).is_ok());
    }
}
