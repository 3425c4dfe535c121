//! Errors of the share adapter: share faults (retried), state-folder faults (camloop's own
//! disk), and refusals (a push that must never go to the control).
//!
//! Each message is complete on its own (it names the path and the OS error) and no error
//! returns a `source()`, so a chain printed with `{:#}` never repeats a cause.

use crate::core::ids::TableVersion;
use std::io;
use std::path::{Path, PathBuf};

use crate::cluster::Epoch;
use crate::core::digest::Sha256;
use crate::core::program::TablePairError;

/// Why a push to the controller share failed. The version stays waiting and is retried.
#[derive(Debug, thiserror::Error)]
pub enum ShareError {
    #[error("share {} is missing: {os_error}", share.display())]
    Missing { share: PathBuf, os_error: io::Error },
    #[error("share {} is not a folder: {os_error}", share.display())]
    NotAFolder { share: PathBuf, os_error: io::Error },
    #[error("share {} is read-only or not writable: {os_error}", share.display())]
    NotWritable { share: PathBuf, os_error: io::Error },
    #[error("share {} is full: {os_error}", share.display())]
    Full { share: PathBuf, os_error: io::Error },
    #[error("cannot {op} {}: {os_error}", path.display())]
    Io {
        op: &'static str,
        path: PathBuf,
        os_error: io::Error,
    },
    #[error("{} read back with sha256 {found}, expected {expected}", path.display())]
    VerifyFailed {
        path: PathBuf,
        expected: Sha256,
        found: Sha256,
    },
}

impl ShareError {
    /// Name the share condition behind an I/O error of `op` on `path` inside `share`.
    pub(crate) fn classify(
        share: &Path,
        op: &'static str,
        path: &Path,
        os_error: io::Error,
    ) -> Self {
        use io::ErrorKind as K;
        let share = share.to_path_buf();
        match os_error.kind() {
            K::NotFound => Self::Missing { share, os_error },
            K::NotADirectory => Self::NotAFolder { share, os_error },
            K::ReadOnlyFilesystem | K::PermissionDenied => Self::NotWritable { share, os_error },
            K::StorageFull | K::QuotaExceeded => Self::Full { share, os_error },
            _ => Self::Io {
                op,
                path: path.to_path_buf(),
                os_error,
            },
        }
    }
}

/// A fault in camloop's own state folder (versions and manifest), or unusable settings.
#[derive(Debug, thiserror::Error)]
pub enum StateError {
    #[error("cannot {op} {}: {os_error}", path.display())]
    Io {
        op: &'static str,
        path: PathBuf,
        os_error: io::Error,
    },
    #[error("manifest {}:{line}: {reason}", path.display())]
    CorruptManifest {
        path: PathBuf,
        line: usize,
        reason: String,
    },
    #[error("kept text {} does not match its manifest sha256 {expected}", path.display())]
    TextMismatch { path: PathBuf, expected: Sha256 },
    #[error("version v{0} is not in the history")]
    UnknownVersion(TableVersion),
    #[error("version v{0} has no kept text (refused, or pruned beyond the kept versions)")]
    NoText(TableVersion),
    #[error("invalid share settings: {0}")]
    TablePair(#[from] TablePairError),
    #[error("invalid share settings: keep_versions must be at least 1")]
    KeepNone,
    /// Another instance owns the machine now (its lease epoch is newer than this one's).
    #[error(
        "{} is fenced at epoch {current}: this instance's lease (epoch {mine}) is no longer the owner's",
        dir.display()
    )]
    Fenced {
        dir: PathBuf,
        mine: Epoch,
        current: Epoch,
    },
    /// The fence stayed locked while a claim waited: the owner is mid-write, or paused while
    /// writing (a stopped process keeps its lock). The claim is tried again later.
    #[error("{} stayed locked for {waited_ms} ms: its owner is writing (or paused mid-write)", dir.display())]
    FenceBusy { dir: PathBuf, waited_ms: u64 },
}

impl StateError {
    pub(crate) fn io(op: &'static str, path: &Path) -> impl FnOnce(io::Error) -> Self {
        move |os_error| Self::Io {
            op,
            path: path.to_path_buf(),
            os_error,
        }
    }
}

/// Why a single push attempt ([`super::Share::push_once`]) did not deliver.
#[derive(Debug, thiserror::Error)]
pub enum PushError {
    /// The request was recorded as refused and will never be pushed.
    #[error("version v{version} refused: {reason}")]
    Refused {
        version: TableVersion,
        reason: String,
    },
    /// The version is recorded and waiting; the share failed.
    #[error("version v{version} is waiting: {error}")]
    Share {
        version: TableVersion,
        error: ShareError,
    },
    #[error(transparent)]
    State(#[from] StateError),
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Linux errno values: the conditions that cannot be produced in a temporary folder.
    #[test]
    fn os_errors_name_the_share_condition() {
        let share = Path::new("/mnt/nc");
        let file = Path::new("/mnt/nc/CAM_T1.SPF");
        let cases = [
            (
                2,
                "share /mnt/nc is missing: No such file or directory (os error 2)",
            ),
            (
                20,
                "share /mnt/nc is not a folder: Not a directory (os error 20)",
            ),
            (
                30,
                "share /mnt/nc is read-only or not writable: Read-only file system (os error 30)",
            ),
            (
                13,
                "share /mnt/nc is read-only or not writable: Permission denied (os error 13)",
            ),
            (
                28,
                "share /mnt/nc is full: No space left on device (os error 28)",
            ),
            (
                122,
                "share /mnt/nc is full: Disk quota exceeded (os error 122)",
            ),
            (
                5,
                "cannot rename to /mnt/nc/CAM_T1.SPF: Input/output error (os error 5)",
            ),
        ];
        for (errno, message) in cases {
            let error = ShareError::classify(
                share,
                "rename to",
                file,
                io::Error::from_raw_os_error(errno),
            );
            assert_eq!(error.to_string(), message, "errno {errno}");
        }
    }
}
