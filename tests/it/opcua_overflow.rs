//! Plant events the OPC UA server's intake had to drop (it was full) are told: a client
//! watching `Server` gets `EventQueueOverflowEventType` events whose counts add up to every
//! event dropped, rather than a silent gap. In-process: the server as the bench runs it and
//! the `async-opcua` client.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::opcua_feed::{part, wait};
use crate::opcua_support::{connect_with, free_port};
use camloop::names::{FeatureName, MachineName};
use camloop::service::metrics::Metrics;
use opcua::client::{ClientBuilder, EventCallback};
use opcua::types::{
    AttributeId, ContentFilter, EventFilter, ExtensionObject, MonitoredItemCreateRequest,
    MonitoringMode, MonitoringParameters, NodeId, ObjectId, ObjectTypeId, ReadValueId,
    SimpleAttributeOperand, TimestampsToReturn, Variant,
};

/// Sends at most this many events waiting for the intake to refuse one: far more than its
/// 4096 places, so a feed that kept up with all of them would be a finding of its own.
const MOST_SENDS: usize = 2_000_000;

fn server_events() -> MonitoredItemCreateRequest {
    let filter = EventFilter {
        select_clauses: Some(vec![
            SimpleAttributeOperand::new_value(ObjectTypeId::BaseEventType, "EventType"),
            SimpleAttributeOperand::new_value(ObjectTypeId::BaseEventType, "Message"),
        ]),
        where_clause: ContentFilter::default(),
    };
    MonitoredItemCreateRequest::new(
        ReadValueId {
            node_id: ObjectId::Server.into(),
            attribute_id: AttributeId::EventNotifier as u32,
            ..Default::default()
        },
        MonitoringMode::Reporting,
        MonitoringParameters {
            sampling_interval: 0.0,
            filter: ExtensionObject::from_message(filter),
            queue_size: 10_000,
            discard_oldest: false,
            ..Default::default()
        },
    )
}

/// The count an overflow event's message gives (its first word).
fn count_of(message: &str) -> u64 {
    message
        .split_whitespace()
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("an overflow message without its count: {message}"))
}

#[test]
fn events_dropped_before_the_server_are_told_by_overflow_events() {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let machines: Vec<(MachineName, Vec<FeatureName>)> =
        vec![("M1".parse().unwrap(), vec!["IN1".parse().unwrap()])];
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    let overflow: NodeId = ObjectTypeId::EventQueueOverflowEventType.into();
    let told: Arc<Mutex<Vec<String>>> = Arc::default();
    let sender = runtime.block_on(async {
        let sender = camloop::service::opcua_port::bench_server(
            std::net::SocketAddr::from(([127, 0, 0, 1], port)),
            &dir.path().join("pki"),
            machines,
            Arc::new(Metrics::default()),
            Arc::new(tokio::sync::RwLock::new(None)),
            shutdown,
        )
        .await
        .unwrap();
        let url = format!("opc.tcp://localhost:{port}/");
        let session = connect_with(&url, dir.path().join("client"), ClientBuilder::new()).await;
        let sink = told.clone();
        let wanted = overflow.clone();
        let on_event = EventCallback::new(move |fields, _| {
            let fields = fields.unwrap_or_default();
            if let (Some(Variant::NodeId(ty)), Some(Variant::LocalizedText(text))) =
                (fields.first(), fields.get(1))
                && **ty == wanted
            {
                sink.lock().unwrap().push(text.text.to_string());
            }
        });
        let sub = session
            .create_subscription(Duration::from_millis(100), 600, 10, 0, 0, true, on_event)
            .await
            .unwrap();
        let created = session
            .create_monitored_items(sub, TimestampsToReturn::Both, vec![server_events()])
            .await
            .unwrap();
        assert!(created[0].result.status_code.is_good());
        (sender, session)
    });
    let (sender, session) = sender;
    // As fast as a thread can: the intake's 4096 places fill before the feed drains them.
    let mut sent = 0;
    while sender.refused() == 0 {
        assert!(
            sent < MOST_SENDS,
            "the intake never refused an event in {sent} sends"
        );
        sender.send(part("M1", "IN1", sent, &format!("P{sent}")));
        sent += 1;
    }
    let dropped = sender.refused();
    assert!(dropped > 0);
    wait("overflow events telling every dropped event", || {
        let total: u64 = told.lock().unwrap().iter().map(|m| count_of(m)).sum();
        assert!(total <= dropped, "told {total} dropped of {dropped}");
        total == dropped
    });
    drop(session);
    let _ = stop.send(true);
    runtime.shutdown_timeout(Duration::from_secs(5));
}
