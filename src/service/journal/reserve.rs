//! Space kept back for the journal: a file of [`RESERVE_BYTES`] written beside it. When the
//! disk fills, the journal deletes it and writes into the space it frees, so the measurements
//! of the parts ground meanwhile are kept (about a hundred at 360 points) while the machine
//! stops learning and raises an alarm. Once space is free again the reserve is written anew.
//!
//! A service shares one reserve among all its journals (see [`share_under`]): a plant of 500
//! machines of 8 lobes would otherwise hold 32 GiB back, and a disk that is full is full for
//! every machine at once. A journal opened outside such a root keeps a reserve of its own.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, Weak};

/// Size of the reserve: about 110 parts of measurement records at 360 points.
pub const RESERVE_BYTES: u64 = 8 * 1024 * 1024;
pub(super) const RESERVE_FILE: &str = "journal.reserve";

#[derive(Debug)]
pub struct DiskReserve {
    path: PathBuf,
    /// The reserve was given up and not written again yet.
    in_use: bool,
}

impl DiskReserve {
    pub(super) fn new(path: PathBuf) -> Self {
        Self {
            path,
            in_use: false,
        }
    }

    pub(super) fn in_use(&self) -> bool {
        self.in_use
    }

    /// Makes sure the reserve file holds its bytes (real blocks, not a sparse file, so the
    /// space is really taken). True when it does; false (and in use) when the disk cannot
    /// hold it.
    pub(super) fn ensure(&mut self) -> bool {
        let complete = std::fs::metadata(&self.path).is_ok_and(|m| m.len() == RESERVE_BYTES);
        if complete {
            self.in_use = false;
            return true;
        }
        let written = std::fs::File::create(&self.path).and_then(|f| {
            allocate(&f)?;
            f.sync_all()
        });
        if written.is_err() {
            let _ = std::fs::remove_file(&self.path);
        }
        self.in_use = written.is_err();
        !self.in_use
    }

    /// Gives the reserve's space up; true if there was a reserve to give.
    pub(super) fn release(&mut self) -> bool {
        let had = std::fs::metadata(&self.path).is_ok();
        self.in_use = true;
        had && std::fs::remove_file(&self.path).is_ok()
    }
}

/// Takes [`RESERVE_BYTES`] of real blocks for `f`: `fallocate` where the file system has it
/// (no data written, so a plant's thousand journals open in moments), else zeros written.
fn allocate(mut f: &std::fs::File) -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        use nix::fcntl::{FallocateFlags, fallocate};
        let len = i64::try_from(RESERVE_BYTES).expect("the reserve size fits an off_t");
        match fallocate(f, FallocateFlags::empty(), 0, len) {
            Ok(()) => return Ok(()),
            // Not supported here (some network file systems): write the zeros instead.
            Err(nix::errno::Errno::EOPNOTSUPP) => {}
            Err(e) => return Err(e.into()),
        }
    }
    let block = vec![0u8; 64 * 1024];
    for _ in 0..RESERVE_BYTES / block.len() as u64 {
        f.write_all(&block)?;
    }
    Ok(())
}

/// A reserve as the journals hold it: their own, or the one their service shares.
pub type SharedReserve = Arc<Mutex<DiskReserve>>;

/// The roots whose journals share a reserve, while their holder keeps it.
static ROOTS: Mutex<Vec<(PathBuf, Weak<Mutex<DiskReserve>>)>> = Mutex::new(Vec::new());

/// Makes every journal opened under `root` (a service's machines folder) share one reserve
/// in `root`, for as long as the returned handle is kept; written now.
pub fn share_under(root: &Path) -> SharedReserve {
    let _ = std::fs::create_dir_all(root);
    let mut reserve = DiskReserve::new(root.join(RESERVE_FILE));
    reserve.ensure();
    let shared = Arc::new(Mutex::new(reserve));
    let mut roots = ROOTS.lock().unwrap_or_else(|p| p.into_inner());
    roots.retain(|(_, w)| w.strong_count() > 0);
    roots.push((root.to_path_buf(), Arc::downgrade(&shared)));
    shared
}

/// The reserve for a journal in `dir`: its service's, else one of its own beside it.
pub(super) fn for_journal(dir: &Path) -> SharedReserve {
    let roots = ROOTS.lock().unwrap_or_else(|p| p.into_inner());
    let shared = roots
        .iter()
        .filter(|(root, _)| dir.starts_with(root))
        .find_map(|(_, w)| w.upgrade());
    drop(roots);
    shared.unwrap_or_else(|| {
        let mut own = DiskReserve::new(dir.join(RESERVE_FILE));
        own.ensure();
        Arc::new(Mutex::new(own))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The journals under a service's root share its one reserve (one file, in the root);
    /// a journal elsewhere keeps its own; once the holder lets go, the root shares no more.
    #[test]
    fn journals_under_a_root_share_one_reserve() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("machines");
        let shared = share_under(&root);
        let a = for_journal(&root.join("M1/IN1"));
        let b = for_journal(&root.join("M2/IN1"));
        assert!(Arc::ptr_eq(&a, &b) && Arc::ptr_eq(&a, &shared));
        assert_eq!(
            std::fs::metadata(root.join(RESERVE_FILE)).unwrap().len(),
            RESERVE_BYTES
        );
        assert!(!root.join("M1/IN1").join(RESERVE_FILE).exists());
        // A journal's folder exists before its reserve is taken (`Journal::open` makes it).
        let elsewhere = dir.path().join("other");
        std::fs::create_dir_all(&elsewhere).unwrap();
        let own = for_journal(&elsewhere);
        assert!(!Arc::ptr_eq(&own, &shared));
        assert!(elsewhere.join(RESERVE_FILE).exists());
        drop((shared, a, b));
        std::fs::create_dir_all(root.join("M3/IN1")).unwrap();
        let later = for_journal(&root.join("M3/IN1"));
        assert!(root.join("M3/IN1").join(RESERVE_FILE).exists());
        drop(later);
    }
}
