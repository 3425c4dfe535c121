//! One push of a 360-point G1 curve table (about 7.7 KB of text) to a share folder on the
//! real file system: store the kept text, write the temporary, fsync, rename, fsync the
//! folder, read back, verify, append the manifest lines (8 fsyncs in all, 9 once pruning
//! starts).

use camloop::core::program::{ProgramSettings, render_g1_table};
use camloop::core::table::TablePoint;
use camloop::share::{ProgramFile, PushRequest, RealFs, Share, ShareConfig};
use criterion::{Criterion, criterion_group, criterion_main};

fn table_text(table: u32) -> String {
    let points: Vec<TablePoint> = (0..360)
        .map(|i| {
            let c_deg = f64::from(i);
            let x_mm = 20.0 + 2.0 * c_deg.to_radians().sin();
            TablePoint {
                c_deg,
                d_mm: x_mm,
                x_mm,
            }
        })
        .collect();
    let settings = ProgramSettings {
        name: format!("CAM_T{table}"),
        table_number: table,
        ..ProgramSettings::default()
    };
    render_g1_table(&points, &settings).expect("a valid table")
}

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
    let texts = [table_text(1), table_text(2)];
    c.bench_function(name, |b| {
        b.iter(|| {
            let table = share.next_table_number();
            let request = PushRequest {
                files: vec![ProgramFile {
                    name: format!("CAM_T{table}.SPF"),
                    text: texts[table as usize - 1].clone(),
                }],
                table_number: table,
                reason: "bench".into(),
                measurement_id: None,
                learning: serde_json::Value::Null,
                rollback_of: None,
                created_at_unix_ms: jiff::Timestamp::UNIX_EPOCH,
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
