//! Who may do what over OPC UA: users are camloop's users (argon2 hashes in the store),
//! checked with the same lockout as the HTTP sign-in; anonymous clients are admitted only
//! when `opcua.anonymous_read` allows it, and may then only browse, read and subscribe.

use std::net::{IpAddr, Ipv6Addr};

use async_trait::async_trait;
use opcua::server::ServerEndpoint;
use opcua::server::authenticator::{
    AuthManager, Password, UserToken, user_pass_security_policy_id, user_pass_security_policy_uri,
};
use opcua::types::{Error, StatusCode, UAString, UserTokenPolicy, UserTokenType};

use crate::service::http::{self, AppState};

/// The client address OPC UA failures and writes are counted and audited under: the OPC UA
/// stack does not tell the server its peer's address, so every OPC UA client shares this
/// one (distinct from the HTTP side's unknown address, 0.0.0.0).
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
        _endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        let rejected =
            |why: &str| Error::new(StatusCode::BadIdentityTokenRejected, why.to_string());
        let name = crate::auth::UserName::new(username).ok();
        let user_text = name.as_ref().map(crate::auth::UserName::as_str);
        let now = crate::clock::now();
        if let Some(until) = self
            .app
            .auth
            .lockout
            .locked_until(user_text, OPCUA_CLIENT, now)
        {
            let e = http::auth_locked(&self.app, user_text, OPCUA_CLIENT, until);
            return Err(rejected(e.message()));
        }
        let checked = http::check_password(&self.app, name.as_ref(), password.get())
            .await
            .map_err(|e| Error::new(StatusCode::BadInternalError, e.message().to_string()))?;
        match checked {
            Ok(user) => {
                tracing::info!(user = %user.name, role = %user.role, "OPC UA: user signed in");
                Ok(UserToken(user.name))
            }
            Err(why) => {
                http::auth_failed(&self.app, "password", user_text, OPCUA_CLIENT, why).await;
                Err(rejected("wrong user name or password"))
            }
        }
    }

    fn user_token_policies(&self, endpoint: &ServerEndpoint) -> Vec<UserTokenPolicy> {
        let mut policies = vec![UserTokenPolicy {
            policy_id: user_pass_security_policy_id(endpoint),
            token_type: UserTokenType::UserName,
            issued_token_type: UAString::null(),
            issuer_endpoint_url: UAString::null(),
            security_policy_uri: user_pass_security_policy_uri(endpoint),
        }];
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
