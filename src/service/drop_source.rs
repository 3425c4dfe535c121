//! The drop folder as a gauge source: complete measurement files go to the machine one by
//! one, and each is moved by the machine's verdict (processed, or rejected with its reason).

use super::machine::{InProcessOutcome, Ingested, SourceEvent};
use super::sources::Intake;
use crate::gauge::{DropFolder, Settle};
use crate::names::MachineName;
use std::time::Duration;
use tokio::sync::watch;
use tracing::{error, warn};

/// Measurement files dropped into a folder (taken when complete, moved to processed/ or
/// rejected/ with a reason).
pub(super) async fn run(
    machine: MachineName,
    folder: std::path::PathBuf,
    poll_ms: u64,
    options: crate::gauge::DropOptions,
    tx: Intake,
    mut shutdown: watch::Receiver<bool>,
) {
    let dbc = crate::gauge::GaugeDbc::builtin();
    if let Err(e) = std::fs::create_dir_all(&folder) {
        error!(machine = %machine, folder = %folder.display(), error = %e, "drop folder unusable");
        return;
    }
    let mut drop_folder = match crate::gauge::DropFolder::open(&folder, dbc, options) {
        Ok(d) => d,
        Err(e) => {
            error!(machine = %machine, folder = %folder.display(), error = %e, "drop folder unusable");
            return;
        }
    };
    let mut tick = tokio::time::interval(Duration::from_millis(poll_ms.max(10)));
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.changed() => return,
        }
        // File work off the async threads.
        let (df, events) = match tokio::task::spawn_blocking(move || {
            let events = drop_folder.poll();
            (drop_folder, events)
        })
        .await
        {
            Ok(done) => done,
            Err(_) => return,
        };
        drop_folder = df;
        for event in events {
            match event {
                crate::gauge::DropEvent::Accepted { measurement, path } => {
                    match hand_over(&machine, drop_folder, measurement, path, &tx).await {
                        Some(df) => drop_folder = df,
                        None => return,
                    }
                }
                crate::gauge::DropEvent::Dressing { report, moved_to } => {
                    let event = SourceEvent::Dressing {
                        wheel_radius_mm: report.wheel_radius_mm,
                        infeed_um: report.infeed_um,
                        source: format!("drop file {}", moved_to.display()),
                        done: None,
                    };
                    if tx.send(event).await.is_err() {
                        return;
                    }
                }
                other => warn!(machine = %machine, event = ?other, "drop folder"),
            }
        }
    }
}

/// Sends one complete file's measurement to the machine and moves the file by its verdict:
/// `rejected/` with the reason beside it, or `processed/`. `None` when the machine is gone
/// (shutdown): the file stays in the inbox and is read again at the next start.
async fn hand_over(
    machine: &str,
    mut drop_folder: DropFolder,
    measurement: crate::core::measure::RawMeasurement,
    path: std::path::PathBuf,
    tx: &Intake,
) -> Option<DropFolder> {
    let settle = if is_in_process(&path) {
        let (done, verdict) = tokio::sync::oneshot::channel();
        let event = SourceEvent::InProcess {
            raw: measurement,
            part: None,
            received: std::time::Instant::now(),
            done: Some(done),
        };
        tx.send(event).await.ok()?;
        match verdict.await.ok()? {
            InProcessOutcome::Refused { reason } => Settle::Rejected { reason },
            InProcessOutcome::Delivered { .. } | InProcessOutcome::Waiting { .. } => {
                Settle::Processed
            }
        }
    } else {
        let (done, verdict) = tokio::sync::oneshot::channel();
        let event = SourceEvent::Measurement {
            raw: measurement,
            ground_with: None,
            done: Some(done),
        };
        tx.send(event).await.ok()?;
        match verdict.await.ok()? {
            Ingested::Rejected { reason } | Ingested::Failed { reason } => {
                Settle::Rejected { reason }
            }
            Ingested::Recorded | Ingested::Master | Ingested::Repeated => Settle::Processed,
            // Kept where it is, claimed, and read again at the next start.
            Ingested::NotRecorded => return Some(drop_folder),
        }
    };
    let (df, settled) = tokio::task::spawn_blocking(move || {
        let settled = drop_folder.settle(&path, settle);
        (drop_folder, settled)
    })
    .await
    .ok()?;
    if let Err(e) = settled {
        warn!(machine = %machine, error = %e, "drop file not settled");
    }
    Some(df)
}

/// A measurement before the finish (stock on) is dropped as `<name>.in-process.csv` (or
/// `.log`); any other measurement file is of a finished part, as files always were.
fn is_in_process(path: &std::path::Path) -> bool {
    path.file_stem()
        .and_then(|s| s.to_str())
        .is_some_and(|s| s.to_ascii_lowercase().ends_with(IN_PROCESS_SUFFIX))
}

/// The end of a measurement file's stem that marks it as taken before the finish.
pub(crate) const IN_PROCESS_SUFFIX: &str = ".in-process";

#[cfg(test)]
mod tests {
    use super::is_in_process;
    use std::path::Path;

    #[test]
    fn only_a_marked_file_is_an_in_process_measurement() {
        assert!(is_in_process(Path::new("inbox/17-IN1.in-process.csv")));
        assert!(is_in_process(Path::new("17-IN1.In-Process.log")));
        assert!(!is_in_process(Path::new("inbox/17-IN1.csv")));
        assert!(!is_in_process(Path::new("in-process.csv")));
        assert!(!is_in_process(Path::new("17-in-process-IN1.csv")));
    }
}
