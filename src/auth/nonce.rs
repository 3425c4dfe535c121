//! One-time values the service hands a client and takes back once: the sign-in form's
//! nonce. A double-submit value alone proves only that the form and the cookie agree, and a
//! page on another port of the same host can set both (cookies ignore ports); a value the
//! service issued, to that client address, within [`NONCE_LIFETIME`], and never used before
//! cannot be made up by such a page.
//!
//! Kept in memory, at most [`MAX_NONCES`] at once (the oldest go first), by their SHA-256:
//! a restart forgets them, and the sign-in page simply issues a new one.

use crate::digest::Sha256;
use jiff::{SignedDuration, Timestamp};
use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::Mutex;

/// How long an issued value may be used: as long as the sign-in form's cookie lives.
pub const NONCE_LIFETIME: SignedDuration = SignedDuration::from_mins(10);
/// At most this many values wait at once; the oldest go first.
pub const MAX_NONCES: usize = 10_000;

#[derive(Debug, Clone, Copy)]
struct Issued {
    client: IpAddr,
    expires_at: Timestamp,
}

/// Values issued and not yet taken back.
#[derive(Debug, Default)]
pub struct Nonces {
    map: Mutex<HashMap<Sha256, Issued>>,
}

/// Why a value was not accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum NonceRefused {
    #[error("the form's value was not issued by this service, or was used already")]
    NotIssued,
    #[error("the form's value was issued to another client address")]
    OtherClient,
    #[error("the form's value has expired")]
    Expired,
}

impl Nonces {
    /// A new random value for `client`, remembered until `now` + [`NONCE_LIFETIME`].
    pub fn issue(&self, client: IpAddr, now: Timestamp) -> Result<String, super::AuthError> {
        let value = super::random_hex(16)?;
        let issued = Issued {
            client,
            expires_at: now.saturating_add(NONCE_LIFETIME).unwrap_or(Timestamp::MAX),
        };
        let mut map = self.map.lock().unwrap_or_else(|p| p.into_inner());
        if map.len() >= MAX_NONCES {
            map.retain(|_, i| i.expires_at > now);
        }
        if map.len() >= MAX_NONCES
            && let Some(oldest) = map
                .iter()
                .min_by_key(|(_, i)| i.expires_at)
                .map(|(k, _)| *k)
        {
            map.remove(&oldest);
        }
        map.insert(Sha256::of(value.as_bytes()), issued);
        Ok(value)
    }

    /// Takes `value` back from `client` at `now`: accepted once, if this service issued it
    /// to that address and it has not expired. Any use ends it, accepted or not.
    pub fn take(&self, value: &str, client: IpAddr, now: Timestamp) -> Result<(), NonceRefused> {
        let mut map = self.map.lock().unwrap_or_else(|p| p.into_inner());
        match map.remove(&Sha256::of(value.as_bytes())) {
            None => Err(NonceRefused::NotIssued),
            Some(i) if i.expires_at <= now => Err(NonceRefused::Expired),
            Some(i) if i.client != client => Err(NonceRefused::OtherClient),
            Some(_) => Ok(()),
        }
    }

    /// Values waiting now (for tests and metrics).
    pub fn len(&self) -> usize {
        self.map.lock().unwrap_or_else(|p| p.into_inner()).len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(s: i64) -> Timestamp {
        Timestamp::from_second(1_800_000_000 + s).unwrap()
    }

    #[test]
    fn a_value_is_taken_once_from_the_address_it_was_issued_to() {
        let nonces = Nonces::default();
        let (here, there): (IpAddr, IpAddr) =
            ("127.0.0.1".parse().unwrap(), "127.0.0.2".parse().unwrap());
        let v = nonces.issue(here, at(0)).unwrap();
        assert_eq!(v.len(), 32);
        assert_eq!(nonces.take(&v, here, at(1)), Ok(()));
        assert_eq!(nonces.take(&v, here, at(2)), Err(NonceRefused::NotIssued));
        // Made up by someone else: never issued.
        let made_up = "0123456789abcdef0123456789abcdef";
        assert_eq!(
            nonces.take(made_up, here, at(2)),
            Err(NonceRefused::NotIssued)
        );
        let w = nonces.issue(here, at(0)).unwrap();
        assert_eq!(
            nonces.take(&w, there, at(1)),
            Err(NonceRefused::OtherClient)
        );
        assert_eq!(nonces.take(&w, here, at(1)), Err(NonceRefused::NotIssued));
        let x = nonces.issue(here, at(0)).unwrap();
        let late = at(NONCE_LIFETIME.as_secs());
        assert_eq!(nonces.take(&x, here, late), Err(NonceRefused::Expired));
    }

    #[test]
    fn at_most_max_nonces_wait_and_the_oldest_go_first() {
        let nonces = Nonces::default();
        let here: IpAddr = "127.0.0.1".parse().unwrap();
        let first = nonces.issue(here, at(-1)).unwrap();
        for i in 1..=MAX_NONCES {
            nonces.issue(here, at(i as i64 / 100)).unwrap();
        }
        assert_eq!(nonces.len(), MAX_NONCES);
        assert_eq!(
            nonces.take(&first, here, at(200)),
            Err(NonceRefused::NotIssued)
        );
    }
}
