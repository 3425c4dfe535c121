//! The OPC UA feed seen by a client, in-process: the server as the bench runs it
//! (`camloop::service::opcua_port::bench_server`) and the `async-opcua` client. Every event
//! reaches every monitored item once (on `Server`, `Machines` and the machine at once); the
//! notifier hierarchy is browsable; a result's variables never mix two parts, never go back
//! to an older part while the status lags, and share their part's time as SourceTimestamp;
//! before a feature's first part its result variables say `BadWaitingForInitialData`. The
//! server's certificate carries the configured subject and BuildDate is the build's.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use camloop::names::{FeatureName, MachineName};
use camloop::service::metrics::Metrics;
use camloop::store::Verdict;
use camloop_loop::PlantEvent;
use opcua::client::{ClientBuilder, DataChangeCallback, EventCallback, Session};
use opcua::types::{
    AttributeId, BrowseDescription, BrowseDirection, ContentFilter, DataValue, DateTime,
    EventFilter, ExtensionObject, MonitoredItemCreateRequest, MonitoringMode, MonitoringParameters,
    NodeId, ObjectId, ObjectTypeId, ReadValueId, ReferenceTypeId, SimpleAttributeOperand,
    StatusCode, TimestampsToReturn, Variant,
};

/// The longest a condition may take (a loaded 2-core machine): a failure, not a pace.
const BOUND: Duration = Duration::from_secs(60);

/// Parts fed for the one feature watched.
const PARTS: usize = 40;

pub(crate) use crate::opcua_support::{connect_with, free_port, namespace};

pub(crate) fn name<T: std::str::FromStr>(s: &str) -> T
where
    T::Err: std::fmt::Debug,
{
    s.parse().unwrap()
}

/// A part's time: parts a second apart from a fixed instant (to the millisecond).
fn part_at(k: usize) -> jiff::Timestamp {
    jiff::Timestamp::from_millisecond(1_795_773_600_000 + 1000 * k as i64).unwrap()
}

pub(crate) fn part(machine: &str, feature: &str, k: usize, part: &str) -> PlantEvent {
    PlantEvent::PartAnalysed {
        machine: name(machine),
        feature: name(feature),
        part: part.parse().unwrap(),
        at: part_at(k),
        verdict: Verdict::Pass,
        max_profile_error_um: k as f64 * 0.5,
        base_radius_error_um: 0.1,
        phase_error_deg: 0.001,
        ground_with_version: camloop::core::ids::TableVersion::new(1),
        repeatability_um: Some(0.3),
    }
}

pub(crate) async fn connect(url: &str, pki: std::path::PathBuf) -> Arc<Session> {
    connect_with(url, pki, ClientBuilder::new()).await
}

fn event_item(node: NodeId) -> MonitoredItemCreateRequest {
    let filter = EventFilter {
        select_clauses: Some(vec![
            SimpleAttributeOperand::new_value(ObjectTypeId::BaseEventType, "EventId"),
            SimpleAttributeOperand::new_value(ObjectTypeId::BaseEventType, "Message"),
        ]),
        where_clause: ContentFilter::default(),
    };
    MonitoredItemCreateRequest::new(
        ReadValueId {
            node_id: node,
            attribute_id: AttributeId::EventNotifier as u32,
            ..Default::default()
        },
        MonitoringMode::Reporting,
        MonitoringParameters {
            sampling_interval: 0.0,
            filter: ExtensionObject::from_message(filter),
            queue_size: 1000,
            discard_oldest: true,
            ..Default::default()
        },
    )
}

/// What the client received: events per watched notifier, values per watched variable.
#[derive(Default)]
struct Seen {
    events: HashMap<NodeId, Vec<(Vec<u8>, String)>>,
    values: HashMap<NodeId, Vec<DataValue>>,
}

pub(crate) fn wait(what: &str, mut ready: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ready() {
        assert!(start.elapsed() < BOUND, "{what} not within {BOUND:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

async fn browse_targets(session: &Session, from: NodeId, ty: ReferenceTypeId) -> Vec<NodeId> {
    let result = session
        .browse(
            &[BrowseDescription {
                node_id: from,
                browse_direction: BrowseDirection::Forward,
                reference_type_id: ty.into(),
                include_subtypes: false,
                node_class_mask: 0,
                result_mask: 0x3f,
            }],
            1000,
            None,
        )
        .await
        .unwrap();
    result[0]
        .references
        .iter()
        .flatten()
        .map(|r| r.node_id.node_id.clone())
        .collect()
}

#[test]
fn events_come_once_per_item_and_results_are_never_torn() {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let listen = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let metrics = Arc::new(Metrics::default());
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    let machines: Vec<(MachineName, Vec<FeatureName>)> = vec![
        (name("M1"), vec![name("F1"), name("F2")]),
        (name("M2"), vec![name("F1")]),
    ];
    let sender = runtime
        .block_on(camloop::service::opcua_port::bench_server(
            listen,
            &dir.path().join("pki"),
            machines,
            metrics.clone(),
            Arc::new(tokio::sync::RwLock::new(None)),
            shutdown,
        ))
        .unwrap();
    let url = format!("opc.tcp://localhost:{port}/");
    let session = runtime.block_on(connect(&url, dir.path().join("client")));
    let ns = runtime.block_on(namespace(&session));
    let id = |path: &str| NodeId::new(ns, path.to_string());
    let server: NodeId = ObjectId::Server.into();
    let notifiers = [server.clone(), id("Machines"), id("Machines/M1")];
    let watched = ["PartId", "Time", "Verdict", "ProfileError", "LatestResult"]
        .map(|v| id(&format!("Machines/M1/Features/F1/{v}")));

    // Identity: the certificate's subject is the config's (not the library's sample
    // subject), and BuildDate is the build's, not the process's start.
    let der = std::fs::read(dir.path().join("pki/own/cert.der")).unwrap();
    let cert = opcua::crypto::X509::from_der(&der).unwrap();
    let subject = cert.subject_name();
    assert!(subject.contains("O=camloop"), "{subject}");
    assert!(
        !subject.contains("C=IE") && !subject.contains("Dublin"),
        "{subject}"
    );
    assert!(cert.is_hostname_valid("localhost").is_ok(), "{subject}");
    let valid = cert.not_after().unwrap() - cert.not_before().unwrap();
    assert_eq!(valid.num_days(), 365, "{subject}");
    let build = runtime
        .block_on(session.read(
            &[ReadValueId::from(NodeId::from(
                opcua::types::VariableId::Server_ServerStatus_BuildInfo_BuildDate,
            ))],
            TimestampsToReturn::Neither,
            0.0,
        ))
        .unwrap();
    let built_s: i64 = env!("CAMLOOP_BUILD_EPOCH_S").parse().unwrap();
    let built = opcua_time(jiff::Timestamp::from_second(built_s).unwrap());
    assert_eq!(build[0].value, Some(Variant::from(built)), "{build:?}");

    // Before any part: the result says it waits for its first value.
    let before = runtime
        .block_on(session.read(
            &watched.clone().map(ReadValueId::from),
            TimestampsToReturn::Both,
            0.0,
        ))
        .unwrap();
    for (node, dv) in watched.iter().zip(&before) {
        assert_eq!(
            dv.status(),
            StatusCode::BadWaitingForInitialData,
            "{node}: {dv:?}"
        );
        assert!(
            matches!(dv.value, None | Some(Variant::Empty)),
            "{node}: {dv:?}"
        );
    }

    // The notifier hierarchy: Server → Machines → each machine → its features.
    let from_server = runtime.block_on(browse_targets(
        &session,
        server.clone(),
        ReferenceTypeId::HasNotifier,
    ));
    assert!(from_server.contains(&id("Machines")), "{from_server:?}");
    let from_machines = runtime.block_on(browse_targets(
        &session,
        id("Machines"),
        ReferenceTypeId::HasNotifier,
    ));
    for m in ["Machines/M1", "Machines/M2"] {
        assert!(from_machines.contains(&id(m)), "{m}: {from_machines:?}");
    }
    let sources = runtime.block_on(browse_targets(
        &session,
        id("Machines/M1"),
        ReferenceTypeId::HasEventSource,
    ));
    assert!(
        sources.contains(&id("Machines/M1/Features/F1")),
        "{sources:?}"
    );

    let seen = Arc::new(Mutex::new(Seen::default()));
    let (events_seen, values_seen) = (seen.clone(), seen.clone());
    runtime.block_on(async {
        let on_event = EventCallback::new(move |fields, item| {
            let fields = fields.unwrap_or_default();
            let event_id = match fields.first() {
                Some(Variant::ByteString(b)) => b.value.clone().unwrap_or_default(),
                other => panic!("no EventId: {other:?}"),
            };
            let message = match fields.get(1) {
                Some(Variant::LocalizedText(t)) => t.text.to_string(),
                other => panic!("no Message: {other:?}"),
            };
            let node = item.item_to_monitor().node_id.clone();
            let mut seen = events_seen.lock().unwrap();
            seen.events
                .entry(node)
                .or_default()
                .push((event_id, message));
        });
        let events = session
            .create_subscription(Duration::from_millis(100), 600, 10, 0, 0, true, on_event)
            .await
            .unwrap();
        let created = session
            .create_monitored_items(
                events,
                TimestampsToReturn::Both,
                notifiers.iter().cloned().map(event_item).collect(),
            )
            .await
            .unwrap();
        for c in &created {
            assert!(c.result.status_code.is_good(), "{:?}", c.result);
        }
        let on_value = DataChangeCallback::new(move |dv, item| {
            let node = item.item_to_monitor().node_id.clone();
            values_seen
                .lock()
                .unwrap()
                .values
                .entry(node)
                .or_default()
                .push(dv);
        });
        let values = session
            .create_subscription(Duration::from_millis(100), 600, 10, 0, 0, true, on_value)
            .await
            .unwrap();
        session
            .create_monitored_items(
                values,
                TimestampsToReturn::Both,
                watched.iter().cloned().map(|n| n.into()).collect(),
            )
            .await
            .unwrap();
    });

    // The status lags (it still shows an older part than the events): the refresh must not
    // write it over the parts' values.
    metrics.update_feature(&name("M1"), &name("F1"), |f| {
        f.last_part = Some("OLD".parse().unwrap());
        f.last_max_error_um = Some(9.0);
        f.last_profile_error_um = Some(9.0);
    });
    for k in 0..PARTS {
        sender.send(part("M1", "F1", k, &format!("P-{k}")));
        // Another machine's event reaches Server and Machines, not Machines/M1.
        if k % 10 == 0 {
            sender.send(part("M2", "F1", k, &format!("Q-{k}")));
        }
        // Let the 250 ms status refresh run between some of the parts.
        if k % 8 == 0 {
            std::thread::sleep(Duration::from_millis(300));
        }
    }
    sender.send(part("M1", "F1", PARTS, "END"));
    wait("the last part's event on every notifier", || {
        let seen = seen.lock().unwrap();
        notifiers.iter().all(|n| {
            seen.events
                .get(n)
                .is_some_and(|e| e.iter().any(|(_, m)| m.contains("\"END\"")))
        })
    });
    wait("the last part's PartId", || {
        let seen = seen.lock().unwrap();
        seen.values.get(&watched[0]).is_some_and(|v| {
            v.iter()
                .any(|dv| dv.value == Some(Variant::from("END".to_string())))
        })
    });

    let seen = seen.lock().unwrap();
    let other_machine = PARTS.div_ceil(10);
    for (node, expected) in [
        (&notifiers[0], PARTS + 1 + other_machine),
        (&notifiers[1], PARTS + 1 + other_machine),
        (&notifiers[2], PARTS + 1),
    ] {
        let events = &seen.events[node];
        let mut ids: Vec<&Vec<u8>> = events.iter().map(|(id, _)| id).collect();
        ids.sort();
        ids.dedup();
        assert_eq!(ids.len(), events.len(), "{node}: an event came twice");
        assert_eq!(events.len(), expected, "{node}: events lost or foreign");
    }
    // Every value notification carries its part's time, and parts only move forward.
    for node in &watched {
        let mut last = None;
        for dv in &seen.values[node] {
            let source = dv.source_timestamp.expect("a SourceTimestamp");
            assert!(last.is_none_or(|l| l <= source), "{node}: went back");
            last = Some(source);
            let k = (0..=PARTS)
                .find(|k| opcua_time(part_at(*k)) == source)
                .unwrap_or_else(|| panic!("{node}: {source} is no part's time: {dv:?}"));
            let expected_part = if k == PARTS {
                "END".to_string()
            } else {
                format!("P-{k}")
            };
            match node.to_string().rsplit('/').next().unwrap() {
                "PartId" => assert_eq!(dv.value, Some(Variant::from(expected_part))),
                "Time" => assert_eq!(dv.value, Some(Variant::from(source))),
                "LatestResult" => {
                    let Some(Variant::String(s)) = &dv.value else {
                        panic!("{dv:?}")
                    };
                    let json: serde_json::Value = serde_json::from_str(s.as_ref()).unwrap();
                    assert_eq!(json["part"], expected_part.as_str());
                }
                _ => {}
            }
        }
    }
    drop(seen);
    let _ = stop.send(true);
    runtime.shutdown_timeout(Duration::from_secs(5));
}

/// An instant as OPC UA's DateTime (100 ns ticks from 1601).
fn opcua_time(at: jiff::Timestamp) -> DateTime {
    DateTime::from(
        at.as_millisecond()
            .saturating_add(11_644_473_600_000)
            .saturating_mul(10_000),
    )
}
