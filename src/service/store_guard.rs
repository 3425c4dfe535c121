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

use super::journal::{Journal, Pending};
use super::machine::StoreHandle;
use crate::config::Config;
use crate::store::{Store, StoreError, StoreIdentity};

/// The file in the var folder that remembers which store camloop last wrote.
pub(crate) const IDENTITY_FILE: &str = "store-identity";

/// What camloop's own state says one machine's store must hold.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct MachineExpectation {
    pub machine: String,
    pub lobe: String,
    /// The newest version in the machine's share manifest, `None` before the first.
    pub newest_share_version: Option<u64>,
    /// Table versions still in the journal, not yet written to the store: a store that was
    /// down for a while is behind the share by exactly these.
    pub tables_in_journal: u64,
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
        machine: String,
        lobe: String,
        share_version: u64,
        store_version: Option<i64>,
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
    created_at_ms: i64,
    /// Where the store was, for the operator reading the file (not compared).
    database: String,
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
        let held = newest.unwrap_or(0).max(0) as u64 + e.tables_in_journal;
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
    remember(&file, &identity, store.target())?;
    Ok(StoreCheck::Remembered(identity))
}

/// The documented recovery (`--accept-new-database`): remembers `store` as the one camloop
/// writes from now on, whatever was remembered before. Returns its identity.
pub(crate) async fn accept_new_store(
    store: &Store,
    var_dir: &Path,
) -> Result<StoreIdentity, StoreMismatch> {
    let identity = store
        .identity()
        .await
        .map_err(|source| StoreMismatch::Store {
            target: store.target().to_owned(),
            source,
        })?;
    remember(&var_dir.join(IDENTITY_FILE), &identity, store.target())?;
    Ok(identity)
}

/// What each configured machine's share manifest and journal say its store must hold. The
/// paths follow the service's layout: `<var>/machines/<name>/` holds the machine's journal,
/// and its `share/` folder the share's manifest (see `service::start`).
pub(crate) fn expectations(config: &Config) -> Vec<MachineExpectation> {
    let var = config.var_dir();
    config
        .machines
        .iter()
        .map(|m| {
            let state_dir = var.join("machines").join(&m.name);
            let manifest = state_dir.join("share").join(crate::share::MANIFEST_FILE);
            let newest_share_version = crate::share::load_manifest(&manifest)
                .ok()
                .map(|loaded| loaded.history.next_version().saturating_sub(1))
                .filter(|&v| v > 0);
            let tables_in_journal = Journal::open(&state_dir).map_or(0, |j| {
                j.records()
                    .iter()
                    .filter(|r| {
                        matches!(r, Pending::Table { machine, lobe, .. }
                            if *machine == m.name && *lobe == m.lobe)
                    })
                    .count() as u64
            });
            MachineExpectation {
                machine: m.name.clone(),
                lobe: m.lobe.clone(),
                newest_share_version,
                tables_in_journal,
            }
        })
        .collect()
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
    let checked = if accept_new {
        accept_new_store(&store, &var_dir).await.map(|identity| {
            info!(store_id = %identity.id, database = %store.target(), "new database accepted: camloop continues on it");
            StoreCheck::Same(identity)
        })
    } else {
        check_store(&store, &var_dir, &expectations(config)).await
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
fn remember(file: &Path, identity: &StoreIdentity, database: &str) -> Result<(), StoreMismatch> {
    let bad = |what: &str, e: std::io::Error| StoreMismatch::Remembered {
        path: file.to_path_buf(),
        reason: format!("cannot {what}: {}", e.kind()),
    };
    let dir = file.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| bad("create its folder", e))?;
    let text = serde_json::to_string(&Remembered {
        store_id: identity.id.clone(),
        created_at_ms: identity.created_at_ms,
        database: database.to_owned(),
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
mod tests {
    use super::*;
    use crate::store::{NewTableVersion, TableStatus};

    struct Site {
        dir: tempfile::TempDir,
    }

    impl Site {
        fn new() -> Self {
            Site {
                dir: tempfile::tempdir().unwrap(),
            }
        }
        fn var(&self) -> PathBuf {
            self.dir.path().join("var")
        }
        fn db(&self, name: &str) -> PathBuf {
            self.var().join(name)
        }
        async fn open(&self, name: &str) -> Store {
            let url = format!("sqlite://{}?mode=rwc", self.db(name).display());
            Store::connect(&url).await.unwrap()
        }
    }

    fn share_at(version: Option<u64>, tables_in_journal: u64) -> Vec<MachineExpectation> {
        vec![MachineExpectation {
            machine: "SIM1".into(),
            lobe: "IN1".into(),
            newest_share_version: version,
            tables_in_journal,
        }]
    }

    async fn add_table(store: &Store) -> i64 {
        store
            .insert_table_version(&NewTableVersion {
                machine: "SIM1".into(),
                lobe: "IN1".into(),
                parent_version: None,
                table_number: 11,
                program_text: "CTABDEF\nCTABEND\n".into(),
                learning_params_json: "{}".into(),
                reason: "nominal table".into(),
                status: TableStatus::Pushed,
                status_why: "pushed to the share".into(),
                created_at_ms: 1_000,
            })
            .await
            .unwrap()
    }

    fn mismatch(e: StoreMismatch) -> (String, Vec<Problem>) {
        let text = e.to_string();
        match e {
            StoreMismatch::Mismatch { problems, .. } => (text, problems),
            other => panic!("expected a mismatch, got {other:?}"),
        }
    }

    #[tokio::test]
    async fn a_fresh_start_passes_and_is_remembered_then_the_same_store_passes() {
        let site = Site::new();
        let store = site.open("camloop.db").await;
        let id = store.identity().await.unwrap();
        assert_eq!(id.id.len(), 32, "{id:?}");
        let first = check_store(&store, &site.var(), &share_at(None, 0)).await;
        assert_eq!(first, Ok(StoreCheck::Remembered(id.clone())));
        let file = std::fs::read_to_string(site.var().join(IDENTITY_FILE)).unwrap();
        assert!(file.contains(&id.id), "{file}");
        add_table(&store).await;
        let again = check_store(&store, &site.var(), &share_at(Some(1), 0)).await;
        assert_eq!(again, Ok(StoreCheck::Same(id)));
    }

    #[tokio::test]
    async fn a_replaced_database_is_refused_naming_both_ids_and_its_path() {
        let site = Site::new();
        let old = site.open("camloop.db").await;
        let old_id = old.identity().await.unwrap().id;
        check_store(&old, &site.var(), &[]).await.unwrap();
        let new = site.open("other.db").await;
        let new_id = new.identity().await.unwrap().id;
        assert_ne!(old_id, new_id);
        let (text, problems) = mismatch(check_store(&new, &site.var(), &[]).await.unwrap_err());
        assert_eq!(problems.len(), 1);
        let path = site.db("other.db").display().to_string();
        assert!(
            text.starts_with(&format!("database {path} does not match")),
            "{text}"
        );
        assert!(
            text.contains(&format!(
                "it is store {new_id}, but camloop last wrote store {old_id}"
            )),
            "{text}"
        );
        assert!(text.contains("--accept-new-database"), "{text}");
        // The refusal leaves the remembered identity alone: the old database still passes.
        assert!(matches!(
            check_store(&old, &site.var(), &[]).await,
            Ok(StoreCheck::Same(_))
        ));
    }

    #[tokio::test]
    async fn a_truncated_database_is_refused_not_taken_for_a_fresh_start() {
        let site = Site::new();
        let store = site.open("camloop.db").await;
        for _ in 0..3 {
            add_table(&store).await;
        }
        check_store(&store, &site.var(), &share_at(Some(3), 0))
            .await
            .unwrap();
        store.close().await;
        std::fs::File::options()
            .write(true)
            .open(site.db("camloop.db"))
            .unwrap()
            .set_len(0)
            .unwrap();
        let emptied = site.open("camloop.db").await;
        let (text, problems) = mismatch(
            check_store(&emptied, &site.var(), &share_at(Some(42), 0))
                .await
                .unwrap_err(),
        );
        assert!(matches!(problems[0], Problem::Replaced { .. }), "{text}");
        assert_eq!(
            problems[1].to_string(),
            "it has no table versions for SIM1 IN1 but the share's manifest holds v42"
        );
    }

    #[tokio::test]
    async fn a_store_behind_the_share_is_refused_unless_the_journal_holds_the_gap() {
        let site = Site::new();
        let store = site.open("camloop.db").await;
        add_table(&store).await;
        let (text, _) = mismatch(
            check_store(&store, &site.var(), &share_at(Some(3), 1))
                .await
                .unwrap_err(),
        );
        assert!(
            text.contains(
                "its newest table version for SIM1 IN1 is v1 but the share's manifest holds v3"
            ),
            "{text}"
        );
        assert!(
            !site.var().join(IDENTITY_FILE).exists(),
            "a refused store is not remembered"
        );
        let two_waiting = check_store(&store, &site.var(), &share_at(Some(3), 2)).await;
        assert!(
            matches!(two_waiting, Ok(StoreCheck::Remembered(_))),
            "{two_waiting:?}"
        );
    }

    #[tokio::test]
    async fn accepting_a_new_database_remembers_it() {
        let site = Site::new();
        let old = site.open("camloop.db").await;
        check_store(&old, &site.var(), &[]).await.unwrap();
        let new = site.open("new.db").await;
        assert!(check_store(&new, &site.var(), &[]).await.is_err());
        let accepted = accept_new_store(&new, &site.var()).await.unwrap();
        assert_eq!(accepted, new.identity().await.unwrap());
        assert_eq!(
            check_store(&new, &site.var(), &[]).await,
            Ok(StoreCheck::Same(accepted))
        );
    }

    #[tokio::test]
    async fn a_damaged_identity_file_is_reported_not_overwritten() {
        let site = Site::new();
        let store = site.open("camloop.db").await;
        std::fs::write(site.var().join(IDENTITY_FILE), "garbage").unwrap();
        let e = check_store(&store, &site.var(), &[]).await.unwrap_err();
        assert_eq!(e.code(), "store_identity_file");
        assert!(
            e.to_string().contains("not a remembered store identity"),
            "{e}"
        );
        assert_eq!(
            std::fs::read_to_string(site.var().join(IDENTITY_FILE)).unwrap(),
            "garbage"
        );
    }
}
