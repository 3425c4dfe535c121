//! The `[mqtt]` section: events to the plant's message broker (off by default).

use super::{ConfigProblem, Lines};
use serde::Deserialize;

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
        }
    }
}

impl MqttSection {
    pub(super) fn problems(&self, lines: &Lines) -> Vec<ConfigProblem> {
        let mut p = Vec::new();
        let mut bad = |key: &str, why: String| {
            p.push(ConfigProblem::at(
                lines.of(&format!("mqtt.{key}")),
                format!("mqtt.{key}: {why}"),
            ));
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
        if !(1..=3600).contains(&self.keep_alive_s) {
            bad(
                "keep_alive_s",
                format!("{} must be 1 to 3600 s", self.keep_alive_s),
            );
        }
        p
    }
}
