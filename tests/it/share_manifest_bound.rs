//! The manifest stays bounded in a long run: pushes through a real share past the
//! compaction threshold, then a restart reads the short manifest and goes on where it was.

use crate::share_support;

use camloop::share::{ARCHIVE_FILE, COMPACT_AFTER_LINES, MANIFEST_FILE, VersionStatus};
use share_support::{dirs, next_request, open};

fn lines(path: &std::path::Path) -> usize {
    std::fs::read_to_string(path).map_or(0, |t| t.lines().count())
}

/// 4 lines per push (version, delivering, pushed, pruned): 160 pushes write about 640
/// lines, past the threshold once.
#[test]
fn a_long_run_compacts_the_manifest_and_a_restart_resumes_from_the_checkpoint() {
    let d = dirs();
    let manifest = d.state.join(MANIFEST_FILE);
    let (mut share, _) = open(&d, 3);
    let mut longest = 0;
    for tag in 1..=160 {
        let pushed = share.push_once(next_request(&share, tag)).unwrap();
        assert_eq!(pushed.version.get(), u64::from(tag));
        longest = longest.max(lines(&manifest));
    }
    assert!(
        longest <= COMPACT_AFTER_LINES,
        "manifest reached {longest} lines"
    );
    let archived = lines(&d.state.join(ARCHIVE_FILE));
    assert!(
        archived >= COMPACT_AFTER_LINES - 1,
        "archive holds {archived} lines"
    );
    let now = lines(&manifest);
    assert!(now < 160 * 4 - archived + 2, "{now} lines after compaction");
    let before = share.history().clone();
    drop(share);

    let (mut share, report) = open(&d, 3);
    assert_eq!(report.torn_manifest_bytes, 0);
    assert_eq!(share.history(), &before);
    assert_eq!(share.history().next_version().get(), 161);
    let last = share.history().last_pushed().unwrap();
    assert_eq!(last.record.version.get(), 160);
    assert!(matches!(last.status, VersionStatus::Pushed { .. }));
    // The kept texts of the newest versions survived compaction: a rollback finds them.
    assert_eq!(share.kept_files(ver(159)).unwrap().len(), 1);
    let rollback = share
        .rollback_request(
            ver(158),
            jiff::Timestamp::from_millisecond(1_800_000_000_000).unwrap(),
        )
        .unwrap();
    assert_eq!(rollback.rollback_of, Some(ver(158)));
    assert_eq!(
        share.push_once(next_request(&share, 161)).unwrap().version,
        ver(161)
    );
}

fn ver(n: u64) -> camloop::core::ids::TableVersion {
    camloop::core::ids::TableVersion::new(n).unwrap()
}
