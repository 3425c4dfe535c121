//! When the drop folder takes a file: at once when it is complete (the `# end` marker, or a
//! declared revolution count met), else once it has been unchanged for `stable_ms`; never
//! under a temporary name; never read when it is over the size limit. Time is passed in as
//! instants, so a 10 s stability rule is tested without waiting.

use crate::gauge_drop_support;

use std::io::Write;
use std::path::Path;

use camloop::gauge::{DropEvent, DropOptions, Rejection};
use gauge_drop_support::{FIXTURE, Folder, accepted, fixture_text, names, only_rejection, rows};

const STABLE_MS: u64 = 10_000;

fn append(path: &Path, text: &str) {
    let mut file = std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .expect("open for append");
    file.write_all(text.as_bytes()).expect("append");
}

fn revolutions_of(events: &[DropEvent]) -> (u32, usize) {
    match events {
        [DropEvent::Accepted { measurement, .. }] => {
            (measurement.header.revolutions, measurement.samples.len())
        }
        other => panic!("expected one accepted file: {other:?}"),
    }
}

/// The fault campaign's case: the gauge PC pauses 3 s after revolution 3 of 5. The file is
/// not taken as a 3-revolution part; it is taken whole once it stops changing.
#[test]
fn a_writer_pausing_after_revolution_three_is_not_taken_early() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    let path = inbox.join("M3_P1_L1.csv");
    std::fs::write(&path, rows(0..3, 360)).expect("write revolutions 0-2");
    assert!(f.at(0).is_empty());
    assert!(f.at(1_000).is_empty());
    assert!(f.at(3_000).is_empty(), "3 s unchanged is not finished");
    append(
        &path,
        &rows(3..5, 360).replace("rev,angle_deg,lift_mm\n", ""),
    );
    assert!(f.at(3_100).is_empty(), "it changed: the wait starts again");
    assert!(f.at(3_100 + STABLE_MS - 1).is_empty());
    assert_eq!(revolutions_of(&f.at(3_100 + STABLE_MS)), (5, 1800));
    assert!(path.exists(), "handed out in place");
}

/// The `# end` marker makes a file complete at once, whatever the stability rule says.
#[test]
fn the_end_marker_takes_a_file_at_the_next_poll() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    let path = inbox.join("M3_P1_L1.csv");
    std::fs::write(&path, rows(0..3, 360)).expect("write");
    assert!(f.at(0).is_empty());
    assert!(f.at(STABLE_MS - 1).is_empty());
    append(&path, "# end\n");
    assert_eq!(revolutions_of(&f.at(STABLE_MS - 1)), (3, 1080));

    let other = inbox.join("M3_P1_L2.csv");
    std::fs::write(&other, format!("{}# END\n", rows(1..4, 360))).expect("write");
    assert_eq!(
        revolutions_of(&f.at(STABLE_MS)),
        (3, 1080),
        "marked complete, numbered from 1: taken at first sight"
    );
}

/// A declared count makes a file complete as soon as every declared reading is there.
#[test]
fn a_declared_revolution_count_takes_the_file_when_met() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    let path = inbox.join("M3_P1_L1.csv");
    let meta = "# revolutions=5 points_per_rev=360\n";
    std::fs::write(&path, format!("{meta}{}", rows(1..4, 360))).expect("write 3 of 5");
    assert!(f.at(0).is_empty());
    assert!(f.at(STABLE_MS - 1).is_empty(), "3 of 5: waits");
    // Every reading is there, but the last line has no newline yet: `0.00061` may be the
    // start of `0.000613`, so the file is not complete.
    let rest = rows(4..6, 360).replace("rev,angle_deg,lift_mm\n", "");
    let (head, tail) = rest.split_at(rest.len() - 2);
    append(&path, head);
    assert!(f.at(STABLE_MS - 1).is_empty(), "last line not ended: waits");
    append(&path, tail);
    assert_eq!(revolutions_of(&f.at(STABLE_MS)), (5, 1800));
}

/// A file that declares more than it holds stays in the inbox (not rejected) while it may
/// still grow, and is rejected once unchanged for `stable_ms`, or at once when it also says
/// it has ended, saying how many revolutions were found and declared.
#[test]
fn a_file_short_of_its_declared_count_waits_then_is_rejected() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    let path = inbox.join("M3_P1_L1.csv");
    let meta = "# revolutions=5 points_per_rev=360\n";
    std::fs::write(&path, format!("{meta}{}", rows(0..3, 360))).expect("write");
    assert!(f.at(0).is_empty());
    assert!(f.at(STABLE_MS - 1).is_empty());
    assert_eq!(names(inbox), ["M3_P1_L1.csv", "processed", "rejected"]);
    let events = f.at(STABLE_MS);
    let reason = only_rejection(&events);
    assert!(
        matches!(
            reason,
            Rejection::Incomplete {
                declared: 5,
                found: 3,
                readings_found: 1080,
                readings_expected: 1800,
                ..
            }
        ),
        "{reason:?}"
    );
    assert_eq!(
        reason.to_string(),
        format!(
            "measurement file {} declares 5 revolutions of 360 points but holds 3 revolutions \
             (1080 of 1800 readings) and has not changed for 10000 ms",
            path.display()
        )
    );
    assert!(inbox.join("rejected/M3_P1_L1.csv.reason.txt").exists());

    let ended = inbox.join("M3_P1_L2.csv");
    std::fs::write(&ended, format!("{meta}{}# end\n", rows(0..4, 360))).expect("write");
    let events = f.at(STABLE_MS + 1);
    assert_eq!(
        only_rejection(&events).to_string(),
        format!(
            "measurement file {} declares 5 revolutions of 360 points but holds 4 revolutions \
             (1440 of 1800 readings) and ends with the `# end` marker",
            ended.display()
        )
    );
}

/// Write-then-rename: names starting with `.` or ending in `.tmp`/`.part` are never read,
/// however long they stay unchanged; the renamed file follows the normal rules.
#[test]
fn temporary_names_are_never_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::open(inbox, STABLE_MS);
    let text = format!("{}# end\n", fixture_text(FIXTURE));
    for name in [".M3_P1_L1.csv", "M3_P1_L2.csv.tmp", "M3_P1_L3.csv.part"] {
        std::fs::write(inbox.join(name), &text).expect("write");
    }
    for ms in [0, STABLE_MS, 100 * STABLE_MS] {
        assert!(f.at(ms).is_empty());
    }
    std::fs::rename(inbox.join("M3_P1_L2.csv.tmp"), inbox.join("M3_P1_L2.csv")).expect("mv");
    assert_eq!(
        accepted(&f.at(100 * STABLE_MS + 1)),
        [inbox.join("M3_P1_L2.csv")]
    );
}

/// A file over the size limit is rejected by its metadata, with its size and the limit.
#[test]
fn a_file_over_the_size_limit_is_rejected_unread() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let mut f = Folder::with(
        inbox,
        DropOptions {
            stable_ms: STABLE_MS,
            max_file_bytes: 20_000,
        },
    );
    let path = inbox.join(FIXTURE);
    std::fs::write(&path, format!("{}# end\n", fixture_text(FIXTURE))).expect("write");
    let bytes = std::fs::metadata(&path).expect("metadata").len();
    assert!(bytes > 20_000);
    assert!(f.at(0).is_empty(), "rejected only once it stops changing");
    let events = f.at(STABLE_MS);
    assert_eq!(
        only_rejection(&events).to_string(),
        format!(
            "file {} is {bytes} bytes, over the drop folder's limit of 20000 bytes: not read",
            path.display()
        )
    );
    assert_eq!(names(&inbox.join("rejected")).len(), 2);
}
