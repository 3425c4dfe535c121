//! A batch of history writes ([`camloop::store::Batch`]), on SQLite and on a throwaway
//! PostgreSQL server: what it writes is seen by no reader until it commits, then all of it at
//! once; a batch dropped before its commit leaves nothing and the writer goes on; a table's
//! parent written earlier in the same batch counts as stored.

use crate::store_support;

use store_support::data::{filter, measurement, ms, table};
use store_support::{f, m};

use camloop::store::{EventKind, EventLevel, NewEvent, Store, VersionStatus};

fn event(at_ms: i64) -> NewEvent {
    NewEvent {
        machine: m("M1"),
        at: ms(at_ms),
        level: EventLevel::Info,
        kind: EventKind::LearningHeld,
        message: format!("pushed at {at_ms}"),
    }
}

async fn stored(store: &Store) -> (usize, usize, usize) {
    let measurements = store
        .measurement_history(&filter("M1"))
        .await
        .unwrap()
        .items
        .len();
    let tables = store.table_versions(&m("M1"), &f("IN1"), 50).await.unwrap();
    let events = store
        .events(&camloop::store::EventFilter {
            machine: Some(m("M1")),
            limit: 50,
            ..Default::default()
        })
        .await
        .unwrap();
    (measurements, tables.len(), events.len())
}

async fn commits_together(store: &Store) {
    let mut batch = store.begin_batch().await.unwrap();
    batch
        .insert_measurement(&measurement("M1", "IN1", 1, 1_000))
        .await
        .unwrap();
    let first = batch
        .insert_table_version(&table("IN1", None, "N1 X=1\n", "waiting"))
        .await
        .unwrap();
    assert!(
        batch
            .has_table_version(&m("M1"), &f("IN1"), first)
            .await
            .unwrap()
    );
    // The second table derives from the first, written in this same batch.
    let second = batch
        .insert_table_version(&table("IN1", Some(first), "N1 X=2\n", "waiting"))
        .await
        .unwrap();
    let pushed = VersionStatus::pushed_at(ms(6_000), "pushed");
    batch
        .set_table_status(&m("M1"), &f("IN1"), second, &pushed, ms(6_000))
        .await
        .unwrap();
    batch.insert_event(&event(6_000)).await.unwrap();
    // Readers have their own connections: nothing of the batch is visible before its commit.
    assert_eq!(stored(store).await, (0, 0, 0));
    batch.commit().await.unwrap();
    assert_eq!(stored(store).await, (1, 2, 1));
    let newest = store
        .latest_table_version(&m("M1"), &f("IN1"))
        .await
        .unwrap();
    let newest = newest.expect("the second version");
    assert_eq!(
        (newest.version, newest.parent_version),
        (second, Some(first))
    );
    assert_eq!(newest.status.name(), "pushed");

    // Dropped before its commit: rolled back, and the writer takes the next write.
    let mut dropped = store.begin_batch().await.unwrap();
    dropped
        .insert_measurement(&measurement("M1", "IN1", 2, 2_000))
        .await
        .unwrap();
    dropped.insert_event(&event(7_000)).await.unwrap();
    drop(dropped);
    store.insert_event(&event(8_000)).await.unwrap();
    assert_eq!(stored(store).await, (1, 2, 2));
}

#[tokio::test]
async fn a_batch_commits_together_or_not_at_all_on_sqlite() {
    commits_together(&store_support::sqlite().await.store).await;
}

#[tokio::test]
async fn a_batch_commits_together_or_not_at_all_on_postgres() {
    let Some(t) =
        store_support::postgres("a_batch_commits_together_or_not_at_all_on_postgres").await
    else {
        return;
    };
    commits_together(&t.store).await;
}
