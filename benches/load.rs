//! Load test of the service (run with `cargo bench --bench load`): 50 simulated machines on one
//! service, each making 60 parts (10 minutes of parts at one per 10 s), run as fast as the
//! machine allows instead of in real time. Checks that no measurement is dropped (every part
//! is in the store) and reports throughput and the resident memory as the run goes.

use camloop::config::Config;
use camloop::service::{self, RunOptions};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

const MACHINES: usize = 50;
const PARTS: u64 = 60;

fn rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .map(str::to_string)
        })
        .and_then(|l| {
            l.split_whitespace()
                .nth(1)
                .and_then(|kb| kb.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn main() {
    // `cargo bench` passes filter arguments; this harness takes none.
    let dir = tempfile::tempdir().expect("temp dir");
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
    let mut text = format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"sqlite://{}/load.db?mode=rwc\"\n[http]\nlisten = \"127.0.0.1:0\"\n",
        dir.path().display()
    );
    for m in 0..MACHINES {
        let _ = write!(
            text,
            "[[machines]]\nname = \"M{m:02}\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"share/M{m:02}\"\n[machines.gauge]\nkind = \"sim\"\npart_interval_ms = 1\nseed = {m}\n",
            recipe.display()
        );
    }
    let config = Config::parse(&text, &dir.path().join("camloop.toml"), |_| None).expect("config");
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let started = Instant::now();
    let rss_start = rss_mib();
    let (total, rss_samples) = runtime.block_on(async {
        let mut running = service::start(config, RunOptions { parts: Some(PARTS) })
            .await
            .expect("service");
        let samples = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let sampler = tokio::spawn({
            let samples = samples.clone();
            async move {
                loop {
                    tokio::time::sleep(std::time::Duration::from_secs(2)).await;
                    samples
                        .lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .push(rss_mib());
                }
            }
        });
        running.machines_done().await;
        let elapsed = started.elapsed();
        sampler.abort();
        let store =
            camloop::store::Store::connect(&format!("sqlite://{}/load.db", dir.path().display()))
                .await
                .expect("store");
        let mut total = 0usize;
        for m in 0..MACHINES {
            let filter = camloop::store::HistoryFilter {
                machine: format!("M{m:02}"),
                limit: 1000,
                ..Default::default()
            };
            total += store
                .measurement_history(&filter)
                .await
                .expect("history")
                .items
                .len();
        }
        running.stop().await;
        println!(
            "load: {MACHINES} machines × {PARTS} parts in {:.1} s",
            elapsed.as_secs_f64()
        );
        let rss: Vec<String> = samples
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .map(|r| format!("{r:.0}"))
            .collect();
        println!("load: resident memory every 2 s, MiB: {}", rss.join(" "));
        (total, vec![rss_start, rss_mib()])
    });
    let expected = MACHINES * PARTS as usize;
    println!(
        "load: {total} of {expected} measurements stored ({} dropped), {:.0} parts/s, resident memory {:.0} MiB at start, {:.0} MiB at the end",
        expected - total,
        total as f64 / started.elapsed().as_secs_f64(),
        rss_samples[0],
        rss_samples[1]
    );
    assert_eq!(total, expected, "measurements were dropped");
}
