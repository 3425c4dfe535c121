//! Who listens for events on camloop's notifiers (the `Machines` folder and each machine), so
//! that an event reaches every monitored item exactly once. The stack's own event path adds
//! the `Server` object's listeners to every node it is asked about, so an event raised on a
//! machine, on `Machines` and on `Server` reached a `Server` listener three times; camloop
//! now hands the stack the `Server` object only and delivers to its own notifiers' items here.
//! Also the events' EventIds ([`EventIds`]), made from what the history keeps of each event.

use std::collections::HashMap;

use opcua::nodes::Event;
use opcua::server::node_manager::MonitoredItemRef;
use opcua::server::{MonitoredItemHandle, SubscriptionCache};
use opcua::sync::Mutex;
use opcua::types::NodeId;

/// One event monitored item on one of camloop's notifiers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Listener {
    session_id: u32,
    handle: MonitoredItemHandle,
}

/// The event monitored items on camloop's notifiers, by notifier.
#[derive(Default)]
pub(crate) struct Listeners {
    by_node: Mutex<HashMap<NodeId, Vec<Listener>>>,
}

impl Listeners {
    /// Records an event monitored item the stack created on `node` for `session_id`.
    pub(crate) fn add(&self, session_id: u32, node: NodeId, handle: MonitoredItemHandle) {
        let mut by_node = self.by_node.lock();
        let list = by_node.entry(node).or_default();
        let listener = Listener { session_id, handle };
        if !list.contains(&listener) {
            list.push(listener);
        }
    }

    /// Forgets deleted monitored items.
    pub(crate) fn remove(&self, items: &[&MonitoredItemRef]) {
        let mut by_node = self.by_node.lock();
        for item in items {
            if let Some(list) = by_node.get_mut(item.node_id()) {
                list.retain(|l| l.handle != item.handle());
            }
        }
        by_node.retain(|_, list| !list.is_empty());
    }

    /// Delivers `event`, once, to every listener on each of `nodes`; the `Server` object's
    /// listeners are the stack's (see [`Listeners`]). A listener whose session or
    /// subscription has gone is forgotten.
    pub(crate) fn notify(
        &self,
        subscriptions: &SubscriptionCache,
        type_tree: &opcua::sync::RwLock<opcua::nodes::DefaultTypeTree>,
        nodes: &[&NodeId],
        event: &dyn Event,
    ) {
        let targets: Vec<Listener> = {
            let by_node = self.by_node.lock();
            nodes
                .iter()
                .filter_map(|n| by_node.get(*n))
                .flatten()
                .copied()
                .collect()
        };
        let mut gone = Vec::new();
        for l in targets {
            let Some(session) = subscriptions.get_session_subscriptions(l.session_id) else {
                gone.push(l);
                continue;
            };
            // The stack's order: the session's subscriptions first, then the type tree.
            let mut session = session.lock();
            let Some(sub) = session.get_mut(l.handle.subscription_id) else {
                gone.push(l);
                continue;
            };
            let tree = type_tree.read();
            sub.notify_event(&l.handle.monitored_item_id, event, &*tree);
        }
        if !gone.is_empty() {
            let mut by_node = self.by_node.lock();
            for list in by_node.values_mut() {
                list.retain(|l| !gone.contains(l));
            }
            by_node.retain(|_, list| !list.is_empty());
        }
    }
}

/// OPC UA EventIds made from what the history keeps of an event, so that no map from
/// EventId to camloop's event is needed and an EventId a client got before a restart still
/// names the same event after it (OPC 10000-5 asks an EventId to be unique per event; it
/// says nothing of how it is made). The layout, 30 bytes:
///
/// ```text
/// 0      format (1)
/// 1      'h': the event is a row of the history (alarms, freezes, refusals), 'o': another
/// 2..10  the event's time, Unix ms, big-endian i64
/// 10..26 the first 16 bytes of SHA-256 over the machine and the message (a row: the
///        history's message; another: the type, source and message too)
/// 26..30 the occurrence: how many events with the same time and digest came before it
/// ```
///
/// The occurrence tells apart events the history cannot (the same machine, millisecond and
/// text); the feed counts them in the order the loops journal them, which is the rows' order
/// of ids.
#[derive(Default)]
pub(crate) struct EventIds {
    seen: HashMap<(i64, Digest), u32>,
    order: std::collections::VecDeque<(i64, Digest)>,
}

/// The digest part of an EventId.
type Digest = [u8; 16];

const FORMAT: u8 = 1;
const ROW: u8 = b'h';
const OTHER: u8 = b'o';
const LEN: usize = 30;

/// Occurrences remembered: far more than one millisecond's events of a plant.
const REMEMBERED: usize = 10_000;

/// What an EventId of a history row says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct RowEventId {
    pub(crate) at: jiff::Timestamp,
    digest: Digest,
    pub(crate) occurrence: u32,
}

impl RowEventId {
    /// The EventId's parts when it is a row's in this format (none: another event's, or
    /// not one this server makes).
    pub(crate) fn parse(bytes: &[u8]) -> Option<Self> {
        if bytes.len() != LEN || bytes[0] != FORMAT || bytes[1] != ROW {
            return None;
        }
        let at_ms = i64::from_be_bytes(bytes[2..10].try_into().ok()?);
        Some(Self {
            at: jiff::Timestamp::from_millisecond(at_ms).ok()?,
            digest: bytes[10..26].try_into().ok()?,
            occurrence: u32::from_be_bytes(bytes[26..30].try_into().ok()?),
        })
    }

    /// Whether a history row of `machine` with `message` is the one this EventId names
    /// (up to the occurrence, which is the caller's to count).
    pub(crate) fn matches(&self, machine: &str, message: &str) -> bool {
        digest(&[machine, message]) == self.digest
    }
}

fn digest(parts: &[&str]) -> Digest {
    use sha2::Digest as _;
    let mut h = sha2::Sha256::new();
    for p in parts {
        h.update(p.as_bytes());
        h.update([0u8]);
    }
    let full = h.finalize();
    let mut out = [0u8; 16];
    out.copy_from_slice(&full[..16]);
    out
}

impl EventIds {
    /// The EventId of a history row: `machine`'s event at `at` with the history's
    /// `message`.
    pub(crate) fn row(&mut self, machine: &str, at: jiff::Timestamp, message: &str) -> Vec<u8> {
        self.make(ROW, at, digest(&[machine, message]))
    }

    /// The EventId of an event that is no history row (a result, a delivery, a dressing).
    pub(crate) fn other(
        &mut self,
        (machine, source, ty): (&str, &str, &str),
        at: jiff::Timestamp,
        message: &str,
    ) -> Vec<u8> {
        self.make(OTHER, at, digest(&[machine, source, ty, message]))
    }

    fn make(&mut self, kind: u8, at: jiff::Timestamp, digest: Digest) -> Vec<u8> {
        let key = (at.as_millisecond(), digest);
        let occurrence = match self.seen.get_mut(&key) {
            Some(n) => {
                *n = n.saturating_add(1);
                *n
            }
            None => {
                if self.order.len() == REMEMBERED
                    && let Some(old) = self.order.pop_front()
                {
                    self.seen.remove(&old);
                }
                self.order.push_back(key);
                self.seen.insert(key, 0);
                0
            }
        };
        let mut id = Vec::with_capacity(LEN);
        id.push(FORMAT);
        id.push(kind);
        id.extend_from_slice(&key.0.to_be_bytes());
        id.extend_from_slice(&digest);
        id.extend_from_slice(&occurrence.to_be_bytes());
        id
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(ms: i64) -> jiff::Timestamp {
        jiff::Timestamp::from_millisecond(ms).unwrap()
    }

    #[test]
    fn a_rows_event_id_is_the_same_in_another_process_and_names_its_row() {
        let mut first = EventIds::default();
        let mut second = EventIds::default();
        let id = first.row("M1", at(1_795_773_600_250), "rollback: IN1 to v2");
        assert_eq!(
            id,
            second.row("M1", at(1_795_773_600_250), "rollback: IN1 to v2")
        );
        assert_eq!(id.len(), LEN);
        let parsed = RowEventId::parse(&id).unwrap();
        assert_eq!(parsed.at, at(1_795_773_600_250));
        assert_eq!(parsed.occurrence, 0);
        assert!(parsed.matches("M1", "rollback: IN1 to v2"));
        assert!(!parsed.matches("M2", "rollback: IN1 to v2"));
        assert!(!parsed.matches("M1", "rollback: IN1 to v3"));
    }

    #[test]
    fn the_same_text_in_the_same_millisecond_gets_the_next_occurrence() {
        let mut ids = EventIds::default();
        let a = ids.row("M1", at(5), "same");
        let b = ids.row("M1", at(5), "same");
        let c = ids.row("M1", at(6), "same");
        assert_ne!(a, b);
        assert_eq!(RowEventId::parse(&b).unwrap().occurrence, 1);
        assert_eq!(RowEventId::parse(&c).unwrap().occurrence, 0);
    }

    #[test]
    fn other_events_are_no_rows_and_differ_from_rows() {
        let mut ids = EventIds::default();
        let row = ids.row("M1", at(5), "x");
        let other = ids.other(("M1", "IN1", "ResultReady"), at(5), "x");
        assert_ne!(row, other);
        assert_eq!(RowEventId::parse(&other), None);
        assert_eq!(RowEventId::parse(b"1700000000000-3"), None);
        assert_eq!(RowEventId::parse(&[]), None);
    }
}
