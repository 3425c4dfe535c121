//! The plant overview's rows: every configured or recorded (machine, feature) with its state,
//! newest parts, table in force and band, read in a few set queries
//! ([`Store::plant_overview`]) rather than a handful per feature, so a plant of 500 machines
//! × 8 features is read at once. The page shows [`MACHINES_PER_PAGE`] machines at a time
//! (the whole plant was 4.6 MB of page). Even so, reading every feature's 50 newest parts and its
//! version in force was seconds on a loaded 2-core machine (200,000 rows spread over a
//! million-row table), so the rows are remembered ([`OverviewMemo`]) and a page reads again
//! only the features with a measurement or a table-version status stored since the last
//! page (found from two ranges of primary keys), and every row at least once a minute
//! whatever the ids say ([`MAX_ROW_AGE`]). Whether a feature's learning is frozen is
//! in its packed learning state: each state is unpacked once and remembered by its row id
//! and SHA-256, so a page unpacks only the states that changed since the last one.

use super::FeatureSheet;
use super::data::{MachineState, SPARK_PARTS, state, store};
use crate::names::{FeatureName, MachineName};
use crate::service::http::AppState;
use crate::service::http::api::ApiError;
use crate::store::{FeatureOverview, OverviewPart, Store, TableVersionHead, VersionStatus};
use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Events of a machine looked at for its alarm (as its feature page lists them).
const EVENTS: u32 = 50;
/// Table versions looked at for the one in force (the newest pushed among them).
const VERSIONS: u32 = 20;

/// One (machine, feature) line of the overview.
pub(super) struct OverviewRow {
    pub machine: MachineName,
    pub lobe: FeatureName,
    pub state: MachineState,
    /// The newest finished production parts, oldest first.
    pub recent: Vec<OverviewPart>,
    pub band_um: Option<f64>,
    /// The version the control has: the newest pushed.
    pub in_force: Option<TableVersionHead>,
}

/// Ids looked at again below the newest seen: a row whose id was handed out before a higher
/// one but committed after it (PostgreSQL's writers run side by side; SQLite's one writer
/// cannot do this) is found at the next view as long as fewer than this many ids came in
/// between. It is only a shortcut: [`MAX_ROW_AGE`] is what bounds a row's staleness.
const LOOK_BACK_IDS: i64 = 1024;

/// The longest a remembered row is shown without being read again, whatever the ids say.
/// Three instances writing batches of 256 records can commit a row after more than
/// [`LOOK_BACK_IDS`] higher ids; that row shows at the latest one view after this age.
/// Every feature of a running plant stores a part about every 30 s and is read again for
/// it anyway, so the age costs reads only for idle features.
pub(super) const MAX_ROW_AGE: Duration = Duration::from_secs(60);

/// A remembered row and the instant its read began (the store's state is at least that new).
struct Entry {
    row: FeatureOverview,
    read_at: Instant,
}

/// The overview's rows as last read, the newest measurement and status ids they cover, and
/// the ids of the look-back window already seen.
#[derive(Default)]
struct Remembered {
    rows: HashMap<(MachineName, FeatureName), Entry>,
    measurement: i64,
    status: i64,
    /// Measurement ids above `measurement - LOOK_BACK_IDS` seen at the last view: looking
    /// back finds them again, and only an id not among them is a change. Without this every
    /// view read again the features of the last 1,024 ids as if they had changed.
    seen_measurements: HashSet<i64>,
    /// The same for table-version status ids.
    seen_statuses: HashSet<i64>,
    /// Rows the last view read from the store (all of them at the first).
    read_last: usize,
}

/// The features of `rows` whose ids are not in `seen`, and the ids to remember as seen for
/// the next look back (those above `newest - LOOK_BACK_IDS`, all of them now seen).
fn unseen(
    rows: &[(i64, MachineName, FeatureName)],
    seen: &HashSet<i64>,
    newest: i64,
) -> (BTreeSet<(MachineName, FeatureName)>, HashSet<i64>) {
    let changed = rows
        .iter()
        .filter(|(id, _, _)| !seen.contains(id))
        .map(|(_, m, f)| (m.clone(), f.clone()))
        .collect();
    let window = rows
        .iter()
        .map(|(id, _, _)| *id)
        .filter(|id| *id > newest - LOOK_BACK_IDS)
        .collect();
    (changed, window)
}

/// Each feature's newest parts and version in force as last read (see the module's doc).
/// One page at a time brings it up to date.
#[derive(Clone, Default)]
pub(super) struct OverviewMemo(Arc<tokio::sync::Mutex<Remembered>>);

/// When a row read now, `index`-th of `count` read together, counts as read: up to half of
/// [`MAX_ROW_AGE`] earlier, spread over the rows, so the rows of one big read (the first
/// view: 4,000 rows) fall due over many views instead of all on one.
fn read_at(now: Instant, index: usize, count: usize) -> Instant {
    let fraction = index as f64 / count.max(1) as f64;
    now.checked_sub(MAX_ROW_AGE.mul_f64(0.5 * fraction))
        .unwrap_or(now)
}

impl OverviewMemo {
    /// Every feature's parts and version in force, read again only where something was
    /// stored since the last call or the row is [`MAX_ROW_AGE`] old.
    async fn read(
        &self,
        store: &Store,
        keys: &[(MachineName, FeatureName)],
    ) -> Result<Vec<FeatureOverview>, ApiError> {
        self.read_as_of(store, keys, Instant::now()).await
    }

    /// How many rows the last view read from the store rather than from memory.
    #[cfg(test)]
    pub(super) async fn rows_read_last(&self) -> usize {
        self.0.lock().await.read_last
    }

    /// [`OverviewMemo::read`] with the clock given: `now` is taken before anything is read.
    pub(super) async fn read_as_of(
        &self,
        store: &Store,
        keys: &[(MachineName, FeatureName)],
        now: Instant,
    ) -> Result<Vec<FeatureOverview>, ApiError> {
        let mut memo = self.0.lock().await;
        // Nothing remembered: every row is read whole after this, so the newest ids and the
        // look-back window below them are only taken as seen.
        let first = memo.rows.is_empty();
        let mut changes = match first {
            true => store.overview_changes(i64::MAX, i64::MAX).await?,
            false => {
                let since = |id: i64| id - LOOK_BACK_IDS;
                store
                    .overview_changes(since(memo.measurement), since(memo.status))
                    .await?
            }
        };
        if first {
            changes = store
                .overview_changes(
                    changes.measurement - LOOK_BACK_IDS,
                    changes.status - LOOK_BACK_IDS,
                )
                .await?;
        }
        let (mut changed, seen_measurements) = unseen(
            &changes.measurements,
            &memo.seen_measurements,
            changes.measurement,
        );
        let (by_status, seen_statuses) =
            unseen(&changes.statuses, &memo.seen_statuses, changes.status);
        changed.extend(by_status);
        if first {
            changed.clear();
        }
        let due = |k: &(MachineName, FeatureName)| match memo.rows.get(k) {
            None => true,
            Some(e) => {
                changed.contains(k) || now.saturating_duration_since(e.read_at) >= MAX_ROW_AGE
            }
        };
        let stale: Vec<(MachineName, FeatureName)> =
            keys.iter().filter(|k| due(k)).cloned().collect();
        // Changed features of other pages are forgotten, so their page reads them again:
        // the newest ids below move on for the whole plant, not for this page alone.
        for k in &changed {
            memo.rows.remove(k);
        }
        memo.read_last = stale.len();
        if !stale.is_empty() {
            let read = store.plant_overview(&stale, SPARK_PARTS, VERSIONS).await?;
            let count = stale.len();
            for (i, (k, row)) in stale.into_iter().zip(read).enumerate() {
                let read_at = read_at(now, i, count);
                memo.rows.insert(k, Entry { row, read_at });
            }
        }
        memo.measurement = changes.measurement;
        memo.status = changes.status;
        memo.seen_measurements = seen_measurements;
        memo.seen_statuses = seen_statuses;
        let learning = store.plant_learning(keys).await?;
        Ok(keys
            .iter()
            .zip(learning)
            .map(|(k, learning)| FeatureOverview {
                learning,
                ..memo.rows.get(k).map(|e| e.row.clone()).unwrap_or_default()
            })
            .collect())
    }
}

/// Whether each feature's newest learning state is frozen, by (row id, SHA-256 of its
/// text): a row replaced in place gets a new SHA-256, so an entry is never stale.
#[derive(Clone, Default)]
pub(super) struct FrozenMemo(Arc<Mutex<HashMap<FeatureKey, Unpacked>>>);

type FeatureKey = (MachineName, FeatureName);

/// A learning state once unpacked: its row id, the SHA-256 of its text, whether frozen.
type Unpacked = (i64, String, bool);

impl FrozenMemo {
    fn get(&self, key: &(MachineName, FeatureName), id: i64, sha: &str) -> Option<bool> {
        let memo = self.0.lock().unwrap_or_else(|p| p.into_inner());
        memo.get(key)
            .filter(|(i, s, _)| *i == id && s == sha)
            .map(|x| x.2)
    }

    fn put(&self, key: (MachineName, FeatureName), id: i64, sha: String, frozen: bool) {
        let mut memo = self.0.lock().unwrap_or_else(|p| p.into_inner());
        memo.insert(key, (id, sha, frozen));
    }
}

/// Every (machine, feature): the configured ones and those only the store knows, in order.
async fn features(
    app: &AppState,
    store: &Store,
) -> Result<BTreeMap<MachineName, BTreeSet<FeatureName>>, ApiError> {
    let mut out: BTreeMap<MachineName, BTreeSet<FeatureName>> = app
        .machines
        .iter()
        .map(|(m, lobes)| (m.clone(), lobes.iter().cloned().collect()))
        .collect();
    for (m, lobe) in store.known_features().await? {
        let lobes = out.entry(m).or_default();
        lobes.extend(lobe);
    }
    Ok(out)
}

/// Whether the learning state in row `id` is frozen: from the memo, or unpacked now.
async fn frozen(
    store: &Store,
    memo: &FrozenMemo,
    key: &(MachineName, FeatureName),
    learning: &Option<(i64, Option<String>)>,
) -> Result<bool, ApiError> {
    let Some((id, sha)) = learning else {
        return Ok(false);
    };
    if let Some(sha) = sha
        && let Some(f) = memo.get(key, *id, sha)
    {
        return Ok(f);
    }
    let state = store.learning_state_row_for_view(*id).await?;
    let frozen = super::data::learning_of(state).frozen.is_some();
    if let Some(sha) = sha {
        memo.put(key.clone(), *id, sha.clone(), frozen);
    }
    Ok(frozen)
}

/// Machines on one page of the overview: 50 machines (400 rows of an 8-lobe shaft) keep a
/// page near 0.5 MB; all 500 machines of a plant on one page were 4.6 MB and over half a
/// second to read, build and send on 2 cores.
pub(super) const MACHINES_PER_PAGE: usize = 50;

/// One page of the overview: its rows, which page of how many, and the plant's size.
pub(super) struct OverviewPage {
    pub rows: Vec<OverviewRow>,
    /// From 1.
    pub page: usize,
    pub pages: usize,
    pub machines: usize,
    pub features: usize,
    /// Every machine in alarm, on whatever page, with the page it is on.
    pub alarms: Vec<(MachineName, usize)>,
}

/// Page `page` (from 1; past the last, the last) of the overview: the rows of its
/// [`MACHINES_PER_PAGE`] machines, in name order.
pub(super) async fn overview(
    app: &AppState,
    rows_memo: &OverviewMemo,
    memo: &FrozenMemo,
    page: usize,
) -> Result<OverviewPage, ApiError> {
    let store = store(app).await?;
    let metrics = app.metrics.snapshot();
    let features = features(app, &store).await?;
    let pages = features.len().div_ceil(MACHINES_PER_PAGE).max(1);
    let page = page.clamp(1, pages);
    let keys: Vec<(MachineName, FeatureName)> = features
        .iter()
        .skip((page - 1) * MACHINES_PER_PAGE)
        .take(MACHINES_PER_PAGE)
        .flat_map(|(m, lobes)| lobes.iter().map(|l| (m.clone(), l.clone())))
        .collect();
    let read = rows_memo.read(&store, &keys).await?;
    let alarms = store.machines_in_alarm(EVENTS).await?;
    let mut rows = Vec::with_capacity(keys.len());
    for (key, f) in keys.into_iter().zip(read) {
        let frozen = frozen(&store, memo, &key, &f.learning).await?;
        let (machine, lobe) = key;
        let sheet = app.dashboard.get(&(machine.clone(), lobe.clone()));
        rows.push(OverviewRow {
            state: state(
                metrics.get(machine.as_str()),
                alarms.contains(&machine),
                frozen,
                f.recent.is_empty(),
            ),
            band_um: sheet.and_then(FeatureSheet::symmetric_band_um),
            in_force: f
                .in_force
                .filter(|v| matches!(v.status, VersionStatus::Pushed { .. })),
            machine,
            lobe,
            recent: f.recent,
        });
    }
    Ok(OverviewPage {
        rows,
        page,
        pages,
        machines: features.len(),
        features: features.values().map(BTreeSet::len).sum(),
        alarms: features
            .keys()
            .enumerate()
            .filter(|(_, m)| alarms.contains(*m))
            .map(|(i, m)| (m.clone(), i / MACHINES_PER_PAGE + 1))
            .collect(),
    })
}
