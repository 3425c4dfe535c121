//! Memory stays bounded by the parsed samples, not the file size: a file over the limit is
//! refused from its metadata, and a large file within it is parsed line by line. Measured
//! as the growth of this process's peak resident set (VmHWM, Linux), alone in its own test
//! binary so no other test allocates meanwhile. Reading a file whole would raise the peak
//! by at least its size (64 MiB and 14 MiB here); the bound checked is 6 MiB.
#![cfg(target_os = "linux")]

use crate::gauge_drop_support;

use std::io::Write;

use camloop::gauge::{DropEvent, GaugeDbc, GaugeError, read_measurement_file};
use gauge_drop_support::{FIXTURE, Folder, fixture_text, only_rejection};

const STABLE_MS: u64 = 10_000;
const MIB: u64 = 1024 * 1024;
const BOUND_BYTES: u64 = 6 * MIB;

/// Peak resident set of this process so far, bytes.
fn peak_rss_bytes() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("proc status");
    let kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmHWM in kB");
    kb * 1024
}

#[test]
fn peak_memory_does_not_grow_with_the_file_size() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inbox = dir.path();
    let base = peak_rss_bytes();

    // 100 MB, sparse: costs no disk, but reading it would fill memory with zeros.
    let huge = inbox.join("M3_P1_L1.csv");
    std::fs::File::create(&huge)
        .expect("create")
        .set_len(100 * MIB)
        .expect("set_len");
    let direct = read_measurement_file(&huge, &GaugeDbc::builtin());
    assert!(
        matches!(direct, Err(GaugeError::TooLarge { bytes, .. }) if bytes == 100 * MIB),
        "{direct:?}"
    );
    let mut f = Folder::open(inbox, STABLE_MS);
    assert!(f.at(0).is_empty());
    let events = f.at(STABLE_MS);
    assert!(
        only_rejection(&events)
            .to_string()
            .contains("is 104857600 bytes, over the drop folder's limit of 16777216 bytes"),
        "{events:?}"
    );
    let grown = peak_rss_bytes().saturating_sub(base);
    eprintln!("after refusing 100 MB: peak grew by {grown} bytes");
    assert!(grown < BOUND_BYTES, "peak grew by {grown} bytes");

    // 14 MiB of comment lines, then a 3 × 360 measurement: within the 16 MiB limit.
    let big = inbox.join("M3_P1_L2.csv");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&big).expect("create"));
    let comment = format!("# {}\n", "x".repeat(1021));
    for _ in 0..14 * 1024 {
        file.write_all(comment.as_bytes()).expect("write");
    }
    file.write_all(fixture_text(FIXTURE).as_bytes())
        .expect("write");
    file.write_all(b"# end\n").expect("write");
    file.flush().expect("flush");
    drop(file);
    assert!(std::fs::metadata(&big).expect("metadata").len() > 14 * MIB);
    let events = f.at(STABLE_MS + 1);
    assert!(
        matches!(&events[..], [DropEvent::Accepted { measurement, .. }] if measurement.samples.len() == 1080),
        "{events:?}"
    );
    let grown = peak_rss_bytes().saturating_sub(base);
    eprintln!("after parsing 14 MiB: peak grew by {grown} bytes");
    assert!(grown < BOUND_BYTES, "peak grew by {grown} bytes");
}
