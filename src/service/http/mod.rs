//! The HTTP side of the service: health, Prometheus metrics, the engineers' read API on the
//! history store (JSON), and the two writes (rollback, dressing), which go as [`Command`]s to
//! the machine's loop. Errors carry a stable code and a message, never SQL text.
//!
//! - `access.rs`: who may call what: the route → role table, the layer that identifies the
//!   caller (bearer token, session, anonymous) and checks it, the lockout.
//! - `route_roles.rs`: the table of every route and the role it needs.
//! - `session.rs`: dashboard sign-in, sessions, CSRF tokens, sign-out.
//! - `audit.rs`: appending to the audit trail, and reading it.
//! - `api.rs`: the `{code, message}` error and the extractors that keep it.
//! - `code.rs`: [`ApiCode`], every error code with its HTTP status.
//! - `routes.rs`: the read handlers and their typed replies.
//! - `writes.rs`: the write handlers and the command hand-over.
//! - `server.rs`: the listener loop: header and body timeouts, the connection caps.
//! - `harden.rs`: the `Host` allow-list, the security headers, the per-client cap.
//! - `tls.rs`: HTTPS with rustls, reloaded on SIGHUP; the self-signed development pair.
//! - `openapi.rs`: the API description, derived by utoipa from the handlers and their types.
//! - `dashboard/`: the engineers' web pages, their live channel and downloads.

pub mod access;
mod api;
mod audit;
mod capability;
mod code;
mod dashboard;
mod harden;
mod openapi;
mod parts;
mod route_roles;
mod routes;
mod server;
mod session;
mod tls;
mod writes;

pub use access::{AuthState, Principal, ROUTES, RouteRule};
pub use api::{ApiError, ApiJson, ApiPath, ApiQuery, Authorized};
pub(crate) use api::{feature_name, machine_name};
pub use audit::record as record_audit;
pub use code::ApiCode;
pub use dashboard::{FeatureSheet, FeatureSheets, Stopping};
pub use harden::{CONTENT_SECURITY_POLICY, HostAllowList, Policy};
pub use routes::{LobeInfo, MachineInfo, MachinesReply};
pub use server::{HttpLimits, serve, serve_with};
pub use tls::{Tls, self_signed};
pub use writes::CommandReply;
// The writes and sign-in checks the OPC UA server goes through as well.
pub(crate) use access::Via;
pub(crate) use dashboard::ack as ack_write;
pub(crate) use session::{SignIn, password_sign_in};
pub(crate) use writes::{RollbackBody, rollback as rollback_write};

use super::machine::StoreHandle;
use super::metrics::Metrics;
use crate::names::{FeatureName, MachineName};
use axum::Router;
use axum::routing::{get, post};
use std::collections::BTreeMap;
use std::sync::Arc;
use tokio::sync::oneshot;

#[derive(Clone)]
pub struct AppState {
    pub store: StoreHandle,
    pub metrics: Arc<Metrics>,
    /// Every configured machine with the names of the lobes or pins it grinds, in grinding
    /// order.
    pub machines: Arc<BTreeMap<MachineName, Vec<FeatureName>>>,
    /// Per machine (by name), the channel to its loop for write requests.
    /// The machines running on this instance (in a cluster, those it holds now).
    pub commands: crate::service::runner::CommandRoutes,
    /// Access: the deprecated shared token, anonymous reading, sessions, the lockout.
    pub auth: Arc<AuthState>,
    /// How long a request body may take to arrive once its headers are in.
    pub body_timeout: std::time::Duration,
    /// The dashboard's view of each configured feature (bands, setup drawing).
    pub dashboard: FeatureSheets,
    /// In a cluster: the leases, for `GET /api/v1/cluster`.
    pub cluster: Option<crate::cluster::Leases>,
}

/// Where a machine's loop sends its answer to a [`Command`].
pub(crate) type Reply = oneshot::Sender<Result<CommandDone, CommandError>>;

/// A write request handed to a machine's loop, answered on `reply` when done. The HTTP
/// side has already checked the caller's role, the machine, the lobe (it is one the machine
/// grinds), and the values' ranges.
pub enum Command {
    /// Deliver stored table `version` of `lobe` again, as a new version under the table
    /// number not in use, and restore the correction it was made from.
    Rollback {
        lobe: FeatureName,
        version: i64,
        reply: Reply,
    },
    /// The wheel was dressed to this radius (mm, already within 5–1000), the dresser
    /// measured this infeed (µm, already within 0–1000) if it said: regenerate the table.
    /// `source` is who reported it (`api:<user>`), as the store keeps it.
    Dressing {
        wheel_radius_mm: f64,
        infeed_um: Option<f64>,
        source: String,
        reply: Reply,
    },
    /// Freeze the learning of `lobe` with this reason, or (`None`) let it learn again.
    Freeze {
        lobe: FeatureName,
        frozen: Option<String>,
        reply: Reply,
    },
    /// Roll several features back together (a whole part: one version of each); every
    /// version is checked before any is pushed.
    RollbackPart {
        versions: Vec<(FeatureName, u64)>,
        reply: Reply,
    },
}

/// A write the machine's loop carried out.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CommandDone {
    /// The table version the write made, when it made one.
    pub version: Option<i64>,
    /// One line for the operator ("rollback to v1 delivered as v7 (T2)").
    pub message: String,
}

/// Why a machine's loop did not carry out a write. Each maps to one HTTP status and one
/// stable code (see [`CommandError::status`] and [`CommandError::code`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    /// The version asked for does not exist for the lobe: 404 `table_version_not_found`.
    #[error("version {version} of {lobe} not found")]
    VersionNotFound { lobe: FeatureName, version: i64 },
    /// The history database is needed and not reachable: 503 `store_unavailable`.
    #[error("the history database is not reachable: {reason}")]
    StoreUnavailable { reason: String },
    /// The loop refused (a guard failed, the stored program is unusable, …): 409
    /// `rollback_refused` or `dressing_refused`.
    #[error("{reason}")]
    Refused { reason: String },
    /// Anything else that went wrong on the machine's side: 500 `command_failed`.
    #[error("{reason}")]
    Failed { reason: String },
    /// The machine's journal could not keep the write: 503 `journal_unavailable`.
    #[error("{reason}")]
    JournalUnavailable { reason: String },
    /// The share's state folder could not be written: 500 `share_state_failed`.
    #[error("{reason}")]
    ShareStateFailed { reason: String },
    /// Another instance of the cluster took the machine meanwhile: 503 `machine_elsewhere`.
    #[error("{reason}")]
    Elsewhere { reason: String },
}

impl CommandError {
    /// The HTTP status: that of [`Self::code`], whichever command was refused.
    pub fn status(&self) -> axum::http::StatusCode {
        use axum::http::StatusCode;
        match self {
            CommandError::VersionNotFound { .. } => StatusCode::NOT_FOUND,
            CommandError::StoreUnavailable { .. } => StatusCode::SERVICE_UNAVAILABLE,
            CommandError::Refused { .. } => StatusCode::CONFLICT,
            CommandError::Failed { .. } | CommandError::ShareStateFailed { .. } => {
                StatusCode::INTERNAL_SERVER_ERROR
            }
            CommandError::JournalUnavailable { .. } | CommandError::Elsewhere { .. } => {
                StatusCode::SERVICE_UNAVAILABLE
            }
        }
    }

    /// The stable code; `refused` is the command's own (`rollback_refused`, …).
    pub fn code(&self, refused: ApiCode) -> ApiCode {
        match self {
            CommandError::VersionNotFound { .. } => ApiCode::TableVersionNotFound,
            CommandError::StoreUnavailable { .. } => ApiCode::StoreUnavailable,
            CommandError::Refused { .. } => refused,
            CommandError::Failed { .. } => ApiCode::CommandFailed,
            CommandError::JournalUnavailable { .. } => ApiCode::JournalUnavailable,
            CommandError::ShareStateFailed { .. } => ApiCode::ShareStateFailed,
            CommandError::Elsewhere { .. } => ApiCode::MachineElsewhere,
        }
    }
}

impl From<crate::service::machine::MachineError> for CommandError {
    /// A write the machine's loop did not make: a rule's refusal is the command's own 409,
    /// a journal or state folder that failed is the service's, with its own code.
    fn from(e: crate::service::machine::MachineError) -> Self {
        use crate::service::machine::MachineError;
        let reason = e.to_string();
        match e {
            MachineError::Refused { .. } => CommandError::Refused { reason },
            MachineError::Journal { .. } => CommandError::JournalUnavailable { reason },
            MachineError::FencedOut { .. } => CommandError::Elsewhere { reason },
            MachineError::ShareState { .. } => CommandError::ShareStateFailed { reason },
            MachineError::Failed { .. } => CommandError::Failed { reason },
        }
    }
}

impl From<crate::service::machine::RollbackError> for CommandError {
    /// A rollback the machine's loop could not make: an unknown version is 404, a store it
    /// could not read 503, anything else (a guard, an unusable stored program) refused.
    fn from(e: crate::service::machine::RollbackError) -> Self {
        use crate::service::machine::RollbackError;
        match e {
            RollbackError::NotFound { lobe, version, .. } => CommandError::VersionNotFound {
                lobe,
                version: i64::try_from(version).unwrap_or(i64::MAX),
            },
            RollbackError::StoreUnavailable => CommandError::StoreUnavailable {
                reason: e.to_string(),
            },
            RollbackError::Delivery(e) => CommandError::from(e),
            e => CommandError::Refused {
                reason: format!("{e:#}"),
            },
        }
    }
}

pub fn router(state: AppState) -> Router {
    let m = "/api/v1/machines/{machine}";
    Router::new()
        .route("/healthz", get(routes::healthz))
        .route("/metrics", get(routes::metrics))
        .route("/openapi.json", get(openapi::openapi))
        .route("/api/v1/machines", get(routes::machines))
        .route("/api/v1/cluster", get(routes::cluster))
        .route(&format!("{m}/measurements"), get(routes::history))
        .route(&format!("{m}/events"), get(routes::events))
        .route(&format!("{m}/parts/{{part}}"), get(parts::part))
        .route(
            &format!("{m}/features/{{feature}}/capability"),
            get(capability::capability),
        )
        .route(&format!("{m}/rollback"), post(writes::rollback_part))
        .route(&format!("{m}/lobes/{{lobe}}/tables"), get(routes::tables))
        .route(
            &format!("{m}/lobes/{{lobe}}/tables/{{version}}/program"),
            get(routes::program),
        )
        .route(
            &format!("{m}/lobes/{{lobe}}/tables/{{version}}/diff"),
            get(routes::diff),
        )
        .route(
            &format!("{m}/lobes/{{lobe}}/rollback"),
            post(writes::rollback),
        )
        .route(
            &format!("{m}/lobes/{{lobe}}/learning"),
            post(writes::freeze),
        )
        .route(
            &format!("{m}/dressings"),
            get(routes::dressings).post(writes::dress),
        )
        .route("/api/v1/measurements/{id}", get(routes::measurement))
        .route(&format!("{m}/events/{{id}}/ack"), post(dashboard::ack))
        .route("/api/v1/audit", get(audit::audit))
        .route("/audit", get(audit::audit_page))
        .route("/signin", get(session::signin_page).post(session::signin))
        .route("/signout", post(session::signout))
        .route("/session", get(session::session))
        .with_state(state.clone())
        .merge(dashboard::router(state.clone()))
        // After routing, so the layer knows the matched route; before every handler, so no
        // handler runs for a caller who may not call it.
        .route_layer(axum::middleware::from_fn_with_state(state, access::guard))
}
