//! What the publisher has done (queue depth, sent, dropped, the link's state), as the
//! service's `/metrics` and `/healthz` show it.

/// The state of the link to the MQTT broker.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, strum::IntoStaticStr, strum::EnumIter)]
#[strum(serialize_all = "snake_case")]
pub enum MqttLinkState {
    /// Not connected yet since start.
    #[default]
    Connecting,
    Connected,
    /// The broker refused the connection (credentials, client id): an operator must act.
    Refused,
    /// The broker cannot be reached, or the connection was lost.
    Unreachable,
}

/// The MQTT link's series.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MqttMetrics {
    pub link: MqttLinkState,
    /// Events waiting on disk.
    pub queued: u64,
    pub sent_total: u64,
    pub dropped_total: u64,
}

/// What the publisher has done, published after every change (for tests and metrics).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Progress {
    /// Events waiting on disk.
    pub queued: usize,
    /// Events (and drop reports) the broker acknowledged.
    pub sent: u64,
    /// Events dropped since start (queue or intake full), reported or not.
    pub dropped: u64,
    pub connected: bool,
    /// The link's state (refused: the broker refused the credentials).
    pub link: MqttLinkState,
}

impl Progress {
    /// As `/metrics` shows it.
    pub fn metrics(&self) -> MqttMetrics {
        MqttMetrics {
            link: self.link,
            queued: u64::try_from(self.queued).unwrap_or(u64::MAX),
            sent_total: self.sent,
            dropped_total: self.dropped,
        }
    }
}
