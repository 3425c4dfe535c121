//! Dashboard sign-in: the sign-in page, sessions, sign-out.
//!
//! - A session is a random key in an `HttpOnly`, `SameSite=Strict` cookie (under TLS named
//!   `__Host-camloop_session`, with `Secure`, so no other origin can set or shadow it); the
//!   service keeps only the key's SHA-256, the user, a CSRF token, the client address and
//!   the listener's port, in memory, for `auth.session_minutes` (a restart signs everyone
//!   out). A session ends when its user is disabled or their password changes, and is not
//!   honoured from another client address or on another listener: a key replayed by a
//!   service on another port of this host (cookies ignore ports) from elsewhere is refused.
//! - Every write a session makes must carry its CSRF token (`X-CSRF-Token`, which the page's
//!   script reads from `GET /session`; a form field on the sign-out form). A cross-site
//!   page can make the browser send the cookie (a sibling port is the same site) but cannot
//!   read the token.
//! - The sign-in form carries a one-time value that must equal a cookie set with the form
//!   (double submit) and be one this service issued to that client address and has not
//!   taken back yet (`crate::auth::Nonces`), so no other page (another site, or another port
//!   of this host, which can set the cookie) can sign a browser in as someone else.
//! - Failures count towards the lockout (`crate::auth::Lockout`, per user and address) and
//!   are audited; the hashes run on the bounded `crate::auth::Hasher`.

use super::AppState;
use super::access::{Principal, Via, client_address, same_secret};
use super::api::ApiError;
use crate::auth::{Client, random_hex, token_digest};
use crate::service::http::ApiCode;
use crate::store::AuditResult;
use axum::extract::FromRequestParts;
use axum::extract::{FromRequest, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{Html, IntoResponse, Redirect, Response};
use axum::{Form, Json};
use std::collections::HashMap;
use std::sync::Mutex;
use tracing::warn;

/// The session cookie's name without TLS.
pub(crate) const SESSION_COOKIE: &str = "camloop_session";
/// The session cookie's name under TLS: the `__Host-` prefix makes the browser take it only
/// from a secure origin, with `Path=/` and no `Domain`, so no other host name or plain-HTTP
/// page can set or shadow it.
pub(crate) const SESSION_COOKIE_TLS: &str = "__Host-camloop_session";
/// The sign-in form's double-submit cookie.
const SIGNIN_COOKIE: &str = "camloop_signin";
/// At most this many sessions live at once; the oldest go first.
const MAX_SESSIONS: usize = 10_000;

/// A signed-in browser.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Session {
    pub user: String,
    /// The SHA-256 of the user's password hash at sign-in: a password changed since (by
    /// `camloop user passwd`) ends the session.
    pub password: crate::digest::Sha256,
    pub csrf: String,
    pub expires_at: jiff::Timestamp,
    /// Where the session was made: it is honoured only from this address, on this listener.
    pub bound: Binding,
}

/// The client address and the listener a session was made at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Binding {
    pub client: std::net::IpAddr,
    /// The listener's port (`None`: not known, as behind no listener in tests).
    pub listener: Option<u16>,
}

/// The port of the listener a request came in on, put into the request by the listener's
/// policy layer (`harden::apply`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Listener(pub u16);

/// The session cookie's name: [`SESSION_COOKIE_TLS`] under TLS.
pub(crate) fn session_cookie_name(tls: bool) -> &'static str {
    if tls {
        SESSION_COOKIE_TLS
    } else {
        SESSION_COOKIE
    }
}

/// Live sessions by the SHA-256 of their key.
#[derive(Debug, Default)]
pub struct Sessions {
    map: Mutex<HashMap<crate::digest::Sha256, Session>>,
}

impl Sessions {
    /// A new session for `user` (whose stored password hash is `password_hash`) until
    /// `expires_at`: its key (for the cookie) and itself.
    pub fn create(
        &self,
        user: &str,
        password_hash: &str,
        expires_at: jiff::Timestamp,
        bound: Binding,
    ) -> Result<(String, Session), ApiError> {
        let random =
            |n| random_hex(n).map_err(|e| ApiError::new(ApiCode::RandomFailed, e.to_string()));
        let key = random(32)?;
        let session = Session {
            user: user.to_string(),
            password: token_digest(password_hash),
            csrf: random(32)?,
            expires_at,
            bound,
        };
        let mut map = self.map.lock().unwrap_or_else(|p| p.into_inner());
        let now = crate::clock::now();
        map.retain(|_, s| s.expires_at > now);
        if map.len() >= MAX_SESSIONS
            && let Some(oldest) = map
                .iter()
                .min_by_key(|(_, s)| s.expires_at)
                .map(|(k, _)| *k)
        {
            map.remove(&oldest);
        }
        map.insert(token_digest(&key), session.clone());
        Ok((key, session))
    }

    /// The live session of `key` at `now`, presented at `at`: a key presented from another
    /// client address or on another listener is not honoured (and the session lives on for
    /// its own browser).
    pub fn get(&self, key: &str, now: jiff::Timestamp, at: Binding) -> Option<Session> {
        let map = self.map.lock().unwrap_or_else(|p| p.into_inner());
        map.get(&token_digest(key))
            .filter(|s| s.expires_at > now && s.bound == at)
            .cloned()
    }

    pub fn remove(&self, key: &str) {
        let mut map = self.map.lock().unwrap_or_else(|p| p.into_inner());
        map.remove(&token_digest(key));
    }
}

/// The value of cookie `name` in the request's `Cookie` headers.
pub fn cookie(headers: &HeaderMap, name: &str) -> Option<String> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|pair| pair.trim().split_once('='))
        .find(|(k, _)| *k == name)
        .map(|(_, v)| v.to_string())
}

/// `now` plus `lasting`, at most jiff's last instant (a configured session length is not
/// bounded by the years jiff holds).
fn until(now: jiff::Timestamp, lasting: jiff::SignedDuration) -> jiff::Timestamp {
    now.saturating_add(lasting).unwrap_or(jiff::Timestamp::MAX)
}

fn set_cookie(app: &AppState, name: &str, value: &str, path: &str, max_age_s: i64) -> String {
    cookie_text(app.auth.secure_cookie, name, value, path, max_age_s)
}

fn cookie_text(secure: bool, name: &str, value: &str, path: &str, max_age_s: i64) -> String {
    let secure = if secure { "; Secure" } else { "" };
    format!("{name}={value}; Path={path}; Max-Age={max_age_s}; HttpOnly; SameSite=Strict{secure}")
}

#[derive(Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct SigninQuery {
    next: Option<String>,
}

/// Where to go after sign-in: a path on this site only.
fn local_path(next: Option<&str>) -> String {
    match next {
        Some(p)
            if p.starts_with('/')
                && !p.starts_with("//")
                && !p.contains('\\')
                && !p.contains(char::is_control)
                && p.len() <= 512 =>
        {
            p.to_string()
        }
        _ => "/".to_string(),
    }
}

/// `GET /signin`: the form, with a fresh double-submit value.
#[utoipa::path(get, path = "/signin", tag = "access", params(SigninQuery), responses((status = 200, description = "the sign-in form", content_type = "text/html")))]
pub(super) async fn signin_page(
    State(app): State<AppState>,
    req: Request,
) -> Result<Response, ApiError> {
    let address = client_address(req.extensions());
    let (mut parts, _) = req.into_parts();
    let super::api::ApiQuery(q) =
        super::api::ApiQuery::<SigninQuery>::from_request_parts(&mut parts, &app).await?;
    signin_form(&app, address, q.next.as_deref(), "", StatusCode::OK)
}

/// The form with a one-time value issued to `address` (see `crate::auth::Nonces`).
fn signin_form(
    app: &AppState,
    address: std::net::IpAddr,
    next: Option<&str>,
    message: &str,
    status: StatusCode,
) -> Result<Response, ApiError> {
    let nonce = app
        .auth
        .signin_nonces
        .issue(address, crate::clock::now())
        .map_err(|e| ApiError::new(ApiCode::RandomFailed, e.to_string()))?;
    let html = super::dashboard::signin_html(&nonce, &local_path(next), message);
    let cookie = set_cookie(app, SIGNIN_COOKIE, &nonce, "/signin", 600);
    Ok((status, [(header::SET_COOKIE, cookie)], Html(html)).into_response())
}

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::ToSchema)]
pub(super) struct SigninForm {
    name: String,
    password: String,
    csrf: String,
    next: Option<String>,
}

/// `POST /signin`: checks the double-submit value, the lockout, then the password.
#[utoipa::path(post, path = "/signin", tag = "access", request_body(content = SigninForm, content_type = "application/x-www-form-urlencoded"), responses((status = 303, description = "signed in: to `next`, with the session cookie"), (status = 200, description = "the form again, saying why not", content_type = "text/html")))]
pub(super) async fn signin(
    State(app): State<AppState>,
    req: Request,
) -> Result<Response, ApiError> {
    let address = client_address(req.extensions());
    let expected = cookie(req.headers(), SIGNIN_COOKIE).unwrap_or_default();
    let listener = req.extensions().get::<Listener>().map(|l| l.0);
    let Form(form) = read_form::<SigninForm>(req, &app).await?;
    // Refused before anything is checked or made: a `Location` cannot carry it.
    if form
        .next
        .as_deref()
        .is_some_and(|n| n.contains(char::is_control))
    {
        return Err(ApiError::new(
            ApiCode::InvalidBody,
            "next: control characters (tab, newline) are not allowed in a path".into(),
        ));
    }
    let now = crate::clock::now();
    let issued = app.auth.signin_nonces.take(&form.csrf, address, now);
    if expected.is_empty()
        || !same_secret(form.csrf.as_bytes(), expected.as_bytes())
        || issued.is_err()
    {
        app.metrics
            .update_access(|a| *a.failures.entry("csrf").or_default() += 1);
        let why = issued.err().map_or(
            "the form's value differs from its cookie".to_string(),
            |e| e.to_string(),
        );
        warn!(client = %address, why, "sign-in refused: CSRF check");
        let p = Principal {
            actor: "anonymous".into(),
            role: None,
            address,
            via: Via::Anonymous,
        };
        let reason = format!("sign-in of {}: {why}", super::access::short(&form.name));
        let entry = p.audit("csrf", AuditResult::Refused, reason);
        super::audit::record_refusal(&app, entry).await;
        let message =
            "The form was not sent from this site's sign-in page (CSRF check). Try again.";
        let next = form.next.as_deref();
        return signin_form(&app, address, next, message, StatusCode::FORBIDDEN);
    }
    let client = Client::Address(address);
    let next = form.next.as_deref();
    let user = match password_sign_in(&app, &form.name, &form.password, client, address).await? {
        Ok(user) => user,
        Err(None) => {
            let message = "Wrong user name or password.";
            return signin_form(&app, address, next, message, StatusCode::UNAUTHORIZED);
        }
        Err(Some(e)) => {
            let message = format!("Locked out: {}.", e.message());
            return signin_form(&app, address, next, &message, e.status());
        }
    };
    let (key, _) = app.auth.sessions.create(
        &user.name,
        &user.password_hash,
        until(now, app.auth.session),
        Binding {
            client: address,
            listener,
        },
    )?;
    let p = Principal {
        actor: user.name.clone(),
        role: Some(user.role),
        address,
        via: Via::Anonymous,
    };
    super::audit::record(&app, p.audit("signin", AuditResult::Ok, "password".into())).await;
    let name = session_cookie_name(app.auth.secure_cookie);
    let cookie = set_cookie(&app, name, &key, "/", app.auth.session.as_secs());
    let clear = set_cookie(&app, SIGNIN_COOKIE, "", "/signin", 0);
    let mut r = Redirect::to(&local_path(form.next.as_deref())).into_response();
    r.headers_mut().append(
        header::SET_COOKIE,
        header::HeaderValue::try_from(cookie).map_err(internal)?,
    );
    r.headers_mut().append(
        header::SET_COOKIE,
        header::HeaderValue::try_from(clear).map_err(internal)?,
    );
    Ok(r)
}

/// A password sign-in through the shared check (`crate::service::sign_in`), its refusals and
/// errors as the API answers them: 429 (locked out, or as many checks in flight as would
/// lock) and 503 (the database, or every hash slot and the queue, busy), with Retry-After.
pub(crate) async fn password_sign_in(
    app: &AppState,
    name: &str,
    password: &str,
    client: Client,
    address: std::net::IpAddr,
) -> Result<Result<crate::store::User, Option<ApiError>>, ApiError> {
    use crate::service::sign_in::{self, SignIn, SignInError};
    match sign_in::password_sign_in(app, name, password, client, address).await {
        Ok(SignIn::Ok(user)) => Ok(Ok(user)),
        Ok(SignIn::Wrong) => Ok(Err(None)),
        Ok(SignIn::Refused(r)) => Ok(Err(Some(
            ApiError::new(ApiCode::LockedOut, r.to_string()).retry_after(r.retry_after_s()),
        ))),
        Err(SignInError::StoreUnavailable) => Err(ApiError::new(
            ApiCode::StoreUnavailable,
            SignInError::StoreUnavailable.to_string(),
        )),
        Err(SignInError::Store(e)) => Err(ApiError::from(e)),
        Err(SignInError::Busy(busy)) => {
            Err(ApiError::new(ApiCode::SigninBusy, busy.to_string()).retry_after(1))
        }
    }
}

fn internal(e: impl std::fmt::Display) -> ApiError {
    ApiError::new(ApiCode::Internal, e.to_string())
}

#[derive(Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::ToSchema)]
pub(super) struct SignoutForm {
    csrf: Option<String>,
}

/// `POST /signout`: ends the session when the form (or the `X-CSRF-Token` header) carries
/// its CSRF token.
#[utoipa::path(post, path = "/signout", tag = "access", request_body(content = SignoutForm, content_type = "application/x-www-form-urlencoded"), responses((status = 303, description = "signed out: to the sign-in page")))]
pub(super) async fn signout(
    State(app): State<AppState>,
    p: Principal,
    req: Request,
) -> Result<Response, ApiError> {
    let header_token = req
        .headers()
        .get("x-csrf-token")
        .and_then(|v| v.to_str().ok())
        .map(str::to_string);
    let Form(form) = read_form::<SignoutForm>(req, &app).await?;
    let Via::Session { csrf, key } = &p.via else {
        return Ok(Redirect::to("/signin").into_response());
    };
    let given = header_token.or(form.csrf).unwrap_or_default();
    if !same_secret(given.as_bytes(), csrf.as_bytes()) {
        app.metrics
            .update_access(|a| *a.failures.entry("csrf").or_default() += 1);
        return Err(ApiError::new(
            ApiCode::CsrfMismatch,
            "sign-out without this session's CSRF token".into(),
        ));
    }
    app.auth.sessions.remove(key);
    super::audit::record(&app, p.audit("signout", AuditResult::Ok, String::new())).await;
    let name = session_cookie_name(app.auth.secure_cookie);
    let clear = set_cookie(&app, name, "", "/", 0);
    Ok(([(header::SET_COOKIE, clear)], Redirect::to("/signin")).into_response())
}

/// `GET /session`: who this browser is, and its CSRF token (same-origin script only: no
/// other site can read the answer).
#[utoipa::path(get, path = "/session", tag = "access", responses((status = 200, description = "who this browser is (`user`, `role`) and its CSRF token (`csrf`), each null when not signed in", content_type = "application/json")))]
pub(super) async fn session(p: Principal) -> Response {
    let csrf = match &p.via {
        Via::Session { csrf, .. } => Some(csrf.clone()),
        _ => None,
    };
    let signed_in = csrf.is_some();
    let body = serde_json::json!({
        "user": signed_in.then_some(&p.actor),
        "role": p.role.map(|r| r.as_str()),
        "csrf": csrf,
    });
    ([(header::CACHE_CONTROL, "no-store")], Json(body)).into_response()
}

/// A urlencoded form body, within the body timeout and size limit of the JSON bodies.
async fn read_form<T: serde::de::DeserializeOwned>(
    req: Request,
    app: &AppState,
) -> Result<Form<T>, ApiError> {
    let (parts, body) = req.into_parts();
    let bytes = super::api::read_body(body, app.body_timeout).await?;
    let req = Request::from_parts(parts, axum::body::Body::from(bytes));
    Form::<T>::from_request(req, app).await.map_err(|r| {
        ApiError::rejected(
            r.status(),
            ApiCode::InvalidBody,
            super::access::short(&r.body_text()),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_local_paths_are_followed_after_sign_in() {
        assert_eq!(
            local_path(Some("/machines/M1/features/IN1")),
            "/machines/M1/features/IN1"
        );
        for bad in [
            "//evil.example/",
            "https://evil.example/",
            "/\\evil",
            "",
            "/a\tb",
            "/a\nb",
        ] {
            assert_eq!(local_path(Some(bad)), "/", "{bad}");
        }
        assert_eq!(local_path(None), "/");
    }

    #[test]
    fn under_tls_the_session_cookie_meets_the_host_prefix_rules() {
        // A browser takes a `__Host-` cookie only with `Secure`, `Path=/` and no `Domain`.
        let name = session_cookie_name(true);
        assert_eq!(name, "__Host-camloop_session");
        let text = cookie_text(true, name, "k", "/", 60);
        assert!(
            text.starts_with("__Host-camloop_session=k; Path=/;"),
            "{text}"
        );
        assert!(
            text.ends_with("; Secure") && !text.contains("Domain"),
            "{text}"
        );
        assert_eq!(session_cookie_name(false), SESSION_COOKIE);
    }

    #[test]
    fn a_session_is_honoured_only_where_it_was_made() {
        let sessions = Sessions::default();
        let now = crate::clock::now();
        let here = Binding {
            client: "127.0.0.1".parse().unwrap(),
            listener: Some(8080),
        };
        let until = now + jiff::SignedDuration::from_hours(1);
        let (key, _) = sessions.create("eng", "hash", until, here).unwrap();
        assert!(sessions.get(&key, now, here).is_some());
        let other_client = Binding {
            client: "127.0.0.2".parse().unwrap(),
            ..here
        };
        let other_listener = Binding {
            listener: Some(8443),
            ..here
        };
        assert!(sessions.get(&key, now, other_client).is_none());
        assert!(sessions.get(&key, now, other_listener).is_none());
        assert!(sessions.get(&key, now, here).is_some(), "still there");
    }

    #[test]
    fn cookies_are_found_by_name() {
        let mut h = HeaderMap::new();
        h.insert(
            header::COOKIE,
            "a=1; camloop_session=abc; b=2".parse().unwrap(),
        );
        assert_eq!(cookie(&h, SESSION_COOKIE).as_deref(), Some("abc"));
        assert_eq!(cookie(&h, "c"), None);
    }
}
