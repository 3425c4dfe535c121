//! Who may call what. [`ROUTES`] (in `route_roles.rs`) is the one table of every route with
//! the role it needs;
//! [`guard`] (a layer on the whole router, after routing) finds the caller's
//! [`Principal`] from the request's headers alone (a bearer token, a dashboard session, or
//! nobody), looks the matched route up in the table and lets the request through or answers
//! 401 (who are you?), 403 (not allowed, or a missing CSRF token), 429 (locked out). A route
//! missing from the table is refused for everyone (500 `route_without_role`), so a new
//! route cannot be open by mistake; a path in the table called with another method gets
//! 405. Every refused write is audited (`refused`, within the trail's budget for refusals
//! of one client). `tests/it/access_matrix.rs` walks the same table.

use super::AppState;
use super::api::ApiError;
use super::session::{Binding, Listener, cookie, session_cookie_name};
use crate::auth::{Hasher, Lockout, effective_role, token_digest};
use crate::config::Secret;
use crate::service::http::ApiCode;
use crate::store::{AuditEntry, AuditResult, Role};
use axum::extract::{ConnectInfo, FromRequestParts, MatchedPath, Request, State};
use axum::http::request::Parts;
use axum::http::{HeaderMap, Method, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Redirect, Response};
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use tracing::warn;

pub use super::route_roles::{Kind, Need, ROUTES, RouteRule, rule_for};

/// The access settings and the in-memory state of sign-ins (sessions, lockout).
#[derive(Debug)]
pub struct AuthState {
    /// The deprecated shared token (`CAMLOOP_API_TOKEN`), acting as `admin`.
    pub legacy_token: Option<Secret>,
    /// Anonymous clients read as `viewer`.
    pub anonymous_read: bool,
    /// Session cookies carry `Secure` (set when the listener serves TLS).
    pub secure_cookie: bool,
    /// How long a session lasts after sign-in.
    pub session: jiff::SignedDuration,
    pub sessions: super::session::Sessions,
    /// The sign-in form's one-time values, issued by `GET /signin`.
    pub signin_nonces: crate::auth::Nonces,
    pub lockout: Lockout,
    /// Where password hashes run: one per core at a time.
    pub hasher: Hasher,
    /// The audit trail's key and head (see `crate::audit_seal`).
    pub audit_seal: std::sync::Arc<crate::audit_seal::AuditSeal>,
}

impl AuthState {
    /// Settings with the defaults for the rest: 8-hour sessions, no `Secure` cookie, an
    /// audit key in memory only (the service sets the one in its var folder).
    pub fn new(legacy_token: Option<Secret>, anonymous_read: bool) -> Self {
        Self {
            legacy_token,
            anonymous_read,
            secure_cookie: false,
            session: jiff::SignedDuration::from_hours(8),
            sessions: Default::default(),
            signin_nonces: Default::default(),
            lockout: Lockout::default(),
            hasher: Hasher::default(),
            audit_seal: std::sync::Arc::new(crate::audit_seal::AuditSeal::ephemeral()),
        }
    }
}

/// How the caller proved who it is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Via {
    Anonymous,
    /// The deprecated shared token.
    SharedToken,
    Token,
    /// A dashboard session, with its CSRF token.
    Session {
        csrf: String,
        key: String,
    },
}

/// Who is calling, put into the request by [`guard`]; handlers take it to audit their
/// writes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Principal {
    /// User name, `anonymous` or `api-token`.
    pub actor: String,
    /// `None`: anonymous without anonymous reading.
    pub role: Option<Role>,
    pub address: IpAddr,
    pub via: Via,
}

impl Principal {
    /// The client address as the audit trail shows it.
    pub fn client(&self) -> String {
        self.address.to_string()
    }

    /// This caller as the service's write path knows callers.
    pub(crate) fn caller(&self) -> crate::service::command::Caller {
        crate::service::command::Caller {
            actor: self.actor.clone(),
            role: self.role,
            client: self.client(),
        }
    }

    /// An audit entry by this caller now; the caller fills the target and change.
    pub fn audit(&self, action: &str, result: AuditResult, reason: String) -> AuditEntry {
        AuditEntry {
            at: crate::clock::now(),
            actor: self.actor.clone(),
            role: self.role.unwrap_or(Role::Viewer),
            client: self.client(),
            action: action.to_string(),
            machine: None,
            feature: None,
            version: None,
            before: None,
            after: None,
            result,
            reason,
        }
    }
}

impl<S: Send + Sync> FromRequestParts<S> for Principal {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        parts
            .extensions
            .get::<Principal>()
            .cloned()
            .ok_or(ApiError::new(
                ApiCode::Unauthorized,
                "no caller identified".into(),
            ))
    }
}

/// Proof that the access layer let the request through (its role checked against
/// [`ROUTES`]), for handlers that need no more than that.
#[derive(Debug, Clone, Copy)]
pub struct Authorized;

impl<S: Send + Sync> FromRequestParts<S> for Authorized {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ApiError> {
        Principal::from_request_parts(parts, state)
            .await
            .map(|_| Authorized)
    }
}

/// The client's address, from the listener (unknown: 0.0.0.0, counted together).
pub(crate) fn client_address(req_extensions: &axum::http::Extensions) -> IpAddr {
    req_extensions
        .get::<ConnectInfo<SocketAddr>>()
        .map_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED), |c| c.0.ip())
}

/// The layer: identify, look the route up, check the role (and a session's CSRF token).
/// Every refused write is audited (within the trail's budget for refusals): the access
/// layer's own 401/403, and a handler's 4xx that the write path did not audit itself.
pub async fn guard(State(app): State<AppState>, mut req: Request, next: Next) -> Response {
    let path = req
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_owned());
    let Some(rule) = path.as_deref().and_then(|p| rule_for(req.method(), p)) else {
        return no_rule(path.as_deref(), req.method());
    };
    let address = client_address(req.extensions());
    let at = Binding {
        client: address,
        listener: req.extensions().get::<Listener>().map(|l| l.0),
    };
    let principal = match identify(&app, req.headers(), at).await {
        Ok(p) => p,
        Err(e) => return e.into_response(),
    };
    let write = !matches!(*req.method(), Method::GET | Method::HEAD);
    let target = format!("{} {}", req.method(), short(req.uri().path()));
    if let Via::Session { csrf, .. } = &principal.via
        && write
        && rule.kind != Kind::Form
    {
        let given = req.headers().get("x-csrf-token").map(|v| v.as_bytes());
        if !given.is_some_and(|g| same_secret(g, csrf.as_bytes())) {
            csrf_refused(&app, &principal, path.as_deref().unwrap_or("")).await;
            return ApiError::new(
                ApiCode::CsrfMismatch,
                "the request did not carry this session's CSRF token".into(),
            )
            .into_response();
        }
    }
    if let Some(refusal) = role_refusal(&principal, rule, req.uri().path()) {
        let response = refusal.into_response();
        if write {
            refused_write(&app, &principal, &target, answer_of(&response)).await;
        }
        return response;
    }
    req.extensions_mut().insert(principal.clone());
    let response = next.run(req).await;
    if write && rule.path != "/signin" && handler_refusal_unaudited(&response) {
        refused_write(&app, &principal, &target, answer_of(&response)).await;
    }
    response
}

/// The answer to a route missing from [`ROUTES`]: 405 when the path has rows for other
/// methods (a wrong method is the client's mistake), else 500 `route_without_role`.
fn no_rule(path: Option<&str>, method: &Method) -> Response {
    let allowed: Vec<&str> = ROUTES
        .iter()
        .filter(|r| Some(r.path) == path)
        .map(|r| r.method)
        .collect();
    if allowed.is_empty() {
        return ApiError::new(
            ApiCode::RouteWithoutRole,
            "this route has no entry in the access table: refused for everyone".into(),
        )
        .into_response();
    }
    let allow = allowed.join(", ");
    let mut r = ApiError::new(
        ApiCode::MethodNotAllowed,
        format!(
            "{} is not allowed here; allowed: {allow}",
            short(method.as_str())
        ),
    )
    .into_response();
    if let Ok(v) = header::HeaderValue::try_from(allow) {
        r.headers_mut().insert(header::ALLOW, v);
    }
    r
}

/// Why `p` may not call the route of `rule` (at `path`), if it may not: 403 for a known
/// caller below the role, a redirect to the sign-in page for an anonymous page visit, 401
/// for the rest.
fn role_refusal(p: &Principal, rule: &RouteRule, path: &str) -> Option<Refusal> {
    let Need::Role(needed) = rule.need else {
        return None;
    };
    match p.role {
        Some(role) if role >= needed => None,
        Some(role) if p.via != Via::Anonymous => Some(Refusal::Error(ApiError::new(
            ApiCode::Forbidden,
            format!("this needs the role {needed}; {} has {role}", p.actor),
        ))),
        _ if rule.kind == Kind::Page => Some(Refusal::SignIn(format!(
            "/signin?next={}",
            encode_path(path)
        ))),
        _ => Some(Refusal::Unauthorized(needed)),
    }
}

enum Refusal {
    Error(ApiError),
    SignIn(String),
    Unauthorized(Role),
}

impl IntoResponse for Refusal {
    fn into_response(self) -> Response {
        match self {
            Refusal::Error(e) => e.into_response(),
            Refusal::SignIn(to) => Redirect::to(&to).into_response(),
            Refusal::Unauthorized(needed) => unauthorized(needed),
        }
    }
}

/// A handler's answer is a refusal the write path has not audited: a 4xx other than the
/// write path's own refusals (which it audits with their before and after) and other than
/// 401/429 (the sign-in checks audit those).
fn handler_refusal_unaudited(response: &Response) -> bool {
    let status = response.status();
    if !status.is_client_error() || status.as_u16() == 401 || status.as_u16() == 429 {
        return false;
    }
    !matches!(
        response.extensions().get::<ApiCode>(),
        Some(
            ApiCode::RollbackRefused
                | ApiCode::FreezeRefused
                | ApiCode::DressingRefused
                | ApiCode::TableVersionNotFound
                | ApiCode::EventNotFound
        )
    )
}

/// What an answer says of a refusal: its status and code.
fn answer_of(response: &Response) -> (u16, &'static str) {
    let code = response
        .extensions()
        .get::<ApiCode>()
        .map_or("-", |c| c.as_str());
    (response.status().as_u16(), code)
}

/// Audits a refused write: who, what (`POST /path`) and the answer's status and code.
async fn refused_write(app: &AppState, p: &Principal, target: &str, answer: (u16, &str)) {
    let (status, code) = answer;
    warn!(user = %p.actor, client = %p.address, target, status, code, "write refused");
    let reason = format!("{target}: {status} {code}");
    let entry = p.audit("refused", AuditResult::Refused, reason);
    super::audit::record_refusal(app, entry).await;
}

fn unauthorized(needed: Role) -> Response {
    let mut r = ApiError::new(
        ApiCode::Unauthorized,
        format!("this needs the role {needed}: send Authorization: Bearer <token>, or sign in"),
    )
    .into_response();
    r.headers_mut().insert(
        header::WWW_AUTHENTICATE,
        header::HeaderValue::from_static("Bearer"),
    );
    r
}

/// Keeps a path safe inside a query: letters, digits and `/-_.` as they are, the rest
/// percent-encoded.
fn encode_path(path: &str) -> String {
    path.bytes()
        .map(|b| match b {
            b'a'..=b'z' | b'A'..=b'Z' | b'0'..=b'9' | b'/' | b'-' | b'_' | b'.' => {
                char::from(b).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

/// The caller: by bearer token, else by session cookie, else anonymous.
async fn identify(app: &AppState, headers: &HeaderMap, at: Binding) -> Result<Principal, ApiError> {
    let auth = &app.auth;
    let address = at.client;
    if let Some(value) = headers.get(header::AUTHORIZATION) {
        let token = value
            .as_bytes()
            .strip_prefix(b"Bearer ")
            .unwrap_or_default();
        return bearer(app, std::str::from_utf8(token).unwrap_or(""), address).await;
    }
    if let Some(key) = cookie(headers, session_cookie_name(auth.secure_cookie)) {
        let now = crate::clock::now();
        if let Some(s) = auth.sessions.get(&key, now, at) {
            // The user may have been disabled, or their password changed, since sign-in (by
            // the command line): either ends the session.
            let store = super::routes::store(app).await?;
            if let Some(user) = store.user(&s.user).await?
                && user.disabled_at.is_none()
                && token_digest(&user.password_hash) == s.password
            {
                return Ok(Principal {
                    actor: user.name,
                    role: Some(user.role),
                    address,
                    via: Via::Session { csrf: s.csrf, key },
                });
            }
            auth.sessions.remove(&key);
        }
    }
    Ok(Principal {
        actor: "anonymous".into(),
        role: auth.anonymous_read.then_some(Role::Viewer),
        address,
        via: Via::Anonymous,
    })
}

/// A bearer token: the shared one, or a user's token from the store. A valid token is
/// never refused for failures; wrong ones count per address (see `crate::auth::Lockout`).
async fn bearer(app: &AppState, token: &str, address: IpAddr) -> Result<Principal, ApiError> {
    let auth = &app.auth;
    let now = crate::clock::now();
    if let Some(shared) = &auth.legacy_token
        && same_secret(token.as_bytes(), shared.expose().as_bytes())
    {
        return Ok(Principal {
            actor: "api-token".into(),
            role: Some(Role::Admin),
            address,
            via: Via::SharedToken,
        });
    }
    let store = match token.is_empty() {
        true => None,
        false => super::routes::store(app).await.ok(),
    };
    let grant = match &store {
        Some(s) => s.token_grant(&token_digest(token)).await?,
        // Not counted as a failure: the token could not be checked.
        None if !token.is_empty() => {
            return Err(ApiError::new(
                ApiCode::Unauthorized,
                "the bearer token cannot be checked while the database is unreachable".into(),
            ));
        }
        None => None,
    };
    let why = match &grant {
        None => "unknown token",
        Some(g) if g.revoked_at.is_some() => "revoked token",
        Some(g) if g.expires_at <= now => "expired token",
        Some(g) if g.user_disabled_at.is_some() => "the token's user is disabled",
        Some(g) => {
            return Ok(Principal {
                actor: g.user.clone(),
                role: Some(effective_role(g.user_role, g.role)),
                address,
                via: Via::Token,
            });
        }
    };
    let user = grant.as_ref().map(|g| g.user.as_str());
    if let Some(until) = auth.lockout.token_locked_until(address, now) {
        return Err(locked(app, user, address, until));
    }
    let counted = auth.lockout.fail_token(address, now);
    crate::service::sign_in::record_failure(app, "token", user, address, why, counted).await;
    Err(ApiError::new(
        ApiCode::Unauthorized,
        "the bearer token is not valid".into(),
    ))
}

/// A refusal while locked out: counted and logged, not audited again (the lock was).
pub(crate) fn locked(
    app: &AppState,
    user: Option<&str>,
    address: IpAddr,
    until: jiff::Timestamp,
) -> ApiError {
    let r = crate::service::sign_in::locked_out(app, user, address, until);
    ApiError::new(ApiCode::LockedOut, r.to_string()).retry_after(r.retry_after_s())
}

async fn csrf_refused(app: &AppState, p: &Principal, path: &str) {
    warn!(user = %p.actor, client = %p.address, path, "refused: no CSRF token");
    app.metrics
        .update_access(|a| *a.failures.entry("csrf").or_default() += 1);
    let reason = format!(
        "a write to {} without this session's CSRF token",
        short(path)
    );
    super::audit::record_refusal(app, p.audit("csrf", AuditResult::Refused, reason)).await;
}

/// At most 64 characters of something a client sent.
pub(super) fn short(text: &str) -> String {
    text.chars().take(64).collect()
}

/// Compares the SHA-256 digests of both in constant time: neither the position of the first
/// difference nor the secret's length shows in the time taken.
pub(super) fn same_secret(given: &[u8], expected: &[u8]) -> bool {
    use sha2::{Digest, Sha256};
    let (a, b) = (Sha256::digest(given), Sha256::digest(expected));
    a.iter()
        .zip(b.iter())
        .fold(0u8, |acc, (x, y)| acc | (x ^ y))
        == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn secrets_compare_equal_only_when_equal() {
        assert!(same_secret(b"let-me-write", b"let-me-write"));
        assert!(!same_secret(b"let-me-writ", b"let-me-write"));
        assert!(!same_secret(b"", b"let-me-write"));
    }
}
