//! Who may do what over OPC UA: users are camloop's users (argon2 hashes in the store),
//! checked by the sign-in the HTTP form uses too (the [`Service`] port's: lockout, bounded
//! hashing), and only on a
//! signed and encrypted endpoint; anonymous clients are admitted only when
//! `opcua.anonymous_read` allows it, and may then only browse, read and subscribe.

use std::collections::{HashMap, HashSet};
use std::net::{IpAddr, Ipv6Addr};
use std::sync::{Arc, RwLock, Weak};
use std::time::Duration;

use async_trait::async_trait;
use opcua::crypto::SecurityPolicy;
use opcua::server::ServerEndpoint;
use opcua::server::address_space::AccessLevel;
use opcua::server::authenticator::{
    AuthManager, Password, UserToken, user_pass_security_policy_id, user_pass_security_policy_uri,
};
use opcua::types::{
    Error, MessageSecurityMode, NodeId, StatusCode, UAString, UserTokenPolicy, UserTokenType,
};

use crate::port::{Service, SignIn};
use camloop_core::digest::Sha256;
use camloop_store::{AuditEntry, AuditResult, Role, Store};

/// The client address OPC UA failures and writes are audited under: the OPC UA stack does
/// not tell the server its peer's address, so every OPC UA client shares this one (distinct
/// from the HTTP side's unknown address, 0.0.0.0). The lockout counts them apart from every
/// HTTP client (the service's lockout has a client of its own for OPC UA).
pub const OPCUA_CLIENT: IpAddr = IpAddr::V6(Ipv6Addr::UNSPECIFIED);

/// Checks identity tokens against camloop's users, and every read and call against the
/// user's state now (see [`SignedIn`]).
pub(crate) struct Users {
    service: Arc<dyn Service>,
    anonymous_read: bool,
    signed_in: Arc<SignedIn>,
}

impl Users {
    /// The users of the service's store; a task checks the signed-in users' state every
    /// [`RECHECK_EVERY`] while these users are in use.
    pub(crate) fn new(service: Arc<dyn Service>, anonymous_read: bool) -> Self {
        let signed_in = Arc::new(SignedIn::default());
        tokio::spawn(keep_rechecking(Arc::downgrade(&signed_in), service.clone()));
        Self {
            service,
            anonymous_read,
            signed_in,
        }
    }
}

/// How often the signed-in OPC UA users' state is read from the store: a user disabled,
/// deleted or given a new password (by `camloop user`, beside the running service) reads
/// and calls nothing within this.
pub(crate) const RECHECK_EVERY: Duration = Duration::from_secs(2);

/// The OPC UA sessions' users: the digest of the password hash each signed in with, and
/// those no longer allowed since (disabled, deleted, or the password changed). The stack's
/// session carries only the user name, so the digest is the one of that user's latest
/// sign-in: a sign-in with the new password admits the user's older sessions again.
#[derive(Debug, Default)]
pub(crate) struct SignedIn {
    users: RwLock<HashMap<String, Sha256>>,
    revoked: RwLock<HashSet<String>>,
}

impl SignedIn {
    fn signed_in(&self, name: &str, password_hash: &str) {
        write(&self.users).insert(name.to_string(), hash_digest(password_hash));
        write(&self.revoked).remove(name);
    }

    /// Whether `name` may no longer read or call.
    pub(crate) fn revoked(&self, name: &str) -> bool {
        self.revoked
            .read()
            .unwrap_or_else(|p| p.into_inner())
            .contains(name)
    }

    /// Reads each signed-in user's state; a store that cannot answer changes nothing.
    async fn recheck(&self, store: &Store) {
        let users: Vec<(String, Sha256)> = self
            .users
            .read()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .map(|(n, d)| (n.clone(), *d))
            .collect();
        for (name, digest) in users {
            let allowed = match store.user(&name).await {
                Ok(Some(u)) => u.disabled_at.is_none() && hash_digest(&u.password_hash) == digest,
                Ok(None) => false,
                Err(_) => continue,
            };
            let mut revoked = write(&self.revoked);
            if allowed {
                revoked.remove(&name);
            } else if revoked.insert(name.clone()) {
                tracing::warn!(user = %name, "OPC UA: the user was disabled, deleted or given a new password: their sessions read and call nothing more");
            }
        }
    }
}

fn write<T>(lock: &RwLock<T>) -> std::sync::RwLockWriteGuard<'_, T> {
    lock.write().unwrap_or_else(|p| p.into_inner())
}

/// Rechecks every [`RECHECK_EVERY`] until the users are dropped (the server stopped).
async fn keep_rechecking(signed_in: Weak<SignedIn>, service: Arc<dyn Service>) {
    let mut tick = tokio::time::interval(RECHECK_EVERY);
    loop {
        tick.tick().await;
        let Some(signed_in) = signed_in.upgrade() else {
            return;
        };
        if let Some(s) = service.store().await {
            signed_in.recheck(&s).await;
        }
    }
}

#[async_trait]
impl AuthManager for Users {
    async fn authenticate_anonymous_token(&self, _endpoint: &ServerEndpoint) -> Result<(), Error> {
        match self.anonymous_read {
            true => Ok(()),
            false => Err(Error::new(
                StatusCode::BadIdentityTokenRejected,
                "anonymous access is not enabled (opcua.anonymous_read)",
            )),
        }
    }

    async fn authenticate_username_identity_token(
        &self,
        endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        let rejected =
            |why: &str| Error::new(StatusCode::BadIdentityTokenRejected, why.to_string());
        // The stack does not say whether the password came encrypted: on an unsecured
        // endpoint it may have come in clear, so a user name is refused there whatever it
        // carries (no user-name policy is offered there either).
        if !user_names_allowed(endpoint) {
            return Err(rejected(
                "user names are refused on an unsecured endpoint: use Basic256Sha256 SignAndEncrypt",
            ));
        }
        let signed_in = self
            .service
            .sign_in(username, password.get())
            .await
            .map_err(|e| Error::new(StatusCode::BadInternalError, e.to_string()))?;
        match signed_in {
            SignIn::Ok(user) => {
                tracing::info!(user = %user.name, role = %user.role, "OPC UA: user signed in");
                self.signed_in.signed_in(&user.name, &user.password_hash);
                Ok(UserToken(user.name))
            }
            SignIn::Wrong => Err(rejected("wrong user name or password")),
            SignIn::Refused(why) => Err(rejected(&why)),
        }
    }

    /// Nothing for a user no longer allowed (see [`SignedIn`]): reads of values fail.
    fn effective_user_access_level(
        &self,
        token: &UserToken,
        user_access_level: AccessLevel,
        _node_id: &NodeId,
    ) -> AccessLevel {
        match !token.is_anonymous() && self.signed_in.revoked(&token.0) {
            true => AccessLevel::empty(),
            false => user_access_level,
        }
    }

    fn is_user_executable(&self, token: &UserToken, _method_id: &NodeId) -> bool {
        token.is_anonymous() || !self.signed_in.revoked(&token.0)
    }

    fn user_token_policies(&self, endpoint: &ServerEndpoint) -> Vec<UserTokenPolicy> {
        let mut policies = Vec::new();
        if user_names_allowed(endpoint) {
            policies.push(UserTokenPolicy {
                policy_id: user_pass_security_policy_id(endpoint),
                token_type: UserTokenType::UserName,
                issued_token_type: UAString::null(),
                issuer_endpoint_url: UAString::null(),
                security_policy_uri: user_pass_security_policy_uri(endpoint),
            });
        }
        if self.anonymous_read {
            policies.push(UserTokenPolicy {
                policy_id: UAString::from("anonymous"),
                token_type: UserTokenType::Anonymous,
                issued_token_type: UAString::null(),
                issuer_endpoint_url: UAString::null(),
                security_policy_uri: UAString::null(),
            });
        }
        policies
    }
}

/// Audits a write refused `BadUserAccessDenied` (anonymous, a role too low, a user disabled
/// since sign-in), within the trail's budget for refusals of OPC UA clients.
pub(crate) async fn refused_write(
    service: &dyn Service,
    user: Option<&str>,
    machine: &str,
    method: &str,
) {
    let entry = AuditEntry {
        at: jiff::Timestamp::now(),
        actor: user.unwrap_or("anonymous").to_string(),
        // The role the user held is not known here (it may be why): the lowest.
        role: Role::Viewer,
        client: OPCUA_CLIENT.to_string(),
        action: "refused".into(),
        machine: Some(camloop_core::names::quote(machine)),
        feature: None,
        version: None,
        before: None,
        after: None,
        result: AuditResult::Refused,
        reason: format!("OPC UA {method}: BadUserAccessDenied"),
    };
    service.audit_refusal(entry).await;
}

/// The digest the signed-in users are remembered by: of the password hash, never the hash.
fn hash_digest(password_hash: &str) -> Sha256 {
    Sha256::of(password_hash.as_bytes())
}

/// User names only where the channel itself signs and encrypts: there the password, clear
/// or not inside the token, never crosses the network in clear.
fn user_names_allowed(endpoint: &ServerEndpoint) -> bool {
    endpoint.security_policy() != SecurityPolicy::None
        && endpoint.message_security_mode() == MessageSecurityMode::SignAndEncrypt
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn user_names_only_on_a_signed_and_encrypted_endpoint() {
        let secure = ServerEndpoint::new_basic256sha256_sign_encrypt("/", &[]);
        let mut none = ServerEndpoint::new_none("/", &[]);
        none.password_security_policy = Some("Basic256Sha256".into());
        assert!(user_names_allowed(&secure));
        assert!(!user_names_allowed(&none));
        let sign_only = ServerEndpoint {
            security_mode: "Sign".into(),
            ..secure.clone()
        };
        assert!(!user_names_allowed(&sign_only));
    }
}
