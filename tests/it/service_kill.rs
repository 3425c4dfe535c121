//! Acceptance: `kill -9` of the real service at random moments never leaves a table version
//! that the history does not know. Every version the share's manifest holds has its row in
//! the store (with the program the share verified and the status the share gave it), the
//! journal drains once the service runs again.
//!
//! Before the write-ahead record (a version's record journalled before the share hears of
//! it), a kill between the push and its record left a version only the share knew: its
//! status could never be written and that feature's journal stopped draining.

use crate::cli_support;
use crate::history_support;
use crate::process_support;

use camloop::store::Store;
use std::path::Path;
use std::time::Duration;

const KILLS: usize = 14;
const SEED: u64 = 0x5EED_0000_0013;

fn config(recipe: &Path) -> String {
    format!(
        "[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n[service]\nvar_dir = \"var\"\n[http]\nlisten = \"127.0.0.1:0\"\n\
         [[machines]]\nname = \"M7\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"share/M7\"\n[machines.gauge]\nkind = \"sim\"\npart_interval_ms = 5\n",
        recipe.display()
    )
}

/// A small deterministic generator (xorshift), so a failure can be replayed.
fn next(state: &mut u64) -> u64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    *state
}

fn manifest_len(path: &Path) -> u64 {
    std::fs::metadata(path).map_or(0, |m| m.len())
}

/// Waits until the manifest has grown past `before` bytes (the service started and delivered
/// at least one step of a version), at most 120 s, failing early if the service exited.
fn wait_for_manifest_growth(path: &Path, before: u64, child: &mut process_support::KillOnDrop) {
    let deadline = std::time::Instant::now() + Duration::from_secs(120);
    while manifest_len(path) <= before {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the service exited ({status}) before writing to the share's manifest");
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the share's manifest did not grow within 120 s of a start"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn killing_the_service_never_leaves_a_version_the_history_does_not_know() {
    let dir = tempfile::tempdir().unwrap();
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    std::fs::write(dir.path().join("camloop.toml"), config(&recipe)).unwrap();
    let mut rng = SEED;
    let manifest = dir.path().join("var/machines/M7/IN1/share/manifest.jsonl");
    for _ in 0..KILLS {
        let before = manifest_len(&manifest);
        let mut child =
            process_support::KillOnDrop::spawn(&mut process_support::camloop_run(dir.path()))
                .unwrap();
        // The kill lands anywhere in the parts after this start has written to the share's
        // manifest: start-up takes 100 ms on an idle machine and seconds on a loaded one, so
        // a kill timed from the spawn alone could land before any part.
        wait_for_manifest_growth(&manifest, before, &mut child);
        std::thread::sleep(Duration::from_millis(next(&mut rng) % 700));
        child.kill().unwrap();
        child.wait().unwrap();
    }
    // A last, graceful run: the journal is written and released as it would be in service.
    let out = cli_support::camloop(
        &["run", "--config", "camloop.toml", "--parts", "5"],
        dir.path(),
    );
    assert!(out.status.success(), "{}", cli_support::stderr(&out));

    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let url = format!("sqlite://{}", dir.path().join("var/camloop.db").display());
        let store = Store::connect(&url).await.unwrap();
        let a = history_support::agreement(&dir.path().join("var"), &store, "M7", "IN1").await;
        // Every manifest version is in the store, with its table number, the program the
        // share verified and the status the share gave it.
        assert!(a.mismatches.is_empty(), "{:#?}", a.mismatches);
        assert!(
            a.pushed >= KILLS as u64,
            "only {} versions pushed: the kills came too early to test anything",
            a.pushed
        );
        // The newest version pushed is the one in force in the stored learning state.
        assert!(a.newest_pushed.is_some());
        assert_eq!(a.in_force_version, a.newest_pushed);
        // Nothing stuck in the journal: what it still holds is already in the store.
        assert!(a.stuck.is_empty(), "{:#?}", a.stuck);
        assert!(a.learned_twice.is_empty(), "{:#?}", a.learned_twice);
    });
}
