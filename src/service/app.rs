//! What every adapter of the service shares: the history store, the metrics, the configured
//! machines and the way to the running ones, access settings. HTTP serves with it and OPC UA
//! calls the same write path through it, so neither adapter owns it.

use super::http::AuthState;
use super::machine::StoreHandle;
use super::metrics::Metrics;
use crate::names::{FeatureName, MachineName};
use std::collections::BTreeMap;
use std::sync::Arc;

#[derive(Clone)]
pub struct AppState {
    pub store: StoreHandle,
    pub metrics: Arc<Metrics>,
    /// Every configured machine with the names of the lobes or pins it grinds, in grinding
    /// order.
    pub machines: Arc<BTreeMap<MachineName, Vec<FeatureName>>>,
    /// Per machine (by name), the channel to its loop for write requests.
    /// The machines running on this instance (in a cluster, those it holds now).
    pub commands: crate::service::command::CommandRoutes,
    /// Access: the deprecated shared token, anonymous reading, sessions, the lockout.
    pub auth: Arc<AuthState>,
    /// How long a request body may take to arrive once its headers are in.
    pub body_timeout: std::time::Duration,
    /// The dashboard's view of each configured feature (bands, setup drawing).
    pub dashboard: crate::quality::FeatureSheets,
    /// In a cluster: the leases, for `GET /api/v1/cluster`.
    pub cluster: Option<crate::cluster::Leases>,
}

impl AppState {
    /// What the service's write path needs of this state.
    pub(crate) fn writes(&self) -> crate::service::command::Writes<'_> {
        crate::service::command::Writes {
            store: &self.store,
            metrics: &self.metrics,
            machines: &self.machines,
            routes: &self.commands,
            audit_seal: &self.auth.audit_seal,
        }
    }

    /// A state for an adapter serving without the HTTP API (the OPC UA benchmark): no
    /// machines, no shared token, no anonymous HTTP reading.
    #[doc(hidden)]
    pub fn without_http(store: StoreHandle, metrics: Arc<Metrics>) -> Self {
        Self {
            store,
            metrics,
            machines: Arc::default(),
            commands: Arc::default(),
            auth: Arc::new(AuthState::new(None, false)),
            body_timeout: std::time::Duration::from_secs(10),
            dashboard: Arc::default(),
            cluster: None,
        }
    }
}
