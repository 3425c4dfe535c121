//! The plant overview's set queries (`Store::plant_overview`, `Store::machines_in_alarm`,
//! `Store::known_features`) against the per-feature reads the feature pages use, on both
//! backends, over a store with what the overview must tell apart: more parts than the
//! sparkline, master runs and in-process measurements (never points), a part stored late
//! with an older time, versions waiting, refused and pushed (the table in force is the
//! newest pushed), acknowledged and unacknowledged errors (one beyond the events looked
//! at), learning states packed in a chain (one frozen), and features with nothing stored.

use crate::overview_reference;
use crate::store_support::data::{measurement, ms, table};
use crate::store_support::{self, TestStore, f, m, tv};
use camloop::names::{FeatureName, MachineName};
use camloop::store::{
    EventKind, EventLevel, FeatureKind, MeasurementStage, NewEvent, NewRecipeSnapshot, Store,
    VersionStatus,
};
use std::collections::BTreeSet;

const PARTS: u32 = 50;
const VERSIONS: u32 = 20;
const EVENTS: u32 = 50;

fn state(step: u32, frozen: Option<&str>) -> String {
    serde_json::json!({"learning": {"correction_um": vec![0.1 * f64::from(step); 36], "frozen": frozen}, "parts": step})
        .to_string()
}

async fn event(s: &Store, machine: &str, at: i64, level: EventLevel) -> i64 {
    let e = NewEvent {
        machine: m(machine),
        at: ms(at),
        level,
        kind: EventKind::TableRefused,
        message: format!("event at {at}"),
    };
    s.insert_event(&e).await.unwrap().0
}

/// The store described in the module's doc.
async fn seed(s: &Store) {
    for n in 1..=60 {
        s.insert_measurement(&measurement("M1", "IN1", n, 10_000 + i64::from(n) * 1000))
            .await
            .unwrap();
    }
    // Newer than every part, yet never a point: master runs (either case) and an in-process
    // measurement; and a part stored last with the oldest time.
    let mut master = measurement("M1", "IN1", 61, 90_000);
    master.part = "MASTER".parse().unwrap();
    let mut lower = measurement("M1", "IN1", 62, 91_000);
    lower.part = "master-7".parse().unwrap();
    let mut in_process = measurement("M1", "IN1", 63, 92_000);
    in_process.stage = MeasurementStage::InProcess;
    let late = measurement("M1", "IN1", 64, 500);
    for x in [master, lower, in_process, late] {
        s.insert_measurement(&x).await.unwrap();
    }
    for n in 1..=3 {
        s.insert_measurement(&measurement("M1", "EX1", 100 + n, 20_000 + i64::from(n)))
            .await
            .unwrap();
    }
    let mut only_master = measurement("M2", "IN1", 200, 30_000);
    only_master.part = "MASTER".parse().unwrap();
    s.insert_measurement(&only_master).await.unwrap();

    // M1 IN1: v1, v2 pushed, v3 refused, v4 waiting: v2 is in force. M1 EX1: v1 waiting,
    // then pushed (a status row appended).
    for (v, status) in [(1, "pushed"), (2, "pushed"), (3, "refused"), (4, "waiting")] {
        let parent = (v > 1).then(|| tv(v - 1));
        s.insert_table_version(&table("IN1", parent, &format!("; v{v}\nM17\n"), status))
            .await
            .unwrap();
    }
    s.insert_table_version(&table("EX1", None, "; ex v1\nM17\n", "waiting"))
        .await
        .unwrap();
    let pushed = VersionStatus::from_column("pushed", "pushed to share".into(), 7_000).unwrap();
    s.set_table_status(&m("M1"), &f("EX1"), tv(1), &pushed, ms(7_000))
        .await
        .unwrap();

    // Learning: three states of M1 IN1 (packed against each other), the newest frozen.
    for step in 1..=3 {
        let frozen = (step == 3).then_some("step reverted: error grew");
        s.save_learning_state(&m("M1"), &f("IN1"), &state(step, frozen), ms(40_000))
            .await
            .unwrap();
    }
    s.save_learning_state(&m("M1"), &f("EX1"), &state(1, None), ms(40_000))
        .await
        .unwrap();

    // Events: M1's error acknowledged; M2's not; M3's unacknowledged error is older than
    // its newest 50 events.
    let e = event(s, "M1", 1_000, EventLevel::Error).await;
    s.acknowledge_event(&m("M1"), camloop::store::EventId(e), ms(2_000), "dashboard")
        .await
        .unwrap();
    event(s, "M1", 3_000, EventLevel::Info).await;
    event(s, "M2", 1_000, EventLevel::Error).await;
    event(s, "M3", 1_000, EventLevel::Error).await;
    for k in 0..EVENTS {
        event(s, "M3", 2_000 + i64::from(k), EventLevel::Warn).await;
    }
    s.insert_recipe_snapshot(&NewRecipeSnapshot {
        machine: m("M1"),
        part: "CAM".parse().unwrap(),
        lobe: f("IN1"),
        kind: FeatureKind::Lobe,
        recipe_json: "{}".into(),
        created_at: ms(1_000),
    })
    .await
    .unwrap();
}

async fn overview_equals_the_feature_reads(t: TestStore) {
    let s = &t.store;
    seed(s).await;
    let keys: Vec<(MachineName, FeatureName)> = [
        ("M1", "IN1"),
        ("M1", "EX1"),
        ("M2", "IN1"),
        ("M3", "IN1"),
        ("M9", "IN1"),
    ]
    .iter()
    .map(|(a, b)| (m(a), f(b)))
    .collect();
    let set = s.plant_overview(&keys, PARTS, VERSIONS).await.unwrap();
    let reference = overview_reference::features(s, &keys, PARTS, VERSIONS).await;
    assert_eq!(set.len(), keys.len());
    for (k, ((r, text), o)) in keys.iter().zip(reference.iter().zip(&set)) {
        assert_eq!(r.recent, o.recent, "{k:?}: parts");
        assert_eq!(r.in_force, o.in_force, "{k:?}: version in force");
        let row = match &o.learning {
            Some((id, _)) => s.learning_state_row_for_view(*id).await.unwrap(),
            None => None,
        };
        assert_eq!(text, &row.map(|l| l.state_json), "{k:?}: learning state");
    }
    // What the two agree on is the right answer, not an empty one.
    let in1 = &set[0];
    assert_eq!(in1.recent.len(), PARTS as usize);
    let parts: Vec<&str> = in1.recent.iter().map(|p| p.part.as_str()).collect();
    assert_eq!(parts.first(), Some(&"P-00011"), "oldest of the newest 50");
    assert_eq!(parts.last(), Some(&"P-00060"), "newest by time, not by id");
    assert_eq!(in1.in_force.as_ref().map(|v| v.version), Some(tv(2)));
    assert_eq!(set[1].recent.len(), 3);
    assert_eq!(set[1].in_force.as_ref().map(|v| v.version), Some(tv(1)));
    assert!(set[2].recent.is_empty() && set[2].in_force.is_none());
    assert!(set[2].learning.is_none() && set[4] == Default::default());
    // The learning state is read whole from its packed chain: the frozen one shows frozen.
    let view = s
        .learning_state_for_view(&m("M1"), &f("IN1"))
        .await
        .unwrap();
    assert_eq!(
        view.map(|l| l.state_json),
        Some(state(3, Some("step reverted: error grew")))
    );

    let alarms = s.machines_in_alarm(EVENTS).await.unwrap();
    assert_eq!(alarms, overview_reference::alarms(s, EVENTS).await);
    assert_eq!(alarms, BTreeSet::from([m("M2")]));

    let known = s.known_features().await.unwrap();
    assert_eq!(
        known,
        vec![(m("M1"), Some(f("IN1"))), (m("M2"), None), (m("M3"), None)]
    );
    changes_by_id(s).await;
}

/// What changed since given ids, each row with its id and feature: nothing above the newest,
/// a new part above them, and looking back finds the rows below again.
async fn changes_by_id(s: &Store) {
    let newest = s.overview_changes(i64::MAX, i64::MAX).await.unwrap();
    assert!(newest.measurements.is_empty() && newest.statuses.is_empty());
    let id = s
        .insert_measurement(&measurement("M3", "EX1", 900, 99_000))
        .await
        .unwrap();
    let after = s
        .overview_changes(newest.measurement, newest.status)
        .await
        .unwrap();
    assert_eq!(after.measurements, vec![(id.0, m("M3"), f("EX1"))]);
    assert_eq!((after.measurement, after.status), (id.0, newest.status));
    assert!(after.statuses.is_empty());
    let back = s
        .overview_changes(newest.measurement - 1, newest.status - 1)
        .await
        .unwrap();
    let ids: Vec<i64> = back.measurements.iter().map(|r| r.0).collect();
    assert_eq!(ids, vec![newest.measurement, id.0]);
    assert_eq!(back.statuses, vec![(newest.status, m("M1"), f("EX1"))]);
}

#[tokio::test]
async fn overview_equals_the_feature_reads_on_sqlite() {
    overview_equals_the_feature_reads(store_support::sqlite().await).await;
}

#[tokio::test]
async fn overview_equals_the_feature_reads_on_postgres() {
    if let Some(t) = store_support::postgres("dashboard_overview").await {
        overview_equals_the_feature_reads(t).await;
    }
}

/// The overview page's rows as (machine, lobe, last part id, table in force), in order.
fn page_rows(page: &str) -> Vec<(String, String, i64, String)> {
    let attr = |row: &str, name: &str| -> String {
        let from = row.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        row[from..from + row[from..].find('"').unwrap()].to_string()
    };
    page.split("<tr data-machine=")
        .skip(1)
        .map(|r| {
            let row = format!("data-machine={r}");
            let cells: Vec<&str> = row.split("<td>").collect();
            // The table's cell: "v2 (T11)" or "—".
            let table = cells[5].split("</td>").next().unwrap().trim().to_string();
            (
                attr(&row, "data-machine"),
                attr(&row, "data-lobe"),
                attr(&row, "data-last-id").parse().unwrap(),
                table,
            )
        })
        .collect()
}

/// What the feature reads say each row must show.
async fn expected_rows(
    s: &Store,
    keys: &[(MachineName, FeatureName)],
) -> Vec<(String, String, i64, String)> {
    let reference = overview_reference::features(s, keys, PARTS, VERSIONS).await;
    keys.iter()
        .zip(reference)
        .map(|((m, f), (r, _))| {
            let table = match &r.in_force {
                Some(v) => format!("v{} (T{})", v.version, v.table_number),
                None => "—".to_string(),
            };
            (
                m.to_string(),
                f.to_string(),
                r.recent.last().map_or(0, |p| p.id.0),
                table,
            )
        })
        .collect()
}

/// The page served twice over a store that changes in between (a new part, a late part
/// with an older time, a status appended): each time every row shows what the feature
/// reads say, so what the page remembers between views never shows an old row.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_overview_page_follows_the_store_between_views() {
    use crate::service_support::get;
    use camloop::service::http::{self, AppState, HttpLimits};
    use std::collections::BTreeMap;
    use std::sync::Arc;
    use std::time::Duration;
    let t = store_support::sqlite().await;
    let s = t.store.clone();
    seed(&s).await;
    let keys: Vec<(MachineName, FeatureName)> = [("M1", "EX1"), ("M1", "IN1"), ("M2", "IN1")]
        .iter()
        .map(|(a, b)| (m(a), f(b)))
        .collect();
    let mut machines: BTreeMap<MachineName, Vec<FeatureName>> = BTreeMap::new();
    for (a, b) in &keys {
        machines.entry(a.clone()).or_default().push(b.clone());
    }
    let limits = HttpLimits {
        max_connections: 16,
        max_connections_per_client: 16,
        header_timeout: Duration::from_secs(10),
        body_timeout: Duration::from_secs(10),
    };
    let state = AppState {
        store: Arc::new(tokio::sync::RwLock::new(Some(s.clone()))),
        metrics: Arc::default(),
        machines: Arc::new(machines),
        commands: Arc::default(),
        auth: Arc::new(http::AuthState::new(None, true)),
        body_timeout: limits.body_timeout,
        dashboard: Arc::new(BTreeMap::new()),
        cluster: None,
    };
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::watch::channel(false);
    tokio::spawn(http::serve(listener, http::router(state), limits, stopped));

    let (status, page) = get(addr, "/").await;
    assert_eq!(status, 200, "{page}");
    let first = page_rows(&page);
    assert_eq!(first, expected_rows(&s, &keys).await);
    assert_eq!(first[1].3, "v2 (T11)", "{first:?}");

    // A new part of M1 IN1, a part of M1 EX1 stored late with the oldest time, and M1 IN1's
    // waiting v4 pushed.
    let new = s
        .insert_measurement(&measurement("M1", "IN1", 70, 95_000))
        .await
        .unwrap();
    s.insert_measurement(&measurement("M1", "EX1", 71, 100))
        .await
        .unwrap();
    let pushed = VersionStatus::from_column("pushed", "pushed to share".into(), 9_000).unwrap();
    s.set_table_status(&m("M1"), &f("IN1"), tv(4), &pushed, ms(9_000))
        .await
        .unwrap();
    let (_, page) = get(addr, "/").await;
    let second = page_rows(&page);
    assert_eq!(second, expected_rows(&s, &keys).await);
    assert_eq!(second[1].2, new.0, "{second:?}");
    assert_eq!(second[1].3, "v4 (T11)", "{second:?}");
    let _ = stop.send(true);
}
