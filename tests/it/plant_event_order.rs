//! A part's plant event (MQTT, OPC UA) goes out after the part's row is in the history: a
//! client that reads the API the moment an event arrives finds the part. Watched here at the
//! machine loop: a task takes each `part_analysed` event as it comes and looks the part up in
//! the store at once, while the loop goes on with its step.

use crate::machine_support::{demo_lobe_setup, nominal_measurement, start_machine};
use camloop::names::MachineName;
use camloop::service::machine::{Ingested, SourceEvent};
use camloop::service::plant::EventSender;
use camloop::sim::PartLabels;
use camloop::store::{HistoryFilter, Store};
use camloop_loop::PlantEvent;
use std::sync::Arc;
use std::sync::atomic::AtomicU64;

const PARTS: usize = 6;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_parts_event_follows_its_history_row() {
    let dir = tempfile::tempdir().unwrap();
    let setup = demo_lobe_setup();
    let mut machine = start_machine(dir.path(), "M1", vec![setup.clone()], Arc::default()).await;
    let (tx, mut events) = tokio::sync::mpsc::channel(64);
    machine.set_plant_events(Some(EventSender::new(tx, Arc::new(AtomicU64::new(0)))));
    let url = format!("sqlite://{}/db.sqlite", dir.path().display());
    let reader = Store::connect(&url).await.unwrap();
    // Each event's part looked up the moment the event arrives.
    let watcher = tokio::spawn(async move {
        let mut seen = Vec::new();
        while let Some(event) = events.recv().await {
            let PlantEvent::PartAnalysed { part, .. } = event else {
                continue;
            };
            let filter = HistoryFilter::new(MachineName::new("M1").unwrap(), 50);
            let rows = reader.measurement_history(&filter).await.unwrap();
            let stored = rows.items.iter().any(|r| r.part == part);
            seen.push((part, stored));
        }
        reader.close().await;
        seen
    });
    for k in 0..PARTS {
        let labels = PartLabels {
            machine: "M1".into(),
            part: format!("P{k}"),
            lobe: "IN1".into(),
        };
        let raw = nominal_measurement(&setup, labels, k as u64);
        let (done, answer) = tokio::sync::oneshot::channel();
        machine
            .handle(SourceEvent::Measurement {
                raw,
                ground_with: None,
                done: Some(done),
            })
            .await;
        assert_eq!(answer.await.unwrap(), Ingested::Recorded, "part {k}");
    }
    drop(machine);
    let seen = watcher.await.unwrap();
    assert_eq!(seen.len(), PARTS, "one event per part: {seen:?}");
    let early: Vec<_> = seen.iter().filter(|(_, stored)| !stored).collect();
    assert!(early.is_empty(), "events before their rows: {early:?}");
}
