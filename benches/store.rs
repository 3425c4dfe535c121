//! History query speed: one lobe's newest 1,000 measurements in a store of 1,000,000, on
//! SQLite and on PostgreSQL (when the server binaries are on the machine).
//!
//! The million rows are seeded once (tools/seed_store.rs) into a cache under the target
//! folder, `camloop-bench/store-1m.sqlite` and `camloop-bench/pg/`, and reused while they
//! hold exactly that many measurements; delete the folder to reseed. The seeding time is
//! printed. PostgreSQL runs as a throwaway server on that kept folder, stopped at the end.

#[path = "../tests/store_support/pg.rs"]
#[allow(dead_code)]
mod pg;
#[path = "../tools/seed_store.rs"]
mod seed_store;

use std::path::PathBuf;
use std::time::Instant;

use camloop::store::{HistoryFilter, Store, Verdict};
use criterion::{Criterion, criterion_group, criterion_main};

const ROWS: i64 = 1_000_000;

fn cache_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target"));
    target.join("camloop-bench")
}

async fn ready(store: &Store) {
    if seed_store::count(store).await.expect("count rows") == ROWS {
        return;
    }
    let t0 = Instant::now();
    seed_store::seed(store, ROWS).await.expect("seed the store");
    eprintln!(
        "seeded {ROWS} measurements on {} in {:.1} s",
        store.backend(),
        t0.elapsed().as_secs_f64()
    );
}

fn bench_backend(c: &mut Criterion, rt: &tokio::runtime::Runtime, store: &Store) {
    let mut group = c.benchmark_group(format!("history_{}", store.backend()));
    group.sample_size(30);
    let lobe = HistoryFilter {
        lobe: Some("L7".parse().expect("a plain name")),
        ..HistoryFilter::new("M3".parse().expect("a plain name"), 1000)
    };
    let first = rt
        .block_on(store.measurement_history(&lobe))
        .expect("history");
    assert_eq!(
        first.items.len(),
        1000,
        "the seed gives each lobe ~7,800 rows"
    );
    group.bench_function("one_lobe_last_1000", |b| {
        b.iter(|| {
            rt.block_on(store.measurement_history(&lobe))
                .expect("history")
        })
    });
    let second = HistoryFilter {
        cursor: first.next_cursor.clone(),
        ..lobe.clone()
    };
    group.bench_function("one_lobe_second_page_of_1000", |b| {
        b.iter(|| {
            rt.block_on(store.measurement_history(&second))
                .expect("history")
        })
    });
    let fails = HistoryFilter {
        verdict: Some(Verdict::Fail),
        limit: 100,
        ..lobe.clone()
    };
    group.bench_function("one_lobe_last_100_fails", |b| {
        b.iter(|| {
            rt.block_on(store.measurement_history(&fails))
                .expect("history")
        })
    });
    group.finish();
}

fn history(c: &mut Criterion) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("tokio runtime");
    let dir = cache_dir();
    std::fs::create_dir_all(&dir).expect("bench cache folder");

    let url = format!(
        "sqlite://{}?mode=rwc",
        dir.join("store-1m.sqlite").display()
    );
    let sqlite = rt.block_on(Store::connect(&url)).expect("open sqlite");
    rt.block_on(ready(&sqlite));
    bench_backend(c, &rt, &sqlite);

    match pg::TempPostgres::start_at(&dir.join("pg")) {
        Ok(server) => {
            let store = rt
                .block_on(Store::connect(&server.url()))
                .expect("open postgres");
            rt.block_on(ready(&store));
            bench_backend(c, &rt, &store);
            rt.block_on(store.close());
            drop(server);
        }
        Err(pg::StartError::NoBinaries(why)) => eprintln!("SKIP postgres history bench: {why}"),
        Err(pg::StartError::Failed(why)) => panic!("postgres for the bench: {why}"),
    }
}

criterion_group!(benches, history);
criterion_main!(benches);
