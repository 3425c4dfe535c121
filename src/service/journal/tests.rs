//! The journal's tests: torn lines, quarantine, records the store refuses, replays that
//! write nothing twice.

use super::*;
use crate::core::learn::LearningParams;
use crate::service::machine::memory::{LoopMemory, TableLearning};
use crate::store::{EventLevel, VersionStatus};

fn event(message: &str) -> Pending {
    Pending::Event {
        machine: "M1".parse().unwrap(),
        at: jiff::Timestamp::from_millisecond(7).unwrap(),
        level: EventLevel::Info,
        kind: EventKind::WheelDressed,
        message: message.into(),
    }
}

fn learning(parts: u64) -> Pending {
    let mut state = LoopMemory::new(250.0);
    state.parts = parts;
    Pending::Learning {
        machine: "M1".parse().unwrap(),
        lobe: "IN1".parse().unwrap(),
        state: Box::new(state),
        saved_at: jiff::Timestamp::from_millisecond(7 + parts as i64).unwrap(),
    }
}

/// A journal that cannot be opened says which file and why, as a typed error the caller
/// can match on.
#[test]
fn a_journal_that_cannot_be_opened_names_its_folder_and_the_cause() {
    let dir = tempfile::tempdir().unwrap();
    let not_a_folder = dir.path().join("state");
    std::fs::write(&not_a_folder, "a file where the folder should be").unwrap();
    let e = Journal::open(&not_a_folder).unwrap_err();
    assert!(
        matches!(&e, JournalError::File { what: "create", path, .. } if *path == not_a_folder),
        "{e:?}"
    );
    let text = e.to_string();
    assert!(
        text.starts_with(&format!("cannot create {}: ", not_a_folder.display())),
        "{text}"
    );
}

#[test]
fn records_survive_a_torn_last_line() {
    let dir = tempfile::tempdir().unwrap();
    let mut j = Journal::open(dir.path()).unwrap();
    let e = event("m");
    j.append(&[e.clone(), e.clone()]).unwrap();
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(dir.path().join("journal.jsonl"))
        .unwrap();
    f.write_all(b"{\"record\":\"event\",\"mach").unwrap();
    // Reopened after the crash: the torn tail is cut, so the next record stands alone.
    let mut j = Journal::open(dir.path()).unwrap();
    assert_eq!(j.pending(), [e.clone(), e.clone()]);
    assert!(
        j.quarantined().is_empty(),
        "a torn tail is cut, not quarantined"
    );
    j.append(std::slice::from_ref(&e)).unwrap();
    assert_eq!(Journal::open(dir.path()).unwrap().pending().len(), 3);
}

/// A whole line that does not parse (a newer layout, a disk error) is moved to the
/// quarantine file and reported with its line number; the records around it stay.
#[test]
fn unreadable_lines_are_quarantined_not_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let good = serde_json::to_string(&event("a")).unwrap();
    let bad = r#"{"record":"measurement","machine":"M1","pass":true}"#;
    std::fs::write(
        dir.path().join("journal.jsonl"),
        format!("{good}\n{bad}\n{good}\n"),
    )
    .unwrap();
    let j = Journal::open(dir.path()).unwrap();
    assert_eq!(j.pending(), [event("a"), event("a")]);
    assert_eq!(j.quarantined().len(), 1);
    assert_eq!(j.quarantined()[0].line, 2);
    let kept = std::fs::read_to_string(dir.path().join(QUARANTINE_FILE)).unwrap();
    assert_eq!(kept, format!("{bad}\n"));
    // Reported once: the journal no longer holds the line.
    assert!(Journal::open(dir.path()).unwrap().quarantined().is_empty());
}

/// A record the store refuses for good (here the status of a version it has never
/// heard of) is set aside with the store's reason, and the records behind it still go
/// in: before, the flush stopped at it on every attempt, and the history behind it
/// stalled for good.
#[tokio::test]
async fn a_record_the_store_refuses_is_set_aside_and_the_rest_go_in() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.path().display());
    let store = Store::connect(&url).await.unwrap();
    let orphan = Pending::VersionStatus {
        machine: "M1".parse().unwrap(),
        lobe: "IN1".parse().unwrap(),
        version: v(41),
        status: VersionStatus::pushed_at(jiff::Timestamp::from_millisecond(8).unwrap(), "x"),
        at: jiff::Timestamp::from_millisecond(8).unwrap(),
    };
    let mut j = Journal::open(dir.path()).unwrap();
    j.append(&[event("a"), orphan.clone(), event("b")]).unwrap();
    let flushed = j.flush(&store).await.unwrap();
    assert_eq!(flushed.written, 2);
    assert_eq!(flushed.refused.len(), 1);
    assert_eq!(flushed.refused[0].kind, "table_status");
    assert!(
        flushed.refused[0].reason.contains("not found"),
        "{:?}",
        flushed.refused
    );
    assert!(j.pending().is_empty());
    let kept = std::fs::read_to_string(dir.path().join(REFUSED_FILE)).unwrap();
    let line: serde_json::Value = serde_json::from_str(kept.trim_end()).unwrap();
    assert_eq!(line["code"], "not_found");
    let back: Pending = serde_json::from_value(line["record"].clone()).unwrap();
    assert_eq!(back, orphan);
    // The journal file no longer holds it: a restart does not meet it again.
    assert_eq!(
        Journal::open(dir.path()).unwrap().records(),
        [event("a"), event("b")]
    );
    let filter = crate::store::EventFilter {
        machine: Some("M1".parse().unwrap()),
        since: None,
        until: None,
        level: None,
        limit: 10,
    };
    let events = store.events(&filter).await.unwrap();
    assert_eq!(events.len(), 2, "{events:?}");
}

/// A journal left by a build whose table records spelled the status as the store's
/// columns (`status` beside `status_why` or `why`) replays into the store with the same
/// status and text, nothing quarantined.
#[tokio::test]
async fn a_journal_with_column_spelled_statuses_replays() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.path().display());
    let store = Store::connect(&url).await.unwrap();
    let table = r#"{"record":"table","machine":"M1","lobe":"IN1","version":1,"parent_version":null,"table_number":1,"program_text":"CTABDEF(X,C,1,1)\nCTABEND\n","learning":{"iteration":0,"params":{},"wheel_radius_mm":250.0,"correction_um":[0.0],"timing_correction_deg":0.0},"reason":"nominal table","status":"waiting","status_why":"waiting: share full","created_at_ms":7}"#;
    let later = r#"{"record":"table_status","machine":"M1","lobe":"IN1","version":1,"status":"pushed","why":"pushed to the share on retry","at_ms":9}"#;
    std::fs::write(
        dir.path().join("journal.jsonl"),
        format!("{table}\n{later}\n"),
    )
    .unwrap();
    let mut j = Journal::open(dir.path()).unwrap();
    assert!(j.quarantined().is_empty(), "{:?}", j.quarantined());
    assert_eq!(j.flush(&store).await.unwrap().written, 2);
    let v = store
        .table_version(&"M1".parse().unwrap(), &"IN1".parse().unwrap(), v(1))
        .await
        .unwrap()
        .unwrap();
    let pushed = VersionStatus::Pushed {
        at: jiff::Timestamp::from_millisecond(9).expect("a time"),
        note: Some("pushed to the share on retry".into()),
    };
    assert_eq!(
        (v.status, v.status_at),
        (pushed, jiff::Timestamp::from_millisecond(9).unwrap())
    );
    let crate::store::RawPool::Sqlite(pool) = store.raw_pool() else {
        panic!("a SQLite store")
    };
    let rows: Vec<(String, String, i64)> =
        sqlx::query_as("SELECT status, why, at_ms FROM table_version_status ORDER BY id")
            .fetch_all(pool)
            .await
            .unwrap();
    let first = ("waiting".to_string(), "waiting: share full".to_string(), 7);
    let second = ("pushed".into(), "pushed to the share on retry".into(), 9);
    assert_eq!(rows, [first, second]);
}

/// One record of every kind the journal carries: an event, a table version (waiting),
/// its later status (pushed), a learning state and a dressing.
fn every_kind_of_record() -> Vec<Pending> {
    let table = TableLearning {
        iteration: 0,
        params: LearningParams::default(),
        wheel_radius_mm: 250.0,
        correction_um: vec![0.0; 4],
        timing_correction_deg: 0.0,
    };
    vec![
        event("a"),
        Pending::Table {
            machine: "M1".parse().unwrap(),
            lobe: "IN1".parse().unwrap(),
            version: v(3),
            parent_version: None,
            table_number: 1,
            program_text: "CTABDEF(X,C,1,1)\nCTABEND\n".into(),
            learning: table,
            reason: "nominal table".into(),
            status: VersionStatus::Waiting {
                reason: Some("waiting: share full".into()),
            },
            created_at: jiff::Timestamp::from_millisecond(7).unwrap(),
            measurement_id: None,
            rollback_of: None,
        },
        Pending::VersionStatus {
            machine: "M1".parse().unwrap(),
            lobe: "IN1".parse().unwrap(),
            version: v(3),
            status: VersionStatus::Pushed {
                at: jiff::Timestamp::from_millisecond(8).expect("a time"),
                note: Some("pushed on retry".into()),
            },
            at: jiff::Timestamp::from_millisecond(8).unwrap(),
        },
        learning(1),
        Pending::Dressing {
            machine: "M1".parse().unwrap(),
            at: jiff::Timestamp::from_millisecond(7).unwrap(),
            old_radius_mm: 250.0,
            new_radius_mm: 249.998,
            infeed_um: Some(2.1),
            source: "api".into(),
        },
    ]
}

/// Every kind of record replayed after a crash (written, not yet released) is recognised
/// in the store and not written again; a second event that differs only in its message
/// still goes in. After the release the newest learning state stays in the journal, so
/// a restart with the database down still finds the loop's memory.
#[tokio::test]
async fn a_replay_writes_nothing_twice() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.path().display());
    let store = Store::connect(&url).await.unwrap();
    let records = every_kind_of_record();
    let mut j = Journal::open(dir.path()).unwrap();
    j.append(&records).unwrap();
    assert_eq!(j.flush(&store).await.unwrap().written, 5);
    // The crash: the journal is read back with every record still in it.
    let mut j = Journal::open(dir.path()).unwrap();
    j.append(&[event("b")]).unwrap();
    assert_eq!(j.flush(&store).await.unwrap().written, 6);
    let crate::store::RawPool::Sqlite(pool) = store.raw_pool() else {
        panic!("a SQLite store")
    };
    for (table, rows) in [
        ("events", 2),
        ("table_versions", 1),
        ("table_version_status", 2),
        ("learning_states", 1),
        ("dressings", 1),
    ] {
        let n: i64 = sqlx::query_scalar(&format!("SELECT COUNT(*) FROM {table}"))
            .fetch_one(pool)
            .await
            .unwrap();
        assert_eq!(n, rows, "{table}");
    }
    // The version keeps the share's number, and its newest status is the retry's.
    let v = store
        .table_version(&"M1".parse().unwrap(), &"IN1".parse().unwrap(), v(3))
        .await
        .unwrap()
        .unwrap();
    let pushed = VersionStatus::Pushed {
        at: jiff::Timestamp::from_millisecond(8).expect("a time"),
        note: Some("pushed on retry".into()),
    };
    assert_eq!(
        (v.version, v.status),
        (crate::core::ids::TableVersion::new(3).unwrap(), pushed)
    );
    assert_eq!(j.release_durable(&store).await.unwrap(), 6);
    let reopened = Journal::open(dir.path()).unwrap();
    assert_eq!(reopened.records(), [learning(1)]);
}

fn v(n: u64) -> crate::core::ids::TableVersion {
    crate::core::ids::TableVersion::new(n).unwrap()
}
