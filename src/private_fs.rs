//! Folders and files only the service's account may read: `var/` and everything camloop
//! makes in it are created 0700 (folders) and 0600 (files), whatever the umask. The service
//! sets its own umask to 077 at start ([`owner_only_umask`]), so the folders and files its
//! libraries make (SQLite's journal files, the share's version folders, the machines'
//! journals) are its owner's only too, not only those made here.

use std::path::Path;

/// Creates `dir` and any missing parents, each new one 0700 (on Unix). Folders that exist
/// already are left as they are.
pub fn create_dir_all(dir: &Path) -> std::io::Result<()> {
    let mut builder = std::fs::DirBuilder::new();
    builder.recursive(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::DirBuilderExt;
        builder.mode(0o700);
    }
    builder.create(dir)
}

/// Narrows the folder or file at `path` to its owner (0700 or 0600; on Unix).
pub fn restrict(path: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let meta = std::fs::metadata(path)?;
        let mode = if meta.is_dir() { 0o700 } else { 0o600 };
        if meta.permissions().mode() & 0o777 != mode {
            std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))?;
        }
    }
    Ok(())
}

/// Sets this process's umask to 077: every folder and file it makes from now on is its
/// owner's only (0700, 0600), whichever library makes it. For the service only: the
/// command line's outputs (programs, charts) keep the user's umask.
pub fn owner_only_umask() {
    #[cfg(unix)]
    {
        use nix::sys::stat::{Mode, umask};
        umask(Mode::from_bits_truncate(0o077));
    }
}

/// Narrows `dir` and the folders and files directly in it to their owner (see
/// [`restrict`]): a var folder made by an older version, whose `machines/` and `share/`
/// were 0755, is narrowed at start. Deeper entries are not walked (a plant's share holds
/// thousands of versions); with `dir` itself 0700 nobody else can reach them.
pub fn restrict_with_children(dir: &Path) -> std::io::Result<()> {
    restrict(dir)?;
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if !std::fs::symlink_metadata(&path)?.file_type().is_symlink() {
            restrict(&path)?;
        }
    }
    Ok(())
}
