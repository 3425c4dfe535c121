//! The history store when the database is down, misplaced, misnamed, damaged, out of disk
//! space or flooded with reads: clear `StoreError`s with stable codes, no panic, no password
//! in the message.

use crate::store_support;

use camloop::store::{Store, StoreError};
use store_support::data::{measurement, ms};
use store_support::m;

#[tokio::test]
async fn sqlite_reopens_with_its_data() {
    let t = store_support::sqlite().await;
    let id = t
        .store
        .insert_measurement(&measurement("M1", "in1", 1, 1))
        .await
        .unwrap();
    t.store.close().await;
    assert_eq!(
        t.store.machines().await.unwrap_err().code(),
        "store_unavailable",
        "a closed pool reports the store unavailable"
    );
    let url = format!("sqlite://{}", t.dir.path().join("var/camloop.db").display());
    let again = Store::connect(&url).await.unwrap();
    assert!(again.measurement(id).await.unwrap().is_some());
}

#[tokio::test]
async fn postgres_down_is_unavailable_without_the_password() {
    // A port that was free a moment ago and has no listener now.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let url = format!("postgres://camloop:s3cret@127.0.0.1:{port}/camloop");
    let e = Store::connect(&url).await.unwrap_err();
    assert_eq!(e.code(), "store_unavailable");
    assert_eq!(
        e.to_string(),
        format!("store unavailable at 127.0.0.1:{port}/camloop: connection refused")
    );
    assert!(!format!("{e:?}").contains("s3cret"));
}

#[tokio::test]
async fn sqlite_in_an_impossible_place_is_unavailable() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "not a folder").unwrap();
    let url = format!("sqlite://{}?mode=rwc", file.join("camloop.db").display());
    let e = Store::connect(&url).await.unwrap_err();
    assert_eq!(e.code(), "store_unavailable");
    assert!(e.to_string().contains("cannot create folder"), "{e}");
}

#[tokio::test]
async fn unknown_url_scheme_is_invalid() {
    let e = Store::connect("mysql://u:p@h/db").await.unwrap_err();
    assert_eq!(
        e.to_string(),
        "invalid database url: scheme `mysql` is not sqlite: or postgres://"
    );
}

/// Inserts `n` measurements on M1/in1 into a SQLite file, then closes the store so the
/// write-ahead log is folded into the file. Returns the file.
async fn filled_sqlite(dir: &std::path::Path, n: u32) -> std::path::PathBuf {
    let path = dir.join("camloop.db");
    let store = Store::connect(&format!("sqlite://{}?mode=rwc", path.display()))
        .await
        .unwrap();
    for i in 0..n {
        store
            .insert_measurement(&measurement("M1", "in1", i, i64::from(i)))
            .await
            .unwrap();
    }
    store.close().await;
    assert!(
        !dir.join("camloop.db-wal").exists(),
        "closing folds the log"
    );
    path
}

fn assert_corrupt(e: &StoreError, path: &std::path::Path, reason: &str) {
    assert_eq!(e.code(), "store_corrupt", "{e}");
    assert!(e.is_permanent());
    let text = e.to_string();
    assert_eq!(
        text,
        format!(
            "database file {} is damaged ({reason}): restore it from a backup, or move it aside \
             and start once with --accept-new-database to begin a new history",
            path.display()
        )
    );
}

#[tokio::test]
async fn sqlite_file_with_a_garbage_header_is_corrupt_not_unavailable() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("camloop.db");
    std::fs::write(&path, vec![0x5a_u8; 8192]).unwrap();
    let e = Store::connect(&format!("sqlite://{}", path.display()))
        .await
        .unwrap_err();
    assert_corrupt(&e, &path, "file is not a database");
    assert_eq!(
        std::fs::read(&path).unwrap(),
        vec![0x5a_u8; 8192],
        "the damaged file is left as it was"
    );
}

#[tokio::test]
async fn half_truncated_sqlite_database_is_corrupt_at_connect() {
    let dir = tempfile::tempdir().unwrap();
    let path = filled_sqlite(dir.path(), 300).await;
    let len = std::fs::metadata(&path).unwrap().len();
    assert!(len > 100_000, "{len} bytes: enough pages to cut");
    std::fs::File::options()
        .write(true)
        .open(&path)
        .unwrap()
        .set_len(len / 2)
        .unwrap();
    let e = Store::connect(&format!("sqlite://{}", path.display()))
        .await
        .unwrap_err();
    assert_corrupt(
        &e,
        &path,
        "file is shorter than its header says: it was cut off",
    );
}

#[tokio::test]
async fn sqlite_pages_damaged_in_the_middle_are_corrupt_on_query() {
    let dir = tempfile::tempdir().unwrap();
    let path = filled_sqlite(dir.path(), 300).await;
    let schema_end = schema_end_bytes(&path).await;
    let mut bytes = std::fs::read(&path).unwrap();
    let len = bytes.len();
    // Every page from 30 % (and past every table's and index's root page) to 70 % of the
    // file overwritten: the header and the schema are intact, so the file opens, and the
    // damage shows on the first query that reads those pages.
    let page = 4096;
    let from = (len * 3 / 10).max(schema_end) / page * page;
    assert!(
        from < len * 6 / 10,
        "the schema takes {schema_end} of {len} bytes"
    );
    for b in &mut bytes[from..(len * 7 / 10) / page * page] {
        *b = 0xa5;
    }
    std::fs::write(&path, &bytes).unwrap();
    let store = Store::connect(&format!("sqlite://{}", path.display()))
        .await
        .unwrap();
    let e = store
        .export(ms(0), jiff::Timestamp::MAX, None, 1000)
        .await
        .unwrap_err();
    assert_corrupt(&e, &path, "database disk image is malformed");
    assert!(e.detail().unwrap().starts_with("exporting measurements: "));
}

/// Where the last root page (of a table or index) ends, bytes: the schema's pages are all
/// before it, since they are made when the migrations run, before any row is written.
async fn schema_end_bytes(path: &std::path::Path) -> usize {
    use sqlx::Connection;
    let mut c = sqlx::SqliteConnection::connect(&format!("sqlite://{}", path.display()))
        .await
        .unwrap();
    let last: i64 = sqlx::query_scalar("SELECT max(rootpage) FROM sqlite_master")
        .fetch_one(&mut c)
        .await
        .unwrap();
    let page: i64 = sqlx::query_scalar("PRAGMA page_size")
        .fetch_one(&mut c)
        .await
        .unwrap();
    c.close().await.unwrap();
    usize::try_from(last * page).unwrap()
}

/// A tmpfs mounted on a tempdir folder, unmounted on drop (also when the test fails).
struct Tmpfs(std::path::PathBuf);

impl Tmpfs {
    /// `None` with the reason when this process may not mount (not root, no capability).
    fn mount(at: std::path::PathBuf, size: &str) -> Result<Self, String> {
        std::fs::create_dir_all(&at).map_err(|e| e.to_string())?;
        let out = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(&at)
            .output()
            .map_err(|e| format!("cannot run mount: {e}"))?;
        if !out.status.success() {
            return Err(String::from_utf8_lossy(&out.stderr).trim().to_owned());
        }
        Ok(Tmpfs(at))
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg("-l")
            .arg(&self.0)
            .status();
    }
}

#[tokio::test]
async fn sqlite_on_a_full_disk_reports_store_full() {
    let dir = tempfile::tempdir().unwrap();
    let fs = match Tmpfs::mount(dir.path().join("small"), "1m") {
        Ok(fs) => fs,
        Err(why) => {
            eprintln!("SKIP sqlite_on_a_full_disk_reports_store_full: cannot mount a tmpfs: {why}");
            return;
        }
    };
    let store = Store::connect(&format!(
        "sqlite://{}?mode=rwc",
        fs.0.join("camloop.db").display()
    ))
    .await
    .unwrap();
    // Each measurement takes about 1 KiB: 1 MiB is full well before 5,000.
    let mut full = None;
    for i in 0..5_000u32 {
        match store
            .insert_measurement(&measurement("M1", "in1", i, i64::from(i)))
            .await
        {
            Ok(_) => {}
            Err(e) => {
                full = Some((i, e));
                break;
            }
        }
    }
    let (at, e) = full.expect("a 1 MiB file system fills up");
    assert!(
        at > 10,
        "the schema and some rows fit first, failed at {at}"
    );
    assert_eq!(e.code(), "store_full", "{e}: {:?}", e.detail());
    assert!(!e.is_permanent());
    assert_eq!(
        e.to_string(),
        format!(
            "database {} is out of disk space: free space on its file system",
            fs.0.join("camloop.db").display()
        )
    );
    store.close().await;
}

/// Every reader blocked behind a table lock (a reader that cannot finish): writes still go
/// through at once, on their own connections, and reads beyond the bound are refused with
/// `store_busy` instead of queueing without end.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_readers_stuck_behind_a_lock_never_hold_up_a_writer() {
    use sqlx::Connection;
    let Some(t) =
        store_support::postgres("postgres_readers_stuck_behind_a_lock_never_hold_up_a_writer")
            .await
    else {
        return;
    };
    let url = t.server.as_ref().unwrap().url();
    let mut locker = sqlx::PgConnection::connect(&url).await.unwrap();
    sqlx::query("BEGIN").execute(&mut locker).await.unwrap();
    sqlx::query("LOCK TABLE measurements IN ACCESS EXCLUSIVE MODE")
        .execute(&mut locker)
        .await
        .unwrap();
    let mut readers = tokio::task::JoinSet::new();
    for _ in 0..20 {
        let store = t.store.clone();
        readers.spawn(async move {
            store
                .measurement_history(&store_support::data::filter("M1"))
                .await
        });
    }
    // Until the first readers are waiting on the lock (polled, at most 10 s). Polled from
    // its own connection: inside the locker's transaction the activity view is a snapshot.
    let mut watcher = sqlx::PgConnection::connect(&url).await.unwrap();
    let mut waiting = 0;
    for _ in 0..1000 {
        waiting = sqlx::query_scalar::<_, i64>(
            "SELECT COUNT(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock'",
        )
        .fetch_one(&mut watcher)
        .await
        .unwrap();
        if let Some(done) = readers.try_join_next() {
            panic!("a reader finished while the lock is held: {done:?}");
        }
        if waiting >= 2 {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    }
    assert!(waiting >= 2, "{waiting} readers waiting on the lock");
    let started = std::time::Instant::now();
    t.store
        .insert_event(&camloop::store::NewEvent {
            machine: m("M1"),
            at: ms(1),
            level: camloop::store::EventLevel::Info,
            kind: camloop::store::EventKind::MeasurementRepeated,
            message: "written while every reader waits".into(),
        })
        .await
        .unwrap();
    assert!(
        started.elapsed() < camloop::store::READ_WAIT,
        "the write took {:?}",
        started.elapsed()
    );
    // The readers beyond the bound (at most 4 are admitted) give up after READ_WAIT, while
    // the admitted ones still wait on the lock; once it goes, those finish.
    let mut outcomes = Vec::new();
    while outcomes.len() < 16 {
        outcomes.push(readers.join_next().await.unwrap().unwrap());
    }
    assert!(
        outcomes.iter().all(|r| r.is_err()),
        "only refusals before the lock goes"
    );
    sqlx::query("ROLLBACK").execute(&mut locker).await.unwrap();
    while let Some(r) = readers.join_next().await {
        outcomes.push(r.unwrap());
    }
    let mut served = 0;
    for outcome in outcomes {
        match outcome {
            Ok(page) => {
                assert!(page.items.is_empty());
                served += 1;
            }
            Err(e) => assert_eq!(e.code(), "store_busy", "{e}"),
        }
    }
    assert!((2..=4).contains(&served), "{served} reads admitted");
}

/// A PostgreSQL read that cannot finish is cancelled by the server at the readers' statement
/// timeout (5 s) and reported as `store_busy`, not left holding its connection.
#[tokio::test]
async fn postgres_read_past_its_statement_timeout_is_busy() {
    use sqlx::Connection;
    let Some(t) = store_support::postgres("postgres_read_past_its_statement_timeout_is_busy").await
    else {
        return;
    };
    let url = t.server.as_ref().unwrap().url();
    let mut locker = sqlx::PgConnection::connect(&url).await.unwrap();
    sqlx::query("BEGIN").execute(&mut locker).await.unwrap();
    sqlx::query("LOCK TABLE events IN ACCESS EXCLUSIVE MODE")
        .execute(&mut locker)
        .await
        .unwrap();
    let started = std::time::Instant::now();
    let e = t
        .store
        .events(&camloop::store::EventFilter {
            limit: 10,
            ..Default::default()
        })
        .await
        .unwrap_err();
    let waited = started.elapsed();
    assert_eq!(e.code(), "store_busy", "{e}");
    assert!(
        (4.5..10.0).contains(&waited.as_secs_f64()),
        "cancelled after {waited:?}"
    );
    assert!(
        e.to_string()
            .ends_with("the read ran past its statement timeout"),
        "{e}"
    );
    sqlx::query("ROLLBACK").execute(&mut locker).await.unwrap();
}

/// Rows written outside camloop (by hand, or by a tool) with a machine name the rule refuses
/// or an event kind camloop never wrote come back as an `invalid` error naming the field, on
/// both backends: never a panic, and never a record with an unchecked name.
#[tokio::test]
async fn rows_with_a_bad_machine_name_or_event_kind_are_invalid_not_a_panic() {
    let mut stores = vec![store_support::sqlite().await];
    stores.extend(store_support::postgres("rows_with_a_bad_machine_name").await);
    for t in &stores {
        let rows = [
            "INSERT INTO machines (name, first_seen_ms) VALUES ('M1', 1)",
            "INSERT INTO events (machine, at_ms, level, kind, message) \
             VALUES ('M1', 1, 'info', 'gauge_down', 'by hand')",
        ];
        raw_execute(&t.store, &rows).await;
        let filter = camloop::store::EventFilter {
            limit: 10,
            ..Default::default()
        };
        let err = t.store.events(&filter).await.unwrap_err();
        assert_eq!(err.code(), "invalid", "{err}");
        assert!(err.to_string().contains("event kind"), "{err}");
        assert!(err.to_string().contains("gauge_down"), "{err}");

        raw_execute(
            &t.store,
            &["INSERT INTO machines (name, first_seen_ms) VALUES ('bad name!', 2)"],
        )
        .await;
        let err = t.store.machines().await.unwrap_err();
        assert_eq!(err.code(), "invalid", "{err}");
        assert!(err.to_string().contains("machine"), "{err}");
        assert!(err.to_string().contains("bad name!"), "{err}");
    }
}

/// Times are kept as integer milliseconds; one outside the years an instant can hold
/// (−9999 to 9999), written by hand, comes back as an `invalid` error naming its column, on
/// both backends: never a panic, never a clamped time.
#[tokio::test]
async fn a_stored_time_no_instant_has_is_invalid_not_a_panic() {
    let mut stores = vec![store_support::sqlite().await];
    stores.extend(store_support::postgres("a_stored_time_no_instant_has").await);
    for t in &stores {
        let rows = [
            "INSERT INTO machines (name, first_seen_ms) VALUES ('M1', 1)",
            "INSERT INTO events (machine, at_ms, level, kind, message) \
             VALUES ('M1', 9223372036854775807, 'info', 'share_back', 'by hand')",
            "INSERT INTO dressings (machine, at_ms, old_radius_mm, new_radius_mm, source) \
             VALUES ('M1', -400000000000000, 250.0, 249.9, 'by hand')",
        ];
        raw_execute(&t.store, &rows).await;
        let filter = camloop::store::EventFilter {
            limit: 10,
            ..Default::default()
        };
        let err = t.store.events(&filter).await.unwrap_err();
        assert_eq!(err.code(), "invalid", "{err}");
        assert!(err.to_string().contains("at_ms"), "{err}");
        assert!(err.to_string().contains("9223372036854775807 ms"), "{err}");
        let err = t.store.dressings(&m("M1"), 10).await.unwrap_err();
        assert_eq!(err.code(), "invalid", "{err}");
        assert!(err.to_string().contains("-400000000000000 ms"), "{err}");
        // The machine's own time is in range and reads.
        assert_eq!(t.store.machines().await.unwrap().len(), 1);
    }
}

/// A measurement row whose lobe fails the name rule, whose part is no part id, or whose
/// digest is not 64 lower-case hex digits (all written outside camloop), is an `invalid`
/// error naming the column and the value, never a panic; put right, the row reads again. A
/// recipe snapshot's part name is read by the names' rule the same way.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rows_with_a_bad_lobe_name_part_or_digest_are_invalid_not_a_panic() {
    let mut stores = vec![store_support::sqlite().await];
    stores.extend(store_support::postgres("rows_with_a_bad_lobe").await);
    for t in &stores {
        let m = store_support::data::measurement("M1", "IN1", 1, 1_000);
        t.store.insert_measurement(&m).await.unwrap();
        let history = store_support::data::filter("M1");
        for (set, column, value) in [
            ("lobe = 'in 1'", "lobe", "in 1"),
            ("lobe = 'IN1', part = 'S 17'", "part", "S 17"),
            ("part = 'S-17', sha256 = 'ABC'", "sha256", "ABC"),
        ] {
            raw_execute(&t.store, &[&format!("UPDATE measurements SET {set}")]).await;
            let err = t.store.measurement_history(&history).await.unwrap_err();
            assert_eq!(err.code(), "invalid", "{err}");
            assert!(err.to_string().contains(column), "{err}");
            assert!(err.to_string().contains(value), "{err}");
        }
        let sha = m.sha256.to_string();
        raw_execute(
            &t.store,
            &[&format!("UPDATE measurements SET sha256 = '{sha}'")],
        )
        .await;
        let page = t.store.measurement_history(&history).await.unwrap();
        assert_eq!(page.items[0].sha256, m.sha256);
        assert_eq!(page.items[0].lobe, "IN1");
        assert_eq!(page.items[0].part, "S-17");
        let part = "S-17".parse().unwrap();
        let rows = t.store.part_measurements(&m.machine, &part).await.unwrap();
        assert_eq!(rows.len(), 1);

        // A part id may hold a dot; a recipe's part name (a plain name) may not.
        raw_execute(
            &t.store,
            &[
                "INSERT INTO recipe_snapshots (machine, part, lobe, kind, recipe_json, sha256, \
               created_at_ms) VALUES ('M1', 'CAM.7', 'IN1', 'lobe', '{}', 'x', 1)",
            ],
        )
        .await;
        let err = t.store.features(&m.machine).await.unwrap_err();
        assert_eq!(err.code(), "invalid", "{err}");
        assert!(err.to_string().contains("part"), "{err}");
        assert!(err.to_string().contains("CAM.7"), "{err}");
    }
}

async fn raw_execute(store: &Store, statements: &[&str]) {
    for sql in statements {
        match store.raw_pool() {
            camloop::store::RawPool::Sqlite(pool) => {
                sqlx::query(sql).execute(pool).await.unwrap();
            }
            camloop::store::RawPool::Postgres(pool) => {
                sqlx::query(sql).execute(pool).await.unwrap();
            }
        }
    }
}
