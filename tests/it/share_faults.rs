//! Share faults: a missing share, a share path that is a file, an unwritable share, a full
//! share, a read-back mismatch; the retry loop on tokio's paused clock.
//!
//! Real file system except where marked FAULT INJECTION: a full disk cannot be made in a
//! temporary folder without privileges, so the "full" tests swap in a [`ShareFs`] that sends
//! the N-th write to `/dev/full` (the kernel's own ENOSPC), and the read-back test swaps in
//! one that flips a byte.

use crate::share_support;

use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use camloop::share::{PushError, RealFs, ShareError, ShareFs, StateError, VersionStatus};
use share_support::{dirs, names, next_request, open, open_with};

#[test]
fn a_missing_share_keeps_the_version_waiting_until_it_is_back() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    std::fs::remove_dir(&d.share).unwrap();
    let request = next_request(&share, 1);
    let err = share.push_once(request.clone()).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "version v1 is waiting: share {} is missing: No such file or directory (os error 2)",
            d.share.display()
        )
    );
    assert!(matches!(
        err,
        PushError::Share {
            version,
            error: ShareError::Missing { .. }
        } if version.get() == 1
    ));
    // camloop never creates the share folder (it is a mount point).
    assert!(!d.share.exists());
    let v1 = share.history().get(ver(1)).unwrap();
    assert!(
        matches!(&v1.status, VersionStatus::Waiting { reason: Some(r) } if r.contains("is missing"))
    );
    assert!(!v1.reached_share);
    // A second failure with the same reason adds no manifest line.
    let lines = |d: &share_support::Dirs| {
        std::fs::read_to_string(d.state.join(camloop::share::MANIFEST_FILE))
            .unwrap()
            .lines()
            .count()
    };
    assert_eq!(lines(&d), 2);
    assert!(share.deliver().is_err());
    assert_eq!(lines(&d), 2);

    std::fs::create_dir(&d.share).unwrap();
    let pushed = share.deliver().unwrap().unwrap();
    assert_eq!(pushed.version.get(), 1);
    assert_eq!(
        std::fs::read_to_string(d.share.join("CAM_T1.SPF")).unwrap(),
        request.files[0].text
    );
}

#[test]
fn a_share_path_that_is_a_file_is_not_a_folder() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    std::fs::remove_dir(&d.share).unwrap();
    std::fs::write(&d.share, "a file where the mount should be").unwrap();
    let err = share.push_once(next_request(&share, 1)).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "version v1 is waiting: share {} is not a folder: Not a directory (os error 20)",
            d.share.display()
        )
    );
    std::fs::remove_file(&d.share).unwrap();
    std::fs::create_dir(&d.share).unwrap();
    assert_eq!(share.deliver().unwrap().unwrap().version.get(), 1);
}

/// Undoes [`make_unwritable`] when dropped, so the temporary folder can be removed.
struct Unwritable {
    dir: PathBuf,
    how: &'static str,
}

impl Drop for Unwritable {
    fn drop(&mut self) {
        if self.how == "chattr +i" {
            let _ = Command::new("chattr").arg("-i").arg(&self.dir).status();
        }
        let _ = std::fs::set_permissions(
            &self.dir,
            std::os::unix::fs::PermissionsExt::from_mode(0o755),
        );
    }
}

fn can_create_in(dir: &Path) -> bool {
    let probe = dir.join("probe");
    let created = std::fs::write(&probe, "x").is_ok();
    let _ = std::fs::remove_file(&probe);
    created
}

/// Make `dir` unwritable for this process for real: mode 0555 stops an ordinary user but
/// not root, so as root the folder is made immutable with `chattr +i` (which stops root too).
/// Panics, naming why, if neither works here.
fn make_unwritable(dir: &Path) -> Unwritable {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o555)).unwrap();
    let mut guard = Unwritable {
        dir: dir.to_path_buf(),
        how: "chmod 0555",
    };
    if can_create_in(dir) {
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o755)).unwrap();
        let status = Command::new("chattr").arg("+i").arg(dir).status();
        guard.how = "chattr +i";
        assert!(
            matches!(status, Ok(s) if s.success()),
            "running as root and `chattr +i` failed ({status:?}): cannot make a folder unwritable here"
        );
    }
    assert!(
        !can_create_in(dir),
        "{} did not make the folder unwritable",
        guard.how
    );
    guard
}

#[test]
fn an_unwritable_share_keeps_the_old_program_and_the_new_one_waits() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    let first = next_request(&share, 1);
    share.push_once(first.clone()).unwrap();
    let guard = make_unwritable(&d.share);
    let err = share.push_once(next_request(&share, 2)).unwrap_err();
    let message = err.to_string();
    let expected_os = match guard.how {
        "chattr +i" => "Operation not permitted (os error 1)",
        _ => "Permission denied (os error 13)",
    };
    assert_eq!(
        message,
        format!(
            "version v2 is waiting: share {} is read-only or not writable: {expected_os}",
            d.share.display()
        ),
        "made unwritable with {}",
        guard.how
    );
    assert_eq!(
        std::fs::read_to_string(d.share.join("CAM_T1.SPF")).unwrap(),
        first.files[0].text
    );
    assert_eq!(names(&d.share), ["CAM_T1.SPF"]);
    drop(guard);
    let pushed = share.deliver().unwrap().unwrap();
    assert_eq!((pushed.version.get(), pushed.table_number), (2, 2));
}

/// FAULT INJECTION: the real file system, except that write number `fail_at` (1-based) of a
/// temporary goes to `/dev/full`, so the error is the kernel's genuine ENOSPC.
struct FullAt {
    fail_at: usize,
    writes: Arc<AtomicUsize>,
}

impl ShareFs for FullAt {
    fn write_temp(&self, dir: &Path, bytes: &[u8]) -> io::Result<PathBuf> {
        if self.writes.fetch_add(1, Ordering::SeqCst) + 1 == self.fail_at {
            let mut full = std::fs::OpenOptions::new().write(true).open("/dev/full")?;
            full.write_all(bytes)?;
            full.sync_all()?;
            unreachable!("/dev/full accepted {} bytes", bytes.len());
        }
        RealFs.write_temp(dir, bytes)
    }
    fn rename(&self, from: &Path, to: &Path) -> io::Result<()> {
        RealFs.rename(from, to)
    }
    fn sync_dir(&self, dir: &Path) -> io::Result<()> {
        RealFs.sync_dir(dir)
    }
    fn read(&self, path: &Path) -> io::Result<Vec<u8>> {
        RealFs.read(path)
    }
    fn remove_file(&self, path: &Path) -> io::Result<()> {
        RealFs.remove_file(path)
    }
    fn list_dir(&self, dir: &Path) -> io::Result<Vec<std::ffi::OsString>> {
        RealFs.list_dir(dir)
    }
}

#[test]
fn a_full_share_fails_before_any_rename_and_leaves_no_temporary() {
    // FAULT INJECTION (see FullAt): write 1 is version 1; version 2 has two files and its
    // second write (write 3) hits ENOSPC after the first temporary was written.
    let d = dirs();
    let writes = Arc::new(AtomicUsize::new(0));
    let fs = FullAt {
        fail_at: 3,
        writes: writes.clone(),
    };
    let (mut share, _) = open_with(&d, 5, Box::new(fs));
    let first = next_request(&share, 1);
    share.push_once(first.clone()).unwrap();
    let mut second = next_request(&share, 2);
    second.files.push(camloop::share::ProgramFile {
        name: "CAMLOOP_GRIND.MPF".into(),
        text: "%_N_CAMLOOP_GRIND_MPF\nCAM_T2\nM30\n".into(),
    });
    let err = share.push_once(second.clone()).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "version v2 is waiting: share {} is full: No space left on device (os error 28)",
            d.share.display()
        )
    );
    assert_eq!(writes.load(Ordering::SeqCst), 3);
    // The first temporary was removed; the share is as before; nothing reached the share,
    // so the table to use is still 2.
    assert_eq!(names(&d.share), ["CAM_T1.SPF"]);
    assert!(!share.history().get(ver(2)).unwrap().reached_share);
    assert_eq!(share.next_table_number(), 2);
    // Space is back (write 4 on): the waiting version goes.
    let pushed = share.deliver().unwrap().unwrap();
    assert_eq!(pushed.version.get(), 2);
    assert_eq!(
        names(&d.share),
        ["CAMLOOP_GRIND.MPF", "CAM_T1.SPF", "CAM_T2.SPF"]
    );
}

/// FAULT INJECTION: the real file system, but reading back returns one byte changed.
struct FlipOnRead;

impl ShareFs for FlipOnRead {
    fn write_temp(&self, dir: &Path, bytes: &[u8]) -> io::Result<PathBuf> {
        RealFs.write_temp(dir, bytes)
    }
    fn rename(&self, from: &Path, to: &Path) -> io::Result<()> {
        RealFs.rename(from, to)
    }
    fn sync_dir(&self, dir: &Path) -> io::Result<()> {
        RealFs.sync_dir(dir)
    }
    fn read(&self, path: &Path) -> io::Result<Vec<u8>> {
        let mut bytes = RealFs.read(path)?;
        bytes[0] ^= 1;
        Ok(bytes)
    }
    fn remove_file(&self, path: &Path) -> io::Result<()> {
        RealFs.remove_file(path)
    }
    fn list_dir(&self, dir: &Path) -> io::Result<Vec<std::ffi::OsString>> {
        RealFs.list_dir(dir)
    }
}

#[test]
fn a_read_back_mismatch_keeps_the_version_waiting_and_its_table_counts_as_in_use() {
    let d = dirs();
    let (mut share, _) = open_with(&d, 5, Box::new(FlipOnRead));
    let err = share.push_once(next_request(&share, 1)).unwrap_err();
    let PushError::Share {
        version,
        error:
            ShareError::VerifyFailed {
                path,
                expected,
                found,
            },
    } = err
    else {
        panic!("{err:?}")
    };
    assert_eq!(version.get(), 1);
    assert_eq!(path, d.share.join("CAM_T1.SPF"));
    assert_ne!(expected, found);
    let v1 = share.history().get(ver(1)).unwrap();
    assert!(v1.reached_share);
    assert!(
        matches!(&v1.status, VersionStatus::Waiting { reason: Some(r) } if r.contains("read back with sha256"))
    );
    // The file may be on the control: the next version must use the other table.
    assert_eq!(share.next_table_number(), 2);
}

#[test]
fn a_state_folder_that_cannot_be_created_is_an_error_naming_it() {
    let d = dirs();
    std::fs::write(&d.state, "not a folder").unwrap();
    let err = camloop::share::Share::open(
        share_support::config(&d, 5),
        Box::new(RealFs),
        share_support::clock(),
    )
    .unwrap_err();
    assert!(matches!(err, StateError::Io { .. }));
    let versions = d.state.join("versions");
    assert_eq!(
        err.to_string(),
        format!(
            "cannot create state folder {}: Not a directory (os error 20)",
            versions.display()
        )
    );
}

fn ver(n: u64) -> camloop::core::ids::TableVersion {
    camloop::core::ids::TableVersion::new(n).unwrap()
}
