//! The drop folder on a real (temporary) directory: complete files are handed out and stay
//! claimed in the inbox until settled into processed/ or rejected/ (with a reason file),
//! garbage goes to rejected/, files still being written wait. Polls are driven with explicit
//! instants, so no test depends on timing except the watcher's, which only waits on a
//! channel.

use crate::gauge_drop_support;

use std::time::Duration;

use camloop::gauge::{
    DropEvent, DropFolder, DropFolderError, DropOptions, GaugeDbc, Settle, watch_drop_folder,
};
use gauge_drop_support::{FIXTURE, Folder, accepted, fixture_text, names, rejected};

const STABLE_MS: u64 = 10_000;

#[test]
fn a_complete_file_is_handed_out_in_place_and_moved_when_settled() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    std::fs::write(inbox.join(FIXTURE), fixture_text(FIXTURE)).expect("write");

    // No end marker and no declared count: taken once unchanged for stable_ms.
    assert!(f.at(0).is_empty());
    assert!(f.at(STABLE_MS - 1).is_empty());
    let events = f.at(STABLE_MS);
    let [DropEvent::Accepted { measurement, path }] = &events[..] else {
        panic!("{events:?}")
    };
    assert_eq!(path, &inbox.join(FIXTURE));
    assert_eq!(measurement.origin, path.display().to_string());
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
    // Still in the inbox, and claimed: not handed out again.
    assert_eq!(names(inbox), [FIXTURE, "processed", "rejected"]);
    assert!(f.at(STABLE_MS + 1).is_empty());
    assert!(f.at(3 * STABLE_MS).is_empty());

    let moved_to = f
        .folder
        .settle(&inbox.join(FIXTURE), Settle::Processed)
        .expect("settle");
    assert_eq!(moved_to, inbox.join("processed").join(FIXTURE));
    assert_eq!(names(inbox), ["processed", "rejected"]);
    assert_eq!(
        std::fs::read_to_string(&moved_to).expect("read"),
        fixture_text(FIXTURE),
        "content moved untouched"
    );
    // Settled once only.
    let again = f.folder.settle(&inbox.join(FIXTURE), Settle::Processed);
    assert!(
        matches!(again, Err(DropFolderError::NotClaimed { .. })),
        "{again:?}"
    );

    // The same name again collides and gets a suffix; nothing is overwritten.
    std::fs::write(inbox.join(FIXTURE), fixture_text(FIXTURE)).expect("write");
    assert!(f.at(4 * STABLE_MS).is_empty());
    let path = accepted(&f.at(5 * STABLE_MS)).remove(0);
    let moved_to = f.folder.settle(&path, Settle::Processed).expect("settle");
    assert_eq!(
        moved_to.file_name().expect("name"),
        "M3_P1234_L2_20240501T101500-1.csv"
    );
    assert_eq!(
        names(&inbox.join("processed")),
        ["M3_P1234_L2_20240501T101500-1.csv", FIXTURE]
    );
}

/// A measurement that parses but fails the service's checks goes to rejected/ with the
/// service's reason, never to processed/.
#[test]
fn a_file_that_fails_the_checks_is_settled_into_rejected() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    std::fs::write(inbox.join(FIXTURE), fixture_text(FIXTURE)).expect("write");
    assert!(f.at(0).is_empty());
    let path = accepted(&f.at(STABLE_MS)).remove(0);
    let reason = "revolution 2 disagrees with the median by 7.1 µm".to_owned();
    let moved_to = f
        .folder
        .settle(&path, Settle::Rejected { reason })
        .expect("settle");
    assert_eq!(moved_to, inbox.join("rejected").join(FIXTURE));
    assert_eq!(names(&inbox.join("processed")), Vec::<String>::new());
    assert_eq!(
        names(&inbox.join("rejected")),
        [FIXTURE.to_owned(), format!("{FIXTURE}.reason.txt")]
    );
    assert_eq!(
        std::fs::read_to_string(inbox.join("rejected").join(format!("{FIXTURE}.reason.txt")))
            .expect("read"),
        "revolution 2 disagrees with the median by 7.1 µm\n"
    );
}

/// Claims live in memory: after a restart an unsettled file is handed out again.
#[test]
fn an_unsettled_file_is_handed_out_again_after_a_restart() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    std::fs::write(inbox.join(FIXTURE), fixture_text(FIXTURE)).expect("write");
    assert!(f.at(0).is_empty());
    let first = accepted(&f.at(STABLE_MS));
    drop(f);
    let mut f = Folder::open(inbox, STABLE_MS);
    assert!(f.at(0).is_empty(), "a new folder waits for stability again");
    assert_eq!(accepted(&f.at(STABLE_MS)), first);
}

#[test]
fn garbage_is_moved_to_rejected_with_a_reason() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    std::fs::write(
        inbox.join("M3_P1_L1.csv"),
        "rev,angle_deg,lift_mm\n0,0,0.1\n0,zero,0\n",
    )
    .expect("write");
    std::fs::write(inbox.join("notes.txt"), "hello").expect("write");
    std::fs::write(inbox.join("binary.csv"), [0xffu8, 0xfe, 0x00]).expect("write");

    assert!(
        f.at(0).is_empty(),
        "a parse error may be a half-written file"
    );
    let got = rejected(&f.at(STABLE_MS));
    let shown = |name: &str| inbox.join(name).display().to_string();
    assert_eq!(
        got,
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
                format!(
                    "measurement file {} line 1 is not utf-8 text",
                    shown("binary.csv")
                )
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
        format!("{}\n", got[0].1)
    );
    assert_eq!(
        std::fs::read(inbox.join("rejected/binary.csv")).expect("read"),
        [0xff, 0xfe, 0x00]
    );
}

/// A dressing report goes to processed/ at once (one phase) with its radius; a bad one to
/// rejected/ with a reason naming the file and, for syntax, the line.
#[test]
fn dressing_reports_are_read_or_rejected_with_the_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    let write = |name: &str, text: &str| std::fs::write(inbox.join(name), text).expect("write");
    write("d1.dressing.toml", "wheel_radius_mm = 249.998\n# end\n");
    write(
        "d2.DRESSING.TOML",
        "# after dressing\nwheel_radius_mm = 249,99\n",
    );
    write("d3.dressing.toml", "wheel_radius_mm = 0.25\n");
    write("d4.dressing.toml", "radius = 249.9\n");
    write("d5.dressing.toml", "wheel_radius_mm = 250.001\n");
    let events = f.at(0);
    let [DropEvent::Dressing { report, moved_to }] = &events[..] else {
        panic!("with the end marker, taken at once: {events:?}")
    };
    assert_eq!(report.wheel_radius_mm, 249.998);
    assert_eq!(moved_to, &inbox.join("processed/d1.dressing.toml"));

    let events = f.at(STABLE_MS);
    assert_eq!(events.len(), 4, "{events:?}");
    let reasons = rejected(&events[..3]);
    assert!(
        reasons[0].1.contains("d2.DRESSING.TOML line 2"),
        "{}",
        reasons[0].1
    );
    assert!(
        reasons[1].1.contains("0.25 mm is not a plausible"),
        "{}",
        reasons[1].1
    );
    assert!(reasons[2].1.contains("radius"), "{}", reasons[2].1);
    assert!(
        matches!(&events[3], DropEvent::Dressing { report, .. } if report.wheel_radius_mm == 250.001),
        "without the marker, taken once unchanged: {:?}",
        events[3]
    );
    assert!(inbox.join("rejected/d3.dressing.toml.reason.txt").exists());
}

#[test]
fn opening_a_missing_folder_names_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("nope");
    let err = DropFolder::open(&missing, GaugeDbc::builtin(), DropOptions::default())
        .expect_err("missing");
    assert!(
        err.to_string()
            .starts_with(&format!("drop folder {} unusable: ", missing.display())),
        "{err}"
    );
}

#[tokio::test]
async fn the_watcher_delivers_and_settles_on_request() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path().to_owned();
    let options = DropOptions {
        stable_ms: 0,
        ..DropOptions::default()
    };
    let folder = DropFolder::open(&inbox, GaugeDbc::builtin(), options).expect("open");
    std::fs::write(inbox.join(FIXTURE), fixture_text(FIXTURE)).expect("write");
    let (tx, mut rx) = tokio::sync::mpsc::channel(4);
    let (settle_tx, settle_rx) = tokio::sync::mpsc::channel(4);
    let watcher = tokio::spawn(watch_drop_folder(
        folder,
        Duration::from_millis(20),
        tx,
        settle_rx,
    ));
    // Waits on the channel, bounded so a broken watcher fails instead of hanging.
    let mut next = async || {
        tokio::time::timeout(Duration::from_secs(30), rx.recv())
            .await
            .expect("an event within 30 s")
            .expect("the watcher is running")
    };
    let event = next().await;
    let DropEvent::Accepted { measurement, path } = &event else {
        panic!("{event:?}")
    };
    assert_eq!(measurement.samples.len(), 1080);
    settle_tx
        .send((path.clone(), Settle::Processed))
        .await
        .expect("watcher listens");
    let event = next().await;
    assert!(
        matches!(&event, DropEvent::Settled { moved_to, .. } if *moved_to == inbox.join("processed").join(FIXTURE)),
        "{event:?}"
    );
    assert!(inbox.join("processed").join(FIXTURE).exists());
    // With nobody listening, the watcher ends at its next poll.
    drop(rx);
    tokio::time::timeout(Duration::from_secs(30), watcher)
        .await
        .expect("the watcher stops once nobody listens")
        .expect("no panic")
        .expect("no join error");
}

/// A dressing report may carry the dresser's measured infeed; an implausible one rejects the
/// file with a reason naming it.
#[test]
fn a_dressing_report_carries_the_dresser_infeed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    let write = |name: &str, text: &str| std::fs::write(inbox.join(name), text).expect("write");
    write(
        "a.dressing.toml",
        "wheel_radius_mm = 249.98\ninfeed_um = 20.3\n# end\n",
    );
    write(
        "b.dressing.toml",
        "wheel_radius_mm = 249.98\ninfeed_um = -2.0\n# end\n",
    );
    let events = f.at(0);
    assert!(
        matches!(&events[..], [DropEvent::Dressing { report, .. }]
            if report.wheel_radius_mm == 249.98 && report.infeed_um == Some(20.3)),
        "{events:?}"
    );
    // A report that does not read is rejected once it has stayed unchanged (it may still be
    // being written), as any other.
    let events = f.at(STABLE_MS);
    let reasons = rejected(&events);
    assert!(
        reasons[0].1.contains("b.dressing.toml") && reasons[0].1.contains("dresser infeed -2"),
        "{}",
        reasons[0].1
    );
}

/// A gauge marks the master's run with a `# master=<id>` line: the drop folder hands out a
/// measurement whose part is the master run's (`MASTER-<id>`), which the service then keeps
/// for the gauge study and never learns from; the same file without the line is a part.
#[test]
fn a_master_line_makes_the_file_a_master_run() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    let text = fixture_text(FIXTURE);
    std::fs::write(inbox.join(FIXTURE), format!("# master=M-0417\n{text}")).expect("write");
    // No end marker: taken once unchanged for stable_ms, as any file.
    assert!(f.at(0).is_empty());
    let events = f.at(STABLE_MS);
    let [DropEvent::Accepted { measurement, .. }] = &events[..] else {
        panic!("{events:?}")
    };
    assert_eq!(measurement.header.part, "MASTER-M-0417");
    assert!(camloop::core::measure::is_master_part(
        &measurement.header.part
    ));
    assert_eq!(
        (
            measurement.header.machine.as_str(),
            measurement.header.lobe.as_str()
        ),
        ("M3", "L2"),
        "the rest of the identity from the file name as before"
    );
}
