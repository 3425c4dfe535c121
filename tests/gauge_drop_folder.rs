//! The drop folder on a real (temporary) directory: complete files are parsed and moved to
//! processed/, garbage to rejected/ with a reason file, files still being written wait.
//! Polls are driven explicitly, so no test depends on timing except the last one, which
//! only waits on a channel.

use std::path::{Path, PathBuf};
use std::time::Duration;

use camloop::gauge::{DropEvent, DropFolder, GaugeDbc, watch_drop_folder};

const FIXTURE: &str = "M3_P1234_L2_20240501T101500.csv";

fn fixture_text(name: &str) -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("list")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn a_complete_file_is_taken_on_the_second_poll_and_moved() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut folder = DropFolder::open(inbox, GaugeDbc::builtin()).expect("open");
    std::fs::write(inbox.join(FIXTURE), fixture_text(FIXTURE)).expect("write");

    assert_eq!(
        folder.poll(),
        [],
        "first sighting only records size and mtime"
    );
    assert!(inbox.join(FIXTURE).exists());

    let events = folder.poll();
    assert_eq!(events.len(), 1, "{events:?}");
    let DropEvent::Accepted {
        measurement,
        moved_to,
    } = &events[0]
    else {
        panic!("{events:?}")
    };
    assert_eq!(moved_to, &inbox.join("processed").join(FIXTURE));
    assert_eq!(measurement.origin, moved_to.display().to_string());
    assert_eq!(
        (
            measurement.header.machine.as_str(),
            measurement.header.part.as_str(),
            measurement.header.lobe.as_str()
        ),
        ("M3", "P1234", "L2")
    );
    assert_eq!(
        (
            measurement.header.revolutions,
            measurement.header.points_per_rev
        ),
        (3, 360)
    );
    assert_eq!(measurement.samples.len(), 1080);
    assert_eq!(names(inbox), ["processed", "rejected"]);
    assert_eq!(names(&inbox.join("processed")), [FIXTURE]);
    // Content moved untouched.
    assert_eq!(
        std::fs::read_to_string(moved_to).expect("read"),
        fixture_text(FIXTURE)
    );

    // The same name again collides and gets a suffix; nothing is overwritten.
    std::fs::write(inbox.join(FIXTURE), fixture_text(FIXTURE)).expect("write");
    assert_eq!(folder.poll(), []);
    let events = folder.poll();
    assert!(matches!(&events[..], [DropEvent::Accepted { moved_to, .. }]
        if moved_to.file_name().is_some_and(|n| n == "M3_P1234_L2_20240501T101500-1.csv")));
    assert_eq!(
        names(&inbox.join("processed")),
        ["M3_P1234_L2_20240501T101500-1.csv", FIXTURE]
    );
}

#[test]
fn garbage_is_moved_to_rejected_with_a_reason() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut folder = DropFolder::open(inbox, GaugeDbc::builtin()).expect("open");
    std::fs::write(
        inbox.join("M3_P1_L1.csv"),
        "rev,angle_deg,lift_mm\n0,0,0.1\n0,zero,0\n",
    )
    .expect("write");
    std::fs::write(inbox.join("notes.txt"), "hello").expect("write");
    std::fs::write(inbox.join("binary.csv"), [0xffu8, 0xfe, 0x00]).expect("write");

    assert_eq!(folder.poll(), []);
    let events = folder.poll();
    let rejected: Vec<(String, String)> = events
        .iter()
        .map(|e| match e {
            DropEvent::Rejected {
                moved_to, reason, ..
            } => (
                moved_to
                    .file_name()
                    .expect("name")
                    .to_string_lossy()
                    .into_owned(),
                reason.clone(),
            ),
            other => panic!("{other:?}"),
        })
        .collect();
    let shown = |name: &str| inbox.join(name).display().to_string();
    assert_eq!(
        rejected,
        [
            (
                "M3_P1_L1.csv".to_owned(),
                format!(
                    "measurement file {}: line 3: angle \"zero\" is not a number in [0, 360) \
                     degrees",
                    shown("M3_P1_L1.csv")
                )
            ),
            (
                "binary.csv".to_owned(),
                format!("measurement file {} is not utf-8 text", shown("binary.csv"))
            ),
            (
                "notes.txt".to_owned(),
                format!(
                    "measurement file {} has no .csv or .log extension",
                    shown("notes.txt")
                )
            ),
        ]
    );
    assert_eq!(names(inbox), ["processed", "rejected"]);
    assert_eq!(
        names(&inbox.join("rejected")),
        [
            "M3_P1_L1.csv",
            "M3_P1_L1.csv.reason.txt",
            "binary.csv",
            "binary.csv.reason.txt",
            "notes.txt",
            "notes.txt.reason.txt"
        ]
    );
    assert_eq!(
        std::fs::read_to_string(inbox.join("rejected/M3_P1_L1.csv.reason.txt")).expect("read"),
        format!("{}\n", rejected[0].1)
    );
    assert_eq!(
        std::fs::read(inbox.join("rejected/binary.csv")).expect("read"),
        [0xff, 0xfe, 0x00]
    );
}

#[test]
fn a_file_still_being_written_is_not_taken() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut folder = DropFolder::open(inbox, GaugeDbc::builtin()).expect("open");
    let text = fixture_text(FIXTURE);
    let (head, tail) = text.split_at(text.len() / 2);
    let path = inbox.join(FIXTURE);
    std::fs::write(&path, head).expect("write first half");
    assert_eq!(folder.poll(), []);
    // The writer appends between polls: the size changed, so the file waits.
    let mut grown = head.to_owned();
    grown.push_str(&tail[..10]);
    std::fs::write(&path, &grown).expect("write more");
    assert_eq!(folder.poll(), []);
    assert!(path.exists());
    std::fs::write(&path, &text).expect("write the rest");
    assert_eq!(folder.poll(), []);
    assert!(path.exists());
    // Unchanged over two polls: taken, and complete.
    let events = folder.poll();
    assert!(
        matches!(&events[..], [DropEvent::Accepted { measurement, .. }] if measurement.samples.len() == 1080),
        "{events:?}"
    );

    // A writer that uses a temporary name: never taken, however stable, until renamed.
    let tmp = inbox.join("M3_P1234_L3.csv.tmp");
    std::fs::write(&tmp, text.replace("# written", "# also written")).expect("write");
    assert_eq!(folder.poll(), []);
    assert_eq!(folder.poll(), []);
    assert_eq!(folder.poll(), []);
    assert!(tmp.exists());
    std::fs::rename(&tmp, inbox.join("M3_P1234_L3.csv")).expect("rename in");
    assert_eq!(folder.poll(), []);
    let events = folder.poll();
    assert!(
        matches!(&events[..], [DropEvent::Accepted { measurement, .. }] if measurement.header.lobe == "L3"),
        "{events:?}"
    );
}

#[test]
fn opening_a_missing_folder_names_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("nope");
    let err = DropFolder::open(&missing, GaugeDbc::builtin()).expect_err("missing");
    assert!(
        err.to_string()
            .starts_with(&format!("drop folder {} unusable: ", missing.display())),
        "{err}"
    );
}

#[tokio::test]
async fn the_watcher_delivers_on_its_interval() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path().to_owned();
    let folder = DropFolder::open(&inbox, GaugeDbc::builtin()).expect("open");
    std::fs::write(inbox.join(FIXTURE), fixture_text(FIXTURE)).expect("write");
    let (tx, mut rx) = tokio::sync::mpsc::channel(4);
    let watcher = tokio::spawn(watch_drop_folder(folder, Duration::from_millis(20), tx));
    // Waits on the channel, bounded so a broken watcher fails instead of hanging.
    let event = tokio::time::timeout(Duration::from_secs(30), rx.recv())
        .await
        .expect("an event within 30 s")
        .expect("the watcher is running");
    assert!(
        matches!(&event, DropEvent::Accepted { measurement, .. } if measurement.samples.len() == 1080),
        "{event:?}"
    );
    // With nobody listening, the watcher ends at its next poll.
    drop(rx);
    tokio::time::timeout(Duration::from_secs(30), watcher)
        .await
        .expect("the watcher stops once nobody listens")
        .expect("no panic")
        .expect("no join error");
}
