//! Who listens for events on camloop's notifiers (the `Machines` folder and each machine), so
//! that an event reaches every monitored item exactly once. The stack's own event path adds
//! the `Server` object's listeners to every node it is asked about, so an event raised on a
//! machine, on `Machines` and on `Server` reached a `Server` listener three times; camloop
//! now hands the stack the `Server` object only and delivers to its own notifiers' items here.

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

/// Where a raised event came from in the history: enough to find its stored row.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Origin {
    pub(crate) machine: crate::names::MachineName,
    pub(crate) at_ms: jiff::Timestamp,
    pub(crate) message: String,
}

/// The OPC UA EventIds of the newest events that are rows of the history (alarms, freezes,
/// refusals), so that `AcknowledgeEvent` takes the EventId a client got as well as camloop's
/// id. Bounded: an older EventId is answered `BadNotFound`.
#[derive(Default)]
pub(crate) struct Recent {
    ids: Mutex<std::collections::VecDeque<(Vec<u8>, Origin)>>,
}

/// EventIds remembered (a plant's alarms of hours).
const RECENT: usize = 10_000;

impl Recent {
    pub(crate) fn remember(&self, event_id: Vec<u8>, origin: Origin) {
        let mut ids = self.ids.lock();
        if ids.len() == RECENT {
            ids.pop_front();
        }
        ids.push_back((event_id, origin));
    }

    pub(crate) fn get(&self, event_id: &[u8]) -> Option<Origin> {
        let ids = self.ids.lock();
        ids.iter()
            .rev()
            .find(|(id, _)| id.as_slice() == event_id)
            .map(|(_, o)| o.clone())
    }
}
