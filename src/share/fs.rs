//! The file-system operations a push makes on the controller share, behind a trait so that
//! faults the test machine cannot produce for real (a full disk) can be injected.

use std::ffi::OsString;
use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use crate::failpoint::crash_point;

/// Name prefix of every temporary camloop writes, on the share and in the state folder.
///
/// It starts with a dot (hidden on the control's file views, and not a valid SINUMERIK
/// program name: names start with a letter or `_`), and cleanup at start removes only names
/// with exactly this prefix.
pub const TEMP_PREFIX: &str = ".camloop-tmp-";

/// Random hex digits after [`TEMP_PREFIX`].
const TEMP_RANDOM_CHARS: usize = 16;

/// Attempts at a fresh temporary name before giving up (a clash is a 2⁻⁶⁴ event).
const TEMP_NAME_ATTEMPTS: usize = 8;

/// File-system operations on the share. Every method is one step of a push, so a fault can
/// be injected at any of them; [`RealFs`] is the production implementation.
pub trait ShareFs: Send {
    /// Create a new file named [`TEMP_PREFIX`] + random characters in `dir`, write `bytes`,
    /// flush it to the device (`fsync`) and return its path. On error no file is left
    /// behind as far as the file system allows.
    fn write_temp(&self, dir: &Path, bytes: &[u8]) -> io::Result<PathBuf>;
    /// Atomically replace `to` by `from` (same folder).
    fn rename(&self, from: &Path, to: &Path) -> io::Result<()>;
    /// Flush a folder's entries (the renames in it) to the device.
    fn sync_dir(&self, dir: &Path) -> io::Result<()>;
    /// Read a whole file.
    fn read(&self, path: &Path) -> io::Result<Vec<u8>>;
    /// Remove a file.
    fn remove_file(&self, path: &Path) -> io::Result<()>;
    /// The names in a folder.
    fn list_dir(&self, dir: &Path) -> io::Result<Vec<OsString>>;
}

/// Gives a program file on the share the read access the share folder gives: the service
/// runs with umask 077 (its var folder is its own), but a plant's share is read by the file
/// server's account, and the folder the plant made for it says who may read what is in it.
/// A folder of 0755 gets files of 0644, 0750 gets 0640, and the demo's share inside the var
/// folder (0700) gets 0600. Nobody but the owner ever gets write access.
fn readable_as(file: &File, dir: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let dir_mode = std::fs::metadata(dir)?.permissions().mode();
        let mode = 0o600 | (dir_mode & 0o044);
        file.set_permissions(std::fs::Permissions::from_mode(mode))?;
    }
    #[cfg(not(unix))]
    let _ = (file, dir);
    Ok(())
}

/// The real file system (`std::fs`), with `fsync` on files and folders.
#[derive(Debug, Clone, Copy, Default)]
pub struct RealFs;

impl ShareFs for RealFs {
    fn write_temp(&self, dir: &Path, bytes: &[u8]) -> io::Result<PathBuf> {
        let (mut file, path) = create_temp(dir, |p| File::create_new(p))?;
        // Written and flushed as two steps (not `write_synced`), so a crash point can land
        // between them.
        let written = readable_as(&file, dir).and_then(|()| file.write_all(bytes));
        let written = written.and_then(|()| {
            crash_point("share_temp_written");
            file.sync_all()
        });
        if let Err(e) = written {
            // Best effort: a leftover temporary is removed at the next start.
            let _ = std::fs::remove_file(&path);
            return Err(e);
        }
        crash_point("share_temp_synced");
        Ok(path)
    }

    fn rename(&self, from: &Path, to: &Path) -> io::Result<()> {
        std::fs::rename(from, to)
    }

    fn sync_dir(&self, dir: &Path) -> io::Result<()> {
        sync_dir(dir)
    }

    fn read(&self, path: &Path) -> io::Result<Vec<u8>> {
        std::fs::read(path)
    }

    fn remove_file(&self, path: &Path) -> io::Result<()> {
        std::fs::remove_file(path)
    }

    fn list_dir(&self, dir: &Path) -> io::Result<Vec<OsString>> {
        std::fs::read_dir(dir)?
            .map(|entry| entry.map(|e| e.file_name()))
            .collect()
    }
}

/// Create something (a file, a folder) under a fresh temporary name in `dir`, never
/// replacing an existing entry. The OS error comes back unchanged (no path added to it).
pub(crate) fn create_temp<T>(
    dir: &Path,
    create: impl Fn(&Path) -> io::Result<T>,
) -> io::Result<(T, PathBuf)> {
    let mut clash = None;
    for _ in 0..TEMP_NAME_ATTEMPTS {
        let path = dir.join(format!("{TEMP_PREFIX}{}", random_hex()));
        match create(&path) {
            Ok(made) => return Ok((made, path)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => clash = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(clash.unwrap_or_else(|| io::Error::from(io::ErrorKind::AlreadyExists)))
}

/// 16 random hex digits, from the standard library's randomly keyed hasher (seeded from the
/// OS per thread) over a per-process counter and the process id.
fn random_hex() -> String {
    use std::hash::{BuildHasher, Hasher};
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
    hasher.write_u64(COUNTER.fetch_add(1, Ordering::Relaxed));
    hasher.write_u32(std::process::id());
    format!("{:0width$x}", hasher.finish(), width = TEMP_RANDOM_CHARS)
}

/// Write all of `bytes` to `file` and flush data and metadata to the device.
pub(crate) fn write_synced(mut file: &File, bytes: &[u8]) -> io::Result<()> {
    file.write_all(bytes)?;
    file.sync_all()
}

/// Flush a folder's entries to the device.
///
/// Some network file systems refuse `fsync` on a folder (`EINVAL`); there the rename is as
/// durable as that file system makes it, and the refusal is not an error.
pub(crate) fn sync_dir(dir: &Path) -> io::Result<()> {
    match File::open(dir).and_then(|d| d.sync_all()) {
        Err(e) if e.kind() == io::ErrorKind::InvalidInput => Ok(()),
        other => other,
    }
}

/// Append one line (which must end in `\n`) in a single write; with `flush`, flush the
/// file's data to the device before returning.
pub(crate) fn append_line(path: &Path, line: &str, flush: bool) -> io::Result<()> {
    let file = OpenOptions::new().create(true).append(true).open(path)?;
    (&file).write_all(line.as_bytes())?;
    if flush { file.sync_data() } else { Ok(()) }
}

pub use crate::digest::{lower_hex, sha256_hex};

/// Whether a folder entry is one of camloop's temporaries.
pub(crate) fn is_temp_name(name: &std::ffi::OsStr) -> bool {
    name.to_str().is_some_and(|n| n.starts_with(TEMP_PREFIX))
}

/// Why a name cannot be a program file on the share, if it cannot.
pub(super) fn bad_file_name(name: &str) -> Option<&'static str> {
    if name.is_empty() {
        Some("is empty")
    } else if name.contains(['/', '\\', '\0']) {
        Some("is not a plain file name")
    } else if name.starts_with('.') {
        Some("starts with '.' (reserved for temporaries)")
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_names_must_be_plain_and_not_hidden() {
        assert_eq!(bad_file_name("CAM_T1.SPF"), None);
        assert!(bad_file_name("").is_some());
        assert!(bad_file_name("../CAM.SPF").is_some());
        assert!(bad_file_name("a\\b").is_some());
        assert!(bad_file_name(".camloop-tmp-x").is_some());
    }

    #[test]
    fn temp_names_are_recognised_by_exact_prefix() {
        assert!(is_temp_name(".camloop-tmp-abc".as_ref()));
        assert!(!is_temp_name(".camloop-abc".as_ref()));
        assert!(!is_temp_name("CAM_T1.SPF".as_ref()));
        assert!(!is_temp_name("x.camloop-tmp-".as_ref()));
    }

    #[test]
    fn write_temp_leaves_an_fsynced_file_with_the_prefix() {
        let dir = tempfile::tempdir().unwrap();
        let path = RealFs.write_temp(dir.path(), b"hello").unwrap();
        assert_eq!(path.parent(), Some(dir.path()));
        assert!(is_temp_name(path.file_name().unwrap()));
        assert_eq!(
            path.file_name().unwrap().len(),
            TEMP_PREFIX.len() + TEMP_RANDOM_CHARS
        );
        assert_eq!(std::fs::read(&path).unwrap(), b"hello");
        let again = RealFs.write_temp(dir.path(), b"hello").unwrap();
        assert_ne!(again, path);
    }

    /// A plant's share folder readable by its group and others (0755, 0750) gives its
    /// programs that read access, whatever the process's umask; the var folder's (0700)
    /// keeps them the owner's. Never writable by anyone else.
    #[test]
    #[cfg(unix)]
    fn program_files_are_as_readable_as_the_share_folder() {
        use std::os::unix::fs::PermissionsExt;
        for (dir_mode, file_mode) in [
            (0o755, 0o644),
            (0o750, 0o640),
            (0o700, 0o600),
            (0o777, 0o644),
        ] {
            let dir = tempfile::tempdir().unwrap();
            std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(dir_mode))
                .unwrap();
            let path = RealFs.write_temp(dir.path(), b"M17\n").unwrap();
            let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode, file_mode, "share folder {dir_mode:o}");
        }
    }

    #[test]
    fn write_temp_in_a_missing_folder_returns_the_plain_os_error() {
        let dir = tempfile::tempdir().unwrap();
        let err = RealFs
            .write_temp(&dir.path().join("gone"), b"x")
            .unwrap_err();
        assert_eq!(err.to_string(), "No such file or directory (os error 2)");
    }
}
