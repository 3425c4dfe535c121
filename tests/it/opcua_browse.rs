//! Browse of camloop's nodes, in-process (the server as the bench runs it, the `async-opcua`
//! client): machines come as configured and features in grinding order, not in the
//! library's hash order (which changed at every start), also across a continuation point;
//! a node id of camloop's namespace that names no node is `BadNodeIdUnknown`, not `Good`
//! with no references.

use std::sync::Arc;

use crate::opcua_support::{connect_with, free_port, namespace};
use camloop::names::{FeatureName, MachineName};
use camloop::service::metrics::Metrics;
use opcua::client::{ClientBuilder, Session};
use opcua::types::{
    BrowseDescription, BrowseDirection, BrowseResult, NodeId, ReferenceTypeId, StatusCode,
};

/// Configured machines, not in name order.
const MACHINES: [&str; 4] = ["M07", "M02", "M11", "M01"];
/// A camshaft's lobes in grinding order, not in name order.
const FEATURES: [&str; 8] = ["IN1", "EX1", "IN2", "EX2", "IN3", "EX3", "IN4", "EX4"];

fn description(node: NodeId, ty: ReferenceTypeId) -> BrowseDescription {
    BrowseDescription {
        node_id: node,
        browse_direction: BrowseDirection::Forward,
        reference_type_id: ty.into(),
        include_subtypes: true,
        node_class_mask: 0,
        result_mask: 0x3f,
    }
}

/// The browse names of a Browse's references, following continuation points.
async fn names(
    session: &Session,
    node: NodeId,
    ty: ReferenceTypeId,
    per_reply: u32,
) -> Vec<String> {
    let mut result: BrowseResult = session
        .browse(&[description(node, ty)], per_reply, None)
        .await
        .unwrap()
        .remove(0);
    assert_eq!(result.status_code, StatusCode::Good);
    let mut names = Vec::new();
    loop {
        for r in result.references.iter().flatten() {
            names.push(r.browse_name.name.to_string());
        }
        if result.continuation_point.is_null() {
            return names;
        }
        result = session
            .browse_next(false, &[result.continuation_point.clone()])
            .await
            .unwrap()
            .remove(0);
        assert_eq!(result.status_code, StatusCode::Good);
    }
}

#[test]
fn browse_gives_configured_and_grinding_order_and_unknown_nodes_are_unknown() {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let features: Vec<FeatureName> = FEATURES.iter().map(|f| f.parse().unwrap()).collect();
    let machines: Vec<(MachineName, Vec<FeatureName>)> = MACHINES
        .iter()
        .map(|m| (m.parse().unwrap(), features.clone()))
        .collect();
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    runtime.block_on(async {
        let _sender = camloop::service::opcua_port::bench_server(
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
        let ns = namespace(&session).await;
        let id = |path: &str| NodeId::new(ns, path.to_string());
        let organizes = ReferenceTypeId::Organizes;
        let components = ReferenceTypeId::HasComponent;

        let machines = names(&session, id("Machines"), organizes, 0).await;
        assert_eq!(machines, MACHINES, "machines as configured");
        for m in MACHINES {
            let features = id(&format!("Machines/{m}/Features"));
            // Three a reply: the order holds across the continuation points.
            for per_reply in [0, 3] {
                let found = names(&session, features.clone(), components, per_reply).await;
                assert_eq!(found, FEATURES, "{m}'s features, {per_reply} a reply");
            }
        }
        let values = names(&session, id("Machines/M02/Features/EX3"), components, 0).await;
        assert_eq!(
            values[..4],
            ["PartId", "Time", "Verdict", "MaxError"],
            "{values:?}"
        );

        let unknown = [
            id("Machines/M99"),
            id("Machines/M02/Features/EX9"),
            id("Machines/M02/Features/EX3/NoSuchValue"),
        ];
        let described: Vec<BrowseDescription> = unknown
            .iter()
            .map(|n| description(n.clone(), ReferenceTypeId::HierarchicalReferences))
            .collect();
        let results = session.browse(&described, 0, None).await.unwrap();
        for (node, r) in unknown.iter().zip(&results) {
            assert_eq!(r.status_code, StatusCode::BadNodeIdUnknown, "{node}");
        }
        // A known node among them still answers.
        let mixed = [
            description(id("Machines/M99"), organizes),
            description(id("Machines"), organizes),
        ];
        let results = session.browse(&mixed, 0, None).await.unwrap();
        assert_eq!(results[0].status_code, StatusCode::BadNodeIdUnknown);
        assert_eq!(results[1].status_code, StatusCode::Good);
        assert_eq!(
            results[1].references.as_ref().map_or(0, Vec::len),
            MACHINES.len()
        );
    });
    let _ = stop.send(true);
    runtime.shutdown_timeout(std::time::Duration::from_secs(5));
}
