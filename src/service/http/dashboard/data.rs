//! What the pages show, read from the store through the readers' gate: a feature's trend,
//! latest part, versions, dressings and events, and the state the overview gives a feature
//! (its rows are read in `overview.rs`).

use crate::names::{FeatureName, MachineName};
use crate::service::http::ApiCode;
use crate::service::http::AppState;
use crate::service::http::api::ApiError;
use crate::service::metrics::MachineMetrics;
use crate::store::{
    Dressing, Event, EventAck, EventFilter, EventId, HistoryFilter, LearningState, MasterRuns,
    MeasurementStage, MeasurementSummary, Store, StoredTableVersion, TableVersionHead,
};

/// Parts in the overview's sparkline.
pub(super) const SPARK_PARTS: u32 = 50;
/// Parts in a feature's trend chart.
pub(super) const TREND_PARTS: u32 = 200;
/// Events listed.
const EVENTS: u32 = 50;

/// What a machine is doing, as the overview shows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum MachineState {
    /// An error event nobody acknowledged, or the journal cannot be written.
    Alarm,
    /// Learning reverted a step and froze: an operator must act.
    Frozen,
    /// A table version waits for the controller share.
    WaitingForShare,
    Running,
    /// No part measured yet.
    Idle,
}

impl MachineState {
    pub(super) fn as_str(self) -> &'static str {
        match self {
            MachineState::Alarm => "alarm",
            MachineState::Frozen => "frozen",
            MachineState::WaitingForShare => "waiting for the share",
            MachineState::Running => "running",
            MachineState::Idle => "idle",
        }
    }
}

pub(super) fn unavailable() -> ApiError {
    ApiError::new(
        ApiCode::StoreUnavailable,
        "the history database is not reachable; measurements are kept in the journal".into(),
    )
}

pub(super) async fn store(app: &AppState) -> Result<Store, ApiError> {
    app.store.read().await.clone().ok_or_else(unavailable)
}

/// What a machine's feature shows as its state; `alarm`: an error event nobody acknowledged
/// among the machine's newest.
pub(super) fn state(
    metrics: Option<&MachineMetrics>,
    alarm: bool,
    frozen: bool,
    no_parts: bool,
) -> MachineState {
    if alarm || metrics.is_some_and(|m| m.journal_failing > 0) {
        MachineState::Alarm
    } else if frozen {
        MachineState::Frozen
    } else if metrics.is_some_and(|m| m.share_waiting > 0) {
        MachineState::WaitingForShare
    } else if no_parts {
        MachineState::Idle
    } else {
        MachineState::Running
    }
}

/// The newest `n` finished production parts of (machine, lobe), newest first: master runs
/// are the gauge study's (the capability panel shows them), in-process measurements are
/// taken with stock on; neither is a point of the trend or the latest result.
pub(super) async fn history(
    store: &Store,
    machine: &MachineName,
    lobe: &FeatureName,
    n: u32,
) -> Result<Vec<MeasurementSummary>, ApiError> {
    let filter = HistoryFilter {
        lobe: Some(lobe.clone()),
        masters: MasterRuns::Excluded,
        stage: Some(MeasurementStage::Final),
        ..HistoryFilter::new(machine.clone(), n)
    };
    Ok(store.measurement_history(&filter).await?.items)
}

/// The machine's newest events with their acknowledgements, newest first.
pub(super) async fn events(
    store: &Store,
    machine: &MachineName,
) -> Result<Vec<(Event, Option<EventAck>)>, ApiError> {
    let filter = EventFilter {
        machine: Some(machine.clone()),
        limit: EVENTS,
        ..EventFilter::default()
    };
    let events = store.events(&filter).await?;
    let from = events.iter().map(|e| e.id).min().unwrap_or(EventId(0));
    let acks = store.event_acks(machine, from, EVENTS).await?;
    Ok(events
        .into_iter()
        .map(|e| {
            let ack = acks.iter().find(|a| a.event == e.id).cloned();
            (e, ack)
        })
        .collect())
}

/// The learning state's parts the dashboard shows (the loop's memory, read leniently: a
/// layout it does not know shows as no correction).
#[derive(Debug, Default, serde::Deserialize)]
pub(super) struct Learning {
    #[serde(default)]
    pub correction_um: Vec<f64>,
    #[serde(default)]
    pub frozen: Option<String>,
}

#[derive(Debug, Default, serde::Deserialize)]
struct Memory {
    #[serde(default)]
    learning: Learning,
}

pub(super) async fn learning(
    store: &Store,
    machine: &MachineName,
    lobe: &FeatureName,
) -> Result<Learning, ApiError> {
    Ok(learning_of(
        store.learning_state_for_view(machine, lobe).await?,
    ))
}

/// The dashboard's part of a stored learning state (none: no correction, not frozen).
pub(super) fn learning_of(state: Option<LearningState>) -> Learning {
    state
        .and_then(|s| serde_json::from_str::<Memory>(&s.state_json).ok())
        .map(|m| m.learning)
        .unwrap_or_default()
}

/// The latest part's curves from its analysis report.
#[derive(Debug, Default, serde::Deserialize)]
pub(super) struct Curves {
    #[serde(default)]
    pub angle_deg: Vec<f64>,
    #[serde(default)]
    pub error_um: Vec<f64>,
    #[serde(default)]
    pub profile_error_um: Vec<f64>,
}

/// The newest part with its measured lift and curves.
pub(super) struct Latest {
    pub summary: MeasurementSummary,
    pub lift_mm: Vec<f64>,
    pub curves: Curves,
}

/// Everything the feature page shows.
pub(super) struct FeatureData {
    /// Oldest first.
    pub parts: Vec<MeasurementSummary>,
    pub latest: Option<Latest>,
    /// Newest first.
    pub versions: Vec<TableVersionHead>,
    pub dressings: Vec<Dressing>,
    pub events: Vec<(Event, Option<EventAck>)>,
    pub learning: Learning,
}

pub(super) async fn feature(
    store: &Store,
    machine: &MachineName,
    lobe: &FeatureName,
) -> Result<FeatureData, ApiError> {
    let mut parts = history(store, machine, lobe, TREND_PARTS).await?;
    parts.reverse();
    let latest = match parts.last() {
        None => None,
        Some(p) => store.measurement(p.id).await?.map(|d| Latest {
            curves: serde_json::from_str(&d.analysis_json).unwrap_or_default(),
            lift_mm: d.averaged_lift_mm,
            summary: d.summary,
        }),
    };
    Ok(FeatureData {
        parts,
        latest,
        versions: store.table_version_heads(machine, lobe, 50).await?,
        dressings: store.dressings(machine, 50).await?,
        events: events(store, machine).await?,
        learning: learning(store, machine, lobe).await?,
    })
}

/// X of `version` minus X of its parent at every C knot of `version`, µm.
pub(super) fn diff_um(
    newer: &StoredTableVersion,
    older: &StoredTableVersion,
) -> Option<Vec<(f64, f64)>> {
    let parse = crate::core::program::parse_table_program;
    let (n, o) = (
        parse(&newer.program_text).ok()?,
        parse(&older.program_text).ok()?,
    );
    Some(
        n.c_knots_deg()
            .into_iter()
            .filter_map(|c| Some((c, (n.x_at(c)? - o.x_at(c)?) * 1000.0)))
            .collect(),
    )
}
