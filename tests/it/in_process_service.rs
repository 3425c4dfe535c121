//! Measure before the finish through the machine loop (`[cycle] program = "whole"`): the
//! whole-cycle main program and the handshake's count 0 on the share at start; an in-process
//! measurement of the part in the machine delivers this part's finish table with the count
//! moved, written after the table in the same push; a wrong-part or incomplete one, or one
//! past the control's wait, delivers nothing and moves no count; neither learns, and the
//! finished part then learns once. Through the service, a drop folder's
//! `<name>.in-process.csv` takes the same way and is kept in the history with its stage
//! (`in_process`), beside the finished part's row (`final`), which alone the capability
//! study counts.

use crate::gauge_drop_support::measurement_csv;
use crate::machine_support::{nominal_measurement, start_machine};
use crate::service_support::{get, json};
use camloop::core::measure::RawMeasurement;
use camloop::recipe::{FeatureSetup, Recipe};
use camloop::service::machine::{InProcessOutcome, Ingested, MachineLoop, SourceEvent};
use camloop::service::metrics::Metrics;
use camloop::sim::{
    CommandedTable, GrinderConfig, PartLabels, SimGrinder, StationErrors, Workpiece,
};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

fn setup() -> FeatureSetup {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe-in-process.toml");
    let recipe = Recipe::load(&path).unwrap();
    recipe.feature_setup(&path, "IN1").unwrap()
}

fn labels(part: &str, lobe: &str) -> PartLabels {
    PartLabels {
        machine: "M1".into(),
        part: part.into(),
        lobe: lobe.into(),
    }
}

/// Part `part` ground with its nominal table and read with the recipe's 20 µm of stock still
/// on (the finish stage's infeed).
fn with_stock(setup: &FeatureSetup, labels: &PartLabels) -> RawMeasurement {
    let camloop::core::compensate::Feature::Cam(g) = setup.feature else {
        panic!("a cam")
    };
    let mut sim = SimGrinder::new(GrinderConfig::default(), Workpiece::Cam(g), 3).unwrap();
    let geometry = setup.feature.part(&setup.nominal).unwrap();
    let table =
        CommandedTable::nominal(&geometry, 360, camloop::core::fit::TableForm::Poly).unwrap();
    let stock = StationErrors {
        size_um: 20.0,
        ..StationErrors::default()
    };
    let ground = sim
        .grind_station(&table, &Workpiece::Cam(g), &stock)
        .unwrap();
    sim.measure(&ground, labels)
}

fn share_file(dir: &Path, name: &str) -> String {
    std::fs::read_to_string(dir.join("share").join(name)).unwrap()
}

fn ready(dir: &Path) -> String {
    share_file(dir, "CAMLOOP_READY.SPF")
}

fn in_force(m: &MachineLoop) -> u64 {
    m.features()[0]
        .memory()
        .in_force_version
        .map_or(0, |v| v.get())
}

async fn machine(dir: &Path) -> MachineLoop {
    start_machine(dir, "M1", vec![setup()], Arc::new(Metrics::default())).await
}

#[tokio::test]
async fn the_whole_cycle_program_and_the_count_0_are_on_the_share_at_start() {
    let dir = tempfile::tempdir().unwrap();
    let m = machine(dir.path()).await;
    let main = std::fs::read_dir(dir.path().join("share"))
        .unwrap()
        .filter_map(Result::ok)
        .find(|e| e.file_name().to_string_lossy().ends_with(".MPF"))
        .map(|e| std::fs::read_to_string(e.path()).unwrap())
        .expect("a main program on the share");
    // The whole cycle's marks: the handshake's subprogram, the wheel spindle, coolant.
    assert!(main.contains("EXTERN CAMLOOP_READY(VAR INT)"), "{main}");
    assert!(main.contains("M1=3 S1="), "{main}");
    assert!(main.contains("M8 ; coolant on"), "{main}");
    assert!(ready(dir.path()).contains("CL_READY=0"));
    assert_eq!(in_force(&m), 1);
}

#[tokio::test]
async fn an_in_process_measurement_delivers_the_finish_table_then_the_count() {
    let dir = tempfile::tempdir().unwrap();
    let mut m = machine(dir.path()).await;
    let s = setup();
    let table_file = format!("{}.SPF", s.program.name);
    let before = share_file(dir.path(), &table_file);
    let parts_before = m.features()[0].memory().parts;
    let raw = with_stock(&s, &labels("17", "IN1"));
    let outcome = m.on_in_process(raw, "17", Instant::now()).await.unwrap();
    assert_eq!(
        outcome,
        InProcessOutcome::Delivered {
            version: 2,
            ready: 1
        }
    );
    assert_eq!(in_force(&m), 2);
    assert_ne!(share_file(dir.path(), &table_file), before);
    assert!(ready(dir.path()).contains("CL_READY=1"));
    // Nothing learned from the in-process measurement: no part counted.
    assert_eq!(m.features()[0].memory().parts, parts_before);

    // The finished part learns once, from the finish table in force.
    let finished = nominal_measurement(&s, labels("17", "IN1"), 5);
    let (done, answer) = tokio::sync::oneshot::channel();
    m.handle(SourceEvent::Measurement {
        raw: finished.clone(),
        ground_with: None,
        done: Some(done),
    })
    .await;
    assert_eq!(answer.await.unwrap(), Ingested::Recorded);
    assert_eq!(m.features()[0].memory().parts, parts_before + 1);
    let (done, answer) = tokio::sync::oneshot::channel();
    m.handle(SourceEvent::Measurement {
        raw: finished,
        ground_with: None,
        done: Some(done),
    })
    .await;
    assert_eq!(answer.await.unwrap(), Ingested::Repeated);
    assert_eq!(m.features()[0].memory().parts, parts_before + 1);
}

#[tokio::test]
async fn a_wrong_or_incomplete_in_process_measurement_delivers_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut m = machine(dir.path()).await;
    let s = setup();
    let table_file = format!("{}.SPF", s.program.name);
    let before = share_file(dir.path(), &table_file);
    let mut two_revs = with_stock(&s, &labels("17", "IN1"));
    two_revs.samples.retain(|x| x.revolution < 2);
    two_revs.header.revolutions = 2;
    let now = Instant::now();
    // Past the recipe's 5 s handshake timeout: the finish is already ground.
    let six_s_ago = now.checked_sub(Duration::from_secs(6)).unwrap();
    let cases = [
        (with_stock(&s, &labels("18", "IN1")), now, "names part 18"),
        (two_revs, now, "revolution"),
        (with_stock(&s, &labels("17", "IN1")), six_s_ago, "too late"),
    ];
    for (raw, received, why) in cases {
        let outcome = m.on_in_process(raw, "17", received).await.unwrap();
        let InProcessOutcome::Refused { reason } = &outcome else {
            panic!("refused: {outcome:?}")
        };
        assert!(reason.contains(why), "{reason}");
        assert_eq!(in_force(&m), 1);
        assert_eq!(share_file(dir.path(), &table_file), before);
        assert!(ready(dir.path()).contains("CL_READY=0"));
        assert_eq!(m.features()[0].memory().parts, 0);
    }
}

/// Drops `raw` into `inbox` as `name`: written under a temporary name and renamed, with the
/// `# end` marker, as the drop-folder rules ask.
fn drop_file(inbox: &Path, name: &str, raw: &RawMeasurement) {
    let tmp = inbox.join(format!(".{name}.tmp"));
    std::fs::write(&tmp, measurement_csv(raw)).unwrap();
    std::fs::rename(&tmp, inbox.join(name)).unwrap();
}

/// Waits (bounded, 20 s) for `path` to exist.
async fn appears(path: &Path) {
    for _ in 0..400 {
        if path.exists() {
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    panic!("{} did not appear within 20 s", path.display());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_service_takes_an_in_process_file_from_the_drop_folder() {
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"sqlite://{}/db.sqlite?mode=rwc\"\n\
         [http]\nlisten = \"127.0.0.1:0\"\n\
         [[machines]]\nname = \"DROP1\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"share\"\n\
         [machines.gauge]\nkind = \"drop\"\nfolder = \"inbox\"\npoll_ms = 20\n",
        dir.path().display(),
        root.join("config/parts/demo-lobe-in-process.toml")
            .display(),
    );
    let config =
        camloop::config::Config::parse(&text, &dir.path().join("camloop.toml"), |_| None).unwrap();
    let running = camloop::service::start(config, camloop::service::RunOptions::default())
        .await
        .unwrap();
    let inbox = dir.path().join("inbox");
    std::fs::create_dir_all(&inbox).unwrap();
    let s = setup();
    let at = |p: &str, l: &str| PartLabels {
        machine: "DROP1".into(),
        ..labels(p, l)
    };

    drop_file(
        &inbox,
        "17-IN1.in-process.csv",
        &with_stock(&s, &at("17", "IN1")),
    );
    appears(&inbox.join("processed/17-IN1.in-process.csv")).await;
    assert!(ready(dir.path()).contains("CL_READY=1"));

    let mut two_revs = with_stock(&s, &at("18", "IN1"));
    two_revs.samples.retain(|x| x.revolution < 2);
    two_revs.header.revolutions = 2;
    drop_file(&inbox, "18-IN1.in-process.csv", &two_revs);
    appears(&inbox.join("rejected/18-IN1.in-process.csv")).await;
    let reason = std::fs::read_to_string(inbox.join("rejected/18-IN1.in-process.csv.reason.txt"))
        .unwrap_or_default();
    assert!(reason.contains("revolution"), "{reason}");
    assert!(ready(dir.path()).contains("CL_READY=1"));

    // The finished part is the one measurement learned from; the history keeps both, each
    // with its stage, and the capability study counts the finished part only.
    drop_file(
        &inbox,
        "17-IN1.csv",
        &nominal_measurement(&s, at("17", "IN1"), 5),
    );
    appears(&inbox.join("processed/17-IN1.csv")).await;
    let history = "/api/v1/machines/DROP1/measurements";
    let mut items = Vec::new();
    for _ in 0..200 {
        let (_, body) = get(running.http_addr, history).await;
        items = json(&body)["items"].as_array().cloned().unwrap_or_default();
        if items.len() >= 2 {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    let stages: Vec<(&str, &str)> = items
        .iter()
        .map(|i| {
            (
                i["part"].as_str().unwrap_or(""),
                i["stage"].as_str().unwrap_or(""),
            )
        })
        .collect();
    assert_eq!(
        stages,
        [("17", "final"), ("17", "in_process")],
        "newest first: the finished part, then its in-process measurement"
    );
    let (_, body) = get(running.http_addr, &format!("{history}?stage=in_process")).await;
    let only = json(&body)["items"].as_array().cloned().unwrap_or_default();
    assert_eq!(only.len(), 1, "{body}");
    assert_eq!(only[0]["stage"], "in_process");
    let (_, body) = get(
        running.http_addr,
        "/api/v1/machines/DROP1/features/IN1/capability",
    )
    .await;
    assert_eq!(json(&body)["parts"], 1, "the finished part only: {body}");
    running.stop().await;
}
