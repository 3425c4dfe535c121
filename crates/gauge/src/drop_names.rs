//! Names in the drop folder: which names are still being written, where a settled file goes
//! (a free name, its reason file), and what kind of entry something that is not a regular
//! file is. Names are handled as `OsStr`, so a file whose name is not UTF-8 keeps its bytes.

use std::ffi::{OsStr, OsString};
use std::fs::FileType;
use std::path::{Path, PathBuf};

/// Names of files still being written: starting with `.` or `~`, or ending in `.tmp`,
/// `.part` or `.partial` (any case). They are never read.
pub fn in_progress(name: &OsStr) -> bool {
    let name = name.to_string_lossy();
    let lower = name.to_ascii_lowercase();
    name.starts_with(['.', '~'])
        || [".tmp", ".part", ".partial"]
            .iter()
            .any(|ext| lower.ends_with(ext))
}

/// `<moved_to>.reason.txt`.
pub fn reason_path(moved_to: &Path) -> PathBuf {
    let mut name = moved_to.file_name().unwrap_or_default().to_os_string();
    name.push(".reason.txt");
    moved_to.with_file_name(name)
}

/// `dir/name`, or `dir/stem-N.ext` with the smallest N ≥ 1 such that neither it nor its
/// reason file exists (a symbolic link counts as existing even when dangling).
pub fn free_name(dir: &Path, name: &OsStr) -> PathBuf {
    let taken = |p: &Path| p.symlink_metadata().is_ok() || reason_path(p).exists();
    let first = dir.join(name);
    if !taken(&first) {
        return first;
    }
    let as_path = Path::new(name);
    let (stem, ext) = match (as_path.file_stem(), as_path.extension()) {
        (Some(stem), Some(ext)) => (stem, Some(ext)),
        _ => (name, None),
    };
    (1u64..)
        .map(|n| {
            let mut candidate = OsString::from(stem);
            candidate.push(format!("-{n}"));
            if let Some(ext) = ext {
                candidate.push(".");
                candidate.push(ext);
            }
            dir.join(candidate)
        })
        .find(|p| !taken(p))
        .expect("some suffix is free")
}

/// What an entry that is not a regular file is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntryKind {
    Directory,
    SymbolicLink,
    Fifo,
    Socket,
    Device,
    Other,
}

impl EntryKind {
    /// `None` for a regular file. Never follows a symbolic link.
    pub fn of(file_type: FileType) -> Option<Self> {
        if file_type.is_symlink() {
            return Some(Self::SymbolicLink);
        }
        if file_type.is_file() {
            return None;
        }
        if file_type.is_dir() {
            return Some(Self::Directory);
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileTypeExt;
            if file_type.is_fifo() {
                return Some(Self::Fifo);
            }
            if file_type.is_socket() {
                return Some(Self::Socket);
            }
            if file_type.is_block_device() || file_type.is_char_device() {
                return Some(Self::Device);
            }
        }
        Some(Self::Other)
    }
}

impl std::fmt::Display for EntryKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Directory => "a directory",
            Self::SymbolicLink => "a symbolic link",
            Self::Fifo => "a named pipe (fifo)",
            Self::Socket => "a socket",
            Self::Device => "a device",
            Self::Other => "not a regular file",
        })
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
            assert!(in_progress(OsStr::new(name)), "{name}");
        }
        for name in ["M3_P1_L1.csv", "a.log", "tmp.csv", "notes.txt"] {
            assert!(!in_progress(OsStr::new(name)), "{name}");
        }
    }

    #[test]
    fn free_names_get_a_suffix_before_the_extension() {
        let dir = tempfile::tempdir().expect("tempdir");
        let d = dir.path();
        let free = |name: &str| free_name(d, OsStr::new(name));
        assert_eq!(free("a.csv"), d.join("a.csv"));
        std::fs::write(d.join("a.csv"), "").expect("write");
        assert_eq!(free("a.csv"), d.join("a-1.csv"));
        // A lone reason file also blocks its name.
        std::fs::write(d.join("a-1.csv.reason.txt"), "").expect("write");
        assert_eq!(free("a.csv"), d.join("a-2.csv"));
        std::fs::write(d.join("noext"), "").expect("write");
        assert_eq!(free("noext"), d.join("noext-1"));
        std::fs::write(d.join("x.dressing.toml"), "").expect("write");
        assert_eq!(free("x.dressing.toml"), d.join("x.dressing-1.toml"));
        assert_eq!(reason_path(&d.join("a.csv")), d.join("a.csv.reason.txt"));
    }

    /// A name that is not UTF-8 keeps its bytes through the suffix.
    #[cfg(unix)]
    #[test]
    fn free_names_keep_non_utf8_bytes() {
        use std::os::unix::ffi::OsStrExt;
        let dir = tempfile::tempdir().expect("tempdir");
        let d = dir.path();
        let name = OsStr::from_bytes(b"M3_\xff.csv");
        std::fs::write(d.join(name), "").expect("write");
        let got = free_name(d, name);
        assert_eq!(
            got.file_name().expect("name").as_encoded_bytes(),
            b"M3_\xff-1.csv"
        );
    }
}
