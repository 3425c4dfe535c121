//! Keeps the address space current: the loops' plant events (the same stream MQTT gets)
//! and the in-process feature status (the one `/metrics` and the API read) become variable
//! values and OPC UA events. Runs on its own task: the loops only `try_send` into its
//! channel, and the OPC UA stack drops or lags a slow client without ever waiting here.

use crate::names::MachineName;
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use opcua::nodes::{BaseEventType, Event};
use opcua::server::SubscriptionCache;
use opcua::server::node_manager::memory::InMemoryNodeManager;
use opcua::types::{ByteString, DataValue, DateTime, LocalizedText, NodeId, ObjectId, Variant};
use tokio::sync::{mpsc, watch};

use super::methods::date_time;
use super::nodes::CamloopNodes;
use super::space::{FeatureValue, Ids, MachineLayout};
use crate::service::metrics::{FeatureStatus, Metrics};
use crate::service::plant::payload;
use camloop_loop::{MACHINE_LEVEL, PlantEvent};

/// How often the feature status is compared with what the address space shows; with the
/// event path (immediate) this bounds how stale a value can be.
pub(crate) const REFRESH_EVERY: Duration = Duration::from_millis(250);

/// The feed's state: what the address space shows now.
pub(crate) struct Feed {
    pub(crate) manager: Arc<InMemoryNodeManager<CamloopNodes>>,
    pub(crate) subscriptions: Arc<SubscriptionCache>,
    pub(crate) ids: Ids,
    pub(crate) metrics: Arc<Metrics>,
    pub(crate) layout: Vec<MachineLayout>,
    pub(crate) dressings: HashMap<MachineName, i64>,
    last: HashMap<NodeId, Variant>,
    journal_failing: HashMap<MachineName, bool>,
    event_seq: u64,
    started_ms: i64,
}

impl Feed {
    pub(crate) fn new(
        manager: Arc<InMemoryNodeManager<CamloopNodes>>,
        subscriptions: Arc<SubscriptionCache>,
        ids: Ids,
        metrics: Arc<Metrics>,
        layout: Vec<MachineLayout>,
    ) -> Self {
        Self {
            manager,
            subscriptions,
            ids,
            metrics,
            layout,
            dressings: HashMap::new(),
            last: HashMap::new(),
            journal_failing: HashMap::new(),
            event_seq: 0,
            started_ms: crate::clock::now().as_millisecond(),
        }
    }

    /// Applies one plant event: its values now, and its OPC UA event.
    pub(crate) fn event(&mut self, e: &PlantEvent, staged: &mut Vec<(NodeId, Variant)>) {
        let machine = e.machine().to_string();
        match e {
            PlantEvent::PartAnalysed {
                feature,
                part,
                at_ms,
                verdict,
                max_profile_error_um,
                base_radius_error_um,
                phase_error_deg,
                repeatability_um,
                ..
            } => {
                let values = [
                    (FeatureValue::PartId, Variant::from(part.clone())),
                    (FeatureValue::Time, Variant::from(date_time(*at_ms))),
                    (FeatureValue::Verdict, Variant::from(verdict.as_str())),
                    (
                        FeatureValue::ProfileErrorUm,
                        Variant::from(*max_profile_error_um),
                    ),
                    (
                        FeatureValue::SizeErrorUm,
                        Variant::from(*base_radius_error_um),
                    ),
                    (FeatureValue::PhaseErrorDeg, Variant::from(*phase_error_deg)),
                ];
                for (v, value) in values {
                    self.stage(self.ids.value(&machine, feature, v), value, staged);
                }
                // The gauge's repeatability comes with the part's event, typed.
                if let Some(um) = repeatability_um {
                    let id = self
                        .ids
                        .value(&machine, feature, FeatureValue::RepeatabilityUm);
                    self.stage(id, Variant::from(*um), staged);
                }
                let message = serde_json::json!({
                    "part": part, "feature": feature, "verdict": verdict.as_str(),
                    "max_profile_error_um": max_profile_error_um,
                })
                .to_string();
                let severity = if verdict.as_str() == "pass" { 100 } else { 500 };
                let ty = self.ids.result_ready_type();
                self.emit(&machine, feature, ty, severity, message, *at_ms);
            }
            PlantEvent::Dressing { at_ms, .. } => {
                let n = self.dressings.entry(e.machine().clone()).or_default();
                *n += 1;
                let n = *n;
                self.stage(self.ids.dressing_count(&machine), Variant::from(n), staged);
                self.alarm(&machine, e.feature(), "dressing", 100, payload(e), *at_ms);
            }
            other => {
                let severity = match other {
                    PlantEvent::Alarm { level, .. } => match level.as_str() {
                        "info" => 100,
                        "warn" => 500,
                        _ => 800,
                    },
                    PlantEvent::TableDelivered { .. } => 100,
                    _ => 700,
                };
                let kind = match other {
                    PlantEvent::Alarm { kind, .. } => kind.clone(),
                    _ => other.name().to_string(),
                };
                self.alarm(
                    &machine,
                    other.feature(),
                    &kind,
                    severity,
                    payload(other),
                    other.at_ms(),
                );
            }
        }
    }

    fn alarm(
        &mut self,
        machine: &str,
        source: &str,
        kind: &str,
        sev: u16,
        body: String,
        at_ms: jiff::Timestamp,
    ) {
        let ty = self.ids.alarm_type();
        self.emit(machine, source, ty, sev, format!("{kind}: {body}"), at_ms);
    }

    /// Raises an event on the machine, the `Machines` folder and the `Server` object (where
    /// generic clients subscribe).
    fn emit(
        &mut self,
        machine: &str,
        source: &str,
        ty: NodeId,
        severity: u16,
        message: String,
        at_ms: jiff::Timestamp,
    ) {
        self.event_seq += 1;
        let id = ByteString::from(format!("{}-{}", self.started_ms, self.event_seq).into_bytes());
        let node = self.ids.machine(machine);
        let event = BaseEventType::new(ty, id, LocalizedText::new("", &message), date_time(at_ms))
            .set_source_node(node.clone())
            .set_source_name(format!("{machine}/{source}").into())
            .set_severity(severity)
            .set_receive_time(DateTime::now());
        let server: NodeId = ObjectId::Server.into();
        let machines = self.ids.machines();
        let targets: [(&dyn Event, &NodeId); 3] =
            [(&event, &node), (&event, &machines), (&event, &server)];
        self.subscriptions.notify_events(targets.into_iter());
    }

    /// Compares the feature status with what is shown; stages what changed.
    pub(crate) fn refresh(&mut self, staged: &mut Vec<(NodeId, Variant)>) {
        let features = self.metrics.features();
        let machines = self.metrics.snapshot();
        let layout = std::mem::take(&mut self.layout);
        for m in &layout {
            for f in &m.features {
                if let Some(s) = features.get(&(m.name.clone(), f.clone())) {
                    for (v, value) in status_values(s) {
                        self.stage(self.ids.value(&m.name, f, v), value, staged);
                    }
                }
            }
            let failing = machines.get(&m.name).is_some_and(|x| x.journal_failing > 0);
            let was = self.journal_failing.insert(m.name.clone(), failing);
            if failing && was != Some(true) {
                let at = crate::clock::now();
                let text =
                    "the journal cannot be written (disk full?): records are not kept".to_string();
                self.alarm(&m.name, MACHINE_LEVEL, "journal_failing", 900, text, at);
            }
            self.stage(
                self.ids.journal_failing(&m.name),
                Variant::from(failing),
                staged,
            );
            let dressings = self.dressings.get(&m.name).copied().unwrap_or(0);
            self.stage(
                self.ids.dressing_count(&m.name),
                Variant::from(dressings),
                staged,
            );
        }
        self.layout = layout;
    }

    fn stage(&mut self, id: NodeId, value: Variant, staged: &mut Vec<(NodeId, Variant)>) {
        if self.last.get(&id) != Some(&value) {
            self.last.insert(id.clone(), value.clone());
            staged.push((id, value));
        }
    }

    /// Writes the staged values; subscribed clients are notified by the stack.
    pub(crate) fn publish(&self, staged: &mut Vec<(NodeId, Variant)>) {
        if staged.is_empty() {
            return;
        }
        let values: Vec<(NodeId, DataValue)> = staged
            .drain(..)
            .map(|(id, v)| (id, DataValue::new_now(v)))
            .collect();
        let items = values.iter().map(|(id, dv)| (id, None, dv.clone()));
        if let Err(e) = self.manager.set_values(&self.subscriptions, items) {
            tracing::debug!(status = %e, "OPC UA: a value could not be set");
        }
    }
}

/// The values a feature status gives (those not yet known are left out).
fn status_values(s: &FeatureStatus) -> Vec<(FeatureValue, Variant)> {
    let mut v = vec![
        (
            FeatureValue::TableVersionInForce,
            Variant::from(i64::try_from(s.in_force_version).unwrap_or(i64::MAX)),
        ),
        (
            FeatureValue::WaitingVersion,
            Variant::from(
                s.waiting_version
                    .and_then(|w| i64::try_from(w).ok())
                    .unwrap_or(0),
            ),
        ),
        (
            FeatureValue::LearningFrozen,
            Variant::from(s.frozen.is_some()),
        ),
        (
            FeatureValue::FrozenReason,
            Variant::from(s.frozen.clone().unwrap_or_default()),
        ),
        (
            FeatureValue::BlockedByGuard,
            Variant::from(s.blocked_by_guard.is_some()),
        ),
        (
            FeatureValue::GuardReason,
            Variant::from(s.blocked_by_guard.clone().unwrap_or_default()),
        ),
    ];
    let optional = [
        (FeatureValue::PartId, s.last_part.clone().map(Variant::from)),
        (
            FeatureValue::MaxErrorUm,
            s.last_max_error_um.map(Variant::from),
        ),
        (
            FeatureValue::ProfileErrorUm,
            s.last_profile_error_um.map(Variant::from),
        ),
        (
            FeatureValue::SizeErrorUm,
            s.last_size_error_um.map(Variant::from),
        ),
        (
            FeatureValue::PhaseErrorDeg,
            s.last_timing_error_deg.map(Variant::from),
        ),
        (
            FeatureValue::Verdict,
            s.last_pass
                .map(|p| Variant::from(if p { "pass" } else { "fail" })),
        ),
    ];
    v.extend(optional.into_iter().filter_map(|(k, x)| Some((k, x?))));
    v
}

/// Runs the feed until shutdown: every event at once, the status every [`REFRESH_EVERY`].
pub(crate) async fn run(
    mut feed: Feed,
    mut rx: mpsc::Receiver<PlantEvent>,
    mut shutdown: watch::Receiver<bool>,
) {
    // The stack builds the address space when its server task starts.
    let machines = feed.ids.machines();
    while !feed.manager.address_space().read().node_exists(&machines) {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let mut tick = tokio::time::interval(REFRESH_EVERY);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut staged = Vec::new();
    loop {
        tokio::select! {
            event = rx.recv() => {
                let Some(event) = event else { return };
                feed.event(&event, &mut staged);
                while let Ok(more) = rx.try_recv() {
                    feed.event(&more, &mut staged);
                }
                feed.refresh(&mut staged);
            }
            _ = tick.tick() => feed.refresh(&mut staged),
            _ = shutdown.changed() => return,
        }
        feed.publish(&mut staged);
    }
}
