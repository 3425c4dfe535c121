//! Writing to the history store safely, on SQLite and on a throwaway PostgreSQL server: an
//! insert is idempotent and refuses bad input, a replayed journal finds what is already
//! stored, concurrent writers lose nothing, and a measurement's stage reads back as written
//! and filters the history.

use crate::store_support;

use store_support::data::{filter, measurement, ms, table};
use store_support::{f, m, tv};

use camloop::store::{
    EventKind, EventLevel, HistoryFilter, MeasurementStage, NewDressing, NewEvent, NewMeasurement,
    Store, StoreError,
};

async fn idempotent(store: &Store) {
    let m = measurement("M9", "in1", 1, 1_000);
    let a = store.insert_measurement(&m).await.unwrap();
    let b = store.insert_measurement(&m).await.unwrap();
    assert_eq!(a, b);
    // Same hash, later arrival: still the stored measurement, nothing new written.
    let late = NewMeasurement {
        received_at: ms(2_000),
        ..m.clone()
    };
    assert_eq!(store.insert_measurement(&late).await.unwrap(), a);
    let page = store.measurement_history(&filter("M9")).await.unwrap();
    assert_eq!(page.items.len(), 1);
    assert_eq!(page.items[0].received_at, ms(1_000));

    // Refused input names the field and writes nothing.
    let mut short = measurement("M9", "in1", 2, 3_000);
    short.averaged_lift_mm.pop();
    let e = store.insert_measurement(&short).await.unwrap_err();
    assert_eq!(
        e.to_string(),
        "invalid averaged_lift_mm: 35 values, expected points_per_rev = 36"
    );
    let mut nan = measurement("M9", "in1", 3, 3_000);
    nan.raw_lift_mm[1][7] = f64::NAN;
    assert!(matches!(
        store.insert_measurement(&nan).await,
        Err(StoreError::Invalid {
            field: "lift_mm",
            ..
        })
    ));
    let mut not_json = measurement("M9", "in1", 4, 3_000);
    not_json.analysis_json = "{".into();
    assert_eq!(
        store
            .insert_measurement(&not_json)
            .await
            .unwrap_err()
            .code(),
        "invalid"
    );
    assert_eq!(
        store
            .measurement_history(&filter("M9"))
            .await
            .unwrap()
            .items
            .len(),
        1
    );
}

#[tokio::test]
async fn idempotent_insert_on_sqlite() {
    idempotent(&store_support::sqlite().await.store).await;
}

#[tokio::test]
async fn idempotent_insert_on_postgres() {
    let Some(t) = store_support::postgres("idempotent_insert_on_postgres").await else {
        return;
    };
    idempotent(&t.store).await;
}

/// What a journal replayed after a crash asks the store: is this record already in? Each
/// look-up finds the stored record and nothing that differs in one identifying field; and
/// the durability call answers yes on an idle store.
async fn replay_lookups(store: &Store) {
    let t = table("in1", None, "CTABDEF(X,C,11,1)\nCTABEND\n", "pushed");
    store.insert_table_version(&t).await.unwrap();
    assert!(
        store
            .table_version_exists(&m("M1"), &f("in1"), ms(5_000), &t.program_text)
            .await
            .unwrap()
    );
    assert!(
        !store
            .table_version_exists(&m("M1"), &f("in1"), ms(5_001), &t.program_text)
            .await
            .unwrap()
    );
    assert!(
        !store
            .table_version_exists(&m("M1"), &f("in1"), ms(5_000), "other")
            .await
            .unwrap()
    );
    assert!(
        !store
            .table_version_exists(&m("M1"), &f("ex1"), ms(5_000), &t.program_text)
            .await
            .unwrap()
    );

    let e = NewEvent {
        machine: m("M1"),
        at: ms(7_000),
        level: EventLevel::Warn,
        kind: EventKind::TableRefused,
        message: "grindability".into(),
    };
    store.insert_event(&e).await.unwrap();
    assert!(store.event_exists(&e).await.unwrap());
    let other = NewEvent {
        message: "axis limits".into(),
        ..e.clone()
    };
    assert!(!store.event_exists(&other).await.unwrap());

    store
        .save_learning_state(&m("M1"), &f("in1"), r#"{"i":1}"#, ms(8_000))
        .await
        .unwrap();
    assert!(
        store
            .learning_state_exists(&m("M1"), &f("in1"), r#"{"i":1}"#, ms(8_000))
            .await
            .unwrap()
    );
    assert!(
        !store
            .learning_state_exists(&m("M1"), &f("in1"), r#"{"i":2}"#, ms(8_000))
            .await
            .unwrap()
    );

    let d = NewDressing {
        machine: m("M1"),
        at: ms(9_000),
        old_radius_mm: 250.0,
        new_radius_mm: 249.98,
        infeed_um: Some(20.2),
        source: "api".into(),
    };
    store.insert_dressing(&d).await.unwrap();
    assert!(store.dressing_exists(&d).await.unwrap());
    let later = NewDressing {
        at: ms(9_001),
        ..d.clone()
    };
    assert!(!store.dressing_exists(&later).await.unwrap());

    assert!(store.checkpoint().await.unwrap());
}

#[tokio::test]
async fn replay_lookups_on_sqlite() {
    replay_lookups(&store_support::sqlite().await.store).await;
}

#[tokio::test]
async fn replay_lookups_on_postgres() {
    let Some(t) = store_support::postgres("replay_lookups_on_postgres").await else {
        return;
    };
    replay_lookups(&t.store).await;
}

/// Writers in parallel (the daemon's gauge tasks): every measurement lands once, and table
/// versions either get distinct numbers or a clean `Conflict`, never a duplicate.
async fn concurrent_writers(store: &Store) {
    // Each measurement inserted by two tasks at once: idempotence under concurrency.
    let mut set = tokio::task::JoinSet::new();
    for n in (0..16u32).chain(0..16) {
        let store = store.clone();
        set.spawn(async move {
            let m = measurement("MC", "in1", n, i64::from(n));
            (n, store.insert_measurement(&m).await.unwrap())
        });
    }
    let mut ids = std::collections::BTreeMap::new();
    while let Some(done) = set.join_next().await {
        let (n, id) = done.unwrap();
        if let Some(first) = ids.insert(n, id) {
            assert_eq!(first, id, "measurement {n} stored under two ids");
        }
    }
    assert_eq!(ids.len(), 16);
    let listed = store
        .measurement_history(&HistoryFilter {
            limit: 100,
            ..filter("MC")
        })
        .await
        .unwrap();
    assert_eq!(listed.items.len(), 16);

    let mut set = tokio::task::JoinSet::new();
    for n in 0..8 {
        let store = store.clone();
        set.spawn(async move {
            let mut t = table("in1", None, &format!("v{n}"), "waiting");
            t.machine = m("MC");
            store.insert_table_version(&t).await
        });
    }
    let mut versions = Vec::new();
    while let Some(done) = set.join_next().await {
        match done.unwrap() {
            Ok(v) => versions.push(v),
            Err(StoreError::Conflict { .. }) => {}
            Err(e) => panic!("unexpected {e:?}"),
        }
    }
    versions.sort();
    let expected: Vec<_> = (1..=versions.len() as i64).map(tv).collect();
    assert_eq!(versions, expected, "numbers are distinct and without gaps");
    let stored = store
        .table_versions(&m("MC"), &f("in1"), 100)
        .await
        .unwrap();
    assert_eq!(stored.len(), versions.len());
}

#[tokio::test]
async fn concurrent_writers_on_sqlite() {
    let t = store_support::sqlite().await;
    concurrent_writers(&t.store).await;
}

#[tokio::test]
async fn concurrent_writers_on_postgres() {
    let Some(t) = store_support::postgres("concurrent_writers_on_postgres").await else {
        return;
    };
    concurrent_writers(&t.store).await;
}

/// A final and an in-process measurement of one part: each reads back with its stage, the
/// history filters by it, and both come back without a filter.
async fn stages(store: &Store) {
    let done = measurement("M1", "in1", 1, 2_000);
    let before = NewMeasurement {
        stage: MeasurementStage::InProcess,
        ..measurement("M1", "in1", 2, 1_000)
    };
    store.insert_measurement(&before).await.unwrap();
    store.insert_measurement(&done).await.unwrap();
    let listed = |stage| {
        let f = HistoryFilter {
            stage,
            ..filter("M1")
        };
        async move {
            let page = store.measurement_history(&f).await.unwrap();
            page.items.iter().map(|s| s.stage).collect::<Vec<_>>()
        }
    };
    assert_eq!(
        listed(None).await,
        [MeasurementStage::Final, MeasurementStage::InProcess]
    );
    assert_eq!(
        listed(Some(MeasurementStage::InProcess)).await,
        [MeasurementStage::InProcess]
    );
    assert_eq!(
        listed(Some(MeasurementStage::Final)).await,
        [MeasurementStage::Final]
    );
}

#[tokio::test]
async fn stages_on_sqlite() {
    stages(&store_support::sqlite().await.store).await;
}

#[tokio::test]
async fn stages_on_postgres() {
    let Some(t) = store_support::postgres("stages_on_postgres").await else {
        return;
    };
    stages(&t.store).await;
}
