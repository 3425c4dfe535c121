//! A machine's loop takes only its own measurements, and each once: a measurement that names
//! another machine or lobe is rejected with a reason; the same reading arriving again (the
//! same file dropped twice, under another name) is recognised by its content and not learned
//! from a second time.

use crate::gauge_drop_support;
use crate::machine_support::{demo_lobe_setup, nominal_measurement, start_machine};

use camloop::core::measure::RawMeasurement;
use camloop::service::machine::{MachineLoop, SourceEvent};
use camloop::service::metrics::{MachineMetrics, Metrics};
use camloop::sim::PartLabels;
use camloop::store::Store;
use gauge_drop_support::measurement_csv;
use std::path::Path;
use std::sync::Arc;

/// A measurement of the demo lobe ground with its nominal table, labelled as given.
fn measurement(machine: &str, part: &str, lobe: &str, seed: u64) -> RawMeasurement {
    let labels = PartLabels {
        machine: machine.into(),
        part: part.into(),
        lobe: lobe.into(),
    };
    nominal_measurement(&demo_lobe_setup(), labels, seed)
}

async fn machine(dir: &Path, metrics: Arc<Metrics>) -> MachineLoop {
    start_machine(dir, "DROP1", vec![demo_lobe_setup()], metrics).await
}

async fn feed(machine: &mut MachineLoop, raw: RawMeasurement) {
    machine
        .handle(SourceEvent::Measurement {
            raw,
            ground_with: None,
            done: None,
        })
        .await;
}

fn of(metrics: &Metrics) -> MachineMetrics {
    metrics.snapshot().get("DROP1").cloned().unwrap_or_default()
}

#[tokio::test]
async fn another_machines_or_lobes_measurement_is_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let metrics = Arc::new(Metrics::default());
    let mut m = machine(dir.path(), metrics.clone()).await;
    feed(&mut m, measurement("SIM1", "P1", "IN1", 1)).await;
    feed(&mut m, measurement("DROP1", "P2", "EX9", 2)).await;
    let seen = of(&metrics);
    assert_eq!((seen.parts_total, seen.measurements_rejected_total), (0, 2));
    // Each kept among the rejects with a reason naming what did not match.
    let reasons: Vec<String> = std::fs::read_dir(dir.path().join("state/IN1/rejected"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".reason.txt"))
        .map(|e| std::fs::read_to_string(e.path()).unwrap())
        .collect();
    assert_eq!(reasons.len(), 2, "{reasons:?}");
    assert!(
        reasons.iter().any(|r| r.contains("machine \"SIM1\""))
            && reasons.iter().any(|r| r.contains("lobe \"EX9\"")),
        "{reasons:?}"
    );
    // Its own measurement still goes through.
    feed(&mut m, measurement("DROP1", "P3", "IN1", 3)).await;
    assert_eq!(of(&metrics).parts_total, 1);
}

#[tokio::test]
async fn the_same_reading_twice_is_learned_once() {
    let dir = tempfile::tempdir().unwrap();
    let metrics = Arc::new(Metrics::default());
    let mut m = machine(dir.path(), metrics.clone()).await;
    let first = measurement("DROP1", "P1", "IN1", 1);
    let mut again = first.clone();
    again.origin = "drop/second-copy.csv".into();
    feed(&mut m, first).await;
    let pushed = of(&metrics).tables_pushed_total;
    feed(&mut m, again).await;
    let seen = of(&metrics);
    assert_eq!(seen.parts_total, 1, "learned twice");
    assert_eq!(
        seen.tables_pushed_total, pushed,
        "a table made from a repeat"
    );
    // A new reading of the same part number is a new measurement.
    feed(&mut m, measurement("DROP1", "P1", "IN1", 2)).await;
    assert_eq!(of(&metrics).parts_total, 2);
}

/// The same through a drop folder under the real service: a file for another machine and a
/// file that fails the checks end in `rejected/` with the reason beside them; a good file in
/// `processed/`; the good file dropped again under another name is processed but not learned
/// from twice.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn drop_files_are_moved_by_the_verdict_and_learned_once() {
    let dir = tempfile::tempdir().unwrap();
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let text = format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"sqlite://{}/db.sqlite?mode=rwc\"\n\
         [http]\nlisten = \"127.0.0.1:0\"\n[[machines]]\nname = \"DROP1\"\nrecipe = \"{}\"\n\
         lobe = \"IN1\"\nshare = \"share/DROP1\"\n[machines.gauge]\nkind = \"drop\"\nfolder = \"inbox\"\npoll_ms = 20\n",
        dir.path().display(),
        recipe.display()
    );
    let config =
        camloop::config::Config::parse(&text, &dir.path().join("camloop.toml"), |_| None).unwrap();
    let running = camloop::service::start(config, camloop::service::RunOptions::default())
        .await
        .unwrap();
    let inbox = dir.path().join("inbox");
    let good = measurement_csv(&measurement("DROP1", "P1", "IN1", 1));
    let write = |name: &str, text: &str| std::fs::write(inbox.join(name), text).unwrap();
    write(
        "a_other_machine.csv",
        &measurement_csv(&measurement("SIM1", "P2", "IN1", 2)),
    );
    let mut short = measurement("DROP1", "P3", "IN1", 3);
    short.samples.retain(|s| s.revolution < 1);
    short.header.revolutions = 1;
    write("b_one_revolution.csv", &measurement_csv(&short));
    write("c_good.csv", &good);
    wait_for(|| moved(&inbox, "processed").len() + moved(&inbox, "rejected").len() >= 5).await;
    write("d_good_again.csv", &good);
    wait_for(|| moved(&inbox, "processed").len() >= 2).await;
    running.stop().await;
    assert_eq!(
        moved(&inbox, "processed"),
        ["c_good.csv", "d_good_again.csv"]
    );
    let rejected = moved(&inbox, "rejected");
    assert_eq!(
        rejected,
        [
            "a_other_machine.csv",
            "a_other_machine.csv.reason.txt",
            "b_one_revolution.csv",
            "b_one_revolution.csv.reason.txt"
        ]
    );
    let reason =
        std::fs::read_to_string(inbox.join("rejected/a_other_machine.csv.reason.txt")).unwrap();
    assert!(reason.contains("machine \"SIM1\""), "{reason}");
    let url = format!("sqlite://{}/db.sqlite", dir.path().display());
    let store = Store::connect(&url).await.unwrap();
    let history = store
        .measurement_history(&camloop::store::HistoryFilter::new(
            "DROP1".parse().unwrap(),
            100,
        ))
        .await
        .unwrap();
    assert_eq!(history.items.len(), 1, "learned from once");
}

/// File names in `inbox/<sub>`, sorted.
fn moved(inbox: &Path, sub: &str) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(inbox.join(sub))
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

async fn wait_for(done: impl Fn() -> bool) {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while !done() {
        assert!(std::time::Instant::now() < deadline, "timed out");
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
}
