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
//! - `.csv` and `.log` files are read by [`read_measurement_file`]; `.dressing.toml` files
//!   are wheel-dressing reports ([`read_dressing_file`]); anything else is rejected with that
//!   reason.
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

/// Suffix of a wheel-dressing report (any case).
pub const DRESSING_SUFFIX: &str = ".dressing.toml";

/// Largest dressing report read, bytes (a report is one line).
const MAX_DRESSING_BYTES: u64 = 64 * 1024;

/// A wheel-dressing report, written by the control's dressing cycle (or whoever dresses)
/// into the drop folder, one line:
///
/// ```toml
/// wheel_radius_mm = 249.998
/// ```
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DressingReport {
    /// The wheel radius after dressing, as the control now believes it, mm.
    pub wheel_radius_mm: f64,
}

/// Reads a dressing report; errors name the file and, for syntax, the line.
pub fn read_dressing_file(path: &Path) -> Result<DressingReport, String> {
    let shown = path.display();
    let len = std::fs::metadata(path)
        .map_err(|e| format!("cannot read dressing report {shown}: {e}"))?
        .len();
    if len > MAX_DRESSING_BYTES {
        return Err(format!(
            "dressing report {shown} is larger than the {MAX_DRESSING_BYTES} bytes allowed"
        ));
    }
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read dressing report {shown}: {e}"))?;
    let report: DressingReport = toml::from_str(&text).map_err(|e| {
        let line = e
            .span()
            .map(|s| format!(" line {}", text[..s.start].matches('\n').count() + 1))
            .unwrap_or_default();
        format!(
            "dressing report {shown}{line}: {}",
            e.message().trim_end_matches('\n')
        )
    })?;
    crate::core::compensate::check_wheel_radius(report.wheel_radius_mm)
        .map_err(|e| format!("dressing report {shown}: {e}"))?;
    Ok(report)
}

/// What happened to one file (or the folder) at a poll.
#[derive(Debug, Clone, PartialEq)]
pub enum DropEvent {
    /// Parsed and moved; the measurement's origin is its new path.
    Accepted {
        measurement: RawMeasurement,
        moved_to: PathBuf,
    },
    /// A wheel-dressing report, parsed and moved to `processed/`.
    Dressing {
        report: DressingReport,
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
        let outcome = if name.to_ascii_lowercase().ends_with(DRESSING_SUFFIX) {
            read_dressing_file(path).map(Taken::Dressing)
        } else {
            read_measurement_file(path, &self.dbc)
                .map(|m| Taken::Measurement(Box::new(m)))
                .map_err(|e| e.to_string())
        };
        let target_dir = match outcome {
            Ok(_) => self.processed.clone(),
            Err(_) => self.rejected.clone(),
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
            Ok(Taken::Measurement(mut measurement)) => {
                measurement.origin = moved_to.display().to_string();
                DropEvent::Accepted {
                    measurement: *measurement,
                    moved_to,
                }
            }
            Ok(Taken::Dressing(report)) => DropEvent::Dressing { report, moved_to },
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

/// What a taken file turned out to be.
enum Taken {
    Measurement(Box<RawMeasurement>),
    Dressing(DressingReport),
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

    /// A dressing report goes to processed/ with its radius; a bad one to rejected/ with a
    /// reason naming the file and, for syntax, the line.
    #[test]
    fn dressing_reports_are_read_or_rejected_with_the_line() {
        let dir = tempfile::tempdir().expect("tempdir");
        let inbox = dir.path();
        let mut folder = DropFolder::open(inbox, GaugeDbc::builtin()).expect("open");
        std::fs::write(
            inbox.join("d1.dressing.toml"),
            "wheel_radius_mm = 249.998\n",
        )
        .expect("write");
        std::fs::write(
            inbox.join("d2.DRESSING.TOML"),
            "# after dressing\nwheel_radius_mm = 249,99\n",
        )
        .expect("write");
        std::fs::write(inbox.join("d3.dressing.toml"), "wheel_radius_mm = 0.25\n").expect("write");
        std::fs::write(inbox.join("d4.dressing.toml"), "radius = 249.9\n").expect("write");
        assert!(
            folder.poll().is_empty(),
            "files are taken at the second poll"
        );
        let events = folder.poll();
        assert_eq!(events.len(), 4, "{events:?}");
        match &events[0] {
            DropEvent::Dressing { report, moved_to } => {
                assert_eq!(report.wheel_radius_mm, 249.998);
                assert_eq!(moved_to, &inbox.join("processed/d1.dressing.toml"));
            }
            other => panic!("{other:?}"),
        }
        let reasons: Vec<&str> = events[1..]
            .iter()
            .map(|e| match e {
                DropEvent::Rejected { reason, .. } => reason.as_str(),
                other => panic!("{other:?}"),
            })
            .collect();
        assert!(
            reasons[0].contains("d2.DRESSING.TOML line 2"),
            "{}",
            reasons[0]
        );
        assert!(
            reasons[1].contains("0.25 mm is not a plausible"),
            "{}",
            reasons[1]
        );
        assert!(reasons[2].contains("radius"), "{}", reasons[2]);
        assert!(inbox.join("rejected/d3.dressing.toml.reason.txt").exists());
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
