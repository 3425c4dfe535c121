//! Keeps the address space current: the loops' plant events (the same stream MQTT gets)
//! and the in-process feature status (the one `/metrics` and the API read) become variable
//! values and OPC UA events. Runs on its own task: the loops only `try_send` into its
//! channel, and the OPC UA stack drops or lags a slow client without ever waiting here.
//!
//! A part's result (`PartId`, `Time`, `Verdict`, the errors, `LatestResult`) is written only
//! from its own `PartAnalysed` event, all of it in one write with the part's time as every
//! value's SourceTimestamp, and never by an older part: the status refresh writes the loop's
//! state only (and `MaxError` once the status has caught up with the shown part), so a
//! client never sees a new part's `Time` beside an older part's `PartId`.

use camloop_core::names::{FeatureName, MachineName};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use opcua::nodes::{BaseEventType, Event};
use opcua::server::SubscriptionCache;
use opcua::server::node_manager::memory::InMemoryNodeManager;
use opcua::types::{
    ByteString, DataValue, DateTime, LocalizedText, NodeId, ObjectId, ObjectTypeId, StatusCode,
    Variant,
};
use tokio::sync::{mpsc, watch};

use super::events::{EventIds, Listeners};
use super::methods::date_time;
use super::nodes::CamloopNodes;
use super::space::{FeatureValue, Ids, MachineLayout};
use crate::port::{FeatureView, Service};
use camloop_loop::{MACHINE_LEVEL, PlantEvent};

/// A plant event's JSON, the same text MQTT's payload carries without its sequence number.
fn payload(event: &PlantEvent) -> String {
    // Strings, numbers and enums only: serializing cannot fail.
    serde_json::to_string(event).expect("a plant event serializes to JSON")
}

/// How often the feature status is compared with what the address space shows; with the
/// event path (immediate) this bounds how stale a value can be.
pub(crate) const REFRESH_EVERY: Duration = Duration::from_millis(250);

/// The feed's state: what the address space shows now.
pub(crate) struct Feed {
    pub(crate) manager: Arc<InMemoryNodeManager<CamloopNodes>>,
    pub(crate) subscriptions: Arc<SubscriptionCache>,
    pub(crate) ids: Ids,
    pub(crate) service: Arc<dyn Service>,
    pub(crate) layout: Vec<MachineLayout>,
    pub(crate) dressings: HashMap<MachineName, i64>,
    pub(crate) listeners: Arc<Listeners>,
    pub(crate) handle: opcua::server::ServerHandle,
    last: HashMap<NodeId, Variant>,
    /// The part each feature shows, and its time (a part never gives way to an older one).
    shown: HashMap<(String, String), (String, jiff::Timestamp)>,
    /// Events raised by the values staged with them: emitted once those values are written.
    pending: Vec<Pending>,
    journal_failing: HashMap<MachineName, bool>,
    /// The EventIds, the same for the same event in every process (see [`EventIds`]).
    event_ids: EventIds,
    /// Plant events the full intake refused (the loops' sender counts them), and how many
    /// of them an overflow event has told.
    pub(crate) dropped: Arc<std::sync::atomic::AtomicU64>,
    dropped_told: u64,
}

impl Feed {
    pub(crate) fn new(
        manager: Arc<InMemoryNodeManager<CamloopNodes>>,
        subscriptions: Arc<SubscriptionCache>,
        ids: Ids,
        service: Arc<dyn Service>,
        layout: Vec<MachineLayout>,
        listeners: Arc<Listeners>,
        handle: opcua::server::ServerHandle,
    ) -> Self {
        Self {
            listeners,
            handle,
            shown: HashMap::new(),
            pending: Vec::new(),
            manager,
            subscriptions,
            ids,
            service,
            layout,
            dressings: HashMap::new(),
            last: HashMap::new(),
            journal_failing: HashMap::new(),
            event_ids: EventIds::default(),
            dropped: Arc::default(),
            dropped_told: 0,
        }
    }

    /// Applies one plant event: its values (staged), and its OPC UA event (raised once the
    /// values are written, so a client that reads on the event reads them).
    pub(crate) fn event(&mut self, e: &PlantEvent, staged: &mut Vec<(NodeId, DataValue)>) {
        let machine = e.machine().to_string();
        match e {
            PlantEvent::PartAnalysed {
                feature,
                part,
                at: at_ms,
                verdict,
                max_profile_error_um,
                ..
            } => {
                let max_error = self
                    .service
                    .feature(e.machine(), feature)
                    .filter(|s| s.last_part.as_deref() == Some(part.as_str()))
                    .and_then(|s| s.last_max_error_um);
                if !self.show_result(e, max_error, staged) {
                    return;
                }
                let message = serde_json::json!({
                    "part": part, "feature": feature, "verdict": verdict.as_str(),
                    "max_profile_error_um": max_profile_error_um,
                })
                .to_string();
                let severity = if verdict.as_str() == "pass" { 100 } else { 500 };
                let ty = self.ids.result_ready_type();
                self.raise(&machine, feature, (ty, severity), message, *at_ms, None);
            }
            PlantEvent::Dressing { at: at_ms, .. } => {
                let n = self.dressings.entry(e.machine().clone()).or_default();
                *n += 1;
                let n = *n;
                self.stage(self.ids.dressing_count(&machine), Variant::from(n), staged);
                let body = payload(e);
                self.alarm(&machine, e.feature(), ("dressing", 100), body, *at_ms, None);
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
                let stored = stored_message(other);
                self.alarm(
                    &machine,
                    other.feature(),
                    (&kind, severity),
                    payload(other),
                    other.at(),
                    stored.as_deref(),
                );
            }
        }
    }

    /// Stages a part's result variables, all with the part's time, unless the feature
    /// shows a newer part (then nothing, and false).
    fn show_result(
        &mut self,
        e: &PlantEvent,
        max_error: Option<f64>,
        staged: &mut Vec<(NodeId, DataValue)>,
    ) -> bool {
        let PlantEvent::PartAnalysed {
            machine,
            feature,
            part,
            at: at_ms,
            ..
        } = e
        else {
            return false;
        };
        let key = (machine.to_string(), feature.to_string());
        if self.shown.get(&key).is_some_and(|(_, at)| at > at_ms) {
            // An older part than the one shown: its values never replace the newer.
            return false;
        }
        self.shown.insert(key, (part.to_string(), *at_ms));
        for (v, value) in result_values(e, max_error) {
            let id = self.ids.value(machine, feature, v);
            // The catch-up of `MaxError` compares with the last value written.
            match &value {
                Some(x) if v == FeatureValue::MaxErrorUm => {
                    self.last.insert(id.clone(), x.clone());
                }
                _ => {
                    self.last.remove(&id);
                }
            }
            staged.push((id, result_value(value, *at_ms)));
        }
        true
    }

    /// A feature's newest stored result at start (see [`super::seed`]): shown as its part
    /// would be, without an event, unless the feature already shows a part (the loops' news
    /// is never replaced by the history's).
    pub(crate) fn seed(&mut self, seed: &super::seed::Seed, staged: &mut Vec<(NodeId, DataValue)>) {
        let PlantEvent::PartAnalysed {
            machine, feature, ..
        } = &seed.part
        else {
            return;
        };
        let key = (machine.to_string(), feature.to_string());
        if self.shown.contains_key(&key) {
            return;
        }
        self.show_result(&seed.part, seed.max_error_um, staged);
    }

    /// A `CamloopAlarmEventType` event; `stored`: the history row's message when the event
    /// is a row of the history.
    fn alarm(
        &mut self,
        machine: &str,
        source: &str,
        (kind, sev): (&str, u16),
        body: String,
        at: jiff::Timestamp,
        stored: Option<&str>,
    ) {
        let ty = self.ids.alarm_type();
        let message = format!("{kind}: {body}");
        self.raise(machine, source, (ty, sev), message, at, stored);
    }

    /// Makes an event of the machine, raised at the next [`Feed::publish`]; its EventId is
    /// made from the history row's message when it is a row (`stored`), so that
    /// `AcknowledgeEvent` finds the row by it, in this process or a later one.
    fn raise(
        &mut self,
        machine: &str,
        source: &str,
        (ty, severity): (NodeId, u16),
        message: String,
        at: jiff::Timestamp,
        stored: Option<&str>,
    ) {
        let bytes = match stored {
            Some(row) => self.event_ids.row(machine, at, row),
            None => {
                let kind = ty.to_string();
                let ids = &mut self.event_ids;
                ids.other((machine, source, &kind), at, &message)
            }
        };
        let id = ByteString::from(bytes);
        let node = self.ids.machine(machine);
        let event = BaseEventType::new(ty, id, LocalizedText::new("", &message), date_time(at))
            .set_source_node(node.clone())
            .set_source_name(format!("{machine}/{source}").into())
            .set_severity(severity)
            .set_receive_time(DateTime::now());
        self.pending.push(Pending { node, event });
    }

    /// Raises the pending events: each reaches every monitored item on its machine, on the
    /// `Machines` folder and on the `Server` object once (the notifier hierarchy), however
    /// many of them a client watches.
    fn emit(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        let machines = self.ids.machines();
        let server: NodeId = ObjectId::Server.into();
        let pending = std::mem::take(&mut self.pending);
        // The stack's own path adds the Server object's items to any node: given the Server
        // object alone, it reaches those and no others.
        self.subscriptions
            .notify_events(pending.iter().map(|p| (&p.event as &dyn Event, &server)));
        let tree = self.handle.type_tree();
        for p in &pending {
            self.listeners
                .notify(&self.subscriptions, tree, &[&p.node, &machines], &p.event);
        }
    }

    /// Compares the feature status with what is shown; stages what changed. A part's result
    /// is not the status's to write (see the module's notes), except `MaxError`, which the
    /// part's event does not carry: it is written once the status shows the same part.
    pub(crate) fn refresh(&mut self, staged: &mut Vec<(NodeId, DataValue)>) {
        let status = self.service.status();
        let features = &status.features;
        let layout = std::mem::take(&mut self.layout);
        for m in &layout {
            for f in &m.features {
                if let Some(s) = features.get(&(m.name.clone(), f.clone())) {
                    for (v, value) in status_values(s) {
                        self.stage(self.ids.value(&m.name, f, v), value, staged);
                    }
                    self.catch_up_max_error(&m.name, f, s, staged);
                }
            }
            let failing = status.journal_failing.contains(&m.name);
            let was = self.journal_failing.insert(m.name.clone(), failing);
            if failing && was != Some(true) {
                let at = jiff::Timestamp::now();
                let text =
                    "the journal cannot be written (disk full?): records are not kept".to_string();
                let kind = ("journal_failing", 900);
                self.alarm(&m.name, MACHINE_LEVEL, kind, text, at, None);
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
        self.tell_dropped();
    }

    /// An `EventQueueOverflowEventType` event on `Server` (and `Machines`) when plant events
    /// were dropped before the server (its intake full) since the last one: those parts'
    /// results and events are not shown, and a client is told so rather than left to
    /// notice a gap.
    fn tell_dropped(&mut self) {
        let dropped = self.dropped.load(std::sync::atomic::Ordering::Relaxed);
        if dropped <= self.dropped_told {
            return;
        }
        let lost = dropped - self.dropped_told;
        self.dropped_told = dropped;
        tracing::warn!(
            lost,
            "OPC UA: plant events dropped, the server's intake was full"
        );
        let at = jiff::Timestamp::now();
        let message = format!(
            "{lost} plant events dropped before the OPC UA server (its intake was full): their results and events are not shown"
        );
        let server: NodeId = ObjectId::Server.into();
        let ty: NodeId = ObjectTypeId::EventQueueOverflowEventType.into();
        let kind = ty.to_string();
        let id = self
            .event_ids
            .other(("Server", "Server", &kind), at, &message);
        let event = BaseEventType::new(
            ty,
            ByteString::from(id),
            LocalizedText::new("", &message),
            date_time(at),
        )
        .set_source_node(server.clone())
        .set_source_name("Server".into())
        .set_severity(800)
        .set_receive_time(DateTime::now());
        // The Server object's listeners are the stack's; camloop's `Machines` listeners
        // get it through the notifier list (no machine's: which one lost it is not known).
        self.pending.push(Pending {
            node: server,
            event,
        });
    }

    /// `MaxError` of the shown part, once the status has it (with the part's time).
    fn catch_up_max_error(
        &mut self,
        machine: &MachineName,
        feature: &FeatureName,
        s: &FeatureView,
        staged: &mut Vec<(NodeId, DataValue)>,
    ) {
        let key = (machine.to_string(), feature.to_string());
        let Some((part, at)) = self.shown.get(&key) else {
            return;
        };
        let (Some(max), Some(last)) = (s.last_max_error_um, s.last_part.as_deref()) else {
            return;
        };
        if last != part.as_str() {
            return;
        }
        let id = self.ids.value(machine, feature, FeatureValue::MaxErrorUm);
        let value = Variant::from(max);
        if self.last.get(&id) != Some(&value) {
            self.last.insert(id.clone(), value.clone());
            staged.push((id, result_value(Some(value), *at)));
        }
    }

    fn stage(&mut self, id: NodeId, value: Variant, staged: &mut Vec<(NodeId, DataValue)>) {
        if self.last.get(&id) != Some(&value) {
            self.last.insert(id.clone(), value.clone());
            staged.push((id, DataValue::new_now(value)));
        }
    }

    /// Writes the staged values in one write (subscribed clients are notified by the stack,
    /// all of them in the same publish), then raises the events they go with.
    pub(crate) fn publish(&mut self, staged: &mut Vec<(NodeId, DataValue)>) {
        if !staged.is_empty() {
            let values: Vec<(NodeId, DataValue)> = std::mem::take(staged);
            let items = values.iter().map(|(id, dv)| (id, None, dv.clone()));
            if let Err(e) = self.manager.set_values(&self.subscriptions, items) {
                tracing::debug!(status = %e, "OPC UA: a value could not be set");
            }
        }
        self.emit();
    }
}

/// The message of the history row an event is (none: the event is no row of the events
/// list, see `plant::event_of`).
fn stored_message(e: &PlantEvent) -> Option<String> {
    match e {
        PlantEvent::Alarm { message, .. }
        | PlantEvent::LearningFrozen {
            reason: message, ..
        } => Some(message.clone()),
        PlantEvent::TableRefused {
            version: None,
            reason,
            ..
        } => Some(reason.clone()),
        _ => None,
    }
}

/// An event waiting for its values to be written.
struct Pending {
    node: NodeId,
    event: BaseEventType,
}

/// A result value with its part's time as SourceTimestamp; none: not known for this part
/// yet (`BadWaitingForInitialData`, never an older part's value).
fn result_value(value: Option<Variant>, at: jiff::Timestamp) -> DataValue {
    let source = date_time(at);
    let now = DateTime::now();
    match value {
        Some(v) => DataValue {
            value: Some(v),
            status: Some(StatusCode::Good),
            source_timestamp: Some(source),
            server_timestamp: Some(now),
            ..DataValue::default()
        },
        None => DataValue {
            // The stack returns a value's status only with a value: an empty one.
            value: Some(Variant::Empty),
            status: Some(StatusCode::BadWaitingForInitialData),
            source_timestamp: Some(source),
            server_timestamp: Some(now),
            ..DataValue::default()
        },
    }
}

/// A part's result variables from its event (`MaxError` from the status, when it already
/// shows the part; the repeatability when the gauge gave one).
fn result_values(
    e: &PlantEvent,
    max_error_um: Option<f64>,
) -> Vec<(FeatureValue, Option<Variant>)> {
    let PlantEvent::PartAnalysed {
        machine,
        feature,
        part,
        at: at_ms,
        verdict,
        max_profile_error_um,
        base_radius_error_um,
        phase_error_deg,
        repeatability_um,
        ground_with_version,
    } = e
    else {
        return Vec::new();
    };
    let latest = serde_json::json!({
        "machine": machine, "feature": feature, "part": part,
        "time_ms": at_ms.as_millisecond(), "verdict": verdict.as_str(),
        "max_error_um": max_error_um,
        "max_profile_error_um": max_profile_error_um,
        "base_radius_error_um": base_radius_error_um,
        "phase_error_deg": phase_error_deg,
        "repeatability_um": repeatability_um,
        "ground_with_version": ground_with_version,
    });
    vec![
        (FeatureValue::PartId, Some(Variant::from(part.to_string()))),
        (FeatureValue::Time, Some(Variant::from(date_time(*at_ms)))),
        (FeatureValue::Verdict, Some(Variant::from(verdict.as_str()))),
        (FeatureValue::MaxErrorUm, max_error_um.map(Variant::from)),
        (
            FeatureValue::ProfileErrorUm,
            Some(Variant::from(*max_profile_error_um)),
        ),
        (
            FeatureValue::SizeErrorUm,
            Some(Variant::from(*base_radius_error_um)),
        ),
        (
            FeatureValue::PhaseErrorDeg,
            Some(Variant::from(*phase_error_deg)),
        ),
        (
            FeatureValue::RepeatabilityUm,
            repeatability_um.map(Variant::from),
        ),
        (
            FeatureValue::LatestResult,
            Some(Variant::from(latest.to_string())),
        ),
    ]
}

/// A table version as the address space's Int64 shows it: 0 for none (the node's
/// documented value before the first table).
fn version_value(v: Option<camloop_core::ids::TableVersion>) -> i64 {
    v.map_or(0, |v| i64::try_from(v.get()).unwrap_or(i64::MAX))
}

/// The loop's state as a feature status gives it (a part's result is its event's).
fn status_values(s: &FeatureView) -> Vec<(FeatureValue, Variant)> {
    let v = vec![
        (
            FeatureValue::TableVersionInForce,
            Variant::from(version_value(s.in_force_version)),
        ),
        (
            FeatureValue::WaitingVersion,
            Variant::from(version_value(s.waiting_version)),
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
    v
}

/// Runs the feed until shutdown: every event at once, the stored results as they are read
/// at start, the status every [`REFRESH_EVERY`].
pub(crate) async fn run(
    mut feed: Feed,
    (mut rx, mut seeds): (
        mpsc::Receiver<PlantEvent>,
        mpsc::Receiver<Vec<super::seed::Seed>>,
    ),
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
            Some(batch) = seeds.recv() => {
                for seed in &batch {
                    feed.seed(seed, &mut staged);
                }
            }
            _ = tick.tick() => feed.refresh(&mut staged),
            _ = shutdown.changed() => return,
        }
        feed.publish(&mut staged);
    }
}
