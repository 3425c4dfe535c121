//! The drop folder: a directory where the control or gauge PC writes measurement files,
//! polled (no inotify, so network shares work), each complete file parsed and moved to
//! `processed/` or `rejected/` (with `<name>.reason.txt` beside it). Nothing is deleted.
//!
//! Rules:
//! - Only regular files directly in the folder are considered. Names starting with `.` or
//!   `~`, or ending in `.tmp`, `.part` or `.partial`, are files still being written and are
//!   left alone: a writer may write under such a name and rename when done.
//! - A file is taken when two consecutive polls see the same size and modification time
//!   (so a renamed-in file is taken at the second poll that sees it, and a file written in
//!   place once it has been still for a whole poll interval).
//! - `.csv` and `.log` files are read by [`read_measurement_file`]; anything else is
//!   rejected with that reason.
//! - A name already present in `processed/` or `rejected/` gets a suffix `-1`, `-2`, …
//!   before the extension.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use tokio::sync::mpsc;

use crate::core::measure::RawMeasurement;

use super::dbc::GaugeDbc;
use super::file::read_measurement_file;

/// Subfolder for files taken as measurements.
pub const PROCESSED_DIR: &str = "processed";
/// Subfolder for files that are not measurements.
pub const REJECTED_DIR: &str = "rejected";

/// What happened to one file (or the folder) at a poll.
#[derive(Debug, Clone, PartialEq)]
pub enum DropEvent {
    /// Parsed and moved; the measurement's origin is its new path.
    Accepted {
        measurement: RawMeasurement,
        moved_to: PathBuf,
    },
    /// Not a measurement; moved with a reason file beside it.
    Rejected {
        file: PathBuf,
        moved_to: PathBuf,
        reason: String,
    },
    /// The folder could not be listed or a file could not be moved; the file stays and is
    /// retried only after it changes.
    Failed { path: PathBuf, error: String },
}

/// Why the drop folder cannot be used at all.
#[derive(Debug, thiserror::Error)]
#[error("drop folder {path} unusable: {source}")]
pub struct DropFolderError {
    pub path: String,
    pub source: std::io::Error,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stamp {
    len: u64,
    modified: Option<SystemTime>,
}

/// A polled drop folder. [`DropFolder::poll`] is synchronous (blocking file I/O);
/// [`watch_drop_folder`] runs it on a tokio interval.
#[derive(Debug)]
pub struct DropFolder {
    inbox: PathBuf,
    processed: PathBuf,
    rejected: PathBuf,
    dbc: GaugeDbc,
    /// Stamp of every candidate at the previous poll.
    seen: HashMap<PathBuf, Stamp>,
    /// Files that could not be moved away, with their stamp then.
    stuck: HashMap<PathBuf, Stamp>,
}

impl DropFolder {
    /// Uses `inbox` (which must exist) and creates `processed/` and `rejected/` in it.
    pub fn open(inbox: &Path, dbc: GaugeDbc) -> Result<Self, DropFolderError> {
        let err = |path: &Path| {
            let path = path.display().to_string();
            move |source| DropFolderError { path, source }
        };
        if !std::fs::metadata(inbox).map_err(err(inbox))?.is_dir() {
            return Err(err(inbox)(std::io::Error::new(
                std::io::ErrorKind::NotADirectory,
                "not a directory",
            )));
        }
        let processed = inbox.join(PROCESSED_DIR);
        let rejected = inbox.join(REJECTED_DIR);
        std::fs::create_dir_all(&processed).map_err(err(&processed))?;
        std::fs::create_dir_all(&rejected).map_err(err(&rejected))?;
        Ok(Self {
            inbox: inbox.to_owned(),
            processed,
            rejected,
            dbc,
            seen: HashMap::new(),
            stuck: HashMap::new(),
        })
    }

    pub fn inbox(&self) -> &Path {
        &self.inbox
    }

    /// One poll: takes every file whose size and mtime did not change since the previous
    /// poll, in name order.
    pub fn poll(&mut self) -> Vec<DropEvent> {
        let mut events = Vec::new();
        let entries = match std::fs::read_dir(&self.inbox) {
            Ok(entries) => entries,
            Err(e) => {
                events.push(DropEvent::Failed {
                    path: self.inbox.clone(),
                    error: format!("cannot list drop folder: {e}"),
                });
                return events;
            }
        };
        let mut now: Vec<(PathBuf, Stamp)> = entries
            .filter_map(Result::ok)
            .filter(|entry| !in_progress(&entry.file_name().to_string_lossy()))
            .filter_map(|entry| {
                let meta = entry.metadata().ok()?;
                meta.is_file().then(|| {
                    let stamp = Stamp {
                        len: meta.len(),
                        modified: meta.modified().ok(),
                    };
                    (entry.path(), stamp)
                })
            })
            .collect();
        now.sort_by(|a, b| a.0.cmp(&b.0));
        let previous = std::mem::take(&mut self.seen);
        self.stuck
            .retain(|path, _| now.iter().any(|(p, _)| p == path));
        for (path, stamp) in now {
            if self.stuck.get(&path) == Some(&stamp) {
                continue;
            }
            if previous.get(&path) == Some(&stamp) {
                if let Some(event) = self.take(&path, stamp) {
                    events.push(event);
                }
            } else {
                self.seen.insert(path, stamp);
            }
        }
        events
    }

    fn take(&mut self, path: &Path, stamp: Stamp) -> Option<DropEvent> {
        let name = path.file_name()?.to_string_lossy().into_owned();
        let (target_dir, outcome) = match read_measurement_file(path, &self.dbc) {
            Ok(m) => (self.processed.clone(), Ok(m)),
            Err(e) => (self.rejected.clone(), Err(e.to_string())),
        };
        let moved_to = free_name(&target_dir, &name);
        if let Err(e) = std::fs::rename(path, &moved_to) {
            self.stuck.insert(path.to_owned(), stamp);
            return Some(DropEvent::Failed {
                path: path.to_owned(),
                error: format!("cannot move to {}: {e}", moved_to.display()),
            });
        }
        Some(match outcome {
            Ok(mut measurement) => {
                measurement.origin = moved_to.display().to_string();
                DropEvent::Accepted {
                    measurement,
                    moved_to,
                }
            }
            Err(reason) => {
                let reason_file = reason_path(&moved_to);
                if let Err(e) = std::fs::write(&reason_file, format!("{reason}\n")) {
                    return Some(DropEvent::Failed {
                        path: reason_file,
                        error: format!("cannot write the reason ({reason}): {e}"),
                    });
                }
                DropEvent::Rejected {
                    file: path.to_owned(),
                    moved_to,
                    reason,
                }
            }
        })
    }
}

/// Names of files still being written (see the module rules).
fn in_progress(name: &str) -> bool {
    let lower = name.to_ascii_lowercase();
    name.starts_with(['.', '~'])
        || [".tmp", ".part", ".partial"]
            .iter()
            .any(|ext| lower.ends_with(ext))
}

fn reason_path(moved_to: &Path) -> PathBuf {
    let mut name = moved_to.file_name().unwrap_or_default().to_os_string();
    name.push(".reason.txt");
    moved_to.with_file_name(name)
}

/// `dir/name`, or `dir/stem-N.ext` with the smallest N ≥ 1 such that neither it nor its
/// reason file exists.
fn free_name(dir: &Path, name: &str) -> PathBuf {
    let taken = |p: &Path| p.exists() || reason_path(p).exists();
    let first = dir.join(name);
    if !taken(&first) {
        return first;
    }
    let (stem, ext) = match name.rsplit_once('.') {
        Some((stem, ext)) if !stem.is_empty() => (stem, format!(".{ext}")),
        _ => (name, String::new()),
    };
    (1u64..)
        .map(|n| dir.join(format!("{stem}-{n}{ext}")))
        .find(|p| !taken(p))
        .expect("some suffix is free")
}

/// Polls `folder` every `every` and sends each event; returns when the receiver is gone.
/// File I/O runs on tokio's blocking pool so a slow network share does not stall the
/// runtime.
pub async fn watch_drop_folder(
    mut folder: DropFolder,
    every: Duration,
    events: mpsc::Sender<DropEvent>,
) -> Result<(), tokio::task::JoinError> {
    let mut ticks = tokio::time::interval(every);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        ticks.tick().await;
        let (back, polled) = tokio::task::spawn_blocking(move || {
            let polled = folder.poll();
            (folder, polled)
        })
        .await?;
        folder = back;
        for event in polled {
            if events.send(event).await.is_err() {
                return Ok(());
            }
        }
        if events.is_closed() {
            return Ok(());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_progress_names() {
        for name in [
            ".M3_P1_L1.csv",
            "~lock",
            "a.csv.tmp",
            "a.CSV.PART",
            "x.partial",
        ] {
            assert!(in_progress(name), "{name}");
        }
        for name in ["M3_P1_L1.csv", "a.log", "tmp.csv", "notes.txt"] {
            assert!(!in_progress(name), "{name}");
        }
    }

    #[test]
    fn free_names_get_a_suffix_before_the_extension() {
        let dir = tempfile::tempdir().expect("tempdir");
        let d = dir.path();
        assert_eq!(free_name(d, "a.csv"), d.join("a.csv"));
        std::fs::write(d.join("a.csv"), "").expect("write");
        assert_eq!(free_name(d, "a.csv"), d.join("a-1.csv"));
        // A lone reason file also blocks its name.
        std::fs::write(d.join("a-1.csv.reason.txt"), "").expect("write");
        assert_eq!(free_name(d, "a.csv"), d.join("a-2.csv"));
        std::fs::write(d.join("noext"), "").expect("write");
        assert_eq!(free_name(d, "noext"), d.join("noext-1"));
        assert_eq!(reason_path(&d.join("a.csv")), d.join("a.csv.reason.txt"));
    }
}
