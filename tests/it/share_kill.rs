//! Acceptance: killing the process at random points during 1,000 pushes leaves the share
//! with only complete, verified programs, and a manifest that parses and agrees with them.
//!
//! The test re-runs its own executable as the pusher (switched by an environment variable):
//! a child opens the real share and state folders and pushes two-file versions in a loop
//! (`CAM_T<n>.SPF` and `CAMLOOP_GRIND.MPF`, each ending in its own SHA-256 line). The parent
//! SIGKILLs it after a random delay (seeded), checks every invariant, restarts it, and
//! repeats until 1,000 versions are pushed. Real file system, real `fsync`, no injection.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use camloop::share::{
    History, MANIFEST_FILE, ProgramFile, PushRequest, RealFs, Share, ShareConfig, TEMP_PREFIX,
    VERSIONS_DIR, VersionStatus, load_manifest, sha256_hex,
};

const CHILD_ENV: &str = "CAMLOOP_SHARE_KILL_TEST_ROOT";
const TEST_FN: &str = "killing_the_pusher_at_random_points_leaves_only_complete_programs";

/// The test's name as the harness knows it: its module path without the binary's name
/// (the test re-runs itself as the child, so the name must match whatever binary holds it).
fn test_name() -> String {
    match module_path!().split_once("::") {
        Some((_, module)) => format!("{module}::{TEST_FN}"),
        None => TEST_FN.to_string(),
    }
}
const TARGET_PUSHES: usize = 1000;
const SEED: u64 = 0x00C0_FFEE_0000_2024;
const MAIN_NAME: &str = "CAMLOOP_GRIND.MPF";
/// Lines of data per program: about 2 KB each.
const DATA_LINES: u32 = 80;

#[test]
fn killing_the_pusher_at_random_points_leaves_only_complete_programs() {
    match std::env::var_os(CHILD_ENV) {
        Some(root) => pusher(Path::new(&root)),
        None => killer(),
    }
}

fn config(root: &Path) -> ShareConfig {
    ShareConfig {
        share_dir: root.join("share"),
        state_dir: root.join("state"),
        table_pair: (1, 2),
        keep_versions: 10,
    }
}

/// A program whose content follows from (kind, version, table) and whose last line is the
/// SHA-256 of everything before it.
fn program_text(kind: &str, version: u64, table: u32) -> String {
    let mut body = format!("; {kind} version {version} table {table}\n");
    for i in 0..DATA_LINES {
        let c_deg = f64::from(i) * 4.5;
        let x_mm = 20.0 + (version as f64 * 1e-3 + c_deg.to_radians()).sin();
        body.push_str(&format!("N{i} C={c_deg:.4} X={x_mm:.4}\n"));
    }
    let sum = sha256_hex(body.as_bytes());
    format!("{body}; sha256 {sum}\n")
}

/// The version a complete program text declares, or why the text is not complete.
fn verify_program(text: &str) -> Result<u64, String> {
    let body_end = text
        .trim_end_matches('\n')
        .rfind('\n')
        .ok_or("no checksum line")?
        + 1;
    let (body, last) = text.split_at(body_end);
    let sum = last
        .strip_prefix("; sha256 ")
        .and_then(|s| s.strip_suffix('\n'))
        .ok_or_else(|| format!("last line is not a checksum: {last:?}"))?;
    if sha256_hex(body.as_bytes()) != sum {
        return Err("checksum does not match".into());
    }
    body.split_whitespace()
        .nth(3)
        .and_then(|v| v.parse().ok())
        .ok_or_else(|| "no version in the first line".into())
}

/// Child: push until 1,000 versions are pushed in total, across all runs.
fn pusher(root: &Path) {
    let clock = Box::new(camloop::clock::now);
    let (mut share, _) = Share::open(config(root), Box::new(RealFs), clock).unwrap();
    if share.history().waiting().is_some() {
        share.deliver().unwrap();
    }
    // Counted in the manifest: the share itself holds only the versions still relevant.
    let mut pushed = pushed_count(
        &load_manifest(&config(root).state_dir.join(MANIFEST_FILE))
            .unwrap()
            .history,
    );
    while pushed < TARGET_PUSHES {
        let version = share.history().next_version().get();
        let table = share.next_table_number();
        let files = vec![
            ProgramFile {
                name: format!("CAM_T{table}.SPF"),
                text: program_text("table", version, table),
            },
            ProgramFile {
                name: MAIN_NAME.into(),
                text: program_text("main", version, table),
            },
        ];
        let request = PushRequest {
            files,
            table_number: table,
            reason: "kill test".into(),
            measurement_id: None,
            learning: serde_json::Value::Null,
            rollback_of: None,
            created_at: jiff::Timestamp::from_millisecond(version as i64).unwrap(),
        };
        share.push_once(request).unwrap();
        pushed += 1;
    }
}

/// Versions pushed so far; the manifest is compacted on the way, so they are counted, not
/// listed.
fn pushed_count(history: &History) -> usize {
    history.pushed_count() as usize
}

/// SplitMix64: a small seeded generator, so the kill delays repeat from run to run.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// What the checks saw after the kills.
#[derive(Debug, Default)]
struct Seen {
    temporaries: usize,
    unconfirmed: usize,
    torn_manifest: usize,
}

/// Every program on the share is complete and agrees with the manifest; every kept text
/// matches its checksum.
fn check(root: &Path, seen: &mut Seen) -> History {
    let config = config(root);
    let loaded = load_manifest(&config.state_dir.join(MANIFEST_FILE))
        .unwrap_or_else(|e| panic!("manifest does not parse: {e}"));
    if loaded.torn_bytes > 0 {
        seen.torn_manifest += 1;
    }
    let history = loaded.history;
    if history
        .versions()
        .last()
        .is_some_and(|v| v.status == VersionStatus::Delivering)
    {
        seen.unconfirmed += 1;
    }
    for entry in std::fs::read_dir(&config.share_dir).unwrap() {
        let name = entry.unwrap().file_name().into_string().unwrap();
        if name.starts_with(TEMP_PREFIX) {
            seen.temporaries += 1;
            continue;
        }
        let text = std::fs::read_to_string(config.share_dir.join(&name)).unwrap();
        let declared = verify_program(&text)
            .unwrap_or_else(|e| panic!("{name} on the share is not complete: {e}"));
        let allowed = allowed_versions(&history, &name);
        let sum = sha256_hex(text.as_bytes());
        let matched = history.versions().iter().find(|v| {
            allowed.contains(&v.record.version.get())
                && v.record
                    .files
                    .iter()
                    .any(|f| f.name == name && f.sha256 == sum)
        });
        let Some(matched) = matched else {
            panic!("{name} (version {declared}) is not a version the manifest allows: {allowed:?}")
        };
        assert_eq!(matched.record.version.get(), declared, "{name}");
    }
    let versions_dir = config.state_dir.join(VERSIONS_DIR);
    for v in history.versions().iter().filter(|v| v.text_kept) {
        let dir = versions_dir.join(format!("v{:06}", v.record.version.get()));
        for f in &v.record.files {
            let bytes = std::fs::read(dir.join(&f.name))
                .unwrap_or_else(|e| panic!("kept text of v{} missing: {e}", v.record.version));
            assert_eq!(
                sha256_hex(&bytes),
                f.sha256,
                "kept text of v{}",
                v.record.version
            );
        }
    }
    history
}

/// The versions whose `name` may be on the share: those that reached the renames, from the
/// newest down to the newest pushed one (older ones were replaced by a verified push).
fn allowed_versions(history: &History, name: &str) -> BTreeSet<u64> {
    let mut allowed = BTreeSet::new();
    for v in history.versions().iter().rev() {
        if !v.reached_share || !v.record.files.iter().any(|f| f.name == name) {
            continue;
        }
        allowed.insert(v.record.version.get());
        if matches!(v.status, VersionStatus::Pushed { .. }) {
            break;
        }
    }
    allowed
}

/// A temporary folder on tmpfs (`/dev/shm`) when the machine has one, else the default.
/// A kill, unlike a power cut, loses nothing the kernel has accepted, so the file system
/// type does not change what this test proves; on tmpfs `fsync` costs nothing, where on a
/// virtual disk each one can take milliseconds (1,000 pushes then take about a minute).
fn temp_root() -> tempfile::TempDir {
    tempfile::tempdir_in("/dev/shm")
        .or_else(|_| tempfile::tempdir())
        .unwrap()
}

/// Parent: kill the pusher at random moments until 1,000 pushes are done.
fn killer() {
    let root_dir = temp_root();
    let root: PathBuf = root_dir.path().to_path_buf();
    std::fs::create_dir(config(&root).share_dir).unwrap();
    let exe = std::env::current_exe().unwrap();
    let mut rng = SplitMix64(SEED);
    let mut seen = Seen::default();
    // The upper end of the random delay adapts to the machine's speed, aiming at about 10
    // pushes per run (about 100 kills); starts at 30 ms.
    let mut max_delay_us = 30_000.0_f64;
    let (mut kills, mut runs) = (0_usize, 0_usize);
    let mut pushed_before = 0;
    loop {
        runs += 1;
        assert!(runs <= 2_000, "no progress after {runs} runs");
        let mut child = Command::new(&exe)
            .args(["--exact", &test_name(), "--nocapture", "--test-threads=1"])
            .env(CHILD_ENV, &root)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let delay = Duration::from_micros((rng.unit() * max_delay_us) as u64);
        // Not a synchronisation: the kill moment is meant to be arbitrary.
        std::thread::sleep(delay);
        child.kill().unwrap();
        let output = child.wait_with_output().unwrap();
        let history = check(&root, &mut seen);
        let pushed = pushed_count(&history);
        use std::os::unix::process::ExitStatusExt;
        match output.status.signal() {
            Some(9) => kills += 1,
            _ if output.status.success() => {
                assert!(
                    pushed >= TARGET_PUSHES,
                    "child stopped early: {pushed} pushed"
                );
                break;
            }
            _ => panic!(
                "pusher failed ({}): {}",
                output.status,
                String::from_utf8_lossy(&output.stderr)
            ),
        }
        let per_run = pushed - pushed_before;
        pushed_before = pushed;
        if per_run > 15 {
            max_delay_us *= 0.8;
        } else if per_run < 5 {
            max_delay_us *= 1.25;
        }
    }
    let history = check(&root, &mut seen);
    println!(
        "in {}: {runs} runs, {kills} kills, {} versions, {} pushed; after kills: {} temporaries, \
         {} unconfirmed deliveries, {} torn manifest lines",
        root.display(),
        history.versions().len(),
        pushed_count(&history),
        seen.temporaries,
        seen.unconfirmed,
        seen.torn_manifest
    );
    assert!(kills >= 30, "only {kills} kills");
    assert!(
        seen.temporaries + seen.unconfirmed > 0,
        "no kill landed during a delivery: the test did not exercise one"
    );
    // The last run ended by itself: the share holds exactly the newest version.
    let last = history.versions().last().unwrap();
    assert!(matches!(last.status, VersionStatus::Pushed { .. }));
    let share_dir = config(&root).share_dir;
    for f in &last.record.files {
        let text = std::fs::read_to_string(share_dir.join(&f.name)).unwrap();
        assert_eq!(sha256_hex(text.as_bytes()), f.sha256);
    }
}
