//! The handshake's timeout path through the service, end to end: the simulated control runs
//! the whole-cycle program from the share and waits for camloop's answer after the
//! measurement before the finish; camloop does not answer in time, because a guard refuses
//! the in-process measurement (the probe slipped) or because the reading reached it after
//! the control's wait (the gauge's handover). Either way the control grinds the finish with
//! the table in force and goes on (every shaft is finished and gauged), an event says why,
//! the handshake's count stays 0, and nothing is learned from the in-process measurement:
//! no table version is made from it, and the first part is as far off as without a
//! measurement before the finish.

use crate::history_support::parts_with_reports;
use crate::in_process_figures::finish_refusals;
use camloop::config::Config;
use camloop::service::{self, RunOptions};
use camloop::store::{HistoryFilter, MeasurementStage, Store};
use std::path::Path;
use std::time::Duration;

const SHAFTS: u64 = 2;

/// What one run through the service left behind.
struct Left {
    /// The finished parts' numbers and their max |error|, µm.
    finished: Vec<(u64, f64)>,
    /// Parts with an in-process row in the history.
    in_process_rows: Vec<u64>,
    /// Warnings that an in-process measurement gave no same-part finish table.
    events: Vec<String>,
    /// Every table version's reason.
    reasons: Vec<String>,
    /// The handshake's file on the share at the end.
    ready: String,
}

/// Runs `SHAFTS` shafts of the demo lobe through the whole cycle, the control waiting
/// `timeout_s` for camloop's answer, on a simulated machine
/// whose in-process gauge settings (`[machines.gauge.grinder.gauge.in_process]`) are `gauge`.
async fn run(gauge: &str, timeout_s: f64) -> Left {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.path().display());
    let parts = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts");
    let wait = "handshake_timeout_s = 5.0";
    let text = std::fs::read_to_string(parts.join("demo-lobe-in-process.toml")).unwrap();
    assert!(text.contains(wait));
    let recipe = dir.path().join("demo-lobe-in-process.toml");
    std::fs::write(
        &recipe,
        text.replace(wait, &format!("handshake_timeout_s = {timeout_s:.1}")),
    )
    .unwrap();
    let lift = "demo-intake-lobe.csv";
    std::fs::copy(parts.join(lift), dir.path().join(lift)).unwrap();
    let text = format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"{url}\"\n[http]\nlisten = \"127.0.0.1:0\"\n\
         [[machines]]\nname = \"CELL\"\nrecipe = \"{}\"\nshare = \"share\"\n\
         [machines.gauge]\nkind = \"sim\"\npart_interval_ms = 1\nseed = 5\n\
         [machines.gauge.grinder]\ndress_every_parts = 0\n\
         [machines.gauge.grinder.gauge.in_process]\n{gauge}\n",
        recipe.display()
    );
    let config = Config::parse(&text, &dir.path().join("camloop.toml"), |_| None).unwrap();
    let mut running = service::start(config, RunOptions::parts(SHAFTS))
        .await
        .unwrap();
    // The condition asserted: the machine finishes its shafts. Bounded, so a stalled control
    // fails the test instead of hanging it (a shaft takes well under a second here).
    tokio::time::timeout(Duration::from_secs(300), running.machines_done())
        .await
        .expect("the machine finished its shafts: the control never stalls at the handshake");
    let store = Store::connect(&url).await.unwrap();
    let finished = parts_with_reports(&store, "CELL", "IN1")
        .await
        .iter()
        .map(|(s, report)| {
            let max = report["error_um"]
                .as_array()
                .unwrap()
                .iter()
                .fold(0.0f64, |m, v| m.max(v.as_f64().unwrap().abs()));
            (s.part.parse().unwrap(), max)
        })
        .collect();
    let in_process = HistoryFilter {
        lobe: Some("IN1".parse().unwrap()),
        stage: Some(MeasurementStage::InProcess),
        ..HistoryFilter::new("CELL".parse().unwrap(), 100)
    };
    let mut in_process_rows: Vec<u64> = store
        .measurement_history(&in_process)
        .await
        .unwrap()
        .items
        .iter()
        .map(|s| s.part.parse().unwrap())
        .collect();
    in_process_rows.sort_unstable();
    let events = finish_refusals(&store).await;
    let reasons = store
        .table_versions(&"CELL".parse().unwrap(), &"IN1".parse().unwrap(), 100)
        .await
        .unwrap()
        .into_iter()
        .map(|v| v.reason)
        .collect();
    let ready = std::fs::read_to_string(dir.path().join("share/CAMLOOP_READY.SPF")).unwrap();
    running.stop().await;
    Left {
        finished,
        in_process_rows,
        events,
        reasons,
        ready,
    }
}

/// What holds whenever camloop does not answer in time, `why` being in every event.
fn finished_with_the_table_in_force(left: &Left, why: &str) {
    let parts: Vec<u64> = left.finished.iter().map(|(p, _)| *p).collect();
    assert_eq!(
        parts,
        (1..=SHAFTS).collect::<Vec<_>>(),
        "every shaft finished"
    );
    // The first part ground with the nominal table in force: as far off as part to part
    // alone (17.95 µm on the demo camshaft's lobes; with its finish table it is within
    // 1 µm), so 10 µm tells the two apart with room on both sides.
    assert!(left.finished[0].1 > 10.0, "first part: {:?}", left.finished);
    assert_eq!(left.events.len(), SHAFTS as usize, "{:?}", left.events);
    for e in &left.events {
        assert!(e.contains(why), "{e}");
        assert!(
            e.contains("the finish grinds with the table in force, nothing learned"),
            "{e}"
        );
    }
    assert!(
        left.reasons.iter().all(|r| !r.contains("same-part")),
        "no version from an in-process measurement: {:?}",
        left.reasons
    );
    assert!(left.ready.contains("CL_READY=0"), "{}", left.ready);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refused_in_process_measurement_lets_the_finish_grind_with_the_table_in_force() {
    // The probe slips on two of the four revolutions: no three agree, a guard refuses it.
    let left = run(
        "faults = [{ kind = \"offset\", revolution = 0, offset_um = 30.0 }, \
         { kind = \"offset\", revolution = 1, offset_um = 30.0 }]",
        // Long enough that a loaded test machine cannot make it a late one instead.
        600.0,
    )
    .await;
    finished_with_the_table_in_force(&left, "revolutions agree within");
    // A measurement that fails the checks has its event and no history row.
    assert_eq!(left.in_process_rows, Vec::<u64>::new());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_in_process_measurement_past_the_controls_wait_is_not_answered() {
    // The recipe's control waits 5 s; the reading reaches camloop 6 s after the wait began.
    let left = run("handover_s = 6.0", 5.0).await;
    finished_with_the_table_in_force(&left, "too late");
    // It read as a measurement of the part: kept in the history with its stage.
    assert_eq!(left.in_process_rows, (1..=SHAFTS).collect::<Vec<_>>());
}
