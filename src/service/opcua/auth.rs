//! Who may do what over OPC UA: users are camloop's users (argon2 hashes in the store),
//! checked as the HTTP sign-in checks them (lockout, bounded hashing), and only on a
//! signed and encrypted endpoint; anonymous clients are admitted only when
//! `opcua.anonymous_read` allows it, and may then only browse, read and subscribe.

use std::net::{IpAddr, Ipv6Addr};

use async_trait::async_trait;
use opcua::crypto::SecurityPolicy;
use opcua::server::ServerEndpoint;
use opcua::server::authenticator::{
    AuthManager, Password, UserToken, user_pass_security_policy_id, user_pass_security_policy_uri,
};
use opcua::types::{
    Error, MessageSecurityMode, StatusCode, UAString, UserTokenPolicy, UserTokenType,
};

use crate::auth::Client;
use crate::service::app::AppState;
use crate::service::command;
use crate::service::http;
use crate::store::{AuditEntry, AuditResult, Role};

/// The client address OPC UA failures and writes are audited under: the OPC UA stack does
/// not tell the server its peer's address, so every OPC UA client shares this one (distinct
/// from the HTTP side's unknown address, 0.0.0.0). The lockout counts them apart from every
/// HTTP client (`crate::auth::Client::OpcUa`).
pub(crate) const OPCUA_CLIENT: IpAddr = IpAddr::V6(Ipv6Addr::UNSPECIFIED);

/// Checks identity tokens against camloop's users.
pub(crate) struct Users {
    pub(crate) app: AppState,
    pub(crate) anonymous_read: bool,
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
        let signed_in = http::password_sign_in(
            &self.app,
            username,
            password.get(),
            Client::OpcUa,
            OPCUA_CLIENT,
        )
        .await
        .map_err(|e| Error::new(StatusCode::BadInternalError, e.message().to_string()))?;
        match signed_in {
            http::SignIn::Ok(user) => {
                tracing::info!(user = %user.name, role = %user.role, "OPC UA: user signed in");
                Ok(UserToken(user.name))
            }
            http::SignIn::Wrong => Err(rejected("wrong user name or password")),
            http::SignIn::Refused(e) => Err(rejected(e.message())),
        }
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
    w: command::Writes<'_>,
    user: Option<&str>,
    machine: &str,
    method: &str,
) {
    let entry = AuditEntry {
        at_ms: crate::clock::now(),
        actor: user.unwrap_or("anonymous").to_string(),
        // The role the user held is not known here (it may be why): the lowest.
        role: Role::Viewer,
        client: OPCUA_CLIENT.to_string(),
        action: "refused".into(),
        machine: Some(crate::names::quote(machine)),
        feature: None,
        version: None,
        before: None,
        after: None,
        result: AuditResult::Refused,
        reason: format!("OPC UA {method}: BadUserAccessDenied"),
    };
    match w.audit_seal.within_refusal_budget(entry) {
        Some(entry) => command::record_audit(w, entry).await,
        None => w
            .metrics
            .update_access(|a| a.refusals_unrecorded_total += 1),
    }
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
