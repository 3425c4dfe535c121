//! The limits the OPC UA server advertises are ones a client can use: a Read of
//! `MaxNodesPerRead` nodes, a Browse of `MaxNodesPerBrowse` and a CreateMonitoredItems of
//! `MaxMonitoredItemsPerCall` in one call each succeed (a Read of 1,001 nodes once failed
//! with `BadDecodingError` while 10,000 were advertised), and a write of thousands of values
//! reaches a subscriber whole: the server splits it into publish messages that fit (a
//! 328 kB publish was dropped whole before). The reading client's own limits are raised so
//! that only the server's are tested; the subscriber keeps the stack's default limits
//! (327,675 bytes a message), as most clients do.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::opcua_feed::{part, wait};
use crate::opcua_support::{connect_with, free_port, namespace, plant, value_nodes};
use camloop::names::{FeatureName, MachineName};
use camloop::service::metrics::Metrics;
use opcua::client::{ClientBuilder, DataChangeCallback, Session};
use opcua::types::{
    BrowseDescription, BrowseDirection, MonitoredItemCreateRequest, NodeId, ReadValueId,
    ReferenceTypeId, StatusCode, TimestampsToReturn, VariableId, Variant,
};

/// The plant: 50 machines × 8 features.
const MACHINES: usize = 50;
const FEATURES: usize = 8;

/// A part id of the longest length a gauge sends (32 characters, the gauges' rule that a
/// plant event's `PartId` holds), a serial number with its batch.
fn serial(m: &MachineName, f: &FeatureName) -> String {
    let id = format!("CS-{m}-{f}-LOT20261129-SN");
    format!("{id}{}", "0".repeat(32usize.saturating_sub(id.len())))
}

async fn limit(session: &Session, id: VariableId) -> usize {
    let read = session
        .read(
            &[ReadValueId::from(NodeId::from(id))],
            TimestampsToReturn::Neither,
            0.0,
        )
        .await
        .unwrap();
    match read[0].value {
        Some(Variant::UInt32(n)) => n as usize,
        ref other => panic!("{id:?}: {other:?}"),
    }
}

#[test]
fn the_advertised_limits_hold_and_a_large_write_reaches_the_subscriber_whole() {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let listen = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let machines = plant(MACHINES, FEATURES);
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    let sender = runtime
        .block_on(camloop::service::opcua_port::bench_server(
            listen,
            &dir.path().join("pki"),
            machines.clone(),
            Arc::new(Metrics::default()),
            Arc::new(tokio::sync::RwLock::new(None)),
            shutdown,
        ))
        .unwrap();
    let url = format!("opc.tcp://localhost:{port}/");
    let builder = ClientBuilder::new()
        .max_message_size(64 * 1024 * 1024)
        .max_chunk_count(0)
        .max_array_length(1_000_000);
    let session = runtime.block_on(connect_with(&url, dir.path().join("client"), builder));
    let subscriber = runtime.block_on(connect_with(
        &url,
        dir.path().join("subscriber"),
        ClientBuilder::new(),
    ));
    let ns = runtime.block_on(namespace(&session));
    let values = value_nodes(ns, &machines);
    let seen: Arc<Mutex<HashMap<NodeId, Vec<Variant>>>> = Arc::default();
    runtime.block_on(async {
        let per_read = limit(
            &session,
            VariableId::Server_ServerCapabilities_OperationLimits_MaxNodesPerRead,
        )
        .await;
        let per_browse = limit(
            &session,
            VariableId::Server_ServerCapabilities_OperationLimits_MaxNodesPerBrowse,
        )
        .await;
        let per_call = limit(
            &session,
            VariableId::Server_ServerCapabilities_OperationLimits_MaxMonitoredItemsPerCall,
        )
        .await;
        assert!(per_read >= 1000 && per_browse > 0 && per_call > 0);

        let to_read: Vec<ReadValueId> = values
            .iter()
            .cycle()
            .take(per_read)
            .cloned()
            .map(ReadValueId::from)
            .collect();
        let read = session
            .read(&to_read, TimestampsToReturn::Both, 0.0)
            .await
            .unwrap_or_else(|e| panic!("a Read of MaxNodesPerRead = {per_read} nodes: {e}"));
        assert_eq!(read.len(), per_read);
        for dv in &read {
            let s = dv.status();
            assert!(
                s.is_good() || s == StatusCode::BadWaitingForInitialData,
                "{dv:?}"
            );
        }

        let to_browse: Vec<BrowseDescription> = values
            .iter()
            .cycle()
            .take(per_browse)
            .map(|n| BrowseDescription {
                node_id: n.clone(),
                browse_direction: BrowseDirection::Forward,
                reference_type_id: ReferenceTypeId::HierarchicalReferences.into(),
                include_subtypes: true,
                node_class_mask: 0,
                result_mask: 0x3f,
            })
            .collect();
        let browsed = session
            .browse(&to_browse, 100, None)
            .await
            .unwrap_or_else(|e| panic!("a Browse of MaxNodesPerBrowse = {per_browse} nodes: {e}"));
        assert_eq!(browsed.len(), per_browse);

        let sink = seen.clone();
        let on_value = DataChangeCallback::new(move |dv, item| {
            if let Some(v) = dv.value {
                let node = item.item_to_monitor().node_id.clone();
                sink.lock().unwrap().entry(node).or_default().push(v);
            }
        });
        // The client asks for no cap of its own: the server's keeps each message small.
        let sub = subscriber
            .create_subscription(Duration::from_millis(100), 600, 10, 0, 0, true, on_value)
            .await
            .unwrap();
        let items: Vec<MonitoredItemCreateRequest> =
            values.iter().cloned().map(Into::into).collect();
        for chunk in items.chunks(per_call) {
            let created = subscriber
                .create_monitored_items(sub, TimestampsToReturn::Both, chunk.to_vec())
                .await
                .unwrap_or_else(|e| {
                    panic!("{} items in one call (limit {per_call}): {e}", chunk.len())
                });
            assert!(created.iter().all(|c| c.result.status_code.is_good()));
        }
    });
    // One part for every feature of every machine, at once: thousands of values in a write
    // (3,668 values, 226,000 bytes as DataValues with their handles, measured once with these
    // 32-character part ids), which the server sends in messages of at most 500 notifications.
    for (m, fs) in &machines {
        for f in fs {
            sender.send(part(m.as_str(), f.as_str(), 1, &serial(m, f)));
        }
    }
    let part_ids: Vec<(NodeId, String)> = machines
        .iter()
        .flat_map(|(m, fs)| {
            fs.iter().map(move |f| {
                (
                    NodeId::new(ns, format!("Machines/{m}/Features/{f}/PartId")),
                    serial(m, f),
                )
            })
        })
        .collect();
    wait("every feature's part at its subscriber", || {
        let seen = seen.lock().unwrap();
        part_ids.iter().all(|(node, p)| {
            seen.get(node)
                .is_some_and(|v| v.contains(&Variant::from(p.clone())))
        })
    });
    let _ = stop.send(true);
    runtime.shutdown_timeout(Duration::from_secs(5));
}
