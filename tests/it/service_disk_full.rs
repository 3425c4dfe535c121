//! A full disk under the real service: camloop's var folder (database, journal, share state)
//! on a small tmpfs that is filled to the last byte while parts are being ground. The policy:
//! the journal gives up its reserve and keeps every measurement, learning stops (no table is
//! made from a part history might not keep), one alarm is raised; when space is freed the
//! reserve is restored, the journal drains into the database and learning resumes.

use crate::service_support;

use camloop::config::Config;
use camloop::service::{self, RunOptions};
use service_support::{get, sim_config};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// A tmpfs mounted for the test and unmounted when it ends, even on a panic.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(at: &Path, size_mib: u32) -> Self {
        std::fs::create_dir_all(at).unwrap();
        let status = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size_mib}m"), "tmpfs"])
            .arg(at)
            .status();
        assert!(
            status.is_ok_and(|s| s.success()),
            "mount -t tmpfs {} failed: this test needs root",
            at.display()
        );
        Tmpfs(at.to_path_buf())
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
    }
}

fn config(dir: &Path) -> Config {
    let url = format!("sqlite://{}/var/db.sqlite?mode=rwc", dir.display());
    sim_config(dir, &url, 20, 3, |_| None)
}

async fn metric(addr: std::net::SocketAddr, name: &str) -> f64 {
    let (_, body) = get(addr, "/metrics").await;
    let prefix = format!("{name}{{machine=\"SIM1\"}} ");
    body.lines()
        .find_map(|l| l.strip_prefix(prefix.as_str()))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(0.0)
}

async fn wait_until(addr: std::net::SocketAddr, name: &str, at_least: f64) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while metric(addr, name).await < at_least {
        assert!(Instant::now() < deadline, "{name} < {at_least} after 120 s");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Writes zeros into `path` until the file system says it is full.
fn fill(path: &Path) {
    let mut f = std::fs::File::create(path).unwrap();
    let block = vec![0u8; 256 * 1024];
    while f.write_all(&block).and_then(|()| f.sync_data()).is_ok() {}
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_keeps_every_measurement_and_stops_learning() {
    // The service's warnings go to the test's output, shown when the test fails.
    let _ = tracing_subscriber::fmt()
        .with_env_filter("camloop=info")
        .with_test_writer()
        .try_init();
    let dir = tempfile::tempdir().unwrap();
    let _var = Tmpfs::mount(&dir.path().join("var"), 48);
    let running = service::start(config(dir.path()), RunOptions::default())
        .await
        .unwrap();
    let addr = running.http_addr;
    wait_until(addr, "camloop_parts_total", 12.0).await;
    let filler = dir.path().join("var/filler");
    fill(&filler);
    let pushed_at_full = metric(addr, "camloop_tables_pushed_total").await;
    wait_until(addr, "camloop_parts_total", 32.0).await;
    // Full all along: no table was made, the alarm stands, the journal runs on its reserve.
    let pushed_while_full = metric(addr, "camloop_tables_pushed_total").await - pushed_at_full;
    assert!(
        pushed_while_full <= 1.0,
        "{pushed_while_full} tables made while the disk was full"
    );
    assert_eq!(metric(addr, "camloop_journal_failing").await, 1.0);
    std::fs::remove_file(&filler).unwrap();
    // The machine's retry (every 2 s) restores the reserve; the journal drains.
    let deadline = Instant::now() + Duration::from_secs(30);
    while metric(addr, "camloop_journal_failing").await != 0.0 {
        assert!(Instant::now() < deadline, "journal did not recover");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let recovered_at = metric(addr, "camloop_parts_total").await;
    wait_until(addr, "camloop_parts_total", recovered_at + 8.0).await;
    // The journal drains into the database: every part measured so far reaches it within
    // 30 s. (Read at the stop instead, one loaded run found 50 of 64 in the database: what
    // the stop's last flush had not written stays in the journal for the next start, which
    // that check could not tell from a loss. A journal that never drains fails here, with
    // the service's log.)
    let measured = metric(addr, "camloop_parts_total").await as i64;
    let db_url = format!("sqlite://{}/var/db.sqlite?mode=ro", dir.path().display());
    let reader = sqlx::SqlitePool::connect(&db_url).await.unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let stored: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM measurements")
            .fetch_one(&reader)
            .await
            .unwrap();
        if stored >= measured {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the journal did not drain: {stored} stored for {measured} measured after 30 s"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    reader.close().await;
    let measured_at_stop = metric(addr, "camloop_parts_total").await as i64;
    running.stop().await;

    let url = format!("sqlite://{}/var/db.sqlite", dir.path().display());
    let store = camloop::store::Store::connect(&url).await.unwrap();
    let camloop::store::RawPool::Sqlite(pool) = store.raw_pool() else {
        panic!("a SQLite store")
    };
    let count = |sql: &'static str| async move {
        sqlx::query_scalar::<_, i64>(sql)
            .fetch_one(pool)
            .await
            .unwrap()
    };
    let stored = count("SELECT COUNT(*) FROM measurements").await;
    assert!(
        stored >= measured,
        "{stored} stored for {measured} measured: every measurement is kept"
    );
    // And none twice: at most the part in hand at the stop comes on top.
    assert!(
        stored <= measured_at_stop + 1,
        "{stored} stored for {measured_at_stop} measured at the stop: a part stored twice"
    );
    assert_eq!(
        count("SELECT COUNT(*) FROM events WHERE kind = 'disk_full'").await,
        1
    );
    assert_eq!(
        count("SELECT COUNT(*) FROM events WHERE kind = 'disk_space_back'").await,
        1
    );
    // Learning resumed: the last parts are back in the converged band.
    let last: f64 = sqlx::query_scalar(
        "SELECT max_profile_error_um FROM measurements ORDER BY id DESC LIMIT 1",
    )
    .fetch_one(pool)
    .await
    .unwrap();
    assert!(last < 1.3, "last part {last} µm");
}
