//! Password sign-in, shared by every adapter that takes a user name and password (the HTTP
//! sign-in form, OPC UA's user-name tokens): a slot in the lockout taken in one step with
//! its count (`crate::auth::Lockout`), then the argon2 check on the hasher's threads, then
//! the count; failures logged, counted in `/metrics` and audited within the trail's budget
//! for refusals. Neither adapter owns it, so neither imports the other for it.

use super::app::AppState;
use crate::auth::{Client, Counted, Refused, UserName};
use crate::store::{AuditEntry, AuditResult, Role, Store, StoreError, User};
use std::net::IpAddr;
use tracing::warn;

/// How a password sign-in ended.
pub(crate) enum SignIn {
    Ok(User),
    /// A wrong name or password: counted, logged and audited.
    Wrong,
    /// Not checked: locked out, or as many checks in flight as would lock.
    Refused(Refusal),
}

/// Why a password was not checked: both pass with time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub(crate) enum Refusal {
    #[error("too many failed attempts: try again in {left_s} s")]
    Locked { left_s: u64 },
    #[error(
        "the attempts of this user from this client being checked now would lock it if wrong: try again in a moment"
    )]
    InFlight,
}

impl Refusal {
    /// Seconds to wait before trying again.
    pub(crate) fn retry_after_s(self) -> u64 {
        match self {
            Refusal::Locked { left_s } => left_s,
            Refusal::InFlight => 1,
        }
    }
}

/// Why a check could not be made at all: nothing was counted.
#[derive(Debug, thiserror::Error)]
pub(crate) enum SignInError {
    #[error("the history database is not reachable; measurements are kept in the journal")]
    StoreUnavailable,
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error(transparent)]
    Busy(#[from] crate::auth::Busy),
}

/// A password sign-in of `name` from `client` (audited under `address`). A check that
/// cannot be made (the database down, every hash slot and the queue taken) is an error and
/// counts nothing.
pub(crate) async fn password_sign_in(
    app: &AppState,
    name: &str,
    password: &str,
    client: Client,
    address: IpAddr,
) -> Result<SignIn, SignInError> {
    let user_name = UserName::new(name).ok();
    let user_text = user_name.as_ref().map(UserName::as_str);
    let attempt = match app
        .auth
        .lockout
        .begin_password(name, client, crate::clock::now())
    {
        Ok(attempt) => attempt,
        Err(Refused::Locked { until }) => {
            return Ok(SignIn::Refused(locked_out(app, user_text, address, until)));
        }
        Err(Refused::Busy) => {
            app.metrics
                .update_access(|a| *a.failures.entry("locked").or_default() += 1);
            return Ok(SignIn::Refused(Refusal::InFlight));
        }
    };
    match check_password(app, user_name.as_ref(), password).await? {
        Ok(user) => {
            attempt.succeeded();
            Ok(SignIn::Ok(user))
        }
        Err(why) => {
            let counted = attempt.failed(crate::clock::now());
            record_failure(app, "password", user_text, address, why, counted).await;
            Ok(SignIn::Wrong)
        }
    }
}

/// The history store, or why not.
async fn store(app: &AppState) -> Result<Store, SignInError> {
    app.store
        .read()
        .await
        .clone()
        .ok_or(SignInError::StoreUnavailable)
}

/// The enabled user `name` whose password is `password`, or why not. A hash is checked even
/// for an unknown user, so the time taken does not tell which names exist.
async fn check_password(
    app: &AppState,
    name: Option<&UserName>,
    password: &str,
) -> Result<Result<User, &'static str>, SignInError> {
    let store = store(app).await?;
    let user = match name {
        Some(n) => store.user(n.as_str()).await?,
        None => None,
    };
    let hash = user
        .as_ref()
        .map_or(DUMMY_HASH, |u| u.password_hash.as_str())
        .to_string();
    let matches = app.auth.hasher.verify(password.to_string(), hash).await?;
    Ok(match user {
        None => Err("unknown user"),
        Some(u) if u.disabled_at.is_some() => Err("disabled user"),
        Some(_) if !matches => Err("wrong password"),
        Some(u) => Ok(u),
    })
}

/// An argon2id hash of a password nobody has, checked for unknown users.
const DUMMY_HASH: &str = "$argon2id$v=19$m=19456,t=2,p=1$c29tZXNhbHRzb21lc2FsdA$QUwJiZ3Eg4pcXfI7u8T/HWl3eo6L6VeKvzZp4RkZ+6Q";

/// Logs one failed sign-in (`kind` "password") or token ("token"), already counted
/// (`counted`), and audits it within the trail's budget for refusals.
pub(crate) async fn record_failure(
    app: &AppState,
    kind: &'static str,
    user: Option<&str>,
    address: IpAddr,
    why: &str,
    counted: Counted,
) {
    let user_text = user.unwrap_or("-");
    warn!(kind, user = user_text, client = %address, why, "authentication failed");
    app.metrics.update_access(|a| {
        *a.failures.entry(kind).or_default() += 1;
        if counted.locked_now {
            a.lockouts_total += 1;
        }
    });
    let (action, locked_what) = if kind == "password" {
        ("signin", "this user from this client")
    } else {
        ("token", "wrong tokens from this address")
    };
    let mut reason = why.to_string();
    if counted.locked_now {
        warn!(user = user_text, client = %address, kind, "locked out for 15 minutes after 5 failures");
        reason.push_str(&format!("; {locked_what} locked out for 15 minutes"));
    }
    let entry = AuditEntry {
        at: crate::clock::now(),
        actor: user.unwrap_or("anonymous").to_string(),
        role: Role::Viewer,
        client: address.to_string(),
        action: action.to_string(),
        machine: None,
        feature: None,
        version: None,
        before: None,
        after: None,
        result: AuditResult::Refused,
        reason,
    };
    record_refusal(app, entry).await;
}

/// A refusal while locked out until `until`: counted and logged, not audited again (the
/// lock was).
pub(crate) fn locked_out(
    app: &AppState,
    user: Option<&str>,
    address: IpAddr,
    until: jiff::Timestamp,
) -> Refusal {
    let left_s = until.duration_since(crate::clock::now()).as_secs().max(0) + 1;
    warn!(user = user.unwrap_or("-"), client = %address, left_s, "refused: locked out");
    app.metrics
        .update_access(|a| *a.failures.entry("locked").or_default() += 1);
    Refusal::Locked {
        left_s: u64::try_from(left_s).unwrap_or(1),
    }
}

/// Appends `entry`, a refusal (a refused write, a failed sign-in), within the trail's budget
/// for refusals of its client; over it, `camloop_audit_refusals_unrecorded_total` counts it
/// and the client's next row says how many went unrecorded.
pub(crate) async fn record_refusal(app: &AppState, entry: AuditEntry) {
    match app.auth.audit_seal.within_refusal_budget(entry) {
        Some(entry) => crate::service::command::record_audit(app.writes(), entry).await,
        None => app
            .metrics
            .update_access(|a| a.refusals_unrecorded_total += 1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::auth::verify_password;

    #[test]
    fn the_dummy_hash_parses_and_matches_nothing_typed() {
        assert!(!verify_password("", DUMMY_HASH));
        assert!(!verify_password("twelve-chars", DUMMY_HASH));
        assert!(argon2::password_hash::phc::PasswordHash::new(DUMMY_HASH).is_ok());
    }
}
