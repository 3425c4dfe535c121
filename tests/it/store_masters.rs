//! The history query's master-run filter on both backends: master runs are parts whose id
//! begins with `MASTER` in any ASCII case (PostgreSQL's LIKE is case-sensitive, SQLite's
//! is not, so the store must not lean on either), paginated like every history.

use crate::store_support;
use crate::store_support::data::{all_pages, filter, measurement};
use camloop::store::{HistoryFilter, MasterRuns, Store};

async fn masters_filter(store: &Store) {
    // Parts 0..12; every third is a master run under one of the spellings a gauge sends,
    // and one production part merely contains the word.
    let spellings = ["MASTER", "master-2", "Master_B", "MASTER-17"];
    let mut expected_masters = Vec::new();
    let mut expected_parts = Vec::new();
    for n in 0..12u32 {
        let mut m = measurement("M1", "in1", n, 1_000 * i64::from(n));
        if n % 3 == 0 {
            m.part = spellings[(n / 3) as usize].parse().unwrap();
            expected_masters.push(m.part.clone());
        } else if n == 4 {
            m.part = "P-MASTER-4".parse().unwrap();
            expected_parts.push(m.part.clone());
        } else {
            expected_parts.push(m.part.clone());
        }
        store.insert_measurement(&m).await.unwrap();
    }
    expected_masters.reverse();
    expected_parts.reverse();
    let parts = |kind| {
        let f = HistoryFilter {
            masters: kind,
            limit: 3,
            ..filter("M1")
        };
        async move {
            all_pages(store, f)
                .await
                .into_iter()
                .map(|s| s.part)
                .collect::<Vec<_>>()
        }
    };
    assert_eq!(parts(MasterRuns::Excluded).await, expected_parts);
    assert_eq!(parts(MasterRuns::Only).await, expected_masters);
    assert_eq!(parts(MasterRuns::Included).await.len(), 12);
}

#[tokio::test]
async fn master_runs_filter_on_sqlite() {
    masters_filter(&store_support::sqlite().await.store).await;
}

#[tokio::test]
async fn master_runs_filter_on_postgres() {
    let Some(t) = store_support::postgres("master_runs_filter_on_postgres").await else {
        return;
    };
    masters_filter(&t.store).await;
}
