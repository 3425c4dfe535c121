//! The whole cycle through the service on the demo camshaft and crankshaft: the simulated
//! control runs camloop's whole-cycle program from the share, the simulated gauge measures
//! each feature before its finish with the stock on, the service delivers that part's finish
//! table and the handshake's count, and the finished features are learned from. Worst
//! feature per shaft for shafts 1–12, with the measurement before the finish and without it
//! (the same cycle less its spark-out before the measurement and the measure stage), and
//! the cycle time per shaft from the program on the share. Printed with `--nocapture`.

use crate::history_support::parts_with_reports;
use camloop::config::Config;
use camloop::core::program::READY_PROGRAM;
use camloop::service::{self, RunOptions};
use camloop::sim::Control;
use camloop::store::{EventFilter, HistoryFilter, MeasurementStage, Store};

/// The simulated cell's events that say a finish went without its same-part table.
pub(crate) async fn finish_refusals(store: &Store) -> Vec<String> {
    store
        .events(&EventFilter {
            machine: Some("CELL".parse().unwrap()),
            limit: 1000,
            ..EventFilter::default()
        })
        .await
        .unwrap()
        .into_iter()
        .map(|e| e.message)
        .filter(|m| m.contains("no same-part finish table"))
        .collect()
}
use std::path::Path;

const SHAFTS: u64 = 12;
/// Undulations per revolution kept when the measured error is judged: the gauge's noise
/// (σ 0.3 µm a reading) is filtered off above it, as a roundness evaluation filters (ISO
/// 12181's 50 UPR); the learning itself stops at order 40 plus its roll-off.
const UPR: usize = 50;

fn parts_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts")
}

/// The recipe in `dir` (its lift files beside it), without the measurement when `measure`
/// is false.
pub(crate) fn recipe(dir: &Path, file: &str, measure: bool) -> std::path::PathBuf {
    let mut text = std::fs::read_to_string(parts_dir().join(file)).unwrap();
    if !measure {
        // The measure stage and the spark-out before it (the deflection's decay for the
        // gauge) go; the rest of the cycle is the same.
        let mut stages: Vec<&str> = text.split("[[cycle.stages]]").collect();
        let at = stages
            .iter()
            .position(|s| s.contains("kind = \"measure\""))
            .unwrap_or_else(|| panic!("{file}: no measure stage"));
        assert!(stages[at - 1].contains("kind = \"spark-out\""), "{file}");
        stages.drain(at - 1..=at);
        text = stages.join("[[cycle.stages]]");
    }
    // The figures are of the grinding, not of this machine's load: a wait the loaded test
    // machine overran (the control's 5 s, in wall-clock time here) would grind that finish
    // with the table in force, which tests/it/in_process_timeout.rs covers. The simulated
    // control's wait is in its own time and is answered at its first poll either way.
    let wait = "handshake_timeout_s = 5.0";
    assert!(text.contains(wait), "{file}: {wait}");
    text = text.replace(wait, "handshake_timeout_s = 600.0");
    for lift in ["demo-intake-lobe.csv", "demo-exhaust-lobe.csv"] {
        std::fs::copy(parts_dir().join(lift), dir.join(lift)).unwrap();
    }
    let path = dir.join(file);
    std::fs::write(&path, text).unwrap();
    path
}

/// The largest error of the measured profile with the orders above [`UPR`] left out, µm.
fn filtered_max_um(error_um: &[f64]) -> f64 {
    let n = error_um.len();
    let mut smooth = vec![0.0; n];
    for k in 0..=UPR.min(n / 2 - 1) {
        let (mut a, mut b) = (0.0, 0.0);
        for (j, e) in error_um.iter().enumerate() {
            let phi = std::f64::consts::TAU * (k * j) as f64 / n as f64;
            a += e * phi.cos();
            b += e * phi.sin();
        }
        let scale = if k == 0 { 1.0 } else { 2.0 } / n as f64;
        for (j, s) in smooth.iter_mut().enumerate() {
            let phi = std::f64::consts::TAU * (k * j) as f64 / n as f64;
            *s += scale * (a * phi.cos() + b * phi.sin());
        }
    }
    smooth.iter().fold(0.0, |m, v| m.max(v.abs()))
}

pub(crate) struct Figures {
    /// Worst feature per shaft: measured max error, and with the orders above 50 left out.
    pub measured_um: Vec<f64>,
    pub filtered_um: Vec<f64>,
    /// Worst feature per shaft: |mean error| (the size), µm.
    pub size_um: Vec<f64>,
    /// Per shaft: coupled grinding, measurement revolutions, s.
    pub grind_s: f64,
    pub measure_s: f64,
    /// The share's program files after the run, by file name.
    pub share: std::collections::BTreeMap<String, String>,
}

/// Runs `SHAFTS` shafts of `file` on a simulated machine through the service.
pub(crate) async fn run(file: &str, features: &[&str], measure: bool) -> Figures {
    run_shafts(file, features, measure, SHAFTS).await
}

/// Runs `shafts` shafts of `file` on a simulated machine through the service.
pub(crate) async fn run_shafts(
    file: &str,
    features: &[&str],
    measure: bool,
    shafts: u64,
) -> Figures {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.path().display());
    let recipe = recipe(dir.path(), file, measure);
    let text = format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"{url}\"\n[http]\nlisten = \"127.0.0.1:0\"\n\
         [[machines]]\nname = \"CELL\"\nrecipe = \"{}\"\nshare = \"share\"\n\
         [machines.gauge]\nkind = \"sim\"\npart_interval_ms = 1\nseed = 3\n\
         [machines.gauge.grinder]\ndress_every_parts = 0\ndress_at_parts = [4, 8]\n\
         dresser_reports_infeed = true\n",
        recipe.display()
    );
    let config = Config::parse(&text, &dir.path().join("camloop.toml"), |_| None).unwrap();
    let mut running = service::start(config, RunOptions::parts(shafts))
        .await
        .unwrap();
    running.machines_done().await;
    let store = Store::connect(&url).await.unwrap();
    // Every finish had its same-part table: a refusal would make these figures the table in
    // force's, so it is named here rather than found in a figure.
    let refused = finish_refusals(&store).await;
    assert_eq!(refused, Vec::<String>::new(), "{file}");
    let mut measured_um = vec![0.0f64; shafts as usize];
    let mut filtered_um = vec![0.0f64; shafts as usize];
    let mut size_um = vec![0.0f64; shafts as usize];
    for f in features {
        let parts = parts_with_reports(&store, "CELL", f).await;
        let numbers: Vec<u64> = parts.iter().map(|(s, _)| s.part.parse().unwrap()).collect();
        assert_eq!(numbers, (1..=shafts).collect::<Vec<_>>(), "{file} {f}");
        // With the measurement, each shaft's in-process reading is kept beside it.
        let in_process = HistoryFilter {
            lobe: Some(f.parse().unwrap()),
            stage: Some(MeasurementStage::InProcess),
            ..HistoryFilter::new("CELL".parse().unwrap(), 10_000)
        };
        let page = store.measurement_history(&in_process).await.unwrap();
        let numbers: Vec<u64> = page
            .items
            .iter()
            .rev()
            .map(|s| s.part.parse().unwrap())
            .collect();
        let expected: Vec<u64> = if measure {
            (1..=shafts).collect()
        } else {
            Vec::new()
        };
        assert_eq!(numbers, expected, "{file} {f}: in-process rows");
        for (s, report) in &parts {
            let error: Vec<f64> = report["error_um"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            let k: usize = s.part.parse::<usize>().unwrap() - 1;
            let max = error.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            measured_um[k] = measured_um[k].max(max);
            filtered_um[k] = filtered_um[k].max(filtered_max_um(&error));
            let mean = error.iter().sum::<f64>() / error.len() as f64;
            size_um[k] = size_um[k].max(mean.abs());
        }
    }
    // The cycle time: the program on the share as the simulated control runs it, the
    // handshake answered at once (the count one ahead of what the control read before).
    let share = dir.path().join("share");
    let main = std::fs::read_to_string(share.join("CAMLOOP_GRIND.MPF")).unwrap();
    let calls = std::cell::Cell::new(0u64);
    let load = |name: &str| {
        if name == READY_PROGRAM {
            calls.set(calls.get() + 1);
            return Some(camloop::core::program::render_ready_program(calls.get()));
        }
        std::fs::read_to_string(share.join(format!("{name}.SPF"))).ok()
    };
    let mut control = Control::new();
    control.enable_overlay();
    let cycle = control.run_cycle(&main, &load).unwrap();
    let (grind_s, measure_s, _) = camloop::sim::cycle_cell::times(&cycle);
    drop(running);
    let share = std::fs::read_dir(&share)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "SPF" || x == "MPF"))
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read_to_string(&p).unwrap())
        })
        .collect();
    Figures {
        measured_um,
        filtered_um,
        size_um,
        grind_s,
        measure_s,
        share,
    }
}

/// A recipe's figures with and without the measurement, as rows of a table.
pub(crate) fn rows(file: &str, with: &Figures, without: &Figures) -> String {
    [
        row(
            &format!("{file}, measured before the finish"),
            &with.measured_um,
        ),
        row("  50 UPR", &with.filtered_um),
        row("  size", &with.size_um),
        row("  part to part only", &without.measured_um),
        row("  50 UPR", &without.filtered_um),
    ]
    .concat()
}

/// The goal, filtered at 50 UPR: the first shaft within 1.0 µm (and far off
/// without the measurement), every shaft from the third within 0.5 µm.
pub(crate) fn assert_goal(file: &str, with: &Figures, without: &Figures, out: &str) {
    let f = &with.filtered_um;
    assert!(f[0] <= 1.0, "{file}: first shaft {:.2} µm\n{out}", f[0]);
    assert!(without.filtered_um[0] > 10.0, "{file}\n{out}");
    assert!(
        f[2..].iter().all(|&e| e <= 0.5),
        "{file}: from the third shaft {f:?}\n{out}"
    );
}

pub(crate) fn row(label: &str, v: &[f64]) -> String {
    let cells: Vec<String> = v.iter().map(|x| format!("{x:.2}")).collect();
    format!("| {label} | {} |\n", cells.join(" | "))
}

/// Through the service, with the measurement before the finish, judged on the measured
/// error with the gauge's noise filtered off above 50 UPR (see [`UPR`]): the goal,
/// the first shaft within 1.0 µm (over 10 µm without the measurement) and every shaft from
/// the third within 0.5 µm, on the camshaft and the crankshaft.
///
/// The size is held too, from the third shaft within 0.2 µm: the wheel wears 0.1 µm a
/// feature, 0.8 µm between two shafts of the camshaft, and a finish table that anticipated
/// that wear (or learned it from its own in-process reading) ground every lobe 0.5–0.6 µm
/// undersize, the plateau this bound keeps out. The gauge's mean over 360 angles and its
/// revolutions is known to about 0.01 µm, so 0.2 µm is the learning's deadband and a
/// quarter of a shaft's wear, not noise.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_first_shaft_is_right_through_the_service() {
    let lobes = ["IN1", "EX1", "IN2", "EX2", "IN3", "EX3", "IN4", "EX4"];
    let pins = ["P1", "P2", "P3", "P4"];
    let mut out = String::new();
    let mut all = Vec::new();
    for (file, features) in [
        ("demo-camshaft-in-process.toml", &lobes[..]),
        ("demo-crankshaft-in-process.toml", &pins[..]),
    ] {
        let with = run(file, features, true).await;
        let without = run(file, features, false).await;
        out.push_str(&rows(file, &with, &without));
        out.push_str(&format!(
            "  cycle per shaft: {:.1} s coupled + {:.1} s measuring with; {:.1} s + {:.1} s without\n",
            with.grind_s, with.measure_s, without.grind_s, without.measure_s
        ));
        all.push((file, with, without));
    }
    println!("{out}");
    for (file, with, without) in &all {
        assert_goal(file, with, without, &out);
        let size = &with.size_um;
        assert!(
            size[2..].iter().all(|&e| e <= 0.2),
            "{file}: size from the third shaft {size:?}\n{out}"
        );
        assert!(with.measure_s > 0.0 && without.measure_s == 0.0, "{out}");
    }
}
