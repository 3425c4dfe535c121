//! The `[mqtt]` section: events to the plant's message broker (off by default). The
//! service's config file holds it; its checks name the key, and the service adds the line.

use serde::Deserialize;
use std::fmt;
use std::path::PathBuf;

/// Environment variable holding the broker password for `mqtt.username`.
pub const ENV_MQTT_PASSWORD: &str = "CAMLOOP_MQTT_PASSWORD";

#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MqttSection {
    /// Publish events at all.
    pub enabled: bool,
    /// The broker's host name or address.
    pub host: String,
    pub port: u16,
    /// MQTT client id; unique per camloop instance on one broker.
    pub client_id: String,
    /// First level of every topic: `<prefix>/<machine>/<feature>/<event>`.
    pub topic_prefix: String,
    /// Events kept on disk while the broker is away; beyond it the oldest are dropped (and
    /// the count is published when the broker is back).
    pub queue_max_events: usize,
    pub keep_alive_s: u64,
    /// User name at the broker; its password comes from `CAMLOOP_MQTT_PASSWORD`.
    pub username: Option<String>,
    /// From the environment only.
    #[serde(skip)]
    pub password: Option<Password>,
    /// Speak MQTT over TLS (port 8883 usually); the broker's certificate is checked against
    /// `tls_ca`, or the system's roots without it.
    pub tls: bool,
    /// PEM file of the CA (or the certificate itself) the broker's certificate must chain to.
    pub tls_ca: Option<PathBuf>,
}

impl Default for MqttSection {
    fn default() -> Self {
        Self {
            enabled: false,
            host: "127.0.0.1".into(),
            port: 1883,
            client_id: "camloop".into(),
            topic_prefix: "camloop".into(),
            queue_max_events: 100_000,
            keep_alive_s: 30,
            username: None,
            password: None,
            tls: false,
            tls_ca: None,
        }
    }
}

/// The broker password: never shown in Debug output or logs.
#[derive(Clone, PartialEq, Eq)]
pub struct Password(String);

impl Password {
    pub fn new(password: impl Into<String>) -> Self {
        Self(password.into())
    }

    pub(crate) fn expose(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for Password {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Password(…)")
    }
}

/// One problem in the section: its key (`mqtt.<key>`) and what is wrong, key first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SectionProblem {
    /// The full key, `mqtt.host` say, for the caller to find its line.
    pub key: String,
    pub message: String,
}

impl MqttSection {
    /// Every problem of an enabled section at once (none when it is off).
    pub fn problems(&self) -> Vec<SectionProblem> {
        let mut p = Vec::new();
        let mut bad = |key: &str, why: String| {
            p.push(SectionProblem {
                key: format!("mqtt.{key}"),
                message: format!("mqtt.{key}: {why}"),
            });
        };
        if !self.enabled {
            return Vec::new();
        }
        if self.host.trim().is_empty() {
            bad("host", "must not be empty".into());
        }
        if self.client_id.is_empty() || self.client_id.len() > 64 {
            bad("client_id", "must be 1 to 64 characters".into());
        }
        let prefix_ok = !self.topic_prefix.is_empty()
            && !self
                .topic_prefix
                .contains(|c: char| c == '+' || c == '#' || c.is_control());
        if !prefix_ok {
            bad(
                "topic_prefix",
                format!(
                    "`{}` must be non-empty, without + # or control characters",
                    self.topic_prefix
                ),
            );
        }
        if !(1..=10_000_000).contains(&self.queue_max_events) {
            bad(
                "queue_max_events",
                format!("{} must be 1 to 10000000", self.queue_max_events),
            );
        }
        if self.password.is_some() && self.username.is_none() {
            bad(
                "username",
                format!("required when {ENV_MQTT_PASSWORD} is set"),
            );
        }
        if self.tls_ca.is_some() && !self.tls {
            bad("tls_ca", "given but mqtt.tls is false".into());
        }
        if !(1..=3600).contains(&self.keep_alive_s) {
            bad(
                "keep_alive_s",
                format!("{} must be 1 to 3600 s", self.keep_alive_s),
            );
        }
        p
    }
}
