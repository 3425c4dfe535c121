//! What is not a regular file in the drop folder (symbolic links, named pipes, directories)
//! is moved aside to rejected/ with a reason, never opened or followed; a file whose name is
//! not UTF-8 keeps its bytes and is named in reasons both lossily and escaped.
#![cfg(unix)]

use crate::gauge_drop_support;

use std::ffi::OsStr;
use std::os::unix::ffi::OsStrExt;
use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

use camloop::gauge::{DropEvent, Settle};
use gauge_drop_support::{FIXTURE, Folder, accepted, fixture_text, names, rejected};

const STABLE_MS: u64 = 10_000;

fn complete_csv() -> String {
    format!("{}# end\n", fixture_text(FIXTURE))
}

#[test]
fn links_pipes_and_folders_are_moved_aside_unopened() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path().join("inbox");
    std::fs::create_dir(&inbox).expect("inbox");
    let outside = dir.path().join("outside.csv");
    std::fs::write(&outside, complete_csv()).expect("write");
    std::os::unix::fs::symlink(&outside, inbox.join("M3_P1_L1.csv")).expect("symlink");
    std::os::unix::fs::symlink(dir.path().join("gone"), inbox.join("dangling.csv"))
        .expect("symlink");
    std::fs::create_dir(inbox.join("sub")).expect("mkdir");
    std::fs::write(inbox.join("sub/M3_P1_L2.csv"), complete_csv()).expect("write");
    let status = std::process::Command::new("mkfifo")
        .arg(inbox.join("pipe.csv"))
        .status()
        .expect("run mkfifo");
    assert!(status.success());

    // Opening the fifo would block: poll on a thread so a regression fails, not hangs.
    let mut f = Folder::open(&inbox, STABLE_MS);
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let events = f.at(0);
        tx.send(rejected(&events)).expect("send");
    });
    let got = rx
        .recv_timeout(Duration::from_secs(30))
        .expect("the poll returns: nothing was opened");
    let shown = |name: &str| inbox.join(name).display().to_string();
    let why = "not a regular file: moved aside without opening or following it";
    assert_eq!(
        got,
        [
            (
                "M3_P1_L1.csv".to_owned(),
                format!("{} is a symbolic link, {why}", shown("M3_P1_L1.csv"))
            ),
            (
                "dangling.csv".to_owned(),
                format!("{} is a symbolic link, {why}", shown("dangling.csv"))
            ),
            (
                "pipe.csv".to_owned(),
                format!("{} is a named pipe (fifo), {why}", shown("pipe.csv"))
            ),
            (
                "sub".to_owned(),
                format!("{} is a directory, {why}", shown("sub"))
            ),
        ]
    );
    assert_eq!(names(&inbox), ["processed", "rejected"]);
    let moved = inbox.join("rejected");
    let link = std::fs::symlink_metadata(moved.join("M3_P1_L1.csv")).expect("moved link");
    assert!(link.file_type().is_symlink(), "the link itself was moved");
    assert_eq!(
        std::fs::read_to_string(&outside).expect("target"),
        complete_csv(),
        "the link's target is untouched"
    );
    assert!(outside.exists());
    assert!(moved.join("sub/M3_P1_L2.csv").exists());
    assert!(moved.join("sub.reason.txt").exists());
    assert!(moved.join("pipe.csv.reason.txt").exists());
}

#[test]
fn a_non_utf8_name_keeps_its_bytes_and_is_shown_escaped() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    let good = OsStr::from_bytes(b"scan_\xff.csv");
    let text = format!("# machine=M3 part=P1 lobe=L1\n{}", complete_csv());
    std::fs::write(inbox.join(good), text).expect("write");
    let bad = OsStr::from_bytes(b"notes_\xfe.txt");
    std::fs::write(inbox.join(bad), "hello").expect("write");

    let events = f.at(0);
    let [DropEvent::Accepted { path, measurement }] = &events[..] else {
        panic!("{events:?}")
    };
    assert_eq!(path.file_name().expect("name"), good);
    assert_eq!(measurement.header.lobe, "L1");
    let moved_to = f
        .folder
        .settle(
            path,
            Settle::Rejected {
                reason: "too few revolutions".to_owned(),
            },
        )
        .expect("settle");
    assert_eq!(moved_to, inbox.join("rejected").join(good));
    let mut reason_name = good.to_os_string();
    reason_name.push(".reason.txt");
    assert!(inbox.join("rejected").join(reason_name).exists());

    let events = f.at(STABLE_MS);
    let got = rejected(&events);
    assert_eq!(
        got,
        [(
            "notes_\u{fffd}.txt".to_owned(),
            format!(
                "measurement file {} (file name bytes \"notes_\\xfe.txt\") has no .csv or \
                 .log extension",
                Path::new(inbox).join("notes_\u{fffd}.txt").display()
            )
        )]
    );
    assert!(
        inbox.join("rejected").join(bad).exists(),
        "moved under its own bytes"
    );
    assert!(accepted(&f.at(2 * STABLE_MS)).is_empty());
}
