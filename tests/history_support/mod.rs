//! What a service that died and ran again must hold, read from one feature's share manifest,
//! journal and store: shared by the kill and crash-point tests, so both judge a restart by
//! the same rules.

#![allow(dead_code)]

use super::store_support::{f, m};
use camloop::digest::Sha256;
use camloop::share::{History, VersionState, VersionStatus, load_manifest};
use camloop::store::{
    HistoryFilter, MeasurementStage, MeasurementSummary, RawPool, Store, StoredTableVersion,
};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A feature's state folder: `<var>/machines/<machine>/<lobe>`.
pub fn feature_dir(var: &Path, machine: &str, lobe: &str) -> PathBuf {
    var.join("machines").join(machine).join(lobe)
}

/// The versions on a feature's share manifest, in order (empty when it has none yet).
pub fn manifest_versions(var: &Path, machine: &str, lobe: &str) -> Vec<u64> {
    let path = feature_dir(var, machine, lobe).join("share/manifest.jsonl");
    if !path.exists() {
        return Vec::new();
    }
    let history = load_manifest(&path).unwrap().history;
    history
        .versions()
        .iter()
        .map(|v| v.record.version.get())
        .collect()
}

/// The journal's records of one feature, as JSON (a torn last line is left out, as the
/// service's start does).
pub fn journal_records(var: &Path, machine: &str, lobe: &str) -> Vec<serde_json::Value> {
    let path = feature_dir(var, machine, lobe).join("journal.jsonl");
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// The measurement identities the journal holds.
pub fn journal_measurements(var: &Path, machine: &str, lobe: &str) -> BTreeSet<String> {
    journal_records(var, machine, lobe)
        .iter()
        .filter(|r| r["record"] == "measurement")
        .map(|r| r["sha256"].as_str().unwrap().to_string())
        .collect()
}

/// The feature's stored finished parts (stage `final`), oldest first (up to 10,000), each
/// with its analysis report.
pub async fn parts_with_reports(
    store: &Store,
    machine: &str,
    lobe: &str,
) -> Vec<(MeasurementSummary, serde_json::Value)> {
    let filter = HistoryFilter {
        lobe: Some(lobe.parse().unwrap()),
        stage: Some(MeasurementStage::Final),
        ..HistoryFilter::new(machine.parse().unwrap(), 10_000)
    };
    let page = store.measurement_history(&filter).await.unwrap();
    let mut out = Vec::new();
    for s in page.items.into_iter().rev() {
        let detail = store.measurement(s.id).await.unwrap().unwrap();
        let report = serde_json::from_str(&detail.analysis_json).unwrap();
        out.push((s, report));
    }
    out
}

/// Each measurement identity the store holds for the feature, with its row count.
pub async fn stored_measurements(
    store: &Store,
    machine: &str,
    lobe: &str,
) -> BTreeMap<String, i64> {
    let RawPool::Sqlite(pool) = store.raw_pool() else {
        panic!("a SQLite store")
    };
    let rows: Vec<(String, i64)> = sqlx::query_as(
        "SELECT sha256, COUNT(*) FROM measurements WHERE machine = $1 AND lobe = $2 \
         GROUP BY sha256",
    )
    .bind(machine)
    .bind(lobe)
    .fetch_all(pool)
    .await
    .unwrap();
    rows.into_iter().collect()
}

/// The loop's memory a start resumes from: the journal's newest learning state, else the
/// store's (as the service loads it).
pub async fn resumed_memory(
    var: &Path,
    store: &Store,
    machine: &str,
    lobe: &str,
) -> Option<serde_json::Value> {
    let journalled = journal_records(var, machine, lobe)
        .into_iter()
        .rev()
        .find(|r| r["record"] == "learning")
        .map(|r| r["state"].clone());
    if journalled.is_some() {
        return journalled;
    }
    let stored = store
        .load_learning_state(&m(machine), &f(lobe))
        .await
        .unwrap()?;
    Some(serde_json::from_str(&stored.state_json).unwrap())
}

/// How one feature's share, journal and store agree.
#[derive(Debug, Default)]
pub struct Agreement {
    /// The versions the manifest tells of (the highest version number): once compacted it
    /// holds only the recent ones, so this is not the length of `held`.
    pub told: u64,
    /// The versions the manifest still holds, in order.
    pub held: Vec<u64>,
    /// Versions the share pushed, held or compacted away.
    pub pushed: u64,
    pub newest_pushed: Option<u64>,
    /// The stored learning state's version in force.
    pub in_force_version: Option<u64>,
    /// Each way share and store disagree on a version (or the versions are not 1..n once).
    pub mismatches: Vec<String>,
    /// Journal records the store does not hold.
    pub stuck: Vec<String>,
    /// Measurements that made more than one version (learned twice).
    pub learned_twice: Vec<String>,
}

/// Compares one feature's manifest with the store, version by version, and its journal with
/// the store.
pub async fn agreement(var: &Path, store: &Store, machine: &str, lobe: &str) -> Agreement {
    let path = feature_dir(var, machine, lobe).join("share/manifest.jsonl");
    let history = load_manifest(&path).unwrap().history;
    let mut a = Agreement {
        told: history.next_version().get() - 1,
        held: history
            .versions()
            .iter()
            .map(|v| v.record.version.get())
            .collect(),
        pushed: history.pushed_count(),
        newest_pushed: history.last_pushed().map(|v| v.record.version.get()),
        ..Agreement::default()
    };
    // A long run compacts the manifest (`share::compact`): it then holds only the versions
    // still needed, and the settled older ones are told of but forgotten. Held ones are
    // ascending, none twice, none above the highest told.
    if !a.held.windows(2).all(|w| w[0] < w[1]) || a.held.last().is_some_and(|&v| v > a.told) {
        a.mismatches.push(format!(
            "manifest versions {:?} (v{} told), not ascending once",
            a.held, a.told
        ));
    }
    let mut made_from: BTreeMap<Sha256, Vec<u64>> = BTreeMap::new();
    for v in history.versions() {
        let version = v.record.version;
        if let Some(m) = v.record.measurement_id {
            made_from.entry(m).or_default().push(version.get());
        }
        let Some(row) = store
            .table_version(&m(machine), &f(lobe), version)
            .await
            .unwrap()
        else {
            a.mismatches.push(format!("v{version}: not in the store"));
            continue;
        };
        a.mismatches.extend(compare_version(v, &row));
    }
    a.mismatches
        .extend(store_versions_told(store, machine, lobe, &history, &a.held).await);
    a.learned_twice = made_from
        .into_iter()
        .filter(|(_, versions)| versions.len() > 1)
        .map(|(m, versions)| format!("measurement {m} made versions {versions:?}"))
        .collect();
    a.in_force_version = store
        .load_learning_state(&m(machine), &f(lobe))
        .await
        .unwrap()
        .and_then(|s| serde_json::from_str::<serde_json::Value>(&s.state_json).ok())
        .and_then(|m| m["in_force_version"].as_u64());
    a.stuck = stuck(var, store, machine, lobe).await;
    a
}

/// How one held version differs between the share and its stored row.
fn compare_version(v: &VersionState, row: &StoredTableVersion) -> Vec<String> {
    let version = v.record.version;
    let mut out = Vec::new();
    if row.table_number != v.record.table_number {
        out.push(format!(
            "v{version}: table {} in the store, {} on the share",
            row.table_number, v.record.table_number
        ));
    }
    let expected = match &v.status {
        VersionStatus::Pushed { .. } | VersionStatus::Refused { .. } => Some(v.status.name()),
        _ => None,
    };
    if expected.is_some_and(|e| e != row.status.name()) {
        out.push(format!(
            "v{version}: {:?} in the store, {:?} on the share",
            row.status, v.status
        ));
    }
    if v.text_kept && row.sha256 != v.record.files[0].sha256 {
        out.push(format!(
            "v{version}: the store's program is not the share's"
        ));
    }
    out
}

/// The store holds every version the share told of, 1..told once each; those the manifest
/// no longer holds were compacted away after they settled (`share::compact`).
async fn store_versions_told(
    store: &Store,
    machine: &str,
    lobe: &str,
    history: &History,
    held: &[u64],
) -> Vec<String> {
    let told = history.next_version().get() - 1;
    let stored = store
        .table_versions(&m(machine), &f(lobe), 1000)
        .await
        .unwrap();
    let mut out = Vec::new();
    let mut numbers: Vec<u64> = stored.iter().map(|r| r.version.get()).collect();
    numbers.sort_unstable();
    if numbers != (1..=told).collect::<Vec<u64>>() {
        out.push(format!(
            "store versions {numbers:?}, not 1..{told} once (the share told of v{told})"
        ));
    }
    for row in stored.iter().filter(|r| {
        let v = r.version.get();
        !held.contains(&v)
            && camloop::core::ids::TableVersion::new(v).is_none_or(|v| !history.is_forgotten(v))
    }) {
        out.push(format!("v{}: in the store, not on the share", row.version));
    }
    out
}

/// What the journal still holds that the store does not: a stalled feature.
async fn stuck(var: &Path, store: &Store, machine: &str, lobe: &str) -> Vec<String> {
    let measurements = stored_measurements(store, machine, lobe).await;
    let mut stuck = Vec::new();
    for record in journal_records(var, machine, lobe) {
        match record["record"].as_str() {
            Some("table") => {
                let v = record["version"].as_u64().unwrap();
                let version =
                    camloop::core::ids::TableVersion::new(v).expect("a version is never 0");
                if store
                    .table_version(&m(machine), &f(lobe), version)
                    .await
                    .unwrap()
                    .is_none()
                {
                    stuck.push(format!("v{v} stuck in the journal"));
                }
            }
            Some("measurement") => {
                let sha = record["sha256"].as_str().unwrap();
                if !measurements.contains_key(sha) {
                    stuck.push(format!("measurement {sha} stuck in the journal"));
                }
            }
            _ => {}
        }
    }
    stuck
}
