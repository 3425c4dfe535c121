//! The `[http]` section: where the API listens, how much it may take of the process, which
//! `Host` names it answers to, TLS, and the start-up rule for network exposure.

use super::{ConfigProblem, Lines};
use serde::Deserialize;
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HttpSection {
    /// Address the API listens on; localhost unless you mean otherwise.
    pub listen: SocketAddr,
    /// Connections served at once; more wait in the kernel's queue until one ends.
    pub max_connections: usize,
    /// Connections one client address may hold at once (default: a quarter of
    /// `max_connections`, at least 1); a client over it has its new connections closed, so
    /// one client cannot hold every slot.
    pub max_connections_per_client: Option<usize>,
    /// A client has this long to send a request's headers (also an idle keep-alive
    /// connection's limit), ms.
    pub header_timeout_ms: u64,
    /// A client has this long to send a request's body once its headers are in, ms.
    pub body_timeout_ms: u64,
    /// `Host` names (with or without a port) the API answers to besides the listen address,
    /// `localhost`, `127.0.0.1` and `[::1]`: a request naming any other host is refused, so a
    /// web page cannot reach the API by DNS rebinding.
    pub allowed_hosts: Vec<String>,
    /// PEM certificate chain; with `tls_key`, the API speaks HTTPS only (reloaded on SIGHUP).
    pub tls_cert: Option<PathBuf>,
    /// PEM private key of `tls_cert`.
    pub tls_key: Option<PathBuf>,
    /// Serve a non-loopback address without TLS anyway (a warning is logged at every start).
    pub allow_insecure_network: bool,
}

impl Default for HttpSection {
    fn default() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 8080)),
            max_connections: 256,
            max_connections_per_client: None,
            header_timeout_ms: 10_000,
            body_timeout_ms: 10_000,
            allowed_hosts: Vec::new(),
            tls_cert: None,
            tls_key: None,
            allow_insecure_network: false,
        }
    }
}

impl HttpSection {
    /// The per-client connection cap in force.
    pub(crate) fn per_client_connections(&self) -> usize {
        self.max_connections_per_client
            .unwrap_or(self.max_connections / 4)
            .clamp(1, self.max_connections.max(1))
    }

    /// TLS is configured (both files given).
    pub fn tls(&self) -> bool {
        self.tls_cert.is_some() && self.tls_key.is_some()
    }

    pub(super) fn problems(&self, lines: &Lines) -> Vec<ConfigProblem> {
        let mut p = Vec::new();
        let mut bad = |key: &str, why: String| {
            p.push(ConfigProblem::at(
                lines.of(&format!("http.{key}")),
                format!("http.{key}{why}"),
            ));
        };
        if !(1..=65_536).contains(&self.max_connections) {
            let n = self.max_connections;
            bad("max_connections", format!(" = {n}: must be 1 to 65536"));
        }
        if let Some(n) = self.max_connections_per_client
            && !(1..=self.max_connections).contains(&n)
        {
            let why = format!(
                " = {n}: must be 1 to max_connections ({})",
                self.max_connections
            );
            bad("max_connections_per_client", why);
        }
        for (key, ms) in [
            ("header_timeout_ms", self.header_timeout_ms),
            ("body_timeout_ms", self.body_timeout_ms),
        ] {
            if !(1..=3_600_000).contains(&ms) {
                bad(key, format!(" = {ms}: must be 1 to 3600000 ms"));
            }
        }
        for host in &self.allowed_hosts {
            let plain = |c: char| c.is_ascii_alphanumeric() || "-.:[]_".contains(c);
            if host.is_empty() || host.len() > 255 || !host.chars().all(plain) {
                let shown = crate::names::quote(host);
                let why =
                    format!(": `{shown}` must be a host name or address, with or without :port");
                bad("allowed_hosts", why);
            }
        }
        if self.tls_cert.is_some() != self.tls_key.is_some() {
            bad("tls_cert", " and http.tls_key: give both or neither".into());
        }
        p
    }
}

/// Why serving this configuration on the network is insecure; empty when it is not. The
/// start-up rule ([`network_exposure`]) refuses a start for any of these unless
/// `allow_insecure_network = true`.
pub(crate) fn insecure_network_reasons(http: &HttpSection, anonymous_read: bool) -> Vec<String> {
    let mut reasons = Vec::new();
    if !http.listen.ip().is_loopback() && !http.tls() {
        reasons.push(format!(
            "http.listen = {} is not a loopback address and TLS is off (http.tls_cert, http.tls_key)",
            http.listen
        ));
    }
    if !http.listen.ip().is_loopback() && anonymous_read {
        reasons.push(format!(
            "auth.anonymous_read lets anyone who reaches http.listen = {} read programs and history",
            http.listen
        ));
    }
    reasons
}

/// The start-up rule: `Ok(warnings)` to log at every start (each an insecure setting the
/// config allowed), or the problem that refuses the start.
pub fn network_exposure(
    http: &HttpSection,
    anonymous_read: bool,
    lines: &Lines,
) -> Result<Vec<String>, ConfigProblem> {
    let reasons = insecure_network_reasons(http, anonymous_read);
    if reasons.is_empty() || http.allow_insecure_network {
        return Ok(reasons);
    }
    Err(ConfigProblem::at(
        lines.of("http.listen"),
        format!(
            "{}: refused; set http.allow_insecure_network = true to serve it anyway",
            reasons.join("; ")
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn http(listen: &str) -> HttpSection {
        HttpSection {
            listen: listen.parse().unwrap(),
            ..HttpSection::default()
        }
    }

    #[test]
    fn a_network_address_needs_tls_or_an_explicit_allowance() {
        let lines = Lines::default();
        assert_eq!(
            network_exposure(&http("127.0.0.1:8080"), false, &lines),
            Ok(vec![])
        );
        let loopback = http("[::1]:8080");
        assert_eq!(network_exposure(&loopback, true, &lines), Ok(vec![]));
        let open = http("0.0.0.0:8080");
        let e = network_exposure(&open, false, &lines).unwrap_err();
        assert!(e.message.contains("allow_insecure_network"), "{e}");
        let allowed = HttpSection {
            allow_insecure_network: true,
            ..open.clone()
        };
        assert_eq!(
            network_exposure(&allowed, false, &lines).map(|w| w.len()),
            Ok(1)
        );
        let tls = HttpSection {
            tls_cert: Some("c.pem".into()),
            tls_key: Some("k.pem".into()),
            ..open
        };
        assert_eq!(network_exposure(&tls, false, &lines), Ok(vec![]));
        // Anonymous read on a network address is refused even under TLS.
        let e = network_exposure(&tls, true, &lines).unwrap_err();
        assert!(e.message.contains("auth.anonymous_read"), "{e}");
    }

    #[test]
    fn the_per_client_cap_defaults_to_a_quarter_and_must_stay_below_the_global_one() {
        assert_eq!(HttpSection::default().per_client_connections(), 64);
        let tiny = HttpSection {
            max_connections: 2,
            ..HttpSection::default()
        };
        assert_eq!(tiny.per_client_connections(), 1);
        let over = HttpSection {
            max_connections_per_client: Some(300),
            ..HttpSection::default()
        };
        let p = over.problems(&Lines::default());
        assert!(
            p[0].message.contains("must be 1 to max_connections (256)"),
            "{p:?}"
        );
    }
}
