//! Space kept back for the journal: a file of [`RESERVE_BYTES`] written beside it. When the
//! disk fills, the journal deletes it and writes into the space it frees, so the measurements
//! of the parts ground meanwhile are kept (about a hundred at 360 points) while the machine
//! stops learning and raises an alarm. Once space is free again the reserve is written anew.

use std::io::Write;
use std::path::PathBuf;

/// Size of the reserve: about 110 parts of measurement records at 360 points.
pub const RESERVE_BYTES: u64 = 8 * 1024 * 1024;
pub(super) const RESERVE_FILE: &str = "journal.reserve";

#[derive(Debug)]
pub(super) struct DiskReserve {
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
