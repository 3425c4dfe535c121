//! The result variables at start: each feature's newest stored result (master runs left
//! out), read from the history store, so that after a restart a client reads the last part
//! with its own time rather than `BadWaitingForInitialData`. Read on a task of its own and
//! handed to the feed machine by machine; the feed never lets a seed replace a part the
//! loops sent since (see `Feed::seed`).

use camloop_loop::PlantEvent;
use tokio::sync::mpsc;

use super::space::MachineLayout;
use crate::port::Service;
use camloop_store::{HistoryFilter, MasterRuns, MeasurementSummary, Store, StoreError};
use std::sync::Arc;

/// A feature's newest stored result, as the feed shows a part.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Seed {
    /// The part as its event would carry it (`ground_with_version` none: the history
    /// does not keep it).
    pub(crate) part: PlantEvent,
    /// `max |error|` of the stored analysis, µm (the loop's `MaxError`).
    pub(crate) max_error_um: Option<f64>,
}

/// Reads every configured feature's newest result and sends them, one machine's at a time;
/// returns when done (a store that is down, or a feature with no result, gives none).
pub(crate) async fn send_newest(
    service: Arc<dyn Service>,
    layout: Vec<MachineLayout>,
    tx: mpsc::Sender<Vec<Seed>>,
) {
    let Some(store) = service.store().await else {
        tracing::info!("OPC UA: no history store at start: results wait for the next parts");
        return;
    };
    for m in &layout {
        let mut seeds = Vec::new();
        for f in &m.features {
            match newest(&store, m, f).await {
                Ok(Some(seed)) => seeds.push(seed),
                Ok(None) => {}
                Err(e) => {
                    tracing::warn!(machine = %m.name, feature = %f, error = %e, "OPC UA: the newest stored result cannot be read; its variables wait for the next part");
                }
            }
        }
        if !seeds.is_empty() && tx.send(seeds).await.is_err() {
            return;
        }
    }
}

async fn newest(
    store: &Store,
    m: &MachineLayout,
    feature: &camloop_core::names::FeatureName,
) -> Result<Option<Seed>, StoreError> {
    let filter = HistoryFilter {
        lobe: Some(feature.clone()),
        masters: MasterRuns::Excluded,
        ..HistoryFilter::new(m.name.clone(), 1)
    };
    let Some(summary) = store.measurement_history(&filter).await?.items.pop() else {
        return Ok(None);
    };
    let analysis = store
        .measurement(summary.id)
        .await?
        .map(|d| d.analysis_json)
        .unwrap_or_default();
    Ok(Some(seed_of(summary, &analysis)))
}

/// The analysis' fields the result variables show beside the summary's.
#[derive(serde::Deserialize)]
struct Reported {
    #[serde(default)]
    error_um: Vec<f64>,
    repeatability_max_um: Option<f64>,
}

/// A stored result as the feed shows it: the summary's fields, `MaxError` as the loop
/// computes it (`max |error_um|`, see `core::turn::measure`) and the repeatability as the
/// live path reads it, from the analysis.
pub(crate) fn seed_of(s: MeasurementSummary, analysis_json: &str) -> Seed {
    let reported = serde_json::from_str::<Reported>(analysis_json).ok();
    let max_error_um = reported
        .as_ref()
        .filter(|r| !r.error_um.is_empty())
        .map(|r| r.error_um.iter().fold(0.0_f64, |m, e| m.max(e.abs())));
    let repeatability_um = reported.and_then(|r| r.repeatability_max_um);
    Seed {
        part: PlantEvent::PartAnalysed {
            machine: s.machine,
            feature: s.lobe,
            part: s.part,
            at: s.received_at,
            verdict: s.verdict,
            max_profile_error_um: s.max_profile_error_um,
            base_radius_error_um: s.base_radius_error_um,
            phase_error_deg: s.phase_error_deg,
            ground_with_version: None,
            repeatability_um,
        },
        max_error_um,
    }
}
