//! The drop folder: a directory where the control or gauge PC writes measurement files,
//! polled (no inotify, so network shares work). A complete measurement file is handed out
//! and stays in the folder, claimed, until the caller settles it into `processed/` or
//! `rejected/` (with `<name>.reason.txt` beside it). Nothing is deleted.
//!
//! Rules:
//! - Names starting with `.` or `~`, or ending in `.tmp`, `.part` or `.partial`, are files
//!   still being written and are never opened: a writer writes under such a name and renames
//!   into place when done.
//! - Anything else that is not a regular file (symbolic link, named pipe, directory, socket,
//!   device) is moved unopened and unfollowed to `rejected/` with a reason, except the
//!   folder's own `processed/` and `rejected/`.
//! - A file larger than [`DropOptions::max_file_bytes`] (from its metadata) is rejected
//!   without being read, once it has stopped changing.
//! - A measurement file is taken as soon as it is complete: it has the `# end` marker line,
//!   or it declares `revolutions=` in its metadata comment and holds every angle of each
//!   revolution. One without either is taken once its size and modification time have stayed
//!   the same for [`DropOptions::stable_ms`]. A file that declares more revolutions than it
//!   holds waits the same time and is then rejected, saying how many it holds.
//! - A file that does not parse waits the same time (it may be half-written), then is
//!   rejected with the parse error.
//! - `.csv` and `.log` files are read by [`open_measurement_file`]; `.dressing.toml` files
//!   are wheel-dressing reports ([`open_dressing_file`]), taken by the same rules and moved
//!   at once (no settling); anything else is rejected with that reason.
//! - A taken measurement is [`DropEvent::Accepted`] and claimed: it is not handed out again
//!   until [`DropFolder::settle`] moves it. The claim is held in memory only, so after a
//!   restart an unsettled file is read and handed out again.
//! - A name already present in `processed/` or `rejected/` gets a suffix `-1`, `-2`, …
//!   before the extension. A name that is not UTF-8 keeps its bytes.

use std::collections::{HashMap, HashSet};
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use tokio::sync::mpsc;

use camloop_core::measure::RawMeasurement;

use super::dbc::GaugeDbc;
pub use super::dressing::{
    DRESSING_SUFFIX, DressingError, DressingReport, open_dressing_file, read_dressing_file,
};
use super::drop_names::{EntryKind, free_name, in_progress, reason_path};
pub use super::drop_reasons::{DropFolderError, Rejection};
use super::file::{MeasurementFile, open_measurement_file, shown_path};

/// Subfolder for files taken as measurements.
pub(crate) const PROCESSED_DIR: &str = "processed";
/// Subfolder for files that are not measurements.
pub(crate) const REJECTED_DIR: &str = "rejected";

/// How the drop folder decides a file is finished and how large one may be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DropOptions {
    /// A file with neither an end marker nor a declared revolution count is taken once its
    /// size and modification time have not changed for this long, ms.
    pub stable_ms: u64,
    /// Larger files are rejected without being read, bytes.
    pub max_file_bytes: u64,
}

impl Default for DropOptions {
    fn default() -> Self {
        Self {
            stable_ms: 10_000,
            max_file_bytes: 16 * 1024 * 1024,
        }
    }
}

/// Where a handed-out measurement file goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Settle {
    /// Checked and used: to `processed/`.
    Processed,
    /// Failed the checks: to `rejected/`, with the reason in `<name>.reason.txt`.
    Rejected { reason: String },
}

/// What happened to one file (or the folder) at a poll.
#[derive(Debug)]
pub enum DropEvent {
    /// A complete measurement, left in the inbox at `path` and claimed until
    /// [`DropFolder::settle`] is called for it. Its origin is `path` as shown.
    Accepted {
        measurement: RawMeasurement,
        path: PathBuf,
    },
    /// A wheel-dressing report, parsed and moved to `processed/`.
    Dressing {
        report: DressingReport,
        moved_to: PathBuf,
    },
    /// Not a measurement (or not a file); moved with a reason file beside it.
    Rejected {
        file: PathBuf,
        moved_to: PathBuf,
        reason: Rejection,
    },
    /// Settled by [`watch_drop_folder`] on request.
    Settled { path: PathBuf, moved_to: PathBuf },
    /// The folder could not be listed or a file could not be moved; the file stays and is
    /// retried only after it changes.
    Failed {
        path: PathBuf,
        error: DropFolderError,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stamp {
    len: u64,
    modified: Option<SystemTime>,
}

/// A file seen and not yet taken.
#[derive(Debug, Clone, Copy)]
struct Watch {
    stamp: Stamp,
    /// When this stamp was first seen.
    since: Instant,
    /// The stamp at which the file was last read and found unfinished.
    read_at: Option<Stamp>,
}

/// What reading a candidate gave.
enum Reading {
    Measurement(Box<MeasurementFile>),
    Dressing(DressingReport, bool),
    Unusable(Rejection),
}

/// A polled drop folder. [`DropFolder::poll`] is synchronous (blocking file I/O);
/// [`watch_drop_folder`] runs it on a tokio interval.
#[derive(Debug)]
pub struct DropFolder {
    inbox: PathBuf,
    processed: PathBuf,
    rejected: PathBuf,
    dbc: GaugeDbc,
    options: DropOptions,
    watches: HashMap<PathBuf, Watch>,
    /// Handed out as accepted, not yet settled.
    claimed: HashSet<PathBuf>,
    /// Files that could not be moved away, with their stamp then.
    stuck: HashMap<PathBuf, Stamp>,
}

impl DropFolder {
    /// Uses `inbox` (which must exist) and creates `processed/` and `rejected/` in it.
    pub fn open(
        inbox: &Path,
        dbc: GaugeDbc,
        options: DropOptions,
    ) -> Result<Self, DropFolderError> {
        let err = |path: &Path| {
            let path = path.display().to_string();
            move |source| DropFolderError::Unusable { path, source }
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
            options,
            watches: HashMap::new(),
            claimed: HashSet::new(),
            stuck: HashMap::new(),
        })
    }

    pub fn inbox(&self) -> &Path {
        &self.inbox
    }

    pub fn options(&self) -> DropOptions {
        self.options
    }

    /// [`DropFolder::poll_at`] the current instant.
    pub fn poll(&mut self) -> Vec<DropEvent> {
        self.poll_at(Instant::now())
    }

    /// One poll at `now` (the stability rule measures from the instants of earlier polls, so
    /// tests pass instants instead of waiting). Events are in name order.
    pub fn poll_at(&mut self, now: Instant) -> Vec<DropEvent> {
        let entries = match std::fs::read_dir(&self.inbox) {
            Ok(entries) => entries,
            Err(source) => {
                return vec![DropEvent::Failed {
                    path: self.inbox.clone(),
                    error: DropFolderError::List {
                        path: self.inbox.display().to_string(),
                        source,
                    },
                }];
            }
        };
        let mut listed: Vec<(PathBuf, std::fs::FileType)> = entries
            .filter_map(Result::ok)
            .filter(|entry| {
                let name = entry.file_name();
                !in_progress(&name) && name != PROCESSED_DIR && name != REJECTED_DIR
            })
            .filter_map(|entry| Some((entry.path(), entry.file_type().ok()?)))
            .collect();
        listed.sort_by(|a, b| a.0.cmp(&b.0));
        let present: HashSet<&PathBuf> = listed.iter().map(|(p, _)| p).collect();
        self.watches.retain(|p, _| present.contains(p));
        self.stuck.retain(|p, _| present.contains(p));
        self.claimed.retain(|p| present.contains(p));
        let mut events = Vec::new();
        for (path, file_type) in listed {
            if self.claimed.contains(&path) {
                continue;
            }
            let Ok(meta) = std::fs::symlink_metadata(&path) else {
                continue; // gone since the listing
            };
            let stamp = Stamp {
                len: meta.len(),
                modified: meta.modified().ok(),
            };
            if self.stuck.get(&path) == Some(&stamp) {
                continue;
            }
            let event = match EntryKind::of(file_type) {
                Some(kind) => {
                    let reason = Rejection::NotAFile {
                        path: shown_path(&path),
                        kind,
                    };
                    Some(self.reject(&path, stamp, reason))
                }
                None => self.consider(&path, stamp, now),
            };
            events.extend(event);
        }
        events
    }

    /// A regular file: taken if finished, else watched.
    fn consider(&mut self, path: &Path, stamp: Stamp, now: Instant) -> Option<DropEvent> {
        let stable_for = Duration::from_millis(self.options.stable_ms);
        let watch = self.watches.entry(path.to_owned()).or_insert(Watch {
            stamp,
            since: now,
            read_at: None,
        });
        if watch.stamp != stamp {
            *watch = Watch {
                stamp,
                since: now,
                read_at: None,
            };
        }
        let stable = now.saturating_duration_since(watch.since) >= stable_for;
        let read_already = watch.read_at == Some(stamp);
        watch.read_at = Some(stamp);
        if stamp.len > self.options.max_file_bytes {
            let reason = Rejection::TooLarge {
                path: shown_path(path),
                bytes: stamp.len,
                limit: self.options.max_file_bytes,
            };
            return stable.then(|| self.reject(path, stamp, reason));
        }
        if read_already && !stable {
            return None; // read at this stamp and unfinished: nothing new to learn
        }
        match self.read(path) {
            Reading::Measurement(file) => self.decide(path, stamp, *file, stable),
            Reading::Dressing(report, end_marker) => {
                (end_marker || stable).then(|| self.take_dressing(path, stamp, report))
            }
            Reading::Unusable(reason) => stable.then(|| self.reject(path, stamp, reason)),
        }
    }

    fn read(&self, path: &Path) -> Reading {
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        if name.to_ascii_lowercase().ends_with(DRESSING_SUFFIX) {
            return match open_dressing_file(path) {
                Ok(d) => Reading::Dressing(d.report, d.end_marker),
                Err(e) => Reading::Unusable(Rejection::Dressing(e)),
            };
        }
        match open_measurement_file(path, &self.dbc, self.options.max_file_bytes) {
            Ok(file) => Reading::Measurement(Box::new(file)),
            Err(e) => Reading::Unusable(Rejection::Measurement(e)),
        }
    }

    /// A parsed measurement: handed out when complete, rejected when it declares more than
    /// it holds and cannot grow any more, else left to wait.
    fn decide(
        &mut self,
        path: &Path,
        stamp: Stamp,
        file: MeasurementFile,
        stable: bool,
    ) -> Option<DropEvent> {
        if let Some(c) = file.completeness {
            if let Some(declared) = c.declared_revolutions
                && !c.declared_count_met()
            {
                let reason = Rejection::Incomplete {
                    path: shown_path(path),
                    declared,
                    points_per_rev: file.measurement.header.points_per_rev,
                    found: c.revolutions_found,
                    readings_found: c.readings_found,
                    readings_expected: c.readings_expected,
                    end_marker: c.end_marker,
                    stable_ms: self.options.stable_ms,
                };
                return (c.end_marker || stable).then(|| self.reject(path, stamp, reason));
            }
            if !(c.is_complete() || stable) {
                return None;
            }
        } else if !stable {
            return None;
        }
        self.watches.remove(path);
        self.claimed.insert(path.to_owned());
        Some(DropEvent::Accepted {
            measurement: file.measurement,
            path: path.to_owned(),
        })
    }

    fn take_dressing(&mut self, path: &Path, stamp: Stamp, report: DressingReport) -> DropEvent {
        let processed = self.processed.clone();
        match self.move_into(path, &processed) {
            Ok(moved_to) => DropEvent::Dressing { report, moved_to },
            Err(error) => self.stuck_at(path, stamp, error),
        }
    }

    fn reject(&mut self, path: &Path, stamp: Stamp, reason: Rejection) -> DropEvent {
        let rejected = self.rejected.clone();
        let moved_to = match self.move_into(path, &rejected) {
            Ok(moved_to) => moved_to,
            Err(error) => return self.stuck_at(path, stamp, error),
        };
        if let Err(error) = write_reason(&moved_to, &reason.to_string()) {
            return DropEvent::Failed {
                path: moved_to,
                error,
            };
        }
        DropEvent::Rejected {
            file: path.to_owned(),
            moved_to,
            reason,
        }
    }

    fn stuck_at(&mut self, path: &Path, stamp: Stamp, error: DropFolderError) -> DropEvent {
        self.stuck.insert(path.to_owned(), stamp);
        DropEvent::Failed {
            path: path.to_owned(),
            error,
        }
    }

    /// Moves `path` (never following a link) to a free name in `dir`; forgets its watch.
    fn move_into(&mut self, path: &Path, dir: &Path) -> Result<PathBuf, DropFolderError> {
        let name: &OsStr = path.file_name().unwrap_or_default();
        let to = free_name(dir, name);
        std::fs::rename(path, &to).map_err(|source| DropFolderError::Move {
            from: shown_path(path),
            to: shown_path(&to),
            source,
        })?;
        self.watches.remove(path);
        Ok(to)
    }

    /// Moves a file handed out as [`DropEvent::Accepted`] to `processed/`, or to `rejected/`
    /// with the reason beside it, and returns where it went. A file that cannot be moved
    /// stays claimed, so the call can be repeated.
    pub fn settle(&mut self, path: &Path, outcome: Settle) -> Result<PathBuf, DropFolderError> {
        if !self.claimed.contains(path) {
            return Err(DropFolderError::NotClaimed {
                path: shown_path(path),
            });
        }
        let dir = match outcome {
            Settle::Processed => self.processed.clone(),
            Settle::Rejected { .. } => self.rejected.clone(),
        };
        let moved_to = self.move_into(path, &dir)?;
        self.claimed.remove(path);
        if let Settle::Rejected { reason } = outcome {
            write_reason(&moved_to, &reason)?;
        }
        Ok(moved_to)
    }
}

fn write_reason(moved_to: &Path, reason: &str) -> Result<(), DropFolderError> {
    let reason_file = reason_path(moved_to);
    std::fs::write(&reason_file, format!("{reason}\n")).map_err(|source| {
        DropFolderError::ReasonFile {
            path: shown_path(&reason_file),
            reason: reason.to_owned(),
            source,
        }
    })
}

/// Polls `folder` every `every` and sends each event, and settles each `(path, outcome)`
/// that arrives on `settle`, reporting it as [`DropEvent::Settled`] or
/// [`DropEvent::Failed`]; returns when the event receiver is gone. File I/O runs on tokio's
/// blocking pool so a slow network share does not stall the runtime.
pub async fn watch_drop_folder(
    mut folder: DropFolder,
    every: Duration,
    events: mpsc::Sender<DropEvent>,
    mut settle: mpsc::Receiver<(PathBuf, Settle)>,
) -> Result<(), tokio::task::JoinError> {
    let mut ticks = tokio::time::interval(every);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        let request = tokio::select! {
            _ = ticks.tick() => None,
            Some(request) = settle.recv() => Some(request),
        };
        let (back, out) = tokio::task::spawn_blocking(move || {
            let out = match request {
                None => folder.poll(),
                Some((path, outcome)) => vec![match folder.settle(&path, outcome) {
                    Ok(moved_to) => DropEvent::Settled { path, moved_to },
                    Err(error) => DropEvent::Failed { path, error },
                }],
            };
            (folder, out)
        })
        .await?;
        folder = back;
        for event in out {
            if events.send(event).await.is_err() {
                return Ok(());
            }
        }
        if events.is_closed() {
            return Ok(());
        }
    }
}
