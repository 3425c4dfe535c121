//! The overview memo: a view reads again only the rows with something new (not those the
//! look back finds again), and its staleness bound: a row PostgreSQL's side-by-side writers
//! commit after more than the look-back's worth of higher ids still shows once its
//! feature's remembered row is `MAX_ROW_AGE` old. SQLite's one writer cannot commit out of id order, so the late
//! commit is made by hand: the row is stored early as an in-process measurement (not an
//! overview point) and turned into a finished part after the first view, keeping its id.

use super::overview::{MAX_ROW_AGE, OverviewMemo};
use crate::digest::Sha256;
use crate::names::{FeatureName, MachineName};
use crate::store::{MeasurementStage, NewMeasurement, Store, Verdict};
use std::time::{Duration, Instant};

fn part(machine: &str, lobe: &str, n: u32, stage: MeasurementStage) -> NewMeasurement {
    NewMeasurement {
        machine: machine.parse().unwrap(),
        part: format!("P-{n}").parse().unwrap(),
        lobe: lobe.parse().unwrap(),
        received_at: jiff::Timestamp::from_millisecond(1_000 * i64::from(n)).unwrap(),
        verdict: Verdict::Pass,
        max_profile_error_um: 2.0,
        base_radius_error_um: 0.0,
        phase_error_deg: 0.0,
        revolutions_used: 1,
        stage,
        points_per_rev: 4,
        origin: "test".into(),
        sha256: Sha256::of(format!("{machine}/{lobe}/{n}").as_bytes()),
        recipe_snapshot: None,
        raw_lift_mm: vec![vec![0.0, 0.1, 0.2, 0.1]],
        averaged_lift_mm: vec![0.0, 0.1, 0.2, 0.1],
        analysis_json: "{}".into(),
    }
}

#[tokio::test]
async fn a_row_committed_below_the_look_back_shows_within_the_age_bound() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/o.db?mode=rwc", dir.path().display());
    let store = Store::connect(&url).await.unwrap();
    let raw = sqlx::SqlitePool::connect(&url).await.unwrap();
    let late = store
        .insert_measurement(&part("M1", "B", 1, MeasurementStage::InProcess))
        .await
        .unwrap();
    // The next ids far above the late row's: 5,000 ids handed out and committed meanwhile.
    sqlx::query("UPDATE sqlite_sequence SET seq = 5000 WHERE name = 'measurements'")
        .execute(&raw)
        .await
        .unwrap();
    let newest = store
        .insert_measurement(&part("M1", "A", 2, MeasurementStage::Final))
        .await
        .unwrap();
    assert!(newest.0 - late.0 > 1024, "ids {} and {}", late.0, newest.0);
    let keys: Vec<(MachineName, FeatureName)> = [("M1", "A"), ("M1", "B")]
        .iter()
        .map(|(m, f)| (m.parse().unwrap(), f.parse().unwrap()))
        .collect();
    let memo = OverviewMemo::default();
    let t0 = Instant::now();
    let first = memo.read_as_of(&store, &keys, t0).await.unwrap();
    assert_eq!(first[0].recent.len(), 1);
    assert!(first[1].recent.is_empty(), "{:?}", first[1]);

    // The late commit: B's row becomes a finished part under its old, low id.
    sqlx::query("UPDATE measurements SET stage = 'final' WHERE id = $1")
        .bind(late.0)
        .execute(&raw)
        .await
        .unwrap();
    let fresh = store.plant_overview(&keys[1..], 50, 20).await.unwrap();
    assert_eq!(fresh[0].recent.len(), 1, "the store has B's part now");

    // Within the bound the remembered row may still show (the ids do not reveal it)...
    let soon = memo
        .read_as_of(&store, &keys, t0 + Duration::from_secs(1))
        .await
        .unwrap();
    assert!(soon[1].recent.is_empty(), "{:?}", soon[1]);
    // ...and at the bound it shows, whatever the ids said.
    let after = memo
        .read_as_of(&store, &keys, t0 + MAX_ROW_AGE)
        .await
        .unwrap();
    let ids: Vec<i64> = after[1].recent.iter().map(|p| p.id.0).collect();
    assert_eq!(ids, vec![late.0]);
    assert_eq!(after[0], first[0], "A unchanged");
    raw.close().await;
}

/// The overview shows one page of machines at a time, while the newest ids the memo keeps
/// move on for the whole plant: a part stored for a feature of another page while this one
/// is viewed shows when that page is viewed next, not a minute later.
#[tokio::test]
async fn a_part_stored_while_another_page_is_viewed_shows_on_its_own_page() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/p.db?mode=rwc", dir.path().display());
    let store = Store::connect(&url).await.unwrap();
    for (lobe, n) in [("A", 1), ("B", 2)] {
        store
            .insert_measurement(&part("M1", lobe, n, MeasurementStage::Final))
            .await
            .unwrap();
    }
    let key =
        |f: &str| -> (MachineName, FeatureName) { ("M1".parse().unwrap(), f.parse().unwrap()) };
    let (page_a, page_b) = ([key("A")], [key("B")]);
    let memo = OverviewMemo::default();
    let t0 = Instant::now();
    memo.read_as_of(&store, &page_a, t0).await.unwrap();
    let before = memo.read_as_of(&store, &page_b, t0).await.unwrap();
    assert_eq!(before[0].recent.len(), 1);
    let new = store
        .insert_measurement(&part("M1", "B", 3, MeasurementStage::Final))
        .await
        .unwrap();
    // Page A viewed after more than the look-back's worth of ids: the newest ids move far
    // past B's new part, so only what page A's view did with it can bring it to page B.
    let raw = sqlx::SqlitePool::connect(&url).await.unwrap();
    sqlx::query("UPDATE sqlite_sequence SET seq = 5000 WHERE name = 'measurements'")
        .execute(&raw)
        .await
        .unwrap();
    raw.close().await;
    store
        .insert_measurement(&part("M1", "A", 4, MeasurementStage::Final))
        .await
        .unwrap();
    memo.read_as_of(&store, &page_a, t0).await.unwrap();
    let after = memo.read_as_of(&store, &page_b, t0).await.unwrap();
    let ids: Vec<i64> = after[0].recent.iter().map(|p| p.id.0).collect();
    assert_eq!(ids.last(), Some(&new.0), "{ids:?}");
    assert_eq!(ids.len(), 2);
}

/// The look back below the newest ids finds the rows of the last view again: they are no
/// change. Before, every view read again each feature with one of the last 1,024
/// measurements or status rows (at 500 machines × 8, a whole page of 400 rows each view).
#[tokio::test]
async fn a_view_reads_again_only_the_features_with_something_new() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/r.db?mode=rwc", dir.path().display());
    let store = Store::connect(&url).await.unwrap();
    let lobes = ["A", "B", "C"];
    for (n, lobe) in (1..).zip(lobes) {
        store
            .insert_measurement(&part("M1", lobe, n, MeasurementStage::Final))
            .await
            .unwrap();
    }
    let keys: Vec<(MachineName, FeatureName)> = lobes
        .iter()
        .map(|f| ("M1".parse().unwrap(), f.parse().unwrap()))
        .collect();
    let memo = OverviewMemo::default();
    let t0 = Instant::now();
    let first = memo.read_as_of(&store, &keys, t0).await.unwrap();
    assert_eq!(
        memo.rows_read_last().await,
        3,
        "the first view reads every row"
    );
    let again = memo.read_as_of(&store, &keys, t0).await.unwrap();
    assert_eq!(memo.rows_read_last().await, 0, "nothing stored since");
    assert_eq!(again, first);

    let new = store
        .insert_measurement(&part("M1", "B", 4, MeasurementStage::Final))
        .await
        .unwrap();
    let after = memo.read_as_of(&store, &keys, t0).await.unwrap();
    assert_eq!(memo.rows_read_last().await, 1, "only B has a new part");
    assert_eq!(after[1].recent.last().map(|p| p.id), Some(new));
    assert_eq!((&after[0], &after[2]), (&first[0], &first[2]));
    memo.read_as_of(&store, &keys, t0).await.unwrap();
    assert_eq!(memo.rows_read_last().await, 0, "B's part is seen now");
}
