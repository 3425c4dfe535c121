//! Tests of the start-up store check: unit cases on SQLite files, and the service refusing
//! to start on an emptied database, then starting once it is accepted.

use super::*;
use crate::store::{NewTableVersion, VersionStatus};

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
        machine: "SIM1".parse().unwrap(),
        lobe: "IN1".parse().unwrap(),
        newest_share_version: version,
        tables_in_journal,
        state_dir: PathBuf::from("/nonexistent/camloop-state"),
    }]
}

async fn add_table(store: &Store) -> crate::core::ids::TableVersion {
    store
        .insert_table_version(&NewTableVersion {
            machine: "SIM1".parse().unwrap(),
            lobe: "IN1".parse().unwrap(),
            version: None,
            parent_version: None,
            table_number: 11,
            program_text: "CTABDEF\nCTABEND\n".into(),
            learning_params_json: "{}".into(),
            reason: "nominal table".into(),
            status: VersionStatus::Pushed {
                at: jiff::Timestamp::from_millisecond(1_000).expect("a time"),
                note: Some("pushed to the share".into()),
            },
            created_at: jiff::Timestamp::from_millisecond(1_000).unwrap(),
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
    // The file keeps its key for the store's creation time (Unix ms), as files written
    // before the field was named `created_at` have it.
    let kept = format!("\"created_at_ms\":{}", id.created_at.as_millisecond());
    assert!(file.contains(&kept), "{file}");
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
    let accepted = accept_new_store(&new, &site.var(), &[]).await.unwrap();
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

#[tokio::test]
async fn an_accepted_store_is_checked_only_for_what_comes_after() {
    let site = Site::new();
    let store = site.open("camloop.db").await;
    accept_new_store(&store, &site.var(), &share_at(Some(42), 0))
        .await
        .unwrap();
    assert!(
        check_store(&store, &site.var(), &share_at(Some(42), 0))
            .await
            .is_ok()
    );
    add_table(&store).await;
    assert!(
        check_store(&store, &site.var(), &share_at(Some(43), 0))
            .await
            .is_ok()
    );
    let (text, _) = mismatch(
        check_store(&store, &site.var(), &share_at(Some(45), 0))
            .await
            .unwrap_err(),
    );
    assert!(
        text.contains("is v1 but the share's manifest holds v45"),
        "{text}"
    );
}

/// The fault campaign's item: stop, `truncate -s 0 var/camloop.db`, start.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_service_refuses_to_start_on_a_truncated_database() {
    let dir = tempfile::tempdir().unwrap();
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let text = format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n\
         [http]\nlisten = \"127.0.0.1:0\"\n[[machines]]\nname = \"SIM1\"\nrecipe = \"{}\"\n\
         lobe = \"IN1\"\nshare = \"share/SIM1\"\n[machines.gauge]\nkind = \"sim\"\n\
         part_interval_ms = 20\nseed = 5\n",
        recipe.display()
    );
    let config = || Config::parse(&text, &dir.path().join("camloop.toml"), |_| None).unwrap();
    let options = || super::super::RunOptions::parts(2);
    let mut running = super::super::start(config(), options()).await.unwrap();
    running.machines_done().await;
    running.stop().await;
    // A restart on the same database passes.
    super::super::start(config(), options())
        .await
        .unwrap()
        .stop()
        .await;

    let db = dir.path().join("var/camloop.db");
    std::fs::File::options()
        .write(true)
        .open(&db)
        .unwrap()
        .set_len(0)
        .unwrap();
    let Err(e) = super::super::start(config(), options()).await else {
        panic!("started on an emptied database");
    };
    let text = format!("{e:#}");
    assert!(
        text.starts_with(&format!("database {} does not match", db.display())),
        "{text}"
    );
    assert!(text.contains("but camloop last wrote store"), "{text}");
    assert!(
        text.contains("it has no table versions for SIM1 IN1 but the share's manifest holds v"),
        "{text}"
    );

    // The recovery: accepted once, the service starts on it.
    let store = Store::connect(&config().database_url()).await.unwrap();
    let expected = expectations(&config());
    assert!(
        expected[0].newest_share_version.unwrap() >= 2,
        "{expected:?}"
    );
    accept_new_store(&store, &config().var_dir(), &expected)
        .await
        .unwrap();
    // The version index is rebuilt from the share: its newest version is in the new store
    // under its own number, with its program text.
    let newest = store
        .latest_table_version(&"SIM1".parse().unwrap(), &"IN1".parse().unwrap())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        newest.version.get(),
        expected[0].newest_share_version.unwrap()
    );
    assert!(
        newest.program_text.contains("CTABDEF("),
        "{}",
        newest.program_text
    );
    assert!(newest.reason.ends_with("(rebuilt from the share)"));
    store.close().await;
    let mut running = super::super::start(config(), options()).await.unwrap();
    running.machines_done().await;
    running.stop().await;
    super::super::start(config(), options())
        .await
        .unwrap()
        .stop()
        .await;
}
