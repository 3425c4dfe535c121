//! The plant overview read the old way, feature by feature through the store's per-feature
//! reads (the ones the feature pages use): the reference the set queries of
//! `Store::plant_overview` and `Store::machines_in_alarm` must equal, and the "before" of
//! the dashboard bench.

use camloop::names::{FeatureName, MachineName};
use camloop::store::{
    EventFilter, EventId, EventLevel, FeatureOverview, HistoryFilter, MasterRuns, MeasurementStage,
    OverviewPart, Store, VersionStatus,
};
use std::collections::BTreeSet;

/// Each feature's overview from `measurement_history` (final parts, masters excluded),
/// `table_version_heads` and `learning_state_for_view`; the learning state as its text.
pub async fn features(
    store: &Store,
    keys: &[(MachineName, FeatureName)],
    parts: u32,
    versions: u32,
) -> Vec<(FeatureOverview, Option<String>)> {
    let mut out = Vec::new();
    for (m, f) in keys {
        let filter = HistoryFilter {
            lobe: Some(f.clone()),
            masters: MasterRuns::Excluded,
            stage: Some(MeasurementStage::Final),
            ..HistoryFilter::new(m.clone(), parts)
        };
        let mut recent: Vec<OverviewPart> = store
            .measurement_history(&filter)
            .await
            .unwrap()
            .items
            .into_iter()
            .map(|s| OverviewPart {
                id: s.id,
                part: s.part,
                received_at: s.received_at,
                verdict: s.verdict,
                max_profile_error_um: s.max_profile_error_um,
            })
            .collect();
        recent.reverse();
        let in_force = store
            .table_version_heads(m, f, versions)
            .await
            .unwrap()
            .into_iter()
            .find(|v| matches!(v.status, VersionStatus::Pushed { .. }));
        let state = store.learning_state_for_view(m, f).await.unwrap();
        let overview = FeatureOverview {
            recent,
            in_force,
            learning: None,
        };
        out.push((overview, state.map(|s| s.state_json)));
    }
    out
}

/// The machines with an unacknowledged error among their newest `events` events, from
/// `events` and `event_acks` as the feature page lists them.
pub async fn alarms(store: &Store, events: u32) -> BTreeSet<MachineName> {
    let mut out = BTreeSet::new();
    for m in store.machines().await.unwrap() {
        let filter = EventFilter {
            machine: Some(m.name.clone()),
            limit: events,
            ..EventFilter::default()
        };
        let list = store.events(&filter).await.unwrap();
        let from = list.iter().map(|e| e.id).min().unwrap_or(EventId(0));
        let acks = store.event_acks(&m.name, from, events).await.unwrap();
        if list
            .iter()
            .any(|e| e.level == EventLevel::Error && !acks.iter().any(|a| a.event == e.id))
        {
            out.insert(m.name);
        }
    }
    out
}
