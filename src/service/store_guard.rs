//! The start-up check that the history database is the one camloop left: a database that
//! was replaced, emptied (`truncate -s 0`) or restored from an old backup must not be taken
//! for a fresh start while the share and the journal continue from where they were.
//!
//! Protocol:
//! 1. The first time a store is connected and checked, camloop remembers its identity
//!    ([`crate::store::StoreIdentity`], made by the schema migration) in
//!    `<var>/store-identity`, written atomically (temporary file, fsync, rename, fsync of
//!    the folder).
//! 2. At every later start [`check_store`] compares the store's identity with the
//!    remembered one, and for every machine the store's newest table version with the
//!    newest on the share (less those still waiting in the journal). Any difference refuses
//!    the start with a [`StoreMismatch`] naming both sides.
//! 3. Recovery is explicit: `--accept-new-database` calls [`accept_new_store`], which
//!    remembers the new identity. Nothing is ever rewritten silently.

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use tracing::{error, info};

mod rebuild;

use super::journal::Pending;
use super::machine::StoreHandle;
use crate::config::Config;
use crate::names::{FeatureName, MachineName};
use crate::store::{Store, StoreError, StoreIdentity};

/// The file in the var folder that remembers which store camloop last wrote.
pub(crate) const IDENTITY_FILE: &str = "store-identity";

/// What camloop's own state says one machine's store must hold.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct MachineExpectation {
    pub machine: MachineName,
    pub lobe: FeatureName,
    /// The newest version in the machine's share manifest, `None` before the first.
    pub newest_share_version: Option<u64>,
    /// Table versions still in the journal, not yet written to the store: a store that was
    /// down for a while is behind the share by exactly these.
    pub tables_in_journal: u64,
    /// The feature's state folder (journal, and the share's manifest under `share/`).
    pub state_dir: std::path::PathBuf,
}

/// A store that passed the check.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum StoreCheck {
    /// The store camloop last wrote.
    Same(StoreIdentity),
    /// No store was remembered yet (a first start, or the first with this check) and the
    /// store agrees with the share: it is remembered from now on.
    Remembered(StoreIdentity),
}

/// One way the store disagrees with camloop's state.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Problem {
    /// The store has another identity than the one camloop remembers.
    Replaced {
        remembered: String,
        found: String,
        file: PathBuf,
    },
    /// The share holds newer table versions than the store and the journal together.
    BehindShare {
        machine: MachineName,
        lobe: FeatureName,
        share_version: u64,
        store_version: Option<crate::core::ids::TableVersion>,
    },
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Problem::Replaced {
                remembered,
                found,
                file,
            } => write!(
                f,
                "it is store {found}, but camloop last wrote store {remembered} (remembered in {})",
                file.display()
            ),
            Problem::BehindShare {
                machine,
                lobe,
                share_version,
                store_version: None,
            } => write!(
                f,
                "it has no table versions for {machine} {lobe} but the share's manifest holds \
                 v{share_version}"
            ),
            Problem::BehindShare {
                machine,
                lobe,
                share_version,
                store_version: Some(v),
            } => write!(
                f,
                "its newest table version for {machine} {lobe} is v{v} but the share's \
                 manifest holds v{share_version}"
            ),
        }
    }
}

/// Why the start is refused, or why the check could not be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum StoreMismatch {
    /// The store is not the history camloop left.
    #[error(
        "database {target} does not match the state camloop left: {}; restore the database \
         camloop last wrote, or start once with --accept-new-database to continue on this one",
        join(.problems)
    )]
    Mismatch {
        /// The database without credentials.
        target: String,
        problems: Vec<Problem>,
    },
    /// The store could not be asked.
    #[error("cannot check database {target} against camloop's state: {source}")]
    Store { target: String, source: StoreError },
    /// The remembered identity could not be read or written.
    #[error("cannot use {}: {reason}", .path.display())]
    Remembered { path: PathBuf, reason: String },
}

impl StoreMismatch {
    /// Stable code: `store_mismatch`, `store_check_failed` or `store_identity_file`.
    pub(crate) fn code(&self) -> &'static str {
        match self {
            StoreMismatch::Mismatch { .. } => "store_mismatch",
            StoreMismatch::Store { .. } => "store_check_failed",
            StoreMismatch::Remembered { .. } => "store_identity_file",
        }
    }
}

fn join(problems: &[Problem]) -> String {
    let texts: Vec<String> = problems.iter().map(Problem::to_string).collect();
    texts.join("; ")
}

/// The remembered identity, as kept in [`IDENTITY_FILE`].
#[derive(Debug, Serialize, Deserialize)]
struct Remembered {
    store_id: String,
    #[serde(rename = "created_at_ms", with = "crate::clock::unix_ms")]
    created_at: jiff::Timestamp,
    /// Where the store was, for the operator reading the file (not compared).
    database: String,
    /// When the store was accepted with `--accept-new-database`: how many table versions
    /// each machine's share was ahead of it then. Its own numbering starts at 1 again, so
    /// later checks count these as held.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    accepted_behind: Vec<Behind>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct Behind {
    machine: MachineName,
    lobe: FeatureName,
    versions: u64,
}

/// Checks `store` against the identity remembered in `var_dir` and against each machine's
/// share; remembers the identity when none was and the store passes.
pub(crate) async fn check_store(
    store: &Store,
    var_dir: &Path,
    expectations: &[MachineExpectation],
) -> Result<StoreCheck, StoreMismatch> {
    let target = store.target().to_owned();
    let asked = |source| StoreMismatch::Store {
        target: target.clone(),
        source,
    };
    let identity = store.identity().await.map_err(asked)?;
    let file = var_dir.join(IDENTITY_FILE);
    let remembered = read_remembered(&file)?;
    let mut problems = Vec::new();
    if let Some(r) = &remembered
        && r.store_id != identity.id
    {
        problems.push(Problem::Replaced {
            remembered: r.store_id.clone(),
            found: identity.id.clone(),
            file: file.clone(),
        });
    }
    for e in expectations {
        let Some(share_version) = e.newest_share_version else {
            continue;
        };
        let newest = store
            .latest_table_version(&e.machine, &e.lobe)
            .await
            .map_err(asked)?
            .map(|t| t.version);
        let accepted_behind = remembered
            .as_ref()
            .filter(|r| r.store_id == identity.id)
            .and_then(|r| {
                r.accepted_behind
                    .iter()
                    .find(|b| b.machine == e.machine && b.lobe == e.lobe)
            })
            .map_or(0, |b| b.versions);
        let held = newest.map_or(0, |v| v.get()) + e.tables_in_journal + accepted_behind;
        if held < share_version {
            problems.push(Problem::BehindShare {
                machine: e.machine.clone(),
                lobe: e.lobe.clone(),
                share_version,
                store_version: newest,
            });
        }
    }
    if !problems.is_empty() {
        return Err(StoreMismatch::Mismatch { target, problems });
    }
    if remembered.is_some() {
        return Ok(StoreCheck::Same(identity));
    }
    remember(&file, &identity, store.target(), Vec::new())?;
    Ok(StoreCheck::Remembered(identity))
}

/// The documented recovery (`--accept-new-database`): remembers `store` as the one camloop
/// writes from now on, whatever was remembered before, together with how far each machine's
/// share is ahead of it (`expectations`), so later starts check only what comes after.
/// Returns its identity.
pub(crate) async fn accept_new_store(
    store: &Store,
    var_dir: &Path,
    expectations: &[MachineExpectation],
) -> Result<StoreIdentity, StoreMismatch> {
    let asked = |source| StoreMismatch::Store {
        target: store.target().to_owned(),
        source,
    };
    let identity = store.identity().await.map_err(asked)?;
    let rebuilt = rebuild::rebuild_versions(store, expectations)
        .await
        .map_err(asked)?;
    info!(
        versions = rebuilt,
        "table versions the shares keep rebuilt into the new database"
    );
    let mut behind = Vec::new();
    for e in expectations {
        let newest = store
            .latest_table_version(&e.machine, &e.lobe)
            .await
            .map_err(asked)?
            .map_or(0, |t| t.version.get());
        let ahead = e
            .newest_share_version
            .unwrap_or(0)
            .saturating_sub(newest + e.tables_in_journal);
        if ahead > 0 {
            behind.push(Behind {
                machine: e.machine.clone(),
                lobe: e.lobe.clone(),
                versions: ahead,
            });
        }
    }
    remember(
        &var_dir.join(IDENTITY_FILE),
        &identity,
        store.target(),
        behind,
    )?;
    Ok(identity)
}

/// What each configured machine's share manifests and journals say its store must hold. The
/// paths follow the service's layout: `<var>/machines/<name>/<feature>/` holds a feature's
/// journal, and its `share/` folder the share's manifest (see `service::start`).
pub(crate) fn expectations(config: &Config) -> Vec<MachineExpectation> {
    let mut out = Vec::new();
    for m in &config.machines {
        let name = &m.name;
        let machine_dir = config.machines_dir().join(name);
        for lobe in crate::config::configured_features(config, m) {
            let state_dir = machine_dir.join(&lobe);
            let manifest = state_dir.join("share").join(crate::share::MANIFEST_FILE);
            let newest_share_version = crate::share::load_manifest(&manifest)
                .ok()
                .map(|loaded| loaded.history.next_version().get().saturating_sub(1))
                .filter(|&v| v > 0);
            // Read only: in a cluster another instance may be appending to it right now.
            let journal = std::fs::read_to_string(state_dir.join("journal.jsonl"));
            let tables_in_journal = journal.map_or(0, |text| {
                text.lines()
                    .filter_map(|line| serde_json::from_str::<Pending>(line).ok())
                    .filter(|r| {
                        matches!(r, Pending::Table { machine, lobe: l, .. }
                            if machine == name && *l == lobe)
                    })
                    .count() as u64
            });
            out.push(MachineExpectation {
                machine: name.clone(),
                lobe,
                newest_share_version,
                tables_in_journal,
                state_dir,
            });
        }
    }
    out
}

/// The start-up step of the service: when the store is connected, checks it against the
/// var folder, the shares and the journals (or, with `accept_new`, accepts it) and refuses
/// the start on a mismatch. A store that fails while being checked is set aside as
/// unavailable, as if it had not connected.
pub(crate) async fn guard_start(
    handle: &StoreHandle,
    config: &Config,
    accept_new: bool,
) -> anyhow::Result<()> {
    let Some(store) = handle.read().await.clone() else {
        return Ok(());
    };
    let var_dir = config.var_dir();
    let expected = expectations(config);
    let checked = if accept_new {
        accept_new_store(&store, &var_dir, &expected).await.map(|identity| {
            info!(store_id = %identity.id, database = %store.target(), "new database accepted: camloop continues on it");
            StoreCheck::Same(identity)
        })
    } else {
        check_store(&store, &var_dir, &expected).await
    };
    match checked {
        Ok(StoreCheck::Same(_)) => Ok(()),
        Ok(StoreCheck::Remembered(identity)) => {
            info!(store_id = %identity.id, database = %store.target(), "history store remembered");
            Ok(())
        }
        Err(StoreMismatch::Store { source, .. }) if !source.is_permanent() => {
            error!(error = %source, "history store failed its start check: taken as unavailable");
            *handle.write().await = None;
            store.close().await;
            Ok(())
        }
        Err(e) => {
            error!(code = e.code(), error = %e, "history store refused: camloop does not start");
            store.close().await;
            Err(anyhow::Error::new(e))
        }
    }
}

/// The start check for a database that connected only after start: the same comparison,
/// never an acceptance.
pub(crate) async fn check_late(store: &Store, config: &Config) -> Result<(), StoreMismatch> {
    check_store(store, &config.var_dir(), &expectations(config))
        .await
        .map(|_| ())
}

fn read_remembered(file: &Path) -> Result<Option<Remembered>, StoreMismatch> {
    let bad = |reason: String| StoreMismatch::Remembered {
        path: file.to_path_buf(),
        reason,
    };
    match std::fs::read_to_string(file) {
        Ok(text) => serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| bad(format!("not a remembered store identity: {e}"))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(bad(format!("cannot read it: {}", e.kind()))),
    }
}

/// Writes the identity file atomically: a temporary beside it, flushed, renamed over it,
/// and the folder flushed so the rename survives a power cut.
fn remember(
    file: &Path,
    identity: &StoreIdentity,
    database: &str,
    accepted_behind: Vec<Behind>,
) -> Result<(), StoreMismatch> {
    let bad = |what: &str, e: std::io::Error| StoreMismatch::Remembered {
        path: file.to_path_buf(),
        reason: format!("cannot {what}: {}", e.kind()),
    };
    let dir = file.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| bad("create its folder", e))?;
    let text = serde_json::to_string(&Remembered {
        store_id: identity.id.clone(),
        created_at: identity.created_at,
        database: database.to_owned(),
        accepted_behind,
    })
    .expect("a struct of strings and integers serialises");
    let mut temp = tempfile::NamedTempFile::new_in(dir).map_err(|e| bad("write it", e))?;
    temp.write_all(format!("{text}\n").as_bytes())
        .and_then(|()| temp.as_file().sync_all())
        .map_err(|e| bad("write it", e))?;
    temp.persist(file).map_err(|e| bad("rename it", e.error))?;
    std::fs::File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(|e| bad("flush its folder", e))
}

#[cfg(test)]
mod tests;
