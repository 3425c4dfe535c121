//! The dashboard on a large store: the plant overview and a feature page rendered by the
//! server (over a real loopback connection, as a browser asks) with 50 machines grinding one
//! lobe and 1,000,000 measurements in SQLite, then the overview of a plant of 500 machines
//! grinding the demo camshaft's 8 lobes (4,000 features, 1,000,000 measurements; the
//! overview's first and last page of 50 machines), with the
//! live channel on that plant: 50 open event streams, from a measurement stored to all 50
//! clients having it. Prints p50/p99 besides criterion's estimate. Before the pages, the
//! overview's reads are made both ways (feature by feature, and the set queries the page
//! uses), timed once and required equal.
//!
//! The store is generated in the setup: the million summary rows by one recursive INSERT in
//! SQLite itself (seconds), then, per feature, what the pages read besides the summaries: the
//! newest part's profile and analysis report (360 points), table versions with a 360-point
//! program (20 per feature in the small plant, 2 in the large one, which the overview reads
//! only the newest of), a learning state, and per machine 10 events and a recipe snapshot.

#[path = "../tests/common/overview_reference.rs"]
mod overview_reference;

use camloop::config::Secret;
use camloop::names::MachineName;
use camloop::recipe::Recipe;
use camloop::service::http::{self, AppState, FeatureSheet, HttpLimits};
use camloop::store::{NewMeasurement, RawPool, Store, Verdict, encode_lifts_mm};
use criterion::{Criterion, criterion_group, criterion_main};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::sync::{mpsc, watch};

const MEASUREMENTS: i64 = 1_000_000;

/// The plant a store is seeded for and the service serves.
#[derive(Clone, Copy)]
struct Plant {
    machines: usize,
    features: &'static [&'static str],
    /// Table versions kept per feature.
    versions: i64,
}

/// 50 machines grinding one lobe: the figures since the dashboard was first measured.
const SMALL: Plant = Plant {
    machines: 50,
    features: &["IN1"],
    versions: 20,
};

/// The plant-scale goal: 500 machines grinding the demo camshaft's 8 lobes.
const LARGE: Plant = Plant {
    machines: 500,
    features: &["IN1", "EX1", "IN2", "EX2", "IN3", "EX3", "IN4", "EX4"],
    versions: 2,
};
const POINTS: usize = 360;
/// 2026-01-01, the first part's time; one part a second across the plant.
const T0_MS: i64 = 1_767_225_600_000;

fn machine(i: usize) -> String {
    format!("M{i:03}")
}

async fn exec(store: &Store, sql: &str) {
    let RawPool::Sqlite(pool) = store.raw_pool() else {
        panic!("sqlite")
    };
    sqlx::query(sql).execute(pool).await.expect(sql);
}

/// A 360-point analysis report shaped as the service stores it (the curves the pages read,
/// and the other per-angle arrays and harmonics that make its size).
fn report(i: usize) -> String {
    let a: Vec<f64> = (0..POINTS).map(|k| k as f64).collect();
    let e: Vec<f64> = a
        .iter()
        .map(|d| (d.to_radians() * 3.0 + i as f64).sin() * 1.5)
        .collect();
    let h: Vec<serde_json::Value> = (1..=50)
        .map(|k| serde_json::json!({"order": k, "amplitude_um": 0.1, "phase_deg": 12.0}))
        .collect();
    serde_json::json!({
        "angle_deg": a, "error_um": e, "profile_error_um": e, "velocity_error_um_per_deg": e,
        "repeatability_um": e, "repeatability_range_um": e, "harmonics": h,
        "phase_error_deg": 0.01, "base_radius_error_um": -0.3,
    })
    .to_string()
}

fn program() -> String {
    let mut s = String::from("; camloop table\nCTABDEF(CL_TNO,C,1,1)\n");
    for k in 0..POINTS {
        s.push_str(&format!(
            "C={k}.0000 X=POLY PO[X]=({:.4},0.0012,-0.0003)\n",
            20.0 + k as f64 * 1e-3
        ));
    }
    s + "CTABEND\nM17\n"
}

/// `plant`'s machines, 1 M measurements spread over its features, and what the pages read
/// besides them (in one transaction: thousands of rows, one sync).
async fn seed(store: &Store, plant: Plant) {
    let t = Instant::now();
    let values: Vec<String> = (0..plant.machines)
        .map(|i| format!("('{}', {T0_MS})", machine(i)))
        .collect();
    exec(
        store,
        &format!(
            "INSERT INTO machines (name, first_seen_ms) VALUES {}",
            values.join(",")
        ),
    )
    .await;
    exec(
        store,
        &format!(
            "WITH RECURSIVE n(i) AS (SELECT 0 UNION ALL SELECT i + 1 FROM n WHERE i < {last}) \
             INSERT INTO measurements (machine, part, lobe, received_at_ms, verdict, \
             max_profile_error_um, base_radius_error_um, phase_error_deg, revolutions_used, \
             points_per_rev, origin, sha256) \
             SELECT printf('M%03d', i % {machines}), CAST(i / {machines} AS TEXT), \
             {feature_case}, {T0_MS} + i * 1000, CASE WHEN i % 17 = 0 THEN 'fail' ELSE 'pass' END, \
             (abs(random()) % 3000) / 1000.0, ((abs(random()) % 2000) - 1000) / 1000.0, \
             ((abs(random()) % 200) - 100) / 10000.0, 3, {POINTS}, 'can0', printf('%064x', i) \
             FROM n",
            last = MEASUREMENTS - 1,
            machines = plant.machines,
            feature_case = feature_case(plant),
        ),
    )
    .await;
    let RawPool::Sqlite(pool) = store.raw_pool() else {
        panic!("sqlite")
    };
    let mut tx = pool.begin().await.unwrap();
    for i in 0..plant.machines {
        let m = machine(i);
        sqlx::query("INSERT INTO recipe_snapshots (machine, part, lobe, kind, recipe_json, sha256, created_at_ms) VALUES ($1, 'DEMO-CAM', 'IN1', 'lobe', '{}', $2, $3)")
            .bind(&m).bind(format!("{i:064x}")).bind(T0_MS).execute(&mut *tx).await.unwrap();
        for k in 0..10i64 {
            sqlx::query("INSERT INTO events (machine, at_ms, level, kind, message) VALUES ($1, $2, $3, 'table_refused', 'step too large')")
                .bind(&m).bind(T0_MS + k * 1000).bind(if k == 9 { "error" } else { "info" })
                .execute(&mut *tx).await.unwrap();
        }
        for f in plant.features {
            seed_feature(&mut tx, plant, i, f).await;
        }
    }
    tx.commit().await.unwrap();
    learning_states(store, plant).await;
    exec(store, "ANALYZE").await;
    // The service checkpoints between parts; a seeded store would otherwise read every page
    // through a 500 MB write-ahead log (a profile showed 36 % of the overview's time in
    // SQLite's WAL lookup).
    exec(store, "PRAGMA wal_checkpoint(TRUNCATE)").await;
    eprintln!(
        "seeded {} machines × {} features, {MEASUREMENTS} measurements in {:.1} s",
        plant.machines,
        plant.features.len(),
        t.elapsed().as_secs_f64()
    );
}

/// The SQL that names the feature of measurement `i` (its machine is `i % machines`): each
/// machine's parts go round its features.
fn feature_case(plant: Plant) -> String {
    let n = plant.features.len();
    let arms: String = plant
        .features
        .iter()
        .enumerate()
        .map(|(k, f)| format!(" WHEN {k} THEN '{f}'"))
        .collect();
    format!("CASE (i / {}) % {n}{arms} END", plant.machines)
}

/// One feature's newest part data, table versions and learning state.
async fn seed_feature(
    tx: &mut sqlx::Transaction<'_, sqlx::Sqlite>,
    plant: Plant,
    i: usize,
    feature: &str,
) {
    let m = machine(i);
    let mut lift = Vec::new();
    encode_lifts_mm(vec![1.5; POINTS], &mut lift).unwrap();
    let newest: i64 =
        sqlx::query_scalar("SELECT MAX(id) FROM measurements WHERE machine = $1 AND lobe = $2")
            .bind(&m)
            .bind(feature)
            .fetch_one(&mut **tx)
            .await
            .unwrap();
    sqlx::query("INSERT INTO measurement_data (measurement_id, codec, averaged_profile, analysis_json) VALUES ($1, 0, $2, $3)")
        .bind(newest).bind(&lift).bind(report(i)).execute(&mut **tx).await.unwrap();
    let text = program();
    for v in 1..=plant.versions {
        let id: i64 = sqlx::query_scalar("INSERT INTO table_versions (machine, lobe, version, parent_version, table_number, program_text, sha256, learning_params_json, reason, created_at_ms, codec, chain_depth) VALUES ($1, $2, $3, $4, $5, $6, $7, '{}', $8, $9, 0, 0) RETURNING id")
            .bind(&m).bind(feature).bind(v).bind((v > 1).then_some(v - 1)).bind(1 + v % 2).bind(&text)
            .bind(format!("{:064x}", v)).bind(format!("part {v}: learned")).bind(T0_MS + v * 60_000)
            .fetch_one(&mut **tx).await.unwrap();
        // Every fifth machine's newest version still waits for its share: the overview's
        // table in force is then the one before.
        let status = if v == plant.versions && i.is_multiple_of(5) {
            "waiting"
        } else {
            "pushed"
        };
        sqlx::query("INSERT INTO table_version_status (table_version_id, status, why, at_ms) VALUES ($1, $2, 'pushed to share', $3)")
            .bind(id).bind(status).bind(T0_MS + v * 60_000).execute(&mut **tx).await.unwrap();
    }
}

/// Every feature's learning state, written as the service writes it (packed against the
/// feature's previous one); every 97th feature frozen, so the overview's state has both.
async fn learning_states(store: &Store, plant: Plant) {
    let mut k = 0usize;
    for i in 0..plant.machines {
        let m = MachineName::new(&machine(i)).unwrap();
        for f in plant.features {
            k += 1;
            let frozen = k.is_multiple_of(97).then_some("step reverted: error grew");
            let memory = serde_json::json!({"learning": {"correction_um": vec![0.25 + k as f64 * 1e-3; POINTS], "frozen": frozen}});
            let at = jiff::Timestamp::from_millisecond(T0_MS).unwrap();
            store
                .save_learning_state(&m, &f.parse().unwrap(), &memory.to_string(), at)
                .await
                .unwrap();
        }
    }
}

/// The service's HTTP side on port 0 with `plant`'s machines configured on the demo
/// camshaft's lobes.
async fn serve(store: Store, plant: Plant) -> (SocketAddr, watch::Sender<bool>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
    let recipe = Recipe::load(&path).unwrap();
    let mut machines = BTreeMap::new();
    let mut sheets = BTreeMap::new();
    for i in 0..plant.machines {
        let name = MachineName::new(&machine(i)).unwrap();
        let features: Vec<camloop::names::FeatureName> =
            plant.features.iter().map(|f| f.parse().unwrap()).collect();
        for f in &features {
            let setup = recipe.feature_setup(&path, f.as_str()).unwrap();
            sheets.insert((name.clone(), f.clone()), FeatureSheet::from_setup(&setup));
        }
        machines.insert(name, features);
    }
    let limits = HttpLimits {
        max_connections: 256,
        max_connections_per_client: 256,
        header_timeout: Duration::from_secs(10),
        body_timeout: Duration::from_secs(10),
    };
    let state = AppState {
        store: Arc::new(tokio::sync::RwLock::new(Some(store))),
        metrics: Arc::default(),
        machines: Arc::new(machines),
        commands: Arc::default(),
        auth: Arc::new(http::AuthState::new(Some(Secret::new("bench")), true)),
        body_timeout: limits.body_timeout,
        dashboard: Arc::new(sheets),
        cluster: None,
    };
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stopped) = watch::channel(false);
    tokio::spawn(http::serve(listener, http::router(state), limits, stopped));
    (addr, stop)
}

/// One GET on a new connection; the body's length (the status must be 200).
async fn get(addr: SocketAddr, path: &str) -> usize {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let req = format!("GET {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n");
    s.write_all(req.as_bytes()).await.unwrap();
    let mut body = Vec::new();
    s.read_to_end(&mut body).await.unwrap();
    assert!(
        body.starts_with(b"HTTP/1.1 200"),
        "{path}: {}",
        String::from_utf8_lossy(&body[..body.len().min(300)])
    );
    body.len()
}

fn percentiles(mut d: Vec<Duration>) -> (f64, f64) {
    d.sort();
    let at = |q: f64| d[((d.len() - 1) as f64 * q).round() as usize].as_secs_f64() * 1000.0;
    (at(0.5), at(0.99))
}

/// 50 event streams; each reports the ids it receives.
async fn clients(addr: SocketAddr, n: usize) -> mpsc::UnboundedReceiver<i64> {
    let (tx, rx) = mpsc::unbounded_channel();
    for _ in 0..n {
        let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
        s.write_all(b"GET /dashboard/events HTTP/1.1\r\nHost: localhost\r\n\r\n")
            .await
            .unwrap();
        let tx = tx.clone();
        tokio::spawn(async move {
            let mut lines = BufReader::new(s).lines();
            while let Ok(Some(line)) = lines.next_line().await {
                // Chunked framing puts the event's lines inside chunks; the id line is whole.
                if let Some(id) = line
                    .strip_prefix("id: ")
                    .and_then(|v| v.trim().parse().ok())
                {
                    let _ = tx.send(id);
                }
            }
        });
    }
    rx
}

fn part(n: i64) -> NewMeasurement {
    NewMeasurement {
        machine: camloop::names::MachineName::new(&machine(7)).expect("a valid name"),
        part: format!("live-{n}").parse().expect("a part id"),
        lobe: "IN1".parse().unwrap(),
        received_at: jiff::Timestamp::from_millisecond(T0_MS + MEASUREMENTS * 1000 + n)
            .expect("a time within jiff's years"),
        verdict: Verdict::Pass,
        max_profile_error_um: 0.5,
        base_radius_error_um: 0.1,
        phase_error_deg: 0.001,
        revolutions_used: 3,
        stage: camloop::store::MeasurementStage::Final,
        points_per_rev: POINTS as u32,
        origin: "bench".into(),
        sha256: format!("{:064x}", 1u64 << 40 | n as u64).parse().unwrap(),
        recipe_snapshot: None,
        raw_lift_mm: Vec::new(),
        averaged_lift_mm: vec![1.5; POINTS],
        analysis_json: "{}".into(),
    }
}

/// Stores one part and waits until all `n` clients have it. The part is stored at a
/// spread-out moment of the poller's 250 ms period (a waiting time outside the measurement):
/// storing right after the previous delivery would always wait the full period.
/// Stores parts until one reaches all 50 clients: the first part starts the poller, and
/// the clients are connected once it reaches them.
async fn wait_for_clients(store: &Store, rx: &mut mpsc::UnboundedReceiver<i64>) {
    let mut k = 0;
    loop {
        k += 1;
        let id = store.insert_measurement(&part(k)).await.unwrap().0;
        let deadline = Instant::now() + Duration::from_secs(2);
        let mut got = 0;
        while let Ok(Some(x)) = tokio::time::timeout_at(deadline.into(), rx.recv()).await {
            got += usize::from(x == id);
            if got == 50 {
                return;
            }
        }
    }
}

async fn one_live(
    store: &Store,
    rx: &mut mpsc::UnboundedReceiver<i64>,
    k: i64,
    n: usize,
) -> Duration {
    tokio::time::sleep(Duration::from_millis((k * 37 % 250) as u64)).await;
    let id = store.insert_measurement(&part(k)).await.unwrap().0;
    let t = Instant::now();
    let mut got = 0;
    while got < n {
        if rx.recv().await.unwrap() == id {
            got += 1;
        }
    }
    t.elapsed()
}

fn bench(c: &mut Criterion) {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    // The plant-scale overview and the live channel first, on a store of their own.
    {
        let (dir, store) = rt.block_on(seeded(LARGE));
        let (addr, stop) = rt.block_on(serve(store.clone(), LARGE));
        // The overview shows 50 machines a page: the first page, and the last.
        let large_pages = [
            ("overview", "/".to_string()),
            ("overview_page_10", "/?page=10".to_string()),
            ("feature_page", "/machines/M007/features/IN1".to_string()),
        ];
        pages(c, &rt, addr, LARGE, &large_pages, cores);
        live(c, &rt, addr, &store, cores);
        let _ = stop.send(true);
        drop(dir);
    }
    let (_dir, store) = rt.block_on(seeded(SMALL));
    let (addr, stop) = rt.block_on(serve(store.clone(), SMALL));
    let small_pages = [
        ("overview", "/".to_string()),
        ("feature_page", "/machines/M007/features/IN1".to_string()),
    ];
    pages(c, &rt, addr, SMALL, &small_pages, cores);
    let _ = stop.send(true);
}

/// The overview's reads both ways on the seeded store, timed once each: feature by feature
/// (as the overview read before, and as the feature pages read) and by the set queries the
/// overview uses now. They must agree on every feature.
async fn reads_both_ways(store: &Store, plant: Plant) {
    let keys: Vec<(MachineName, camloop::names::FeatureName)> = (0..plant.machines)
        .flat_map(|i| {
            let m = MachineName::new(&machine(i)).unwrap();
            plant
                .features
                .iter()
                .map(move |f| (m.clone(), f.parse().unwrap()))
        })
        .collect();
    let t = Instant::now();
    let reference = overview_reference::features(store, &keys, 50, 20).await;
    let alarms = overview_reference::alarms(store, 50).await;
    let per_feature = t.elapsed();
    let t = Instant::now();
    let set = store.plant_overview(&keys, 50, 20).await.unwrap();
    let set_alarms = store.machines_in_alarm(50).await.unwrap();
    let set_time = t.elapsed();
    assert_eq!(alarms, set_alarms);
    assert_eq!(reference.len(), set.len());
    for ((r, text), s) in reference.iter().zip(&set) {
        assert_eq!((&r.recent, &r.in_force), (&s.recent, &s.in_force));
        let (id, _) = s
            .learning
            .clone()
            .expect("every feature has a learning state");
        let row = store.learning_state_row_for_view(id).await.unwrap();
        assert_eq!(text.as_deref(), row.map(|l| l.state_json).as_deref());
    }
    eprintln!(
        "overview reads, {} features: feature by feature {:.0} ms, set queries {:.0} ms (equal)",
        keys.len(),
        per_feature.as_secs_f64() * 1000.0,
        set_time.as_secs_f64() * 1000.0
    );
}

/// Where a view's time goes in the store: each read one overview view makes (the
/// plant-wide ones, then those of the first and the last page of 50 machines), 20 times
/// each, p50 / p99 in ms.
async fn store_calls(store: &Store, plant: Plant) {
    let page = |n: usize| -> Vec<(MachineName, camloop::names::FeatureName)> {
        (n * 50..((n + 1) * 50).min(plant.machines))
            .flat_map(|i| {
                let m = MachineName::new(&machine(i)).unwrap();
                plant
                    .features
                    .iter()
                    .map(move |f| (m.clone(), f.parse().unwrap()))
            })
            .collect()
    };
    let (first, last) = (page(0), page(plant.machines.div_ceil(50) - 1));
    let newest = store.overview_changes(i64::MAX, i64::MAX).await.unwrap();
    let mut line = String::new();
    macro_rules! time {
        ($name:literal, $call:expr) => {{
            let mut v = Vec::new();
            for _ in 0..20 {
                let t = Instant::now();
                $call.await.unwrap();
                v.push(t.elapsed());
            }
            let (p50, p99) = percentiles(v);
            line.push_str(&format!("; {} {p50:.1} / {p99:.1}", $name));
        }};
    }
    time!("known_features", store.known_features());
    time!("machines_in_alarm", store.machines_in_alarm(50));
    time!(
        "overview_changes (look-back 1,024 ids)",
        store.overview_changes(newest.measurement - 1024, newest.status - 1024)
    );
    time!("plant_learning, first page", store.plant_learning(&first));
    time!("plant_learning, last page", store.plant_learning(&last));
    time!(
        "plant_overview, first page",
        store.plant_overview(&first, 50, 20)
    );
    time!(
        "plant_overview, last page",
        store.plant_overview(&last, 50, 20)
    );
    eprintln!(
        "a view's store reads, {} machines × {} features, p50 / p99 ms{line}",
        plant.machines,
        plant.features.len()
    );
}

/// A store in a temporary folder, seeded for `plant`.
async fn seeded(plant: Plant) -> (tempfile::TempDir, Store) {
    let dir = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).unwrap();
    let url = format!("sqlite://{}/bench.db?mode=rwc", dir.path().display());
    let store = Store::connect(&url).await.unwrap();
    seed(&store, plant).await;
    reads_both_ways(&store, plant).await;
    store_calls(&store, plant).await;
    (dir, store)
}

/// Each page 100 times for its percentiles, then criterion's estimate.
fn pages(
    c: &mut Criterion,
    rt: &tokio::runtime::Runtime,
    addr: SocketAddr,
    plant: Plant,
    pages: &[(&str, String)],
    cores: usize,
) {
    let size = format!(
        "{}_machines_{}_features",
        plant.machines,
        plant.features.len()
    );
    for (name, path) in pages {
        let times: Vec<Duration> = rt.block_on(async {
            let mut v = Vec::new();
            for _ in 0..100 {
                let t = Instant::now();
                get(addr, path).await;
                v.push(t.elapsed());
            }
            v
        });
        // The first asks with nothing remembered (the overview unpacks every learning state).
        let first = times[0].as_secs_f64() * 1000.0;
        let (p50, p99) = percentiles(times);
        let bytes = rt.block_on(get(addr, path));
        eprintln!(
            "{name} ({bytes} bytes, {} machines × {} features, 1 M measurements, {cores} cores): first {first:.1} ms, p50 {p50:.1} ms, p99 {p99:.1} ms",
            plant.machines,
            plant.features.len()
        );
        c.bench_function(&format!("dashboard_{name}_{size}_1M"), |b| {
            b.iter(|| rt.block_on(get(addr, path)))
        });
    }
}

/// The live channel: 50 event streams, from a measurement stored to all of them having it.
fn live(
    c: &mut Criterion,
    rt: &tokio::runtime::Runtime,
    addr: SocketAddr,
    store: &Store,
    cores: usize,
) {
    let mut rx = rt.block_on(clients(addr, 50));
    rt.block_on(wait_for_clients(store, &mut rx));
    let mut k = 1000;
    let times: Vec<Duration> = rt.block_on(async {
        let mut v = Vec::new();
        for _ in 0..40 {
            k += 1;
            v.push(one_live(store, &mut rx, k, 50).await);
        }
        v
    });
    let (p50, p99) = percentiles(times);
    eprintln!(
        "live channel, 50 open streams ({cores} cores): stored → all 50 have it: p50 {p50:.0} ms, p99 {p99:.0} ms"
    );
    let mut g = c.benchmark_group("dashboard_live");
    g.sample_size(10);
    g.bench_function("stored_to_50_sse_clients", |b| {
        b.iter_custom(|iters| {
            rt.block_on(async {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    k += 1;
                    total += one_live(store, &mut rx, k, 50).await;
                }
                total
            })
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
