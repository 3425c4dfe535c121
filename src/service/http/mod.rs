//! The HTTP side of the service: health, Prometheus metrics, the engineers' read API on the
//! history store (JSON), and the writes (rollback, freezing, dressing), which go as
//! `MachineCommand`s to the machine's loop. Errors carry a stable code and a message, never SQL text.
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
mod table_routes;
mod tls;
mod writes;

pub use crate::service::app::AppState;
pub use access::{AuthState, Principal, ROUTES, RouteRule};
pub use api::{ApiError, ApiJson, ApiPath, ApiQuery, Authorized};
pub use audit::record as record_audit;
pub use code::ApiCode;
pub use dashboard::{FeatureSheet, FeatureSheets, Stopping};
pub use harden::{CONTENT_SECURITY_POLICY, HostAllowList, Policy};
pub use routes::{LobeInfo, MachineInfo, MachinesReply};
pub use server::{HttpLimits, serve, serve_with};
pub use tls::{Tls, days_left, self_signed};
pub use writes::{CommandReply, command_code};
// The sign-in check the OPC UA server goes through as well.

use axum::Router;
use axum::routing::{get, post};

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
        .route(
            &format!("{m}/lobes/{{lobe}}/tables"),
            get(table_routes::tables),
        )
        .route(
            &format!("{m}/lobes/{{lobe}}/tables/{{version}}/program"),
            get(table_routes::program),
        )
        .route(
            &format!("{m}/lobes/{{lobe}}/tables/{{version}}/diff"),
            get(table_routes::diff),
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
