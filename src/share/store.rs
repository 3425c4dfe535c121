//! [`Share`]: the synchronous push — record a version in the state folder, deliver it to the
//! controller share atomically, verify it, keep the history.

use crate::core::ids::TableVersion;
use std::fs;
use std::path::PathBuf;

use super::error::{PushError, ShareError, StateError};
use super::fs::{ShareFs, bad_file_name, is_temp_name};
use super::manifest::{self, FileRecord, History, Record, VersionRecord, VersionStatus};
use super::request::{OpenReport, ProgramFile, PushRequest, Pushed, Submitted};
use super::state::{clean_versions_dir, cut_manifest, read_kept, store_text, version_dir};
use crate::core::digest::Sha256;
use crate::core::program::{check_table_pair, next_table_number};
use crate::failpoint::crash_point;

/// Manifest file name inside the state folder.
pub const MANIFEST_FILE: &str = "manifest.jsonl";
/// Folder of kept version texts inside the state folder.
pub const VERSIONS_DIR: &str = "versions";

/// Where programs go and where their history is kept.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShareConfig {
    /// The controller's file share (a mounted folder). Holds only the current program files.
    pub share_dir: PathBuf,
    /// camloop's own folder for kept versions and the manifest; never on the share.
    pub state_dir: PathBuf,
    /// The two curve-table numbers that alternate between versions (different, both ≥ 1).
    pub table_pair: (u32, u32),
    /// How many of the newest accepted versions keep their text for rollback, ≥ 1. Older
    /// texts are removed; their manifest records stay.
    pub keep_versions: usize,
}

/// The only clock the adapter reads (for status records).
pub type Clock = Box<dyn FnMut() -> jiff::Timestamp + Send>;

/// The program share with its version history. One `Share` per state folder: two processes
/// on the same state folder are not supported.
pub struct Share {
    config: ShareConfig,
    fs: Box<dyn ShareFs>,
    clock: Clock,
    history: History,
    /// Complete lines in the manifest.
    manifest_lines: usize,
    share_cleaned: bool,
    /// With several instances: this owner's epoch, checked before every write.
    fence: Option<super::Fence>,
}

impl std::fmt::Debug for Share {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Share")
            .field("config", &self.config)
            .field("versions", &self.history.versions().len())
            .finish_non_exhaustive()
    }
}

impl Share {
    /// Open (creating it if needed) the state folder: cut a torn manifest line, remove
    /// temporaries and orphan version folders, and remove camloop temporaries from the share
    /// (names starting with [`super::TEMP_PREFIX`] only) if the share is reachable.
    pub fn open(
        config: ShareConfig,
        fs: Box<dyn ShareFs>,
        clock: Clock,
    ) -> Result<(Self, OpenReport), StateError> {
        check_table_pair(config.table_pair)?;
        if config.keep_versions == 0 {
            return Err(StateError::KeepNone);
        }
        let versions_dir = config.state_dir.join(VERSIONS_DIR);
        fs::create_dir_all(&versions_dir)
            .map_err(StateError::io("create state folder", &versions_dir))?;
        let manifest_path = config.state_dir.join(MANIFEST_FILE);
        let mut loaded = manifest::load_settled(&manifest_path)?;
        loaded.history.forget_settled();
        let mut report = OpenReport {
            torn_manifest_bytes: loaded.torn_bytes,
            ..OpenReport::default()
        };
        if loaded.torn_bytes > 0 {
            cut_manifest(&manifest_path, loaded.good_len)?;
        }
        report.removed_state_entries = clean_versions_dir(&versions_dir, &loaded.history)?;
        let mut share = Self {
            config,
            fs,
            clock,
            history: loaded.history,
            manifest_lines: loaded.lines,
            share_cleaned: false,
            fence: None,
        };
        match share.clean_share() {
            Ok(removed) => report.removed_share_temporaries = removed,
            Err(e) => report.share_unavailable = Some(e),
        }
        share.compact_if_long();
        Ok((share, report))
    }

    /// Fences every later write with `fence` (see [`super::Fence`]): once another owner
    /// claims a newer epoch, submits and deliveries are refused with
    /// [`StateError::Fenced`].
    pub fn set_fence(&mut self, fence: super::Fence) {
        self.fence = Some(fence);
    }

    fn hold_fence(&self) -> Result<Option<super::Held>, StateError> {
        self.fence.as_ref().map(super::Fence::hold).transpose()
    }

    pub fn config(&self) -> &ShareConfig {
        &self.config
    }

    /// Every version so far, with its status.
    pub fn history(&self) -> &History {
        &self.history
    }

    /// The table number the next version must define: the other one of the pair than the
    /// table of the newest version that may be on the share (confirmed or not), so the
    /// table the control may be using is never redefined.
    pub fn next_table_number(&self) -> u32 {
        let current = self.history.on_share().map_or(0, |v| v.record.table_number);
        next_table_number(current, self.config.table_pair)
    }

    /// Record a request as a new version: its text goes to the state folder first, then its
    /// manifest line. An accepted version supersedes any older waiting one (which stays in
    /// the history). A request that must not reach the control is recorded as refused.
    pub fn submit(&mut self, request: PushRequest) -> Result<Submitted, StateError> {
        let _held = self.hold_fence()?;
        let version = self.history.next_version();
        let refused = self.refusal(&request);
        if refused.is_none() {
            store_text(
                &self.config.state_dir.join(VERSIONS_DIR),
                version,
                &request.files,
            )?;
        }
        let record = VersionRecord {
            version,
            created_at: request.created_at,
            table_number: request.table_number,
            files: request
                .files
                .iter()
                .map(|f| FileRecord {
                    name: f.name.clone(),
                    sha256: Sha256::of(f.text.as_bytes()),
                    bytes: f.text.len() as u64,
                })
                .collect(),
            reason: request.reason,
            measurement_id: request.measurement_id,
            learning: request.learning,
            rollback_of: request.rollback_of,
            refused: refused.clone(),
            epoch: self.fence.as_ref().map(super::Fence::epoch),
        };
        self.append(Record::Version(record), Flush::Now)?;
        Ok(match refused {
            Some(reason) => Submitted::Refused { version, reason },
            None => Submitted::Accepted { version },
        })
    }

    /// Deliver the waiting version, if any: write every file to a temporary on the share and
    /// flush it, record "delivering", rename each into place, flush the folder, read every
    /// file back and compare its SHA-256, record "pushed". On a share fault the version keeps
    /// waiting (the reason is recorded when it changes) and the error names the condition.
    pub fn deliver(&mut self) -> Result<Option<Pushed>, PushError> {
        if self.history.waiting().is_none() {
            return Ok(None);
        }
        // Held through the renames: a new owner's claim waits until this push is done.
        let _held = self.hold_fence()?;
        let Some(waiting) = self.history.waiting() else {
            return Ok(None);
        };
        let record = waiting.record.clone();
        let version = record.version;
        let files = self.kept_files(version)?;
        let result = if self.share_cleaned {
            Ok(Vec::new())
        } else {
            self.clean_share()
        };
        let result = result.and_then(|_| self.write_temporaries(&files));
        let result = match result {
            Ok(temps) => self.rename_and_verify(&record, &files, temps),
            Err(e) => Err(PushError::Share { version, error: e }),
        };
        match result {
            Ok(paths) => {
                let at = (self.clock)();
                // Not flushed on its own: losing this line (power cut) only means one more
                // delivery of the same version at the next start; the next flush takes it.
                self.append(Record::Pushed { version, at }, Flush::WithNext)?;
                let (pruned, prune_error) = self.prune();
                Ok(Some(Pushed {
                    version,
                    table_number: record.table_number,
                    paths,
                    pruned,
                    prune_error,
                }))
            }
            Err(PushError::Share { version, error }) => {
                self.record_waiting(version, &error)?;
                Err(PushError::Share { version, error })
            }
            Err(other) => Err(other),
        }
    }

    /// [`Self::submit`] then [`Self::deliver`]: one attempt, no retry.
    pub fn push_once(&mut self, request: PushRequest) -> Result<Pushed, PushError> {
        match self.submit(request)? {
            Submitted::Refused { version, reason } => Err(PushError::Refused { version, reason }),
            Submitted::Accepted { .. } => Ok(self
                .deliver()?
                .expect("the version just accepted is the newest, so it is waiting")),
        }
    }

    /// A request that re-pushes the kept text of `version` as a new version, with reason
    /// `"rollback to v<version>"` and the original measurement and learning parameters.
    ///
    /// The text defines the table number it was made with. If that is not
    /// [`Self::next_table_number`], submitting the request refuses it (it would redefine the
    /// table the control may be using): re-render the program for the next table number and
    /// replace `files` and `table_number` before submitting.
    pub fn rollback_request(
        &self,
        version: TableVersion,
        created_at: jiff::Timestamp,
    ) -> Result<PushRequest, StateError> {
        let kept = self.held(version)?;
        let record = kept.record.clone();
        Ok(PushRequest {
            files: self.kept_files(version)?,
            table_number: record.table_number,
            reason: format!("rollback to v{version}"),
            measurement_id: record.measurement_id,
            learning: record.learning,
            rollback_of: Some(version),
            created_at,
        })
    }

    /// The kept text of a version, each file checked against its manifest SHA-256.
    pub fn kept_files(&self, version: TableVersion) -> Result<Vec<ProgramFile>, StateError> {
        let state = self.held(version)?;
        if !state.text_kept {
            return Err(StateError::NoText(version));
        }
        read_kept(&self.version_dir(version), &state.record.files)
    }

    /// A version the history holds; a forgotten one (settled, so without kept text) is
    /// [`StateError::NoText`].
    fn held(&self, version: TableVersion) -> Result<&manifest::VersionState, StateError> {
        match self.history.get(version) {
            Some(v) => Ok(v),
            None if self.history.is_forgotten(version) => Err(StateError::NoText(version)),
            None => Err(StateError::UnknownVersion(version)),
        }
    }

    /// Folder of a version's kept text: `<state>/versions/v000042`.
    pub(crate) fn version_dir(&self, version: TableVersion) -> PathBuf {
        version_dir(&self.config.state_dir.join(VERSIONS_DIR), version)
    }

    fn refusal(&self, request: &PushRequest) -> Option<String> {
        if request.files.is_empty() {
            return Some("no program files".to_owned());
        }
        for (i, file) in request.files.iter().enumerate() {
            if let Some(why) = bad_file_name(&file.name) {
                return Some(format!("file name {:?} {why}", file.name));
            }
            if request.files[..i].iter().any(|f| f.name == file.name) {
                return Some(format!("file name {:?} appears twice", file.name));
            }
        }
        if let Some(of) = request.rollback_of
            && self.history.get(of).is_none()
        {
            return Some(if self.history.is_forgotten(of) {
                format!("rollback to v{of}, whose text is no longer kept")
            } else {
                format!("rollback to v{of}, which does not exist")
            });
        }
        let next = self.next_table_number();
        if request.table_number != next {
            let why = match self.history.on_share() {
                Some(v) if v.record.table_number == request.table_number => format!(
                    "table {} may be in use on the control (defined by v{})",
                    request.table_number, v.record.version
                ),
                _ => format!(
                    "table {} is not the next of the pair {:?}",
                    request.table_number, self.config.table_pair
                ),
            };
            return Some(format!("{why}; the next table is {next}"));
        }
        None
    }

    fn write_temporaries(&self, files: &[ProgramFile]) -> Result<Vec<PathBuf>, ShareError> {
        let share = &self.config.share_dir;
        let mut temps = Vec::with_capacity(files.len());
        for file in files {
            match self.fs.write_temp(share, file.text.as_bytes()) {
                Ok(path) => temps.push(path),
                Err(e) => {
                    self.discard(&temps);
                    return Err(ShareError::classify(
                        share,
                        "write a temporary in",
                        share,
                        e,
                    ));
                }
            }
        }
        Ok(temps)
    }

    fn rename_and_verify(
        &mut self,
        record: &VersionRecord,
        files: &[ProgramFile],
        temps: Vec<PathBuf>,
    ) -> Result<Vec<PathBuf>, PushError> {
        let version = record.version;
        let share = self.config.share_dir.clone();
        let at = (self.clock)();
        // Flushed before the first rename: the table numbering relies on it.
        if let Err(e) = self.append(Record::Delivering { version, at }, Flush::Now) {
            self.discard(&temps);
            return Err(e.into());
        }
        let fail = |error| PushError::Share { version, error };
        let mut paths = Vec::with_capacity(files.len());
        for (i, (tmp, file)) in temps.iter().zip(files).enumerate() {
            let target = share.join(&file.name);
            if let Err(e) = self.fs.rename(tmp, &target) {
                self.discard(&temps[i..]);
                return Err(fail(ShareError::classify(&share, "rename to", &target, e)));
            }
            paths.push(target);
        }
        self.fs
            .sync_dir(&share)
            .map_err(|e| fail(ShareError::classify(&share, "flush", &share, e)))?;
        crash_point("share_renamed");
        for (path, file) in paths.iter().zip(&record.files) {
            let bytes = self
                .fs
                .read(path)
                .map_err(|e| fail(ShareError::classify(&share, "read back", path, e)))?;
            let found = Sha256::of(&bytes);
            if found != file.sha256 {
                return Err(fail(ShareError::VerifyFailed {
                    path: path.clone(),
                    expected: file.sha256,
                    found,
                }));
            }
        }
        Ok(paths)
    }

    /// Remove temporaries of a failed attempt. A leftover is removed at the next start.
    fn discard(&self, temps: &[PathBuf]) {
        for tmp in temps {
            let _ = self.fs.remove_file(tmp);
        }
    }

    fn record_waiting(
        &mut self,
        version: TableVersion,
        error: &ShareError,
    ) -> Result<(), StateError> {
        let reason = error.to_string();
        let unchanged = self.history.get(version).is_some_and(
            |v| matches!(&v.status, VersionStatus::Waiting { reason: Some(r) } if *r == reason),
        );
        if unchanged {
            return Ok(());
        }
        let at = (self.clock)();
        // Informational: the version record itself keeps the version waiting.
        self.append(
            Record::Waiting {
                version,
                at,
                reason,
            },
            Flush::WithNext,
        )
    }

    /// Remove the kept text of accepted versions older than the newest `keep_versions`
    /// (never the waiting one, which is always the newest accepted).
    fn prune(&mut self) -> (Vec<TableVersion>, Option<StateError>) {
        let kept: Vec<TableVersion> = self
            .history
            .versions()
            .iter()
            .filter(|v| v.text_kept)
            .map(|v| v.record.version)
            .collect();
        let excess = kept.len().saturating_sub(self.config.keep_versions);
        let mut pruned = Vec::new();
        for &version in &kept[..excess] {
            let at = (self.clock)();
            // The record goes first: a kill after it leaves an orphan folder that the next
            // start removes, never a record pointing at a missing text.
            if let Err(e) = self.append(Record::Pruned { version, at }, Flush::Now) {
                return (pruned, Some(e));
            }
            let dir = self.version_dir(version);
            if let Err(e) = fs::remove_dir_all(&dir) {
                return (pruned, Some(StateError::io("remove", &dir)(e)));
            }
            pruned.push(version);
        }
        (pruned, None)
    }

    /// Remove camloop temporaries (and nothing else) from the share.
    fn clean_share(&mut self) -> Result<Vec<PathBuf>, ShareError> {
        let share = &self.config.share_dir;
        let names = self
            .fs
            .list_dir(share)
            .map_err(|e| ShareError::classify(share, "list", share, e))?;
        let mut removed = Vec::new();
        for name in names.into_iter().filter(|n| is_temp_name(n)) {
            let path = share.join(name);
            self.fs
                .remove_file(&path)
                .map_err(|e| ShareError::classify(share, "remove", &path, e))?;
            removed.push(path);
        }
        self.share_cleaned = true;
        Ok(removed)
    }

    fn append(&mut self, record: Record, flush: Flush) -> Result<(), StateError> {
        let path = self.config.state_dir.join(MANIFEST_FILE);
        super::fs::append_line(&path, &manifest::line(&record), flush == Flush::Now)
            .map_err(StateError::io("append to", &path))?;
        // Past the write a process death keeps the line (only a power cut could lose an
        // unflushed one), so the crash point goes here, before the history takes it.
        if let Some(step) = manifest_step(&record) {
            crash_point(step);
        }
        self.manifest_lines += 1;
        self.history
            .apply(record)
            .map_err(|e| StateError::CorruptManifest {
                line: self.manifest_lines,
                path,
                reason: e.0,
            })?;
        // Keeps memory bounded in a service that pushes for months; the manifest keeps all.
        self.history.forget_settled();
        self.compact_if_long();
        Ok(())
    }

    /// Compacts the manifest once it is long (see [`super::compact`]). A failure leaves the
    /// manifest whole and is retried with the next line, so it is only reported.
    fn compact_if_long(&mut self) {
        if self.manifest_lines < super::compact::COMPACT_AFTER_LINES {
            return;
        }
        let at = (self.clock)();
        let dir = &self.config.state_dir;
        match super::compact::compact(
            dir,
            MANIFEST_FILE,
            &dir.join(VERSIONS_DIR),
            &self.history,
            self.manifest_lines,
            at,
        ) {
            Ok(()) => self.manifest_lines = 1,
            Err(e) => tracing::warn!(error = %e, "manifest not compacted; retried later"),
        }
    }
}

/// The crash point after a manifest line of this kind (the lines of a part's push).
fn manifest_step(record: &Record) -> Option<&'static str> {
    match record {
        Record::Version(_) => Some("manifest:version"),
        Record::Delivering { .. } => Some("manifest:delivering"),
        Record::Pushed { .. } => Some("manifest:pushed"),
        Record::Waiting { .. } | Record::Pruned { .. } | Record::Checkpoint(_) => None,
    }
}

/// Whether a manifest line must be on the device before the next step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Flush {
    Now,
    /// With the next flushed line (`fdatasync` flushes all the file's data).
    WithNext,
}
