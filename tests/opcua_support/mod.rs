//! The OPC UA client side shared by the in-process OPC UA tests (`tests/it/opcua_*.rs`) and
//! the bench (`benches/opcua.rs`): the plant of machines × features, every value node of it,
//! a SignAndEncrypt anonymous session and camloop's namespace index.

#![allow(dead_code)]

use std::sync::Arc;

use camloop::names::{FeatureName, MachineName};
use opcua::client::{ClientBuilder, IdentityToken, Session};
use opcua::crypto::SecurityPolicy;
use opcua::types::{
    MessageSecurityMode, NodeId, ReadValueId, TimestampsToReturn, UserTokenPolicy, Variant,
};

/// The value variables of every feature (see the address space in docs/src/opcua.md).
pub const VALUES: [&str; 15] = [
    "PartId",
    "Time",
    "Verdict",
    "MaxError",
    "ProfileError",
    "SizeError",
    "PhaseError",
    "Repeatability",
    "LatestResult",
    "TableVersionInForce",
    "WaitingVersion",
    "LearningFrozen",
    "FrozenReason",
    "BlockedByGuard",
    "GuardReason",
];

/// A free TCP port on localhost for the server.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .expect("a free port")
        .local_addr()
        .expect("its address")
        .port()
}

/// `machines` machines `M00`, `M01`, … of `features` features `F1`, `F2`, … each.
pub fn plant(machines: usize, features: usize) -> Vec<(MachineName, Vec<FeatureName>)> {
    let features: Vec<FeatureName> = (1..=features)
        .map(|f| format!("F{f}").parse().expect("a feature name"))
        .collect();
    (0..machines)
        .map(|m| {
            let name = format!("M{m:02}").parse().expect("a machine name");
            (name, features.clone())
        })
        .collect()
}

/// Every value node ([`VALUES`]) of every feature of `machines`, in camloop's namespace `ns`.
pub fn value_nodes(ns: u16, machines: &[(MachineName, Vec<FeatureName>)]) -> Vec<NodeId> {
    machines
        .iter()
        .flat_map(|(m, fs)| {
            fs.iter().flat_map(move |f| {
                VALUES
                    .iter()
                    .map(move |v| NodeId::new(ns, format!("Machines/{m}/Features/{f}/{v}")))
            })
        })
        .collect()
}

/// A SignAndEncrypt anonymous session from `builder` (its limits as the caller set them),
/// its client certificate made in `pki`, the server's trusted.
pub async fn connect_with(
    url: &str,
    pki: std::path::PathBuf,
    builder: ClientBuilder,
) -> Arc<Session> {
    let mut client = builder
        .application_name("camloop test client")
        .application_uri("urn:camloop:test-client")
        .product_uri("urn:camloop:test-client")
        .pki_dir(pki)
        .create_sample_keypair(true)
        .trust_server_certs(true)
        .session_retry_limit(3)
        .client()
        .expect("an OPC UA client");
    let endpoint = (
        url,
        SecurityPolicy::Basic256Sha256.to_str(),
        MessageSecurityMode::SignAndEncrypt,
        UserTokenPolicy::anonymous(),
    );
    let (session, event_loop) = client
        .connect_to_matching_endpoint(endpoint, IdentityToken::Anonymous)
        .await
        .expect("a session");
    let _event_loop = event_loop.spawn();
    session.wait_for_connection().await;
    session
}

/// camloop's namespace index, from the server's namespace array.
pub async fn namespace(session: &Session) -> u16 {
    let read = session
        .read(
            &[ReadValueId::from(NodeId::from(
                opcua::types::VariableId::Server_NamespaceArray,
            ))],
            TimestampsToReturn::Neither,
            0.0,
        )
        .await
        .expect("the namespace array");
    let Some(Variant::Array(a)) = read[0].value.clone() else {
        panic!("no namespace array")
    };
    let index = a
        .values
        .iter()
        .position(|v| matches!(v, Variant::String(s) if s.as_ref() == "urn:camloop:ua"))
        .expect("camloop's namespace");
    u16::try_from(index).expect("a namespace index")
}
