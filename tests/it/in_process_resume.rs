//! The whole cycle stopped between two features of a shaft and started again: the simulated
//! machine's operator resumes (R90 < 0), the whole-cycle program starts at the first
//! feature without a gauge record, and the run finishes that shaft rather than a new one:
//! every feature's parts are gauged once each, none lost, none twice.

use crate::in_process_figures::recipe;
use camloop::config::Config;
use camloop::service::{self, RunOptions};
use camloop::store::{HistoryFilter, MeasurementStage, Store};
use std::path::Path;

const LOBES: [&str; 8] = ["IN1", "EX1", "IN2", "EX2", "IN3", "EX3", "IN4", "EX4"];

fn config(dir: &Path, url: &str) -> Config {
    let recipe = recipe(dir, "demo-camshaft-in-process.toml", true);
    let text = format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"{url}\"\n[http]\nlisten = \"127.0.0.1:0\"\n\
         [[machines]]\nname = \"CELL\"\nrecipe = \"{}\"\nshare = \"share\"\n\
         [machines.gauge]\nkind = \"sim\"\npart_interval_ms = 1\nseed = 5\n",
        recipe.display()
    );
    Config::parse(&text, &dir.join("camloop.toml"), |_| None).unwrap()
}

/// `lobe`'s finished parts in the history, oldest first.
async fn finished_parts(store: &Store, lobe: &str) -> Vec<u64> {
    store
        .measurement_history(&HistoryFilter {
            lobe: Some(lobe.parse().unwrap()),
            stage: Some(MeasurementStage::Final),
            ..HistoryFilter::new("CELL".parse().unwrap(), 100)
        })
        .await
        .unwrap()
        .items
        .iter()
        .rev()
        .map(|s| s.part.parse().unwrap())
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_whole_cycle_stopped_mid_shaft_resumes_where_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.path().display());
    let running = service::start(config(dir.path(), &url), RunOptions::parts(1000))
        .await
        .unwrap();
    // Stop once the first lobe of shaft 2 is in: the simulator stops before the next
    // lobe's measurement goes out.
    let from = crate::service_support::stop_mid_shaft(
        running,
        2,
        &dir.path().join("share/CAMLOOP_RESUME.SPF"),
    )
    .await;
    let store = Store::connect(&url).await.unwrap();
    let shaft = finished_parts(&store, "IN1").await.len() as u64;
    for (k, lobe) in LOBES.iter().enumerate() {
        let expected = if k + 1 < from { shaft } else { shaft - 1 };
        let parts = finished_parts(&store, lobe).await;
        assert_eq!(parts, (1..=expected).collect::<Vec<_>>(), "{lobe}");
    }

    let mut running = service::start(config(dir.path(), &url), RunOptions::parts(2))
        .await
        .unwrap();
    running.machines_done().await;
    running.stop().await;
    // The resumed run finished the shaft in the machine (the lobes from the resume point
    // on); the next run was a new shaft, every lobe of it.
    for lobe in LOBES {
        let parts = finished_parts(&store, lobe).await;
        assert_eq!(parts, (1..=shaft + 1).collect::<Vec<_>>(), "{lobe}");
    }
}
