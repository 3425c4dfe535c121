//! One push of a 360-point G1 curve table (about 7.7 KB of text) to a share folder on the
//! real file system: store the kept text, write the temporary, fsync, rename, fsync the
//! folder, read back, verify, append the manifest lines (8 fsyncs in all, 9 once pruning
//! starts).

// The share tests' table programs; the bench uses only those.
#[allow(dead_code)]
#[path = "../tests/share_support/mod.rs"]
mod share_support;
use share_support::table_program;

use camloop::share::{PushRequest, RealFs, Share, ShareConfig};
use criterion::{Criterion, criterion_group, criterion_main};

/// Bench pushes into a share and a state folder under `root`.
fn bench_push(c: &mut Criterion, name: &str, root: &std::path::Path) {
    let share_dir = root.join("share");
    std::fs::create_dir(&share_dir).expect("share folder");
    let config = ShareConfig {
        share_dir,
        state_dir: root.join("state"),
        table_pair: (1, 2),
        keep_versions: 10,
    };
    let (mut share, _) = Share::open(
        config,
        Box::new(RealFs),
        Box::new(|| jiff::Timestamp::UNIX_EPOCH),
    )
    .expect("open the state folder");
    let programs = [table_program(1, 0), table_program(2, 0)];
    c.bench_function(name, |b| {
        b.iter(|| {
            let table = share.next_table_number();
            let request = PushRequest {
                files: vec![programs[table as usize - 1].clone()],
                table_number: table,
                reason: "bench".into(),
                measurement_id: None,
                learning: serde_json::Value::Null,
                rollback_of: None,
                created_at: jiff::Timestamp::UNIX_EPOCH,
            };
            share.push_once(request).expect("push")
        })
    });
}

fn benches(c: &mut Criterion) {
    // On the disk the build runs on (fsync cost included), and on tmpfs when there is one
    // (fsync free: the CPU and system-call cost alone).
    let disk = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).expect("temporary folder");
    bench_push(c, "push_360_point_table_disk", disk.path());
    if let Ok(tmpfs) = tempfile::tempdir_in("/dev/shm") {
        bench_push(c, "push_360_point_table_tmpfs", tmpfs.path());
    }
}

criterion_group!(share_benches, benches);
criterion_main!(share_benches);
