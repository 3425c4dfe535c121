//! `camloop history --last N` reads the store page by page: more than one page (10,000 rows)
//! comes out whole, newest first.

use crate::cli_support;
use crate::store_support;

use camloop::cli::history::newest;
use camloop::store::{HistoryFilter, Store};
use cli_support::{camloop, camloop_ok};

/// A SQLite store in `dir` with `n` measurements of M1/IN1, received at 1, 2, … n s.
async fn store_with(dir: &std::path::Path, n: u32) -> (Store, String) {
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.display());
    let store = Store::connect(&url).await.unwrap();
    // The first through the store (it registers the machine); the rest in one statement.
    store
        .insert_measurement(&store_support::data::measurement("M1", "IN1", 1, 1_000))
        .await
        .unwrap();
    let camloop::store::RawPool::Sqlite(pool) = store.raw_pool() else {
        panic!("a SQLite store")
    };
    sqlx::query(
        "INSERT INTO measurements (machine, part, lobe, received_at_ms, verdict, \
         max_profile_error_um, base_radius_error_um, phase_error_deg, revolutions_used, \
         points_per_rev, origin, sha256) \
         WITH RECURSIVE n(i) AS (SELECT 2 UNION ALL SELECT i + 1 FROM n WHERE i < $1) \
         SELECT 'M1', 'P-' || i, 'IN1', i * 1000, 'pass', 1.0, 0.0, 0.0, 3, 36, 'bulk', \
         printf('%064d', i) FROM n",
    )
    .bind(i64::from(n))
    .execute(pool)
    .await
    .unwrap();
    (store, url)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn newest_pages_through_the_store_until_it_has_n_rows() {
    let dir = tempfile::tempdir().unwrap();
    let (store, _) = store_with(dir.path(), 25).await;
    let filter = HistoryFilter::new("M1".parse().unwrap(), 0);
    // Pages of 10: 23 rows take three queries and come out newest first, none twice.
    let rows = newest(&store, filter.clone(), 23, 10).await.unwrap();
    let times: Vec<i64> = rows
        .iter()
        .map(|m| m.received_at.as_millisecond())
        .collect();
    let expected: Vec<i64> = (3..=25).rev().map(|i| i * 1000).collect();
    assert_eq!(times, expected);
    // More asked than there are: all 25.
    assert_eq!(
        newest(&store, filter.clone(), 40, 10).await.unwrap().len(),
        25
    );
    assert_eq!(newest(&store, filter, 0, 10).await.unwrap().len(), 0);
}

#[test]
fn history_last_beyond_one_page_is_not_capped() {
    let dir = tempfile::tempdir().unwrap();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let n = 10_050;
    let url = runtime.block_on(async {
        let (store, url) = store_with(dir.path(), n).await;
        store.close().await;
        url
    });
    let last = (n - 1).to_string();
    let out = camloop_ok(
        &[
            "history",
            "--machine",
            "M1",
            "--last",
            &last,
            "--format",
            "csv",
            "--database",
            &url,
        ],
        dir.path(),
    );
    let csv = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 10_049);
    // Newest first, down to the second-oldest.
    assert!(rows[0].contains(",10050000,M1,P-10050,"), "{}", rows[0]);
    assert!(rows[10_048].contains(",2000,M1,P-2,"), "{}", rows[10_048]);
}

/// Master runs (part ids `MASTER…`, any case) are a gauge study's: `history` lists the
/// production parts only, and `--masters` lists the master runs only, each in its order.
#[test]
fn history_leaves_master_runs_out_unless_asked_for_them() {
    let dir = tempfile::tempdir().unwrap();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let url = runtime.block_on(async {
        let (store, url) = store_with(dir.path(), 6).await;
        // Three master runs between the parts, received at 2.5 s, 4.5 s and 7 s.
        for (n, part, at_ms) in [
            (101, "MASTER", 2_500),
            (102, "master-B", 4_500),
            (103, "Master", 7_000),
        ] {
            let mut m = store_support::data::measurement("M1", "IN1", n, at_ms);
            m.part = part.parse().unwrap();
            store.insert_measurement(&m).await.unwrap();
        }
        store.close().await;
        url
    });
    let parts_of = |extra: &[&str]| {
        let mut args = vec![
            "history",
            "--machine",
            "M1",
            "--last",
            "50",
            "--format",
            "csv",
        ];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--database", &url]);
        let out = camloop(&args, dir.path());
        assert!(out.status.success(), "{}", cli_support::stderr(&out));
        let csv = String::from_utf8_lossy(&out.stdout).into_owned();
        let header: Vec<String> = csv
            .lines()
            .next()
            .unwrap()
            .split(',')
            .map(str::to_owned)
            .collect();
        let column = header
            .iter()
            .position(|h| h == "part")
            .expect("a part column");
        csv.lines()
            .skip(1)
            .map(|l| l.split(',').nth(column).unwrap().to_owned())
            .collect::<Vec<_>>()
    };
    assert_eq!(
        parts_of(&[]),
        ["P-6", "P-5", "P-4", "P-3", "P-2", "P-00001"]
    );
    assert_eq!(parts_of(&["--masters"]), ["Master", "master-B", "MASTER"]);
}
