//! The audit trail's seal: the key (`audit-key`) and the signed head (`audit-head`), two
//! files beside the first admin's password, outside the database, readable only by the
//! service's account (0600). Every writer of the trail (the service, `camloop user` and
//! `camloop token`) keys its rows with the key and leaves the head it reached; `camloop
//! audit verify` checks the rows with the key and that the trail still holds the head.
//!
//! What this proves, and what not: someone who can write the database but not read these
//! files can neither change, insert nor re-chain a keyed row, nor remove the newest rows,
//! without `verify` finding it. Someone who can read the key (the service's account, root)
//! can forge rows; keep a copy of `audit-head` elsewhere to hold them to an earlier state.

use crate::store::{AuditEntry, AuditHead, AuditKey, Store, StoreError};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use tracing::warn;

/// The key's file name in the seal's folder.
pub const KEY_FILE: &str = "audit-key";
/// The head's file name in the seal's folder.
pub const HEAD_FILE: &str = "audit-head";

/// Why the seal's files could not be used.
#[derive(Debug, thiserror::Error)]
pub enum SealError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Text {
        path: PathBuf,
        source: crate::store::AuditKeyError,
    },
    #[error("{path} can be read by other accounts (mode {mode:o}): make it 0600 (chmod 600)")]
    Readable { path: PathBuf, mode: u32 },
    #[error("the operating system's random source failed: {0}")]
    Random(String),
}

/// The key, and where the head is kept (nowhere for an ephemeral seal).
#[derive(Debug)]
pub struct AuditSeal {
    key: AuditKey,
    head: Option<PathBuf>,
    /// How many refused attempts the trail takes per client (a flood must not fill the disk).
    refusals: crate::auth::RefusalBudget,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> SealError + '_ {
    move |source| SealError::Io {
        path: path.to_path_buf(),
        source,
    }
}

impl AuditSeal {
    /// The seal in `dir`, its key made (random, 0600) when there is none yet. A key that
    /// other accounts can read is refused.
    pub fn open_or_create(dir: &Path) -> Result<Self, SealError> {
        let path = dir.join(KEY_FILE);
        if !path.exists() {
            let mut bytes = [0u8; 32];
            getrandom::fill(&mut bytes).map_err(|e| SealError::Random(e.to_string()))?;
            let key = AuditKey::from_bytes(bytes);
            write_private_new(&path, &format!("{}\n", key.to_hex())).map_err(io(&path))?;
        }
        Self::open(dir)?.ok_or_else(|| SealError::Io {
            path: path.clone(),
            source: std::io::Error::from(std::io::ErrorKind::NotFound),
        })
    }

    /// The seal in `dir`, or `None` when it has no key.
    pub fn open(dir: &Path) -> Result<Option<Self>, SealError> {
        let path = dir.join(KEY_FILE);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(io(&path)(e)),
        };
        refuse_readable_by_others(&path)?;
        let key = AuditKey::from_hex(&text).map_err(|source| SealError::Text {
            path: path.clone(),
            source,
        })?;
        Ok(Some(Self {
            key,
            head: Some(dir.join(HEAD_FILE)),
            refusals: Default::default(),
        }))
    }

    /// A seal whose key lives only in memory and that keeps no head: for a server started
    /// without a var folder (the benches, tests of the API alone).
    pub fn ephemeral() -> Self {
        let mut bytes = [0u8; 32];
        // A failing random source gives a fixed key: these trails are thrown away.
        let _ = getrandom::fill(&mut bytes);
        Self {
            key: AuditKey::from_bytes(bytes),
            head: None,
            refusals: Default::default(),
        }
    }

    pub fn key(&self) -> &AuditKey {
        &self.key
    }

    /// `entry`, a refusal, if the trail takes it within the budget for refusals of its
    /// client (see `crate::auth::RefusalBudget`), its reason saying how many of that
    /// client's refusals before it were not recorded; `None`: count it only.
    pub fn within_refusal_budget(&self, mut entry: AuditEntry) -> Option<AuditEntry> {
        match self.refusals.admit(&entry.client, entry.at) {
            crate::auth::Admit::Record { unrecorded_before } => {
                if unrecorded_before > 0 {
                    entry.reason.push_str(&format!(
                        "; {unrecorded_before} refusals of this client before this one were not recorded (over the audit's budget)"
                    ));
                }
                Some(entry)
            }
            crate::auth::Admit::Skip => None,
        }
    }

    /// The head kept in the seal's folder, if there is one. A head not signed by this key
    /// is an error: it was changed.
    pub fn head(&self) -> Result<Option<AuditHead>, SealError> {
        let Some(path) = &self.head else {
            return Ok(None);
        };
        match std::fs::read_to_string(path) {
            Ok(text) => AuditHead::parse_signed(&text, &self.key)
                .map(Some)
                .map_err(|source| SealError::Text {
                    path: path.clone(),
                    source,
                }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(io(path)(e)),
        }
    }

    /// Appends `entry` keyed, then keeps the head it reached (unless a later one is kept
    /// already: several writers share the folder). A head that cannot be written is
    /// logged: the row is stored and the head is only a checkpoint.
    pub async fn append(&self, store: &Store, entry: &AuditEntry) -> Result<i64, StoreError> {
        let head = store.append_audit(&self.key, entry).await?;
        if let Err(e) = self.keep_head(&head) {
            warn!(error = %e, "audit head not written");
        }
        Ok(head.last_id)
    }

    fn keep_head(&self, head: &AuditHead) -> Result<(), SealError> {
        let Some(path) = &self.head else {
            return Ok(());
        };
        if let Ok(Some(kept)) = self.head()
            && kept.last_id > head.last_id
        {
            return Ok(());
        }
        let tmp = path.with_extension("tmp");
        let _ = std::fs::remove_file(&tmp);
        write_private_new(&tmp, &head.signed_text(&self.key)).map_err(io(&tmp))?;
        std::fs::rename(&tmp, path).map_err(io(path))
    }
}

/// Writes `text` to a new file that only its owner can read and write (0600 from the
/// moment it exists), and syncs it.
fn write_private_new(path: &Path, text: &str) -> std::io::Result<()> {
    if let Some(dir) = path.parent()
        && !dir.as_os_str().is_empty()
    {
        crate::private_fs::create_dir_all(dir)?;
    }
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    let mut file = options.open(path)?;
    file.write_all(text.as_bytes())?;
    file.sync_all()
}

/// Refuses a secret file that accounts other than its owner can read or write.
pub(crate) fn refuse_readable_by_others(path: &Path) -> Result<(), SealError> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(path)
            .map_err(io(path))?
            .permissions()
            .mode()
            & 0o777;
        if mode & 0o077 != 0 {
            return Err(SealError::Readable {
                path: path.to_path_buf(),
                mode,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_key_is_made_once_owner_only_and_refused_when_others_can_read_it() {
        let dir = tempfile::tempdir().unwrap();
        let seal = AuditSeal::open_or_create(dir.path()).unwrap();
        let again = AuditSeal::open_or_create(dir.path()).unwrap();
        assert_eq!(seal.key(), again.key(), "made once, then read");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let path = dir.path().join(KEY_FILE);
            let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode, 0o600);
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
            let refused = AuditSeal::open(dir.path()).unwrap_err();
            assert!(
                matches!(refused, SealError::Readable { mode: 0o644, .. }),
                "{refused}"
            );
        }
    }
}
