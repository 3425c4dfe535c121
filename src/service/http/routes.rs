//! The read handlers: health, metrics, machines, measurements, dressings, events (table
//! versions are `table_routes.rs`).
//! Each reply is a typed record serialised as JSON; errors are `{code, message}`.

use super::AppState;
use super::api::{ApiError, ApiPath, ApiQuery};
use crate::core::ids::PartId;
use crate::names::{FeatureName, MachineName, PartName};
use crate::service::http::ApiCode;
use crate::store::{EventFilter, HistoryFilter, MasterRuns, MeasurementId, Store, Verdict};
use axum::Json;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

pub(super) async fn store(state: &AppState) -> Result<Store, ApiError> {
    state.store.read().await.clone().ok_or(ApiError::new(
        ApiCode::StoreUnavailable,
        "the history database is not reachable; measurements are kept in the journal".into(),
    ))
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct Health {
    /// "starting" while the machines open, "degraded" while a component is (see
    /// `components`), else "ok".
    #[schema(value_type = String)]
    status: crate::service::health::State,
    /// "up" or "down".
    database: &'static str,
    /// Configured machines.
    machines: usize,
    /// Each component's state, with the reason when it is not ok.
    components: Vec<crate::service::health::Component>,
}

/// Service and database health. Answered on the listener's own threads, from memory only
/// (no database query, no wait on a lock), so it answers while the machines' work saturates
/// the service.
#[utoipa::path(get, path = "/healthz", tag = "service", responses((status = 200, description = "service up (starting, ok or degraded, with each component's state); the database up or down", body = Health)))]
pub(super) async fn healthz(State(state): State<AppState>) -> Json<Health> {
    use crate::service::health;
    // A connector holding the lock to put a new connection in: not up yet. Connected, the
    // database is up while it answers its probe (`service::database_health`).
    let connected = state.store.try_read().is_ok_and(|s| s.is_some());
    let mut components = state.metrics.health.components();
    let answering = !components
        .iter()
        .any(|c| c.name == "database" && c.state != health::State::Ok);
    let up = connected && answering;
    let lag = state.metrics.backlog.lag(std::time::Instant::now());
    components.push(health::loop_component(lag));
    if let Some(m) = state.metrics.mqtt() {
        let degraded = state.metrics.mqtt_degraded();
        components.push(health::Component {
            name: "mqtt".into(),
            state: if degraded {
                health::State::Degraded
            } else {
                health::State::Ok
            },
            reason: degraded.then(|| format!("the MQTT link is {}", <&str>::from(m.link))),
        });
    }
    Json(Health {
        status: health::status(&components),
        database: if up { "up" } else { "down" },
        machines: state.machines.len(),
        components,
    })
}

/// Prometheus metrics.
#[utoipa::path(get, path = "/metrics", tag = "service", responses((status = 200, description = "Prometheus metrics", content_type = "text/plain")))]
pub(super) async fn metrics(State(state): State<AppState>) -> Response {
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        state.metrics.render() + &state.auth.hasher.render_metrics(),
    )
        .into_response()
}

/// `GET /api/v1/machines`.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct MachinesReply {
    /// Configured machines first (in name order), then machines only the store knows.
    pub machines: Vec<MachineInfo>,
    /// Names of the configured machines.
    pub configured: Vec<String>,
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct MachineInfo {
    #[schema(value_type = String)]
    pub name: MachineName,
    /// In this service's configuration (else only in the history).
    pub configured: bool,
    /// When the store first saw it; `None` before its first record.
    pub first_seen_ms: Option<i64>,
    pub lobes: Vec<LobeInfo>,
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct LobeInfo {
    #[schema(value_type = String)]
    pub lobe: FeatureName,
    /// The part (recipe) name, once the store has a record of it.
    #[schema(value_type = Option<String>)]
    pub part: Option<PartName>,
    /// "lobe" or "pin", once the store has a record of it.
    pub kind: Option<&'static str>,
    /// Ground by this service's configuration (else only in the history).
    pub configured: bool,
    /// Its loop's state in this service: the latest part's errors, the table version on the
    /// control, frozen, blocked by a guard (configured features only).
    #[schema(value_type = Option<Object>)]
    pub status: Option<crate::service::metrics::FeatureStatus>,
}

/// `GET /api/v1/cluster`: which instance runs which machine.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct ClusterReply {
    enabled: bool,
    /// The instance that answered.
    instance: Option<String>,
    machines: Vec<LeaseInfo>,
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
struct LeaseInfo {
    #[schema(value_type = String)]
    machine: MachineName,
    owner: String,
    /// The fencing epoch: raised at every change of owner.
    epoch: u64,
    /// The lease is current (not run out, not released).
    live: bool,
    /// The instance that answered runs it.
    here: bool,
}

#[utoipa::path(get, path = "/api/v1/cluster", tag = "service", responses((status = 200, description = "each machine's lease (owner, fencing epoch, live, run here); `{enabled: false}` without `[cluster]`", body = ClusterReply)))]
pub(super) async fn cluster(State(state): State<AppState>) -> Result<Json<ClusterReply>, ApiError> {
    let Some(leases) = &state.cluster else {
        let off = ClusterReply {
            enabled: false,
            instance: None,
            machines: Vec::new(),
        };
        return Ok(Json(off));
    };
    let rows = leases
        .all()
        .await
        .map_err(|e| ApiError::new(ApiCode::ClusterUnavailable, e.to_string()))?;
    let here = |r: &crate::cluster::LeaseRow| r.live && r.owner == leases.instance();
    let machines = rows
        .iter()
        .map(|r| LeaseInfo {
            here: here(r),
            machine: r.machine.clone(),
            owner: r.owner.clone(),
            epoch: r.epoch.0,
            live: r.live,
        })
        .collect();
    Ok(Json(ClusterReply {
        enabled: true,
        instance: Some(leases.instance().to_string()),
        machines,
    }))
}

/// Machines and their lobes or pins: configured ones and those in the history.
#[utoipa::path(get, path = "/api/v1/machines", tag = "history", responses((status = 200, description = "machines and their lobes or pins: configured ones and those in the history", body = MachinesReply)))]
pub(super) async fn machines(
    State(state): State<AppState>,
) -> Result<Json<MachinesReply>, ApiError> {
    let store = store(&state).await?;
    let statuses = state.metrics.features();
    let mut out: Vec<MachineInfo> = state
        .machines
        .iter()
        .map(|(name, lobes)| MachineInfo {
            name: name.clone(),
            configured: true,
            first_seen_ms: None,
            lobes: lobes
                .iter()
                .map(|l| LobeInfo {
                    lobe: l.clone(),
                    part: None,
                    kind: None,
                    configured: true,
                    status: Some(
                        statuses
                            .get(&(name.clone(), l.clone()))
                            .cloned()
                            .unwrap_or_default(),
                    ),
                })
                .collect(),
        })
        .collect();
    // Every machine's features in one query, not one per machine: at plant scale the
    // per-machine queries made this read wait ~1 s behind each other.
    let mut features: BTreeMap<MachineName, Vec<crate::store::FeatureKey>> = BTreeMap::new();
    for f in store.feature_keys().await? {
        features.entry(f.machine.clone()).or_default().push(f);
    }
    for m in store.machines().await? {
        let i = match out.iter().position(|o| o.name == m.name) {
            Some(i) => i,
            None => {
                out.push(MachineInfo {
                    name: m.name.clone(),
                    configured: false,
                    first_seen_ms: None,
                    lobes: Vec::new(),
                });
                out.len() - 1
            }
        };
        out[i].first_seen_ms = Some(m.first_seen.as_millisecond());
        for f in features.remove(&m.name).unwrap_or_default() {
            let lobes = &mut out[i].lobes;
            let j = match lobes
                .iter()
                .position(|l| l.lobe == f.lobe && l.part.is_none())
            {
                Some(j) => j,
                None => {
                    lobes.push(LobeInfo {
                        lobe: f.lobe.clone(),
                        part: None,
                        kind: None,
                        configured: false,
                        status: None,
                    });
                    lobes.len() - 1
                }
            };
            lobes[j].part = Some(f.part.clone());
            lobes[j].kind = Some(f.kind.as_str());
        }
    }
    let configured = state.machines.keys().map(ToString::to_string).collect();
    Ok(Json(MachinesReply {
        machines: out,
        configured,
    }))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct HistoryQuery {
    /// Only this lobe or pin.
    #[param(value_type = Option<String>)]
    lobe: Option<FeatureName>,
    /// From this time, Unix ms.
    #[serde(rename = "since_ms", default, with = "crate::clock::unix_ms::option")]
    #[param(value_type = Option<i64>)]
    since: Option<jiff::Timestamp>,
    /// Before this time, Unix ms.
    #[serde(rename = "until_ms", default, with = "crate::clock::unix_ms::option")]
    #[param(value_type = Option<i64>)]
    until: Option<jiff::Timestamp>,
    /// Only this verdict: `pass` or `fail`.
    verdict: Option<String>,
    /// Only this stage: `final` (the finished part) or `in_process` (before the finish).
    #[param(value_type = Option<String>)]
    stage: Option<crate::store::MeasurementStage>,
    /// At most this many (default 100).
    limit: Option<u32>,
    /// Where the previous page ended (its `next_cursor`).
    cursor: Option<String>,
    /// `true`: the master runs (part ids `MASTER…`) only; default: production parts only.
    #[serde(default)]
    masters: bool,
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct Items<T> {
    pub(super) items: Vec<T>,
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct HistoryPage {
    items: Vec<MeasurementItem>,
    next_cursor: Option<String>,
}

#[derive(Debug, Serialize, Clone, utoipa::ToSchema)]
pub(super) struct MeasurementItem {
    id: i64,
    #[schema(value_type = String)]
    machine: MachineName,
    #[schema(value_type = String)]
    part: PartId,
    #[schema(value_type = String)]
    lobe: FeatureName,
    received_at_ms: i64,
    verdict: &'static str,
    /// `final` (the finished part) or `in_process` (before the finish, stock on).
    stage: &'static str,
    max_profile_error_um: f64,
    base_radius_error_um: f64,
    phase_error_deg: f64,
    revolutions_used: u32,
    points_per_rev: u32,
    origin: String,
}

impl From<crate::store::MeasurementSummary> for MeasurementItem {
    fn from(m: crate::store::MeasurementSummary) -> Self {
        Self {
            id: m.id.0,
            verdict: m.verdict.as_str(),
            stage: m.stage.as_str(),
            machine: m.machine,
            part: m.part,
            lobe: m.lobe,
            received_at_ms: m.received_at.as_millisecond(),
            max_profile_error_um: m.max_profile_error_um,
            base_radius_error_um: m.base_radius_error_um,
            phase_error_deg: m.phase_error_deg,
            revolutions_used: m.revolutions_used,
            points_per_rev: m.points_per_rev,
            origin: m.origin,
        }
    }
}

/// Measurement history of production parts, newest first, keyset-paged (`masters=true`:
/// the master runs instead).
#[utoipa::path(get, path = "/api/v1/machines/{machine}/measurements", tag = "history", params(("machine" = String, Path, description = "machine name"), HistoryQuery), responses((status = 200, description = "measurements, newest first, keyset-paged", body = HistoryPage)))]
pub(super) async fn history(
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<MachineName>,
    ApiQuery(q): ApiQuery<HistoryQuery>,
) -> Result<Json<HistoryPage>, ApiError> {
    if let (Some(a), Some(b)) = (q.since, q.until)
        && a >= b
    {
        return Err(ApiError::new(
            ApiCode::InvalidRange,
            "since_ms must be before until_ms".into(),
        ));
    }
    let verdict = match q.verdict.as_deref() {
        None => None,
        Some(v) => {
            Some(Verdict::parse(v).map_err(|e| ApiError::from(crate::store::StoreError::from(e)))?)
        }
    };
    let filter = HistoryFilter {
        machine,
        lobe: q.lobe,
        since: q.since,
        until: q.until,
        verdict,
        stage: q.stage,
        limit: q.limit.unwrap_or(100),
        cursor: q.cursor,
        masters: if q.masters {
            MasterRuns::Only
        } else {
            MasterRuns::Excluded
        },
    };
    let page = store(&state).await?.measurement_history(&filter).await?;
    Ok(Json(HistoryPage {
        items: page.items.into_iter().map(Into::into).collect(),
        next_cursor: page.next_cursor,
    }))
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct MeasurementReply {
    id: i64,
    #[schema(value_type = String)]
    machine: MachineName,
    #[schema(value_type = String)]
    lobe: FeatureName,
    received_at_ms: i64,
    averaged_lift_mm: Vec<f64>,
    raw_kept: bool,
    /// The analysis report as stored (error curve, spectrum, …).
    #[schema(value_type = Object)]
    analysis: serde_json::Value,
}

/// One measurement with its averaged profile and analysis.
#[utoipa::path(get, path = "/api/v1/measurements/{id}", tag = "history", params(("id" = i64, Path, description = "measurement id")), responses((status = 200, description = "one measurement with its averaged profile and analysis", body = MeasurementReply)))]
pub(super) async fn measurement(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Json<MeasurementReply>, ApiError> {
    let detail = store(&state)
        .await?
        .measurement(MeasurementId(id))
        .await?
        .ok_or(ApiError::new(
            ApiCode::MeasurementNotFound,
            format!("measurement {id} not found"),
        ))?;
    // The store checks it is JSON on the way in.
    let analysis = serde_json::from_str(&detail.analysis_json).unwrap_or_default();
    Ok(Json(MeasurementReply {
        id,
        machine: detail.summary.machine,
        lobe: detail.summary.lobe,
        received_at_ms: detail.summary.received_at.as_millisecond(),
        averaged_lift_mm: detail.averaged_lift_mm,
        raw_kept: detail.raw_lift_mm.is_some(),
        analysis,
    }))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
#[derive(utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct LimitQuery {
    /// At most this many.
    pub(super) limit: Option<u32>,
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct DressingItem {
    at_ms: i64,
    old_radius_mm: f64,
    new_radius_mm: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    infeed_um: Option<f64>,
    source: String,
}

/// Wheel dressings, newest first.
#[utoipa::path(get, path = "/api/v1/machines/{machine}/dressings", tag = "history", params(("machine" = String, Path, description = "machine name"), LimitQuery), responses((status = 200, description = "wheel dressings, newest first", body = Items<DressingItem>)))]
pub(super) async fn dressings(
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<MachineName>,
    ApiQuery(q): ApiQuery<LimitQuery>,
) -> Result<Json<Items<DressingItem>>, ApiError> {
    let limit = q.limit.unwrap_or(100);
    let dressings = store(&state).await?.dressings(&machine, limit).await?;
    let items = dressings
        .into_iter()
        .map(|d| DressingItem {
            at_ms: d.at.as_millisecond(),
            old_radius_mm: d.old_radius_mm,
            new_radius_mm: d.new_radius_mm,
            infeed_um: d.infeed_um,
            source: d.source,
        })
        .collect();
    Ok(Json(Items { items }))
}

#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(super) struct EventItem {
    /// The event's id: what `POST …/events/{id}/ack` and OPC UA's `AcknowledgeEvent` take.
    id: i64,
    at_ms: i64,
    level: &'static str,
    kind: String,
    message: String,
}

/// Alarms and events, newest first.
#[utoipa::path(get, path = "/api/v1/machines/{machine}/events", tag = "history", params(("machine" = String, Path, description = "machine name"), LimitQuery), responses((status = 200, description = "alarms and events, newest first", body = Items<EventItem>)))]
pub(super) async fn events(
    State(state): State<AppState>,
    ApiPath(machine): ApiPath<MachineName>,
    ApiQuery(q): ApiQuery<LimitQuery>,
) -> Result<Json<Items<EventItem>>, ApiError> {
    let filter = EventFilter {
        machine: Some(machine),
        limit: q.limit.unwrap_or(100),
        ..EventFilter::default()
    };
    let events = store(&state).await?.events(&filter).await?;
    let items = events
        .into_iter()
        .map(|e| EventItem {
            id: e.id.0,
            at_ms: e.at.as_millisecond(),
            level: e.level.as_str(),
            kind: e.kind.as_str().to_owned(),
            message: e.message,
        })
        .collect();
    Ok(Json(Items { items }))
}
