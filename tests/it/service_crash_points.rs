//! Acceptance: the real service, aborted at every durability step of a part (its crash
//! points, `camloop::failpoint::STEPS`), loses no part, learns none twice, numbers no version
//! twice, stalls no feature, and keeps share and store in agreement once it runs again; the
//! next part is learned from the table in force. Once for one lobe, once for the whole
//! 8-lobe demo camshaft.
//!
//! Where `tests/it/service_kill.rs` kills at random moments, this lands a crash between every
//! pair of steps on purpose, so a window no random kill happened to hit is tested all the
//! same. It prints a table (step, where it crashed, what the restart found) for the record.

use crate::history_support::{
    self, agreement, journal_measurements, resumed_memory, stored_measurements,
};
use crate::process_support;
use camloop::failpoint::{CRASH_AT_VAR, STEPS};
use camloop::store::Store;
use std::collections::BTreeSet;
use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::ExitStatus;
use std::time::{Duration, Instant};

const MACHINE: &str = "M7";
/// A run that has neither crashed nor finished in this long is a failure.
const RUN_LIMIT: Duration = Duration::from_secs(60);
/// The simulator dresses the wheel after every second part (shaft), so the dressing's
/// steps are reached a few parts in.
const DRESS_EVERY_PARTS: u32 = 2;
/// Steps crashed at once in each pass.
const WORKERS: usize = 4;

/// One lobe or the whole shaft.
struct Pass {
    name: &'static str,
    recipe: &'static str,
    /// The `lobe` key: one feature of the recipe; `None`: every feature.
    lobe: Option<&'static str>,
    features: u64,
    /// Parts (shafts) the crash run may grind: more than any crash point needs, so a step
    /// never reached ends the run gracefully and fails the test.
    crash_run_parts: u64,
    restart_parts: u64,
}

const LOBE: Pass = Pass {
    name: "one lobe",
    recipe: "config/parts/demo-lobe.toml",
    lobe: Some("IN1"),
    features: 1,
    crash_run_parts: 6,
    restart_parts: 3,
};

const SHAFT: Pass = Pass {
    name: "8-lobe shaft",
    recipe: "config/parts/demo-camshaft.toml",
    lobe: None,
    features: 8,
    crash_run_parts: 4,
    restart_parts: 2,
};

fn config(pass: &Pass) -> String {
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join(pass.recipe);
    let lobe = pass
        .lobe
        .map_or(String::new(), |l| format!("lobe = \"{l}\"\n"));
    format!(
        "[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n[service]\nvar_dir = \"var\"\n\
         [http]\nlisten = \"127.0.0.1:0\"\n[[machines]]\nname = \"{MACHINE}\"\nrecipe = \"{}\"\n\
         {lobe}share = \"share/{MACHINE}\"\n[machines.gauge]\nkind = \"sim\"\npart_interval_ms = 5\n\
         [machines.gauge.grinder]\ndress_every_parts = {DRESS_EVERY_PARTS}\n",
        recipe.display()
    )
}

/// Where the crash lands: a graceful run of `warm_up` parts first (for a step only a start
/// reaches), then the `nth` time the step is reached. The counts follow what a part does:
/// at the first start every feature delivers its nominal table (the main program goes with
/// the last one), then each part of each feature is gauged, learned and delivered; the aim
/// is part 3 of one lobe, the middle of the second shaft.
fn crash_at(step: &str, features: u64) -> (u64, u64) {
    let lobe_in_part = features / 2 + 1;
    let parts_before = if features == 1 { 2 } else { 1 };
    let per_part = parts_before * features + lobe_in_part;
    // A dressing regenerates every feature's table.
    let dressed = parts_before / u64::from(DRESS_EVERY_PARTS) * features;
    match step {
        "journaled:measurement" | "store_commit:measurement" => (0, per_part),
        "share_temp_written" | "share_temp_synced" => (0, features + 1 + dressed + per_part),
        "resume_written" => (0, 1 + per_part),
        "store_commit:recipe_snapshot" => (2, lobe_in_part),
        "journaled:dressing" | "store_commit:dressing" | "store_commit:event" => (0, 1),
        _ => (0, features + dressed + per_part),
    }
}

/// Starts `camloop run` in `dir` for `parts` parts, `crash` in its environment (or none),
/// its output to files; waits, bounded, for it to end. Returns stderr and the log's tail.
fn run(dir: &Path, parts: u64, crash: Option<&str>, log: &str) -> (ExitStatus, String) {
    let stderr = std::fs::File::create(dir.join(format!("{log}.err"))).unwrap();
    let stdout = std::fs::File::create(dir.join(format!("{log}.log"))).unwrap();
    let mut command = process_support::camloop_run(dir);
    command
        .args(["--parts", &parts.to_string()])
        .env_remove(CRASH_AT_VAR)
        .stdout(stdout)
        .stderr(stderr);
    if let Some(c) = crash {
        command.env(CRASH_AT_VAR, c);
    }
    let mut child = process_support::KillOnDrop::spawn(&mut command).unwrap();
    let what = format!("camloop ({crash:?})");
    let status = child.exit_within(RUN_LIMIT, Duration::from_millis(10), &what);
    let stderr = std::fs::read_to_string(dir.join(format!("{log}.err"))).unwrap();
    let stdout = std::fs::read_to_string(dir.join(format!("{log}.log"))).unwrap();
    let tail: Vec<&str> = stdout.lines().rev().take(12).collect();
    let tail: Vec<&str> = tail.into_iter().rev().collect();
    (status, format!("{stderr}\n{}", tail.join("\n")))
}

/// What a feature held when the process died.
struct AtCrash {
    measurements: BTreeSet<String>,
    learned: u64,
    newest_version: u64,
}

/// One line of the printed table, and what is wrong with it.
struct Row {
    step: &'static str,
    nth: u64,
    crashed_at: String,
    parts_stored: usize,
    duplicates: usize,
    versions: usize,
    stalled: usize,
    mismatches: usize,
    problems: Vec<String>,
}

fn features(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir.join("var/machines").join(MACHINE))
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.path().join("journal.jsonl").exists())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

async fn open_store(dir: &Path) -> Store {
    let url = format!("sqlite://{}", dir.join("var/camloop.db").display());
    Store::connect(&url).await.unwrap()
}

async fn at_crash(dir: &Path, lobes: &[String]) -> Vec<AtCrash> {
    let var = dir.join("var");
    let store = open_store(dir).await;
    let mut held = Vec::new();
    for lobe in lobes {
        let mut measurements = journal_measurements(&var, MACHINE, lobe);
        measurements.extend(stored_measurements(&store, MACHINE, lobe).await.into_keys());
        let memory = resumed_memory(&var, &store, MACHINE, lobe).await;
        held.push(AtCrash {
            measurements,
            learned: memory.map_or(0, |m| m["parts"].as_u64().unwrap()),
            newest_version: history_support::manifest_versions(&var, MACHINE, lobe)
                .last()
                .copied()
                .unwrap_or(0),
        });
    }
    store.close().await;
    held
}

/// Crashes the service at `step`, runs it again gracefully and checks what it holds.
fn crash_and_restart(pass: &Pass, step: &'static str, rt: &tokio::runtime::Runtime) -> Row {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    std::fs::write(dir.join("camloop.toml"), config(pass)).unwrap();
    let (warm_up, nth) = crash_at(step, pass.features);
    if warm_up > 0 {
        let (status, stderr) = run(dir, warm_up, None, "warm-up");
        assert!(status.success(), "{step}: warm-up run: {stderr}");
    }
    let armed = format!("{step}:{nth}");
    let (status, stderr) = run(dir, pass.crash_run_parts, Some(&armed), "crash");
    assert_eq!(
        status.signal(),
        Some(6),
        "{}: {step} never aborted the service ({status}); a step not reached is a failure: {stderr}",
        pass.name
    );
    assert!(
        stderr.contains(&format!("crash point {step} reached (time {nth})")),
        "{step}: the abort did not name the step: {stderr}"
    );
    let lobes = features(dir);
    assert_eq!(lobes.len() as u64, pass.features, "{lobes:?}");
    let held = rt.block_on(at_crash(dir, &lobes));
    let gauged: usize = held.iter().map(|h| h.measurements.len()).sum();

    let (status, stderr) = run(dir, pass.restart_parts, None, "restart");
    assert!(status.success(), "{step}: the restart failed: {stderr}");
    let mut row = Row {
        step,
        nth,
        crashed_at: crashed_at(gauged as u64, warm_up, pass.features, step),
        parts_stored: 0,
        duplicates: 0,
        versions: 0,
        stalled: 0,
        mismatches: 0,
        problems: Vec::new(),
    };
    // A crash in the first part would test the start, not a part a few parts in.
    if gauged < 2 {
        row.problems
            .push(format!("crashed after only {gauged} measurements"));
    }
    rt.block_on(check_restart(dir, &lobes, &held, &mut row));
    row
}

/// "part k" for one lobe; "shaft s lobe j" for a shaft (from the measurements durable at
/// the crash: the one in hand is among them for every step but the start's and dressing's,
/// which come after the part named).
fn crashed_at(gauged: u64, warm_up: u64, features: u64, step: &str) -> String {
    let start = if warm_up > 0 {
        ", then a start"
    } else if step.contains("dressing") || step == "store_commit:event" {
        ", then a dressing"
    } else {
        ""
    };
    if features == 1 {
        format!("part {gauged}{start}")
    } else if gauged == 0 {
        format!("start{start}")
    } else {
        let (shaft, lobe) = ((gauged - 1) / features + 1, (gauged - 1) % features + 1);
        format!("shaft {shaft} lobe {lobe}{start}")
    }
}

async fn check_restart(dir: &Path, lobes: &[String], held: &[AtCrash], row: &mut Row) {
    let var = dir.join("var");
    let store = open_store(dir).await;
    for (lobe, before) in lobes.iter().zip(held) {
        let stored = stored_measurements(&store, MACHINE, lobe).await;
        let lost: Vec<&String> = before
            .measurements
            .iter()
            .filter(|m| !stored.contains_key(*m))
            .collect();
        if !lost.is_empty() {
            row.problems.push(format!("{lobe}: parts lost {lost:?}"));
        }
        let twice = stored.values().filter(|n| **n > 1).count();
        let a = agreement(&var, &store, MACHINE, lobe).await;
        row.duplicates += twice + a.learned_twice.len();
        row.problems
            .extend(a.learned_twice.iter().map(|t| format!("{lobe}: {t}")));
        row.parts_stored += stored.len();
        // No part learned twice (learned ≤ stored), and only the part in hand at the crash
        // may be kept without being learned (the same part gauged again after the restart
        // is the same measurement, learned then).
        let memory = resumed_memory(&var, &store, MACHINE, lobe).await.unwrap();
        let learned = memory["parts"].as_u64().unwrap();
        let stored_n = stored.len() as u64;
        if learned > stored_n || stored_n > learned + 1 || learned <= before.learned {
            row.problems.push(format!(
                "{lobe}: {} stored ({} at the crash), {learned} learned ({} at the crash)",
                stored.len(),
                before.measurements.len(),
                before.learned
            ));
        }
        row.versions += a.told as usize;
        row.mismatches += a.mismatches.len();
        row.problems
            .extend(a.mismatches.iter().map(|m| format!("{lobe}: {m}")));
        let pushed_since = a.newest_pushed.is_some_and(|p| p > before.newest_version);
        if !a.stuck.is_empty() || !pushed_since {
            row.stalled += 1;
            row.problems.push(format!(
                "{lobe}: stalled (newest pushed {:?}, v{} at the crash; {:?})",
                a.newest_pushed, before.newest_version, a.stuck
            ));
        }
        if a.in_force_version != a.newest_pushed {
            row.problems.push(format!(
                "{lobe}: learning goes on from v{:?}, the share pushed v{:?}",
                a.in_force_version, a.newest_pushed
            ));
        }
    }
    store.close().await;
}

fn crash_every_step(pass: &Pass) {
    let started = Instant::now();
    let steps: Vec<&'static str> = STEPS
        .iter()
        .copied()
        .filter(|s| pass.features > 1 || *s != "resume_written")
        .collect();
    // The runs wait mostly on fsync, not the processor: a few at once keep the wall time
    // down on two cores. Each step has its own folder.
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut rows: Vec<(usize, Row)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..WORKERS)
            .map(|_| {
                scope.spawn(|| {
                    let rt = tokio::runtime::Builder::new_current_thread()
                        .enable_all()
                        .build()
                        .unwrap();
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                        let Some(step) = steps.get(i) else {
                            return done;
                        };
                        done.push((i, crash_and_restart(pass, step, &rt)));
                    }
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| w.join().unwrap())
            .collect()
    });
    rows.sort_by_key(|(i, _)| *i);
    let rows: Vec<Row> = rows.into_iter().map(|(_, r)| r).collect();
    let mut table = format!(
        "crash points, {} ({:.1} s)\n{:<30} {:>4}  {:<24} {:>6} {:>5} {:>8} {:>7} {:>10}\n",
        pass.name,
        started.elapsed().as_secs_f64(),
        "step",
        "n",
        "crashed at",
        "stored",
        "dups",
        "versions",
        "stalled",
        "mismatches"
    );
    for r in &rows {
        table.push_str(&format!(
            "{:<30} {:>4}  {:<24} {:>6} {:>5} {:>8} {:>7} {:>10}\n",
            r.step,
            r.nth,
            r.crashed_at,
            r.parts_stored,
            r.duplicates,
            r.versions,
            r.stalled,
            r.mismatches
        ));
    }
    eprintln!("{table}");
    let problems: Vec<String> = rows
        .iter()
        .flat_map(|r| r.problems.iter().map(move |p| format!("{}: {p}", r.step)))
        .collect();
    assert!(problems.is_empty(), "{problems:#?}");
}

#[test]
fn a_crash_at_any_step_of_a_lobe_loses_nothing() {
    crash_every_step(&LOBE);
}

#[test]
fn a_crash_at_any_step_of_a_shaft_loses_nothing() {
    crash_every_step(&SHAFT);
}
