//! Prometheus metrics of the service, kept per machine and rendered in the text exposition
//! format at `/metrics`.

use crate::names::{FeatureName, MachineName};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::sync::Mutex;

/// Counters and gauges of one machine.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MachineMetrics {
    pub parts_total: u64,
    pub measurements_rejected_total: u64,
    pub tables_pushed_total: u64,
    pub tables_refused_total: u64,
    pub alarms_total: u64,
    /// Versions waiting for the share.
    pub share_waiting: u64,
    /// Records in the journal not yet in the database.
    pub journal_pending: u64,
    pub last_max_error_um: f64,
    /// 1 while learning holds: a table waits for the share, or a measurement could not be
    /// recorded.
    pub learning_held: u64,
    /// 1 while the journal cannot be written (e.g. the disk is full).
    pub journal_failing: u64,
    pub processing_seconds_sum: f64,
    pub processing_seconds_count: u64,
    /// In a cluster: leases of this machine this instance won, and lost (not renewed in
    /// time, or taken by another instance while this one could not renew).
    pub leases_taken_total: u64,
    pub leases_lost_total: u64,
}

/// Name, type, help and value of one metric family.
type Family = (
    &'static str,
    &'static str,
    &'static str,
    fn(&MachineMetrics) -> f64,
);

/// Every metric family, in the order rendered.
const FAMILIES: [Family; 14] = [
    (
        "camloop_parts_total",
        "counter",
        "Parts measured and processed.",
        |m| m.parts_total as f64,
    ),
    (
        "camloop_measurements_rejected_total",
        "counter",
        "Measurements refused by the checks.",
        |m| m.measurements_rejected_total as f64,
    ),
    (
        "camloop_tables_pushed_total",
        "counter",
        "Table versions delivered to the share.",
        |m| m.tables_pushed_total as f64,
    ),
    (
        "camloop_tables_refused_total",
        "counter",
        "Tables refused by a guard.",
        |m| m.tables_refused_total as f64,
    ),
    ("camloop_alarms_total", "counter", "Alarms raised.", |m| {
        m.alarms_total as f64
    }),
    (
        "camloop_share_waiting",
        "gauge",
        "Table versions waiting for the share.",
        |m| m.share_waiting as f64,
    ),
    (
        "camloop_learning_held",
        "gauge",
        "1 while learning holds (a table waits for the share, or a part could not be recorded).",
        |m| m.learning_held as f64,
    ),
    (
        "camloop_journal_failing",
        "gauge",
        "1 while the journal cannot be written (e.g. disk full).",
        |m| m.journal_failing as f64,
    ),
    (
        "camloop_journal_pending",
        "gauge",
        "Records waiting for the database.",
        |m| m.journal_pending as f64,
    ),
    (
        "camloop_last_max_error_um",
        "gauge",
        "Max lift error of the last part, micrometres.",
        |m| m.last_max_error_um,
    ),
    (
        "camloop_part_processing_seconds_sum",
        "counter",
        "Time from measurement to table delivered and recorded.",
        |m| m.processing_seconds_sum,
    ),
    (
        "camloop_part_processing_seconds_count",
        "counter",
        "Parts timed.",
        |m| m.processing_seconds_count as f64,
    ),
    (
        "camloop_leases_taken_total",
        "counter",
        "Leases of the machine this instance won (cluster only).",
        |m| m.leases_taken_total as f64,
    ),
    (
        "camloop_leases_lost_total",
        "counter",
        "Leases of the machine this instance lost before handing it over (cluster only).",
        |m| m.leases_lost_total as f64,
    ),
];

/// The state of one feature (lobe or pin) of a machine, for the API and `/metrics`.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct FeatureStatus {
    /// Parts of this feature measured by this service since it started.
    pub parts: u64,
    /// The shaft (part number) the newest measurement came from.
    pub last_part: Option<crate::core::ids::PartId>,
    pub last_max_error_um: Option<f64>,
    pub last_profile_error_um: Option<f64>,
    pub last_timing_error_deg: Option<f64>,
    pub last_size_error_um: Option<f64>,
    /// The newest measurement passed its tolerance bands.
    pub last_pass: Option<bool>,
    /// Table version on the control.
    #[serde(with = "crate::core::ids::lenient_version::zero_for_none")]
    pub in_force_version: Option<crate::core::ids::TableVersion>,
    /// A newer version waits for the share.
    pub waiting_version: Option<crate::core::ids::TableVersion>,
    /// Learning is frozen, and why.
    pub frozen: Option<String>,
    /// The guard that blocked several parts in a row (the alarm stands), and its reason.
    pub blocked_by_guard: Option<String>,
}

/// Gauges per feature: name, help, value (none: not rendered yet).
type FeatureFamily = (
    &'static str,
    &'static str,
    fn(&FeatureStatus) -> Option<f64>,
);

const FEATURE_FAMILIES: [FeatureFamily; 5] = [
    (
        "camloop_feature_max_error_um",
        "Max lift error of the feature's last part, micrometres.",
        |f| f.last_max_error_um,
    ),
    (
        "camloop_feature_timing_error_deg",
        "Timing (index) error of the feature's last part, degrees.",
        |f| f.last_timing_error_deg,
    ),
    (
        "camloop_feature_table_version",
        "Table version on the control.",
        |f| Some(f.in_force_version.map_or(0.0, |v| v.get() as f64)),
    ),
    (
        "camloop_blocked_by_guard",
        "1 while the same guard has refused or limited the feature's parts in a row (alarm).",
        |f| Some(f64::from(u8::from(f.blocked_by_guard.is_some()))),
    ),
    (
        "camloop_learning_frozen",
        "1 while the feature's learning is frozen after a revert.",
        |f| Some(f64::from(u8::from(f.frozen.is_some()))),
    ),
];

#[derive(Debug, Default)]
pub struct Metrics {
    machines: Mutex<BTreeMap<MachineName, MachineMetrics>>,
    features: Mutex<BTreeMap<(MachineName, FeatureName), FeatureStatus>>,
    access: Mutex<AccessMetrics>,
    /// Measurements received and not yet recorded: the loop's lag.
    pub backlog: super::backlog::Backlog,
    /// The components' states `/healthz` reports.
    pub health: super::health::HealthBoard,
    /// The link to the MQTT broker, when `[mqtt]` is enabled.
    mqtt: Mutex<Option<MqttMetrics>>,
    /// When the listener's TLS certificate stops being valid, when it serves TLS.
    tls_not_after: Mutex<Option<jiff::Timestamp>>,
}

pub use camloop_mqtt::{MqttLinkState, MqttMetrics};

/// Counters of the listener's access control.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AccessMetrics {
    /// Failed sign-ins and tokens, by kind (`password`, `token`, `locked`, `csrf`).
    pub failures: BTreeMap<&'static str, u64>,
    /// Users and addresses locked out.
    pub lockouts_total: u64,
    /// Audit rows that could not be written (the database was unreachable).
    pub audit_failures_total: u64,
    /// Refusals counted but not audited: their client was over the audit's budget.
    pub refusals_unrecorded_total: u64,
}

impl Metrics {
    /// Changes one machine's metrics.
    pub fn update(&self, machine: &MachineName, f: impl FnOnce(&mut MachineMetrics)) {
        let mut map = self.machines.lock().unwrap_or_else(|p| p.into_inner());
        f(map.entry(machine.clone()).or_default());
    }

    pub fn snapshot(&self) -> BTreeMap<MachineName, MachineMetrics> {
        self.machines
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Changes one feature's status.
    pub fn update_feature(
        &self,
        machine: &MachineName,
        feature: &FeatureName,
        f: impl FnOnce(&mut FeatureStatus),
    ) {
        let mut map = self.features.lock().unwrap_or_else(|p| p.into_inner());
        f(map.entry((machine.clone(), feature.clone())).or_default());
    }

    /// Every feature's status, by (machine, feature).
    pub fn features(&self) -> BTreeMap<(MachineName, FeatureName), FeatureStatus> {
        self.features
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Changes the access counters.
    pub(crate) fn update_access(&self, f: impl FnOnce(&mut AccessMetrics)) {
        f(&mut self.access.lock().unwrap_or_else(|p| p.into_inner()));
    }

    /// Sets the MQTT link's series.
    pub fn set_mqtt(&self, m: MqttMetrics) {
        *self.mqtt.lock().unwrap_or_else(|p| p.into_inner()) = Some(m);
    }

    /// The MQTT link's series (`None`: MQTT is off).
    pub fn mqtt(&self) -> Option<MqttMetrics> {
        *self.mqtt.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Whether the MQTT link is enabled and not up for a reason an operator should see:
    /// refused by the broker, or the broker unreachable (for `/healthz`).
    pub fn mqtt_degraded(&self) -> bool {
        self.mqtt()
            .is_some_and(|m| matches!(m.link, MqttLinkState::Refused | MqttLinkState::Unreachable))
    }

    /// Sets when the listener's TLS certificate in force stops being valid.
    pub(crate) fn set_tls_not_after(&self, at: jiff::Timestamp) {
        *self.tls_not_after.lock().unwrap_or_else(|p| p.into_inner()) = Some(at);
    }

    /// Days to the TLS certificate's expiry, counted at each scrape (so it falls day by
    /// day between reloads); nothing without TLS.
    fn render_tls(&self, s: &mut String) {
        let at = *self.tls_not_after.lock().unwrap_or_else(|p| p.into_inner());
        let Some(at) = at else { return };
        let days = super::http::days_left(at, jiff::Timestamp::now());
        let name = "camloop_tls_certificate_expiry_days";
        let _ = writeln!(
            s,
            "# HELP {name} Days until the listener's TLS certificate expires (negative: expired).\n# TYPE {name} gauge\n{name} {days:.3}"
        );
    }

    fn render_mqtt(&self, s: &mut String) {
        let Some(m) = self.mqtt() else { return };
        let name = "camloop_mqtt_link_state";
        let _ = writeln!(
            s,
            "# HELP {name} The link to the MQTT broker: 1 for the state it is in (refused: the broker refused the credentials).\n# TYPE {name} gauge"
        );
        for state in <MqttLinkState as strum::IntoEnumIterator>::iter() {
            let label: &'static str = state.into();
            let _ = writeln!(
                s,
                "{name}{{state=\"{label}\"}} {}",
                u8::from(state == m.link)
            );
        }
        for (name, kind, help, value) in [
            (
                "camloop_mqtt_queue_events",
                "gauge",
                "Events waiting on disk for the MQTT broker.",
                m.queued,
            ),
            (
                "camloop_mqtt_sent_total",
                "counter",
                "Events (and drop reports) the MQTT broker acknowledged.",
                m.sent_total,
            ),
            (
                "camloop_mqtt_dropped_total",
                "counter",
                "Events dropped since start (queue or intake full).",
                m.dropped_total,
            ),
        ] {
            let _ = writeln!(
                s,
                "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {value}"
            );
        }
    }

    pub fn access(&self) -> AccessMetrics {
        self.access
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    fn render_access(&self, s: &mut String) {
        let a = self.access();
        let name = "camloop_auth_failures_total";
        let _ = writeln!(
            s,
            "# HELP {name} Failed sign-ins, tokens and CSRF checks, by kind.\n# TYPE {name} counter"
        );
        for kind in ["password", "token", "locked", "csrf"] {
            let n = a.failures.get(kind).copied().unwrap_or(0);
            let _ = writeln!(s, "{name}{{kind=\"{kind}\"}} {n}");
        }
        let name = "camloop_auth_lockouts_total";
        let _ = writeln!(
            s,
            "# HELP {name} Users and client addresses locked out after repeated failures.\n# TYPE {name} counter\n{name} {}",
            a.lockouts_total
        );
        let name = "camloop_audit_failures_total";
        let _ = writeln!(
            s,
            "# HELP {name} Audit rows that could not be stored.\n# TYPE {name} counter\n{name} {}",
            a.audit_failures_total
        );
        let name = "camloop_audit_refusals_unrecorded_total";
        let _ = writeln!(
            s,
            "# HELP {name} Refused attempts not audited: their client was over the audit's budget for refusals.\n# TYPE {name} counter\n{name} {}",
            a.refusals_unrecorded_total
        );
    }

    /// The text exposition format (version 0.0.4).
    pub fn render(&self) -> String {
        let map = self.snapshot();
        let mut s = String::new();
        for (name, kind, help, value) in FAMILIES {
            let _ = writeln!(s, "# HELP {name} {help}\n# TYPE {name} {kind}");
            for (machine, m) in &map {
                let _ = writeln!(s, "{name}{{machine=\"{machine}\"}} {}", value(m));
            }
        }
        let features = self.features();
        for (name, help, value) in FEATURE_FAMILIES {
            let _ = writeln!(s, "# HELP {name} {help}\n# TYPE {name} gauge");
            for ((machine, lobe), f) in &features {
                if let Some(v) = value(f) {
                    let _ = writeln!(s, "{name}{{machine=\"{machine}\",lobe=\"{lobe}\"}} {v}");
                }
            }
        }
        self.render_access(&mut s);
        self.render_lag(&mut s);
        self.render_mqtt(&mut s);
        self.render_tls(&mut s);
        s
    }

    fn render_lag(&self, s: &mut String) {
        let lag = self.backlog.lag(std::time::Instant::now());
        let name = "camloop_measurements_waiting";
        let _ = writeln!(
            s,
            "# HELP {name} Measurements received and not yet recorded (journalled or rejected).\n# TYPE {name} gauge\n{name} {}",
            lag.waiting
        );
        let name = "camloop_oldest_waiting_seconds";
        let _ = writeln!(
            s,
            "# HELP {name} How long the oldest measurement not yet recorded has waited (0: none waits).\n# TYPE {name} gauge\n{name} {}",
            lag.oldest.map_or(0.0, |d| d.as_secs_f64())
        );
        render_part_seconds(s, &self.backlog.done.counts());
        let (appends, syncs, batches) = super::journal::commit_totals();
        let (store_batches, store_records) = super::journal::store_totals();
        for (name, help, value) in [
            (
                "camloop_journal_appends_total",
                "Journal appends made durable.",
                appends,
            ),
            (
                "camloop_journal_syncs_total",
                "Journal syncs issued (group commit: one per batch).",
                syncs,
            ),
            (
                "camloop_journal_batches_total",
                "Journal batches written.",
                batches,
            ),
            (
                "camloop_store_batches_total",
                "Store transactions of journal records (group commit across machines).",
                store_batches,
            ),
            (
                "camloop_store_records_total",
                "Journal records written to the store in them.",
                store_records,
            ),
        ] {
            let _ = writeln!(
                s,
                "# HELP {name} {help}\n# TYPE {name} counter\n{name} {value}"
            );
        }
    }
}

/// The part-time histogram in the exposition format (cumulative buckets).
fn render_part_seconds(s: &mut String, c: &super::backlog::PartCounts) {
    let name = "camloop_part_seconds";
    let _ = writeln!(
        s,
        "# HELP {name} From a measurement received to its part done (recorded, and its table durable on the share), seconds.\n# TYPE {name} histogram"
    );
    let mut below = 0u64;
    for (le, n) in super::backlog::PART_SECONDS_BUCKETS.iter().zip(&c.buckets) {
        below += n;
        let _ = writeln!(s, "{name}_bucket{{le=\"{le}\"}} {below}");
    }
    let _ = writeln!(
        s,
        "{name}_bucket{{le=\"+Inf\"}} {}\n{name}_sum {}\n{name}_count {}",
        c.count, c.sum_s, c.count
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_every_family_per_machine() {
        let m = Metrics::default();
        m.update(&"M1".parse().unwrap(), |x| {
            x.parts_total = 3;
            x.last_max_error_um = 0.5;
        });
        let text = m.render();
        assert!(
            text.contains("camloop_parts_total{machine=\"M1\"} 3\n"),
            "{text}"
        );
        assert!(
            text.contains("camloop_last_max_error_um{machine=\"M1\"} 0.5\n"),
            "{text}"
        );
        assert_eq!(text.matches("# TYPE").count(), 14 + 5 + 4 + 2 + 1 + 3 + 2);
        // The part-time histogram: every bucket, cumulative, even before any part.
        assert!(
            text.contains("camloop_part_seconds_bucket{le=\"2\"} 0\n"),
            "{text}"
        );
        assert!(text.contains("camloop_part_seconds_count 0\n"), "{text}");
        let machine: MachineName = "M1".parse().unwrap();
        m.backlog.received(&machine, std::time::Instant::now());
        m.backlog.recorded(&machine);
        let text = m.render();
        assert!(
            text.contains("camloop_part_seconds_bucket{le=\"+Inf\"} 1\n"),
            "{text}"
        );
        assert!(
            text.contains("camloop_part_seconds_bucket{le=\"30\"} 1\n"),
            "{text}"
        );
        assert!(text.contains("camloop_part_seconds_count 1\n"), "{text}");
        m.update_feature(&"M1".parse().unwrap(), &"IN1".parse().unwrap(), |f| {
            f.last_max_error_um = Some(0.7);
            f.blocked_by_guard = Some("correction at its limit".into());
        });
        let text = m.render();
        assert!(
            text.contains("camloop_feature_max_error_um{machine=\"M1\",lobe=\"IN1\"} 0.7\n"),
            "{text}"
        );
        assert!(
            text.contains("camloop_blocked_by_guard{machine=\"M1\",lobe=\"IN1\"} 1\n"),
            "{text}"
        );
        assert!(
            text.contains("camloop_learning_held{machine=\"M1\"} 0\n"),
            "{text}"
        );
        assert!(
            !text.contains("camloop_mqtt"),
            "no MQTT series while MQTT is off"
        );
    }

    #[test]
    fn the_mqtt_link_shows_its_state_and_queue_and_a_refusal_is_degraded() {
        let m = Metrics::default();
        assert!(!m.mqtt_degraded());
        m.set_mqtt(MqttMetrics {
            link: MqttLinkState::Refused,
            queued: 7,
            sent_total: 2,
            dropped_total: 1,
        });
        let text = m.render();
        for line in [
            "camloop_mqtt_link_state{state=\"refused\"} 1\n",
            "camloop_mqtt_link_state{state=\"connected\"} 0\n",
            "camloop_mqtt_queue_events 7\n",
            "camloop_mqtt_sent_total 2\n",
            "camloop_mqtt_dropped_total 1\n",
        ] {
            assert!(text.contains(line), "{line}{text}");
        }
        assert!(m.mqtt_degraded());
        m.set_mqtt(MqttMetrics {
            link: MqttLinkState::Connected,
            ..MqttMetrics::default()
        });
        assert!(!m.mqtt_degraded());
    }
}
