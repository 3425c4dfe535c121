//! The HTTP side of the service: health, Prometheus metrics, and the engineers' read API on
//! the history store (JSON). Errors carry a stable code and a message, never SQL text.

use super::machine::StoreHandle;
use super::metrics::Metrics;
use crate::store::{EventFilter, HistoryFilter, MeasurementId, Store, StoreError, Verdict};
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};
use serde::Deserialize;
use serde_json::{Value, json};
use std::sync::Arc;

#[derive(Clone)]
pub struct AppState {
    pub store: StoreHandle,
    pub metrics: Arc<Metrics>,
    pub machines: Arc<Vec<String>>,
    /// Per machine, the channel to its loop for write requests.
    pub commands: Arc<std::collections::HashMap<String, tokio::sync::mpsc::Sender<Command>>>,
    /// Write requests need it (`Authorization: Bearer …`); none configured: writes refused.
    pub token: Option<crate::config::Secret>,
}

/// A write request handed to a machine's loop, answered when done.
pub enum Command {
    Rollback {
        version: i64,
        reply: tokio::sync::oneshot::Sender<Result<String, String>>,
    },
    /// The wheel was dressed to this radius: regenerate the table.
    Dressing {
        wheel_radius_mm: f64,
        reply: tokio::sync::oneshot::Sender<Result<String, String>>,
    },
}

pub fn router(state: AppState) -> Router {
    Router::new()
        .route("/healthz", get(healthz))
        .route("/metrics", get(metrics))
        .route("/openapi.json", get(openapi))
        .route("/api/v1/machines", get(machines))
        .route("/api/v1/machines/{machine}/measurements", get(history))
        .route("/api/v1/machines/{machine}/events", get(events))
        .route(
            "/api/v1/machines/{machine}/lobes/{lobe}/tables",
            get(tables),
        )
        .route(
            "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/program",
            get(program),
        )
        .route(
            "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/diff",
            get(diff),
        )
        .route(
            "/api/v1/machines/{machine}/lobes/{lobe}/rollback",
            axum::routing::post(rollback),
        )
        .route(
            "/api/v1/machines/{machine}/dressings",
            get(dressings).post(dress),
        )
        .route("/api/v1/measurements/{id}", get(measurement))
        .with_state(state)
}

/// axum's JSON body extractor, its rejections as the API's `{code, message}` errors.
pub struct ApiJson<T>(pub T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned> axum::extract::FromRequest<S> for ApiJson<T> {
    type Rejection = ApiError;

    async fn from_request(req: axum::extract::Request, state: &S) -> Result<Self, ApiError> {
        Json::<T>::from_request(req, state)
            .await
            .map(|Json(v)| ApiJson(v))
            .map_err(|r| ApiError(r.status(), "invalid_body", r.body_text()))
    }
}

/// axum's query extractor, its rejections as the API's `{code, message}` errors.
pub struct ApiQuery<T>(pub T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned> axum::extract::FromRequestParts<S>
    for ApiQuery<T>
{
    type Rejection = ApiError;

    async fn from_request_parts(
        parts: &mut axum::http::request::Parts,
        state: &S,
    ) -> Result<Self, ApiError> {
        Query::<T>::from_request_parts(parts, state)
            .await
            .map(|Query(v)| ApiQuery(v))
            .map_err(|r| ApiError(r.status(), "invalid_query", r.body_text()))
    }
}

/// axum's path extractor, its rejections as the API's `{code, message}` errors.
pub struct ApiPath<T>(pub T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned + Send> axum::extract::FromRequestParts<S>
    for ApiPath<T>
{
    type Rejection = ApiError;

    async fn from_request_parts(
        parts: &mut axum::http::request::Parts,
        state: &S,
    ) -> Result<Self, ApiError> {
        Path::<T>::from_request_parts(parts, state)
            .await
            .map(|Path(v)| ApiPath(v))
            .map_err(|r| ApiError(r.status(), "invalid_path", r.body_text()))
    }
}

/// An API error: HTTP status, stable code, message.
pub struct ApiError(StatusCode, &'static str, String);

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        (self.0, Json(json!({ "code": self.1, "message": self.2 }))).into_response()
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        let status = match e {
            StoreError::NotFound { .. } => StatusCode::NOT_FOUND,
            StoreError::Invalid { .. } => StatusCode::BAD_REQUEST,
            StoreError::Conflict { .. } => StatusCode::CONFLICT,
            StoreError::Unavailable { .. } => StatusCode::SERVICE_UNAVAILABLE,
            _ => StatusCode::INTERNAL_SERVER_ERROR,
        };
        // Display never carries SQL text or credentials (see StoreError).
        ApiError(status, e.code(), e.to_string())
    }
}

async fn store(state: &AppState) -> Result<Store, ApiError> {
    state.store.read().await.clone().ok_or(ApiError(
        StatusCode::SERVICE_UNAVAILABLE,
        "store_unavailable",
        "the history database is not reachable; measurements are kept in the journal".into(),
    ))
}

fn check_name(what: &'static str, name: &str) -> Result<(), ApiError> {
    let ok = (1..=64).contains(&name.len())
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if ok {
        Ok(())
    } else {
        Err(ApiError(
            StatusCode::BAD_REQUEST,
            "invalid_name",
            format!("{what}: 1–64 letters, digits, '-' or '_'"),
        ))
    }
}

async fn healthz(State(state): State<AppState>) -> Json<Value> {
    let database = if state.store.read().await.is_some() {
        "up"
    } else {
        "down"
    };
    Json(json!({ "status": "ok", "database": database, "machines": state.machines.len() }))
}

async fn metrics(State(state): State<AppState>) -> Response {
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        state.metrics.render(),
    )
        .into_response()
}

async fn machines(State(state): State<AppState>) -> Result<Json<Value>, ApiError> {
    let store = store(&state).await?;
    let mut out = Vec::new();
    for m in store.machines().await? {
        let features = store.features(&m.name).await?;
        let lobes: Vec<Value> = features
            .iter()
            .map(|f| json!({ "part": f.part, "lobe": f.lobe, "kind": f.kind.as_str() }))
            .collect();
        out.push(json!({ "name": m.name, "first_seen_ms": m.first_seen_ms, "lobes": lobes }));
    }
    Ok(Json(
        json!({ "machines": out, "configured": *state.machines }),
    ))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HistoryQuery {
    lobe: Option<String>,
    since_ms: Option<i64>,
    until_ms: Option<i64>,
    verdict: Option<String>,
    limit: Option<u32>,
    cursor: Option<String>,
}

async fn history(
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<String>,
    ApiQuery(q): ApiQuery<HistoryQuery>,
) -> Result<Json<Value>, ApiError> {
    check_name("machine", &machine)?;
    if let Some(l) = &q.lobe {
        check_name("lobe", l)?;
    }
    if let (Some(a), Some(b)) = (q.since_ms, q.until_ms)
        && a >= b
    {
        return Err(ApiError(
            StatusCode::BAD_REQUEST,
            "invalid_range",
            "since_ms must be before until_ms".into(),
        ));
    }
    let verdict = match q.verdict.as_deref() {
        None => None,
        Some(v) => Some(Verdict::parse(v).map_err(ApiError::from)?),
    };
    let filter = HistoryFilter {
        machine,
        lobe: q.lobe,
        since_ms: q.since_ms,
        until_ms: q.until_ms,
        verdict,
        limit: q.limit.unwrap_or(100),
        cursor: q.cursor,
    };
    let page = store(&state).await?.measurement_history(&filter).await?;
    let items: Vec<Value> = page
        .items
        .iter()
        .map(|m| {
            json!({
                "id": m.id.0, "machine": m.machine, "part": m.part, "lobe": m.lobe,
                "received_at_ms": m.received_at_ms, "verdict": m.verdict.as_str(),
                "max_profile_error_um": m.max_profile_error_um, "base_radius_error_um": m.base_radius_error_um,
                "phase_error_deg": m.phase_error_deg, "revolutions_used": m.revolutions_used,
                "points_per_rev": m.points_per_rev, "origin": m.origin,
            })
        })
        .collect();
    Ok(Json(
        json!({ "items": items, "next_cursor": page.next_cursor }),
    ))
}

async fn measurement(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Json<Value>, ApiError> {
    let detail = store(&state)
        .await?
        .measurement(MeasurementId(id))
        .await?
        .ok_or(ApiError(
            StatusCode::NOT_FOUND,
            "measurement_not_found",
            format!("measurement {id} not found"),
        ))?;
    let analysis: Value = serde_json::from_str(&detail.analysis_json).unwrap_or(Value::Null);
    Ok(Json(json!({
        "id": id,
        "machine": detail.summary.machine,
        "lobe": detail.summary.lobe,
        "received_at_ms": detail.summary.received_at_ms,
        "averaged_lift_mm": detail.averaged_lift_mm,
        "raw_kept": detail.raw_lift_mm.is_some(),
        "analysis": analysis,
    })))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitQuery {
    limit: Option<u32>,
}

async fn tables(
    State(state): State<AppState>,
    ApiPath((machine, lobe)): ApiPath<(String, String)>,
    ApiQuery(q): ApiQuery<LimitQuery>,
) -> Result<Json<Value>, ApiError> {
    check_name("machine", &machine)?;
    check_name("lobe", &lobe)?;
    let versions = store(&state)
        .await?
        .table_versions(&machine, &lobe, q.limit.unwrap_or(50))
        .await?;
    let items: Vec<Value> = versions
        .iter()
        .map(|t| {
            json!({
                "version": t.version, "parent_version": t.parent_version, "table_number": t.table_number,
                "sha256": t.sha256, "reason": t.reason, "status": t.status.as_str(), "status_why": t.status_why,
                "created_at_ms": t.created_at_ms,
            })
        })
        .collect();
    Ok(Json(json!({ "items": items })))
}

async fn program(
    State(state): State<AppState>,
    ApiPath((machine, lobe, version)): ApiPath<(String, String, i64)>,
) -> Result<Response, ApiError> {
    check_name("machine", &machine)?;
    check_name("lobe", &lobe)?;
    let t = store(&state)
        .await?
        .table_version(&machine, &lobe, version)
        .await?
        .ok_or(ApiError(
            StatusCode::NOT_FOUND,
            "table_version_not_found",
            format!("version {version} not found"),
        ))?;
    Ok((
        [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
        t.program_text,
    )
        .into_response())
}

/// How a table version differs from its parent: X (as the control interpolates it) at every
/// point of the newer table, newer minus older, µm.
async fn diff(
    State(state): State<AppState>,
    ApiPath((machine, lobe, version)): ApiPath<(String, String, i64)>,
) -> Result<Json<Value>, ApiError> {
    check_name("machine", &machine)?;
    check_name("lobe", &lobe)?;
    let store = store(&state).await?;
    let not_found = |v: i64| {
        ApiError(
            StatusCode::NOT_FOUND,
            "table_version_not_found",
            format!("version {v} not found"),
        )
    };
    let newer = store
        .table_version(&machine, &lobe, version)
        .await?
        .ok_or_else(|| not_found(version))?;
    let Some(parent) = newer.parent_version else {
        return Err(ApiError(
            StatusCode::NOT_FOUND,
            "no_parent_version",
            format!("version {version} is the first"),
        ));
    };
    let older = store
        .table_version(&machine, &lobe, parent)
        .await?
        .ok_or_else(|| not_found(parent))?;
    let parse = |text: &str, v: i64| {
        crate::core::program::parse_table_program(text).map_err(|e| {
            ApiError(
                StatusCode::INTERNAL_SERVER_ERROR,
                "program_unreadable",
                format!("version {v}: {e}"),
            )
        })
    };
    let (new_t, old_t) = (
        parse(&newer.program_text, version)?,
        parse(&older.program_text, parent)?,
    );
    let points: Vec<(f64, f64)> = new_t
        .c_knots_deg()
        .into_iter()
        .filter_map(|c| Some((c, (new_t.x_at(c)? - old_t.x_at(c)?) * 1000.0)))
        .collect();
    let (at, max) = points.iter().fold((0.0, 0.0f64), |(a, m), &(c, d)| {
        if d.abs() > m { (c, d.abs()) } else { (a, m) }
    });
    let rms = (points.iter().map(|p| p.1 * p.1).sum::<f64>() / points.len().max(1) as f64).sqrt();
    let delta: Vec<Value> = points
        .iter()
        .map(|(c, d)| json!({ "c_deg": c, "delta_x_um": d }))
        .collect();
    Ok(Json(json!({
        "version": version,
        "parent_version": parent,
        "table_numbers": [older.table_number, newer.table_number],
        "max_abs_delta_x_um": max,
        "at_c_deg": at,
        "rms_delta_x_um": rms,
        "points": delta,
    })))
}

/// The configured token must be presented as `Authorization: Bearer <token>`. Compared in
/// constant time; never logged.
fn authorize(state: &AppState, headers: &axum::http::HeaderMap) -> Result<(), ApiError> {
    let Some(token) = &state.token else {
        return Err(ApiError(
            StatusCode::FORBIDDEN,
            "writes_disabled",
            "no API token is configured (CAMLOOP_API_TOKEN)".into(),
        ));
    };
    let given = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .unwrap_or("");
    let expected = token.expose().as_bytes();
    let same = given.len() == expected.len()
        && given
            .bytes()
            .zip(expected)
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0;
    if same {
        Ok(())
    } else {
        Err(ApiError(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "missing or wrong API token".into(),
        ))
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RollbackBody {
    version: i64,
}

/// Deliver a stored table version again (as a new version, under the table number not in use).
async fn rollback(
    State(state): State<AppState>,
    ApiPath((machine, lobe)): ApiPath<(String, String)>,
    headers: axum::http::HeaderMap,
    ApiJson(body): ApiJson<RollbackBody>,
) -> Result<Json<Value>, ApiError> {
    authorize(&state, &headers)?;
    check_name("machine", &machine)?;
    check_name("lobe", &lobe)?;
    if body.version < 1 {
        return Err(ApiError(
            StatusCode::BAD_REQUEST,
            "invalid_version",
            "version must be ≥ 1".into(),
        ));
    }
    let message = command(&state, &machine, |reply| Command::Rollback {
        version: body.version,
        reply,
    })
    .await?;
    message
        .map(|message| Json(json!({ "status": "ok", "message": message })))
        .map_err(|message| ApiError(StatusCode::CONFLICT, "rollback_refused", message))
}

/// Hands a write request to the machine's loop and waits for its answer.
async fn command(
    state: &AppState,
    machine: &str,
    make: impl FnOnce(tokio::sync::oneshot::Sender<Result<String, String>>) -> Command,
) -> Result<Result<String, String>, ApiError> {
    let stopped = |what: &str| {
        ApiError(
            StatusCode::SERVICE_UNAVAILABLE,
            "machine_stopped",
            format!("machine {machine} {what}"),
        )
    };
    let sender = state.commands.get(machine).ok_or(ApiError(
        StatusCode::NOT_FOUND,
        "machine_not_found",
        format!("machine {machine} is not configured"),
    ))?;
    let (reply, answer) = tokio::sync::oneshot::channel();
    sender
        .send(make(reply))
        .await
        .map_err(|_| stopped("is not running"))?;
    answer.await.map_err(|_| stopped("stopped"))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DressingBody {
    wheel_radius_mm: f64,
}

/// A wheel dressing reported by the operator or a cell controller: the table is regenerated
/// for the new radius.
async fn dress(
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<String>,
    headers: axum::http::HeaderMap,
    ApiJson(body): ApiJson<DressingBody>,
) -> Result<Json<Value>, ApiError> {
    authorize(&state, &headers)?;
    check_name("machine", &machine)?;
    let radius =
        crate::core::compensate::check_wheel_radius(body.wheel_radius_mm).map_err(|e| {
            ApiError(
                StatusCode::BAD_REQUEST,
                "invalid_wheel_radius",
                e.to_string(),
            )
        })?;
    let message = command(&state, &machine, |reply| Command::Dressing {
        wheel_radius_mm: radius,
        reply,
    })
    .await?;
    message
        .map(|message| Json(json!({ "status": "ok", "message": message })))
        .map_err(|message| ApiError(StatusCode::CONFLICT, "dressing_refused", message))
}

async fn dressings(
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<String>,
    ApiQuery(q): ApiQuery<LimitQuery>,
) -> Result<Json<Value>, ApiError> {
    check_name("machine", &machine)?;
    let limit = q.limit.unwrap_or(100);
    let dressings = store(&state).await?.dressings(&machine, limit).await?;
    let items: Vec<Value> = dressings
        .iter()
        .map(|d| json!({ "at_ms": d.at_ms, "old_radius_mm": d.old_radius_mm, "new_radius_mm": d.new_radius_mm, "source": d.source }))
        .collect();
    Ok(Json(json!({ "items": items })))
}

async fn events(
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<String>,
    ApiQuery(q): ApiQuery<LimitQuery>,
) -> Result<Json<Value>, ApiError> {
    check_name("machine", &machine)?;
    let filter = EventFilter {
        machine: Some(machine),
        limit: q.limit.unwrap_or(100),
        ..EventFilter::default()
    };
    let events = store(&state).await?.events(&filter).await?;
    let items: Vec<Value> = events
        .iter()
        .map(|e| json!({ "at_ms": e.at_ms, "level": e.level.as_str(), "kind": e.kind, "message": e.message }))
        .collect();
    Ok(Json(json!({ "items": items })))
}

async fn openapi() -> Json<Value> {
    let get = |summary: &str| json!({ "get": { "summary": summary, "responses": { "200": { "description": "OK" }, "4XX": { "description": "error: {code, message}" }, "503": { "description": "store unavailable" } } } });
    Json(json!({
        "openapi": "3.0.3",
        "info": { "title": "camloop", "version": env!("CARGO_PKG_VERSION") },
        "paths": {
            "/healthz": get("service and database health"),
            "/metrics": get("Prometheus metrics"),
            "/api/v1/machines": get("machines and their lobes or pins"),
            "/api/v1/machines/{machine}/measurements": get("measurement history, newest first; filters lobe, since_ms, until_ms, verdict, limit, cursor"),
            "/api/v1/machines/{machine}/events": get("alarms and events, newest first"),
            "/api/v1/machines/{machine}/lobes/{lobe}/tables": get("table versions, newest first"),
            "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/program": get("program text of a table version"),
            "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/diff": get("X difference to the parent version at every table point, µm"),
            "/api/v1/measurements/{id}": get("one measurement with its averaged profile and analysis"),
            "/api/v1/machines/{machine}/dressings": {
                "get": get("wheel dressings, newest first")["get"],
                "post": { "summary": "report a wheel dressing; body {\"wheel_radius_mm\": R}; regenerates the table for the new radius; needs Authorization: Bearer <CAMLOOP_API_TOKEN>", "responses": { "200": { "description": "recorded, table regenerated" }, "400": { "description": "implausible radius" }, "401": { "description": "unauthorized" }, "403": { "description": "writes disabled" }, "409": { "description": "refused" } } }
            },
            "/api/v1/machines/{machine}/lobes/{lobe}/rollback": { "post": { "summary": "deliver a stored version again; body {\"version\": N}; needs Authorization: Bearer <CAMLOOP_API_TOKEN>", "responses": { "200": { "description": "delivered" }, "401": { "description": "unauthorized" }, "403": { "description": "writes disabled" }, "409": { "description": "refused" } } } },
        }
    }))
}
