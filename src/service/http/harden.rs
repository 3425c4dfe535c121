//! What every response of the listener goes through, whatever the route:
//! - the `Host` allow-list: a request naming a host the service does not answer to is
//!   refused with 421 before any handler runs, so a web page whose name was re-pointed at
//!   this address (DNS rebinding) cannot read the API from a browser;
//! - the security headers: a CSP that allows only the service's own scripts, styles and
//!   images and no framing, `nosniff`, `X-Frame-Options: DENY`, `Referrer-Policy:
//!   no-referrer`, HSTS under TLS, and `Cache-Control: no-store` on every response whose
//!   handler did not choose its own caching (the API, the pages, the programs);
//! - the per-client connection cap ([`PerClient`]), used by the accept loop.

use super::api::ApiError;
use crate::service::http::ApiCode;
use axum::Router;
use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, Mutex};

/// The dashboard is one script and one stylesheet of its own and inline SVG: nothing else
/// may load, run or frame it.
pub const CONTENT_SECURITY_POLICY: &str = "default-src 'self'; script-src 'self'; \
     style-src 'self'; img-src 'self'; object-src 'none'; base-uri 'none'; \
     form-action 'self'; frame-ancestors 'none'";

/// HSTS under TLS: one year.
const HSTS: &str = "max-age=31536000";

/// The `Host` names the service answers to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HostAllowList {
    /// Lower-case host names or addresses (IPv6 in brackets), each with the port it must
    /// come with, `None`: none or the listen port.
    entries: Vec<(String, Option<u16>)>,
    port: u16,
}

impl HostAllowList {
    /// The listen address, `localhost`, `127.0.0.1` and `[::1]`, and the `extra` names of
    /// `http.allowed_hosts` (each with or without a port).
    pub fn new(listen: SocketAddr, extra: &[String]) -> Self {
        let mut entries: Vec<(String, Option<u16>)> = ["localhost", "127.0.0.1", "[::1]"]
            .iter()
            .map(|h| (h.to_string(), None))
            .collect();
        if !listen.ip().is_unspecified() {
            entries.push((host_text(listen.ip()), None));
        }
        for e in extra {
            let lower = e.to_ascii_lowercase();
            let (host, port) = split_host(&lower);
            entries.push((host.to_string(), port));
        }
        Self {
            entries,
            port: listen.port(),
        }
    }

    /// Whether a request's `Host` value names this service.
    pub fn allows(&self, host: &str) -> bool {
        let lower = host.to_ascii_lowercase();
        let (name, port) = split_host(&lower);
        self.entries.iter().any(|(h, p)| {
            *h == name
                && match (p, port) {
                    (Some(want), got) => got == Some(*want),
                    (None, got) => got.is_none() || got == Some(self.port),
                }
        })
    }
}

/// An address as it appears in a `Host` header.
fn host_text(ip: IpAddr) -> String {
    match ip {
        IpAddr::V4(v4) => v4.to_string(),
        IpAddr::V6(v6) => format!("[{v6}]"),
    }
}

/// `name:port` → (name, Some(port)); `[v6]:port` keeps its brackets; no port: `None`.
fn split_host(host: &str) -> (&str, Option<u16>) {
    let cut = match host.strip_prefix('[') {
        Some(rest) => rest.find(']').map(|i| i + 2),
        None => host.rfind(':'),
    };
    match cut {
        Some(i) if host[i..].starts_with(':') => match host[i + 1..].parse() {
            Ok(port) => (&host[..i], Some(port)),
            Err(_) => (host, Some(0)),
        },
        _ => (host, None),
    }
}

/// The listener's policy for every response.
#[derive(Debug, Clone)]
pub struct Policy {
    pub hosts: HostAllowList,
    /// TLS is on: add HSTS.
    pub tls: bool,
}

/// `app` behind the host check and the security headers.
pub fn apply(app: Router, policy: Policy) -> Router {
    app.layer(middleware::from_fn_with_state(Arc::new(policy), guard))
}

async fn guard(State(policy): State<Arc<Policy>>, mut req: Request, next: Next) -> Response {
    // Sessions are bound to the listener they were made on (see `session.rs`).
    req.extensions_mut()
        .insert(super::session::Listener(policy.hosts.port));
    let host = req
        .headers()
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .or_else(|| req.uri().authority().map(|a| a.as_str()));
    let mut response = match host {
        Some(h) if policy.hosts.allows(h) => next.run(req).await,
        other => {
            let shown = crate::names::quote(other.unwrap_or(""));
            ApiError::new(
                ApiCode::HostNotAllowed,
                format!("this service does not answer to host `{shown}` (http.allowed_hosts)"),
            )
            .into_response()
        }
    };
    security_headers(response.headers_mut(), policy.tls);
    response
}

fn security_headers(h: &mut HeaderMap, tls: bool) {
    let set = |h: &mut HeaderMap, name, value: &'static str| {
        h.insert(name, HeaderValue::from_static(value));
    };
    set(h, header::CONTENT_SECURITY_POLICY, CONTENT_SECURITY_POLICY);
    set(h, header::X_CONTENT_TYPE_OPTIONS, "nosniff");
    set(h, header::X_FRAME_OPTIONS, "DENY");
    set(h, header::REFERRER_POLICY, "no-referrer");
    if !h.contains_key(header::CACHE_CONTROL) {
        set(h, header::CACHE_CONTROL, "no-store");
    }
    if tls {
        set(h, header::STRICT_TRANSPORT_SECURITY, HSTS);
    }
}

/// Connections open per client address, each at most `max`: the accept loop closes a
/// client's connection beyond it at once, so one client holding its cap leaves the rest of
/// the global slots to everyone else.
#[derive(Debug)]
pub(crate) struct PerClient {
    max: usize,
    open: Mutex<HashMap<IpAddr, usize>>,
}

/// One admitted connection; its count goes when it is dropped.
#[derive(Debug)]
pub(crate) struct ClientSlot {
    table: Arc<PerClient>,
    ip: IpAddr,
}

impl PerClient {
    pub fn new(max: usize) -> Arc<Self> {
        Arc::new(Self {
            max: max.max(1),
            open: Mutex::default(),
        })
    }

    /// A slot for `ip`, or `None` when it holds its cap already.
    pub(crate) fn admit(self: &Arc<Self>, ip: IpAddr) -> Option<ClientSlot> {
        let mut open = self.open.lock().unwrap_or_else(|p| p.into_inner());
        let n = open.entry(ip).or_insert(0);
        if *n >= self.max {
            return None;
        }
        *n += 1;
        Some(ClientSlot {
            table: self.clone(),
            ip,
        })
    }
}

impl Drop for ClientSlot {
    fn drop(&mut self) {
        let mut open = self.table.open.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(n) = open.get_mut(&self.ip) {
            *n -= 1;
            if *n == 0 {
                open.remove(&self.ip);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_allow_list_takes_the_listen_address_localhost_and_the_configured_names() {
        let listen: SocketAddr = "192.168.4.7:8080".parse().unwrap();
        let list = HostAllowList::new(listen, &["camloop.plant".into(), "gw:443".into()]);
        for ok in [
            "192.168.4.7:8080",
            "192.168.4.7",
            "localhost",
            "LOCALHOST:8080",
            "127.0.0.1:8080",
            "[::1]:8080",
            "camloop.plant",
            "camloop.plant:8080",
            "gw:443",
        ] {
            assert!(list.allows(ok), "{ok}");
        }
        for refused in [
            "attacker.example",
            "attacker.example:8080",
            "localhost:9999",
            "localhost.attacker.example",
            "gw",
            "gw:8080",
            "camloop.plant:x",
            "",
        ] {
            assert!(!list.allows(refused), "{refused}");
        }
        let any: SocketAddr = "0.0.0.0:8080".parse().unwrap();
        assert!(!HostAllowList::new(any, &[]).allows("0.0.0.0:8080"));
    }

    #[test]
    fn a_client_gets_its_cap_and_its_slots_come_back() {
        let table = PerClient::new(2);
        let a: IpAddr = "10.0.0.1".parse().unwrap();
        let b: IpAddr = "10.0.0.2".parse().unwrap();
        let first = table.admit(a).unwrap();
        let _second = table.admit(a).unwrap();
        assert!(table.admit(a).is_none());
        assert!(table.admit(b).is_some());
        drop(first);
        assert!(table.admit(a).is_some());
    }
}
