//! Fencing for several instances: the owner of a machine holds an epoch (from its lease in
//! PostgreSQL) and the machine's state folder holds the highest epoch any owner claimed.
//! Every write of the manifest and every delivery checks, under an exclusive lock, that its
//! epoch is still that one; a new owner raises it under the same lock. So a push from an
//! instance that lost its lease (paused, cut off from the database) is refused, and a push
//! already under way finishes before the new owner begins.
//!
//! Layout: `<machine state>/fence` (`epoch <n> owner <name>`, replaced by rename) and
//! `<machine state>/fence.lock` (the lock, never renamed: a lock belongs to its inode).

use super::error::StateError;
use std::fs::{File, TryLockError};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::cluster::Epoch;

const FENCE_FILE: &str = "fence";
const LOCK_FILE: &str = "fence.lock";

/// This owner's epoch for one machine's state folder.
#[derive(Debug, Clone)]
pub struct Fence {
    dir: PathBuf,
    epoch: Epoch,
}

/// The fence locked and checked; unlocked when dropped.
#[derive(Debug)]
pub struct Held {
    _lock: File,
}

impl Fence {
    /// Raises the fence of `dir` to `epoch` for `owner`, waiting at most `wait` for a write
    /// under way ([`StateError::FenceBusy`] after that: an owner paused mid-write keeps its
    /// lock, and a claim must never take the fence from under a write). Refused with
    /// [`StateError::Fenced`] when the fence already holds a higher epoch (an owner newer
    /// than this lease); an equal one is this owner's own, claimed again.
    pub fn claim(
        dir: &Path,
        epoch: Epoch,
        owner: &str,
        wait: Duration,
    ) -> Result<Fence, StateError> {
        std::fs::create_dir_all(dir).map_err(StateError::io("create", dir))?;
        let lock = lock_within(dir, wait)?;
        let current = read_epoch(dir)?;
        if current > epoch {
            return Err(StateError::Fenced {
                dir: dir.to_path_buf(),
                mine: epoch,
                current,
            });
        }
        let temp = dir.join(format!("{FENCE_FILE}.tmp"));
        let path = dir.join(FENCE_FILE);
        let write = || -> std::io::Result<()> {
            let mut f = File::create(&temp)?;
            f.write_all(format!("epoch {epoch} owner {owner}\n").as_bytes())?;
            f.sync_all()?;
            std::fs::rename(&temp, &path)?;
            File::open(dir)?.sync_all()
        };
        write().map_err(StateError::io("write", &path))?;
        drop(lock);
        Ok(Fence {
            dir: dir.to_path_buf(),
            epoch,
        })
    }

    pub fn epoch(&self) -> Epoch {
        self.epoch
    }

    /// Locks the fence and checks it still holds this epoch.
    pub fn hold(&self) -> Result<Held, StateError> {
        let lock = lock(&self.dir)?;
        let current = read_epoch(&self.dir)?;
        if current != self.epoch {
            return Err(StateError::Fenced {
                dir: self.dir.clone(),
                mine: self.epoch,
                current,
            });
        }
        Ok(Held { _lock: lock })
    }
}

/// The highest epoch claimed in `dir` (0: none yet).
pub fn read_epoch(dir: &Path) -> Result<Epoch, StateError> {
    let path = dir.join(FENCE_FILE);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Epoch(0)),
        Err(e) => return Err(StateError::io("read", &path)(e)),
    };
    text.split_whitespace()
        .nth(1)
        .and_then(|n| n.parse().ok())
        .map(Epoch)
        .ok_or_else(|| StateError::CorruptManifest {
            path,
            line: 1,
            reason: format!("not `epoch <n> owner <name>`: {:?}", text.trim()),
        })
}

fn lock_file(dir: &Path) -> Result<File, StateError> {
    let path = dir.join(LOCK_FILE);
    std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(StateError::io("open", &path))
}

/// The owner's lock: contended only by a claim, which holds it for one small write.
fn lock(dir: &Path) -> Result<File, StateError> {
    let file = lock_file(dir)?;
    file.lock()
        .map_err(StateError::io("lock", &dir.join(LOCK_FILE)))?;
    Ok(file)
}

/// A claimer's lock: given up after `wait`.
fn lock_within(dir: &Path, wait: Duration) -> Result<File, StateError> {
    let file = lock_file(dir)?;
    let started = Instant::now();
    loop {
        match file.try_lock() {
            Ok(()) => return Ok(file),
            Err(TryLockError::WouldBlock) if started.elapsed() < wait => {
                std::thread::sleep(Duration::from_millis(10));
            }
            Err(TryLockError::WouldBlock) => {
                return Err(StateError::FenceBusy {
                    dir: dir.to_path_buf(),
                    waited_ms: started.elapsed().as_millis() as u64,
                });
            }
            Err(TryLockError::Error(e)) => {
                return Err(StateError::io("lock", &dir.join(LOCK_FILE))(e));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Long enough for any write in these tests.
    const WAIT: Duration = Duration::from_secs(10);

    #[test]
    fn a_newer_claim_fences_the_older_owner_out() {
        let dir = tempfile::tempdir().unwrap();
        let old = Fence::claim(dir.path(), Epoch(3), "a", WAIT).unwrap();
        assert!(old.hold().is_ok());
        let new = Fence::claim(dir.path(), Epoch(4), "b", WAIT).unwrap();
        match old.hold() {
            Err(StateError::Fenced { mine, current, .. }) => {
                assert_eq!((mine, current), (Epoch(3), Epoch(4)))
            }
            other => panic!("the old owner still holds the fence: {other:?}"),
        }
        assert!(new.hold().is_ok());
        // An owner with an older lease cannot take the fence back.
        assert!(matches!(
            Fence::claim(dir.path(), Epoch(3), "a", WAIT),
            Err(StateError::Fenced {
                current: Epoch(4),
                ..
            })
        ));
        assert_eq!(read_epoch(dir.path()).unwrap(), Epoch(4));
    }

    #[test]
    fn a_claim_waits_for_a_push_under_way() {
        let dir = tempfile::tempdir().unwrap();
        let old = Fence::claim(dir.path(), Epoch(1), "a", WAIT).unwrap();
        let held = old.hold().unwrap();
        let path = dir.path().to_path_buf();
        let claimer =
            std::thread::spawn(move || Fence::claim(&path, Epoch(2), "b", WAIT).map(|f| f.epoch()));
        std::thread::sleep(std::time::Duration::from_millis(100));
        // Still the old owner's while it holds the lock.
        assert_eq!(read_epoch(dir.path()).unwrap(), Epoch(1));
        assert!(!claimer.is_finished());
        drop(held);
        assert_eq!(claimer.join().unwrap().unwrap(), Epoch(2));
        assert!(old.hold().is_err());
    }

    #[test]
    fn a_claim_gives_up_on_an_owner_paused_mid_write() {
        let dir = tempfile::tempdir().unwrap();
        let old = Fence::claim(dir.path(), Epoch(1), "a", WAIT).unwrap();
        let _held = old.hold().unwrap();
        let started = Instant::now();
        match Fence::claim(dir.path(), Epoch(2), "b", Duration::from_millis(200)) {
            Err(StateError::FenceBusy { waited_ms, .. }) => assert!(waited_ms >= 200),
            other => panic!("a claim took the fence from under a write: {other:?}"),
        }
        assert!(started.elapsed() >= Duration::from_millis(200));
        // Nothing changed: the owner mid-write still owns it.
        assert_eq!(read_epoch(dir.path()).unwrap(), Epoch(1));
    }
}
