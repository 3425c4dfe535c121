//! Acceptance for several instances: three `camloop run` processes with `[cluster]` on one
//! throwaway PostgreSQL share 30 machines, each machine a thread outside camloop that grinds
//! what its share's program couples and drops the measurement into its inbox. One instance
//! is killed with SIGKILL mid-run and started again; then another is paused (SIGSTOP) until
//! its machines have moved, and let go on (SIGCONT), as a suspended VM would. Checked:
//! - the leases split the machines evenly; the dead instance's machines are taken within
//!   10 s (the default lease of 6 s, plus a quarter lease until the others look) and handed
//!   back when it returns; the paused one notices it lost its leases and writes nothing
//!   more (its writes are fenced);
//! - every machine keeps producing: every dropped file is taken, none rejected, none waits
//!   in its inbox longer than a takeover (plus 2 s);
//! - no measurement lost and none stored twice: the store holds each dropped part once;
//! - no version number used twice, no version pushed by two owners: each machine's manifest
//!   holds versions 1..n once each, every one carries the fencing epoch of its owner, epochs
//!   never go down, and the store holds the same versions with the same programs.

use crate::cluster_support::{self, Dropped, Machine};
use crate::process_support::KillOnDrop;
use crate::store_support;
use sqlx::Row;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

const MACHINES: usize = 30;
const INSTANCES: [&str; 3] = ["a", "b", "c"];
/// The default lease; the takeover bound the issue sets follows from it.
const LEASE_MS: u64 = 6000;
const TAKEOVER_LIMIT: Duration = Duration::from_secs(10);
/// Shortest time between two parts of one machine. 30 machines at one part every 3 s is
/// 10 parts a second, some 20 times a real cell's rate (a lobe takes 30–60 s to grind), and
/// what three debug-build instances and 30 simulated grinders keep up with on 2 cores that
/// are also kept busy from outside. At 1.5 s the same run is overloaded: parts queue behind
/// each other, and a part's wait grows with the queue, not with the takeover under test.
const MACHINE_CYCLE: Duration = Duration::from_millis(3000);
/// A returning instance holds its fair share within this: it looks every 250 ms while the
/// others hand machines over, and a handover waits only for the part in hand.
const REJOIN_LIMIT: Duration = Duration::from_secs(15);

fn machine_name(i: usize) -> String {
    format!("M{:02}", i + 1)
}

fn config(root: &Path, instance: &str, db_url: &str) -> String {
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let mut text = format!(
        "[service]\nvar_dir = \"var-{instance}\"\n[database]\nurl = \"{db_url}\"\n\
         [http]\nlisten = \"127.0.0.1:0\"\n\
         [cluster]\nenabled = true\ninstance = \"{instance}\"\nlease_ms = {LEASE_MS}\nstate_dir = \"state\"\n"
    );
    for i in 0..MACHINES {
        let m = machine_name(i);
        text.push_str(&format!(
            "[[machines]]\nname = \"{m}\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"shares/{m}\"\n\
             [machines.gauge]\nkind = \"drop\"\nfolder = \"inbox/{m}\"\npoll_ms = 50\n",
            recipe.display()
        ));
    }
    std::fs::write(root.join(format!("{instance}.toml")), &text).unwrap();
    text
}

fn start(root: &Path, instance: &str) -> KillOnDrop {
    let log = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(root.join(format!("{instance}.log")))
        .unwrap();
    KillOnDrop::spawn(
        Command::new(env!("CARGO_BIN_EXE_camloop"))
            .args(["run", "--config", &format!("{instance}.toml")])
            .current_dir(root)
            .stdout(log.try_clone().unwrap())
            .stderr(log),
    )
    .unwrap()
}

/// Every machine's lease epoch: one more each time the machine changed owner.
async fn epochs(db: &sqlx::PgPool) -> HashMap<String, u64> {
    sqlx::query("SELECT machine, epoch FROM camloop_leases")
        .fetch_all(db)
        .await
        .unwrap()
        .iter()
        .map(|r| (r.get::<String, _>(0), r.get::<i64, _>(1) as u64))
        .collect()
}

/// How many machines changed owner 0, 1, 2, … times between two readings of the epochs.
fn owner_changes(before: &HashMap<String, u64>, after: &HashMap<String, u64>) -> Vec<usize> {
    let mut histogram = Vec::new();
    for (m, b) in before {
        let n = (after[m] - b) as usize;
        if histogram.len() <= n {
            histogram.resize(n + 1, 0);
        }
        histogram[n] += 1;
    }
    histogram
}

/// Owner of every leased machine whose lease has not expired.
async fn owners(db: &sqlx::PgPool) -> HashMap<String, String> {
    sqlx::query("SELECT machine, owner FROM camloop_leases WHERE expires_at > now()")
        .fetch_all(db)
        .await
        .map(|rows| {
            rows.iter()
                .map(|r| (r.get::<String, _>(0), r.get::<String, _>(1)))
                .collect()
        })
        .unwrap_or_default()
}

fn counts(owners: &HashMap<String, String>) -> BTreeMap<String, usize> {
    let mut c = BTreeMap::new();
    for o in owners.values() {
        *c.entry(o.clone()).or_default() += 1;
    }
    c
}

/// Polls the leases until `done` holds; panics naming what was seen after `limit`.
async fn wait_leases(
    root: &Path,
    db: &sqlx::PgPool,
    limit: Duration,
    what: &str,
    done: impl Fn(&HashMap<String, String>) -> bool,
) -> Duration {
    let at = Instant::now();
    loop {
        let o = owners(db).await;
        if done(&o) {
            return at.elapsed();
        }
        assert!(
            at.elapsed() < limit,
            "{what}: after {limit:?} the leases are {:?}\n{}",
            counts(&o),
            log_tails(root)
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

#[test]
fn three_instances_share_the_machines_and_survive_a_kill() {
    let Some(server) = store_support::pg::start_or_skip("cluster_takeover") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    for i in INSTANCES {
        config(root, i, &server.url());
    }
    let stop = Arc::new(AtomicBool::new(false));
    let machines: Vec<_> = (0..MACHINES)
        .map(|i| {
            let name = machine_name(i);
            let inbox = root.join("inbox").join(&name);
            std::fs::create_dir_all(&inbox).unwrap();
            let machine = Machine {
                share: root.join("shares").join(&name),
                inbox,
                name,
                cycle: MACHINE_CYCLE,
                seed: 1000 + i as u64,
            };
            let stop = stop.clone();
            std::thread::spawn(move || machine.run(stop, Duration::from_secs(40)))
        })
        .collect();
    // Killed on drop: a failed assertion never leaves instances running.
    let mut children: HashMap<&str, KillOnDrop> =
        INSTANCES.iter().map(|&i| (i, start(root, i))).collect();

    let rt = tokio::runtime::Runtime::new().unwrap();
    let report = rt.block_on(async {
        let db = sqlx::PgPool::connect(&server.url()).await.unwrap();
        let even = |o: &HashMap<String, String>| {
            o.len() == MACHINES && INSTANCES.iter().all(|i| counts(o).get(*i) == Some(&10))
        };
        wait_leases(
            root,
            &db,
            Duration::from_secs(40),
            "three instances split 30 machines",
            even,
        )
        .await;
        tokio::time::sleep(Duration::from_secs(6)).await;

        // SIGKILL: no release, no goodbye; its leases run out.
        let before_kill = epochs(&db).await;
        let held: Vec<String> = owners(&db)
            .await
            .into_iter()
            .filter(|(_, o)| o == "c")
            .map(|(m, _)| m)
            .collect();
        let killed = Instant::now();
        let mut child = children.remove("c").unwrap();
        child.kill().unwrap();
        child.wait().unwrap();
        let mut takeover: HashMap<String, Duration> = HashMap::new();
        while takeover.len() < held.len() {
            let o = owners(&db).await;
            for m in &held {
                if o.get(m).is_some_and(|owner| owner != "c") && !takeover.contains_key(m) {
                    takeover.insert(m.clone(), killed.elapsed());
                }
            }
            assert!(
                killed.elapsed() < Duration::from_secs(30),
                "the dead instance's machines not taken: {:?}\n{}",
                counts(&o),
                log_tails(root)
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        tokio::time::sleep(Duration::from_secs(4)).await;

        let restarted_ms = cluster_support::now_ms();
        children.insert("c", start(root, "c"));
        let rebalance = wait_leases(
            root,
            &db,
            REJOIN_LIMIT,
            "the returning instance gets its share",
            even,
        )
        .await;
        let rejoin = (restarted_ms, cluster_support::now_ms());
        tokio::time::sleep(Duration::from_secs(3)).await;
        // Steady again: every machine changed owner at most twice since the kill (to a
        // survivor, then back), and not once more in these 3 s.
        let changes = owner_changes(&before_kill, &epochs(&db).await);
        assert!(
            changes.len() <= 3,
            "owner changes per machine after a kill and a return (machines with 0, 1, 2, … changes): {changes:?}\n{}",
            log_tails(root)
        );
        // Nothing lost before b is paused: its log up to here has no lost lease.
        let b_before_pause = std::fs::read_to_string(root.join("b.log")).unwrap().len();

        // SIGSTOP: b stays alive, holding its leases' memory, its files open, until its
        // leases have run out and the others own its machines; then it goes on (SIGCONT)
        // and must write nothing more for them.
        children["b"].signal("-STOP");
        let no_b = |o: &HashMap<String, String>| {
            o.len() == MACHINES && !o.values().any(|owner| owner == "b")
        };
        let paused_takeover = wait_leases(
            root,
            &db,
            Duration::from_secs(30),
            "a paused instance's machines move",
            no_b,
        )
        .await;
        tokio::time::sleep(Duration::from_secs(1)).await;
        children["b"].signal("-CONT");
        wait_leases(
            root,
            &db,
            Duration::from_secs(30),
            "the paused instance gets its share back",
            even,
        )
        .await;
        tokio::time::sleep(Duration::from_secs(3)).await;

        // A quick restart, as a service manager restarts a crashed process within its
        // lease: the new process must not go on renewing its predecessor's leases for
        // machines it does not run (they would run nowhere); it takes them again.
        let mut child = children.remove("a").unwrap();
        child.kill().unwrap();
        child.wait().unwrap();
        let quick_ms = cluster_support::now_ms();
        children.insert("a", start(root, "a"));
        tokio::time::sleep(Duration::from_secs(8)).await;
        let quick = (quick_ms, cluster_support::now_ms());
        wait_leases(root, &db, Duration::from_secs(30), "a quick restart", even).await;
        check_cluster_api(root);
        (takeover, rebalance, paused_takeover, rejoin, quick, changes, b_before_pause)
    });
    let (takeover, rebalance, paused_takeover, rejoin, quick, changes, b_before_pause) = report;

    stop.store(true, Ordering::SeqCst);
    let dropped: Vec<(String, Vec<Dropped>)> = machines
        .into_iter()
        .enumerate()
        .map(|(i, h)| (machine_name(i), h.join().unwrap()))
        .collect();
    for (_, mut child) in children {
        // SIGTERM: a graceful stop releases the leases.
        child.signal("-TERM");
        child.wait().unwrap();
    }

    let mut times: Vec<Duration> = takeover.values().copied().collect();
    times.sort();
    let mut waits: Vec<Duration> = dropped
        .iter()
        .flat_map(|(_, d)| d.iter().map(|p| p.waited))
        .collect();
    waits.sort();
    let parts: usize = dropped.iter().map(|(_, d)| d.len()).sum();
    // The parts in the inbox at any time while the restarted instance took its share back
    // (dropped before and taken during, or dropped during): how long the handover kept
    // them waiting. Counting only the parts dropped inside the window left it empty once
    // the instance started fast enough to take its share within one or two drops.
    let rejoining: Vec<Duration> = dropped
        .iter()
        .flat_map(|(_, d)| d.iter())
        .filter(|p| {
            let taken_ms = p.dropped_ms + u64::try_from(p.waited.as_millis()).unwrap_or(u64::MAX);
            p.dropped_ms <= rejoin.1 && taken_ms >= rejoin.0
        })
        .map(|p| p.waited)
        .collect();
    let rejoin_max = rejoining.iter().max().copied().unwrap_or_default();
    let quick_max = dropped
        .iter()
        .flat_map(|(_, d)| d.iter())
        .filter(|p| (quick.0..=quick.1).contains(&p.dropped_ms))
        .map(|p| p.waited)
        .max()
        .unwrap_or_default();
    eprintln!("around a quick restart the longest a part waited was {quick_max:?}");
    eprintln!(
        "while an instance rejoined: {} parts in the inbox, the longest waited {rejoin_max:?}",
        rejoining.len()
    );
    // A handover is between parts: the old owner notices the new instance at its next round
    // (0.5 s at most), finishes the part in hand and releases; the new owner looks every
    // 250 ms while below its share, opens the machine and measures the part that waited.
    // Two parts' processing and one opening: 1.3-2.4 s in a debug build with both cores
    // busy from outside (when the holders looked every quarter lease, 1.5 s, it was 5-6 s).
    assert!(
        !rejoining.is_empty() && rejoin_max < Duration::from_secs(4),
        "a handover kept a part waiting {rejoin_max:?}"
    );
    eprintln!(
        "takeover of {} machines: p50 {:?}, max {:?}; rebalance after the restart {rebalance:?}; \
         a paused instance's machines all moved after {paused_takeover:?}; \
         owner changes per machine from the kill to the return (machines with 0, 1, 2 changes): \
         {changes:?}; {parts} parts, wait in the inbox p50 {:?} max {:?}",
        times.len(),
        percentile(&times, 0.5),
        times[times.len() - 1],
        percentile(&waits, 0.5),
        waits[waits.len() - 1],
    );
    assert!(
        times[times.len() - 1] < TAKEOVER_LIMIT,
        "takeover took {:?}",
        times[times.len() - 1]
    );
    for (m, parts) in &dropped {
        assert!(parts.len() >= 8, "{m} made only {} parts", parts.len());
        for p in parts {
            assert_eq!(
                p.rejected, None,
                "{m} {} was not taken as a measurement",
                p.file
            );
            assert!(
                p.waited < TAKEOVER_LIMIT + Duration::from_secs(2),
                "{m} {} waited {:?} in the inbox",
                p.file,
                p.waited
            );
        }
    }
    rt.block_on(check_history(root, &server.url(), &dropped));
    assert_logs_clean(root, b_before_pause);
}

/// The store holds every dropped part once; each machine's versions are 1..n once each, with
/// non-decreasing epochs, and the store holds the same versions with the same programs.
async fn check_history(root: &Path, url: &str, dropped: &[(String, Vec<Dropped>)]) {
    let db = sqlx::PgPool::connect(url).await.unwrap();
    let store = camloop::store::Store::connect(url).await.unwrap();
    for (m, parts) in dropped {
        let stored: Vec<String> =
            sqlx::query("SELECT part FROM measurements WHERE machine = $1 ORDER BY part")
                .bind(m)
                .fetch_all(&db)
                .await
                .unwrap()
                .iter()
                .map(|r| r.get(0))
                .collect();
        let mut expected: Vec<String> = parts.iter().map(|p| p.part.clone()).collect();
        expected.sort();
        assert_eq!(
            stored, expected,
            "{m}: the store's parts are not the parts dropped"
        );

        let manifest = root.join(format!("state/machines/{m}/IN1/share/manifest.jsonl"));
        let history = camloop::share::load_manifest(&manifest).unwrap().history;
        let versions = history.versions();
        let mut last_epoch = 0;
        for (i, v) in versions.iter().enumerate() {
            let version = v.record.version;
            assert_eq!(
                version.get(),
                i as u64 + 1,
                "{m}: versions are not 1..n once each"
            );
            let epoch = v
                .record
                .epoch
                .unwrap_or_else(|| panic!("{m} v{version} has no epoch"))
                .0;
            assert!(
                epoch >= last_epoch,
                "{m} v{version}: epoch {epoch} after {last_epoch}"
            );
            last_epoch = epoch;
            let row = store
                .table_version(&m.parse().unwrap(), &"IN1".parse().unwrap(), version)
                .await
                .unwrap()
                .unwrap_or_else(|| panic!("{m} v{version} is on the share, not in the store"));
            assert_eq!(row.table_number, v.record.table_number, "{m} v{version}");
            assert_eq!(
                row.sha256, v.record.files[0].sha256,
                "{m} v{version}: another program"
            );
        }
        assert!(versions.len() > 2, "{m}: only {} versions", versions.len());
        let fence =
            std::fs::read_to_string(root.join(format!("state/machines/{m}/fence"))).unwrap();
        assert!(
            fence_epoch(&fence) >= last_epoch,
            "{m}: fence {fence:?} behind v{}",
            versions.len()
        );
    }
    store.close().await;
}

fn fence_epoch(text: &str) -> u64 {
    text.split_whitespace()
        .nth(1)
        .and_then(|e| e.parse().ok())
        .unwrap_or(0)
}

/// `GET /api/v1/cluster` on instance a: every machine leased and live, a third run there.
fn check_cluster_api(root: &Path) {
    let log = std::fs::read_to_string(root.join("a.log")).unwrap();
    // The newest start's address (the log is appended to across restarts).
    let addr = log
        .rsplit("listen=")
        .next()
        .filter(|_| log.contains("listen="))
        .and_then(|rest| rest.split_whitespace().next())
        .unwrap_or_else(|| panic!("no listen address in a.log:\n{log}"));
    let mut stream = std::net::TcpStream::connect(addr).unwrap();
    use std::io::{Read, Write};
    write!(
        stream,
        "GET /api/v1/cluster HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).unwrap();
    let body = &response[response.find('{').unwrap()..=response.rfind('}').unwrap()];
    let reply: serde_json::Value = serde_json::from_str(body).unwrap();
    assert_eq!(reply["enabled"], true, "{reply}");
    assert_eq!(reply["instance"], "a", "{reply}");
    let machines = reply["machines"].as_array().unwrap();
    assert_eq!(machines.len(), MACHINES, "{reply}");
    assert!(machines.iter().all(|m| m["live"] == true), "{reply}");
    let here = machines.iter().filter(|m| m["here"] == true).count();
    assert_eq!(here, MACHINES / INSTANCES.len(), "{reply}");
}

/// The last lines of each instance's log, for a failure's message.
fn log_tails(root: &Path) -> String {
    let mut out = String::new();
    for i in INSTANCES {
        let log = std::fs::read_to_string(root.join(format!("{i}.log"))).unwrap_or_default();
        let lines: Vec<&str> = log.lines().filter(|l| !l.contains(" part ")).collect();
        out.push_str(&format!("--- {i}.log (without part lines), last 20:\n"));
        for l in &lines[lines.len().saturating_sub(20)..] {
            out.push_str(l);
            out.push('\n');
        }
    }
    out
}

/// No instance panicked or logged an error, but for the paused one's lost leases after its
/// pause (`b_before_pause`: the length of its log then).
fn assert_logs_clean(root: &Path, b_before_pause: usize) {
    for i in INSTANCES {
        let log = std::fs::read_to_string(root.join(format!("{i}.log"))).unwrap();
        let steady = if i == "b" {
            &log[..b_before_pause]
        } else {
            &log[..]
        };
        for lost in [
            "lease lost",
            "not renewed in time",
            "ran out while the machine opened",
        ] {
            assert!(
                !steady.contains(lost),
                "{i} lost a lease in a steady state ({lost}):\n{}",
                log_tails(root)
            );
        }
        assert!(!log.contains("panicked"), "{i} panicked:\n{log}");
        assert!(
            log.contains("camloop started"),
            "{i} logged nothing:\n{log}"
        );
        // The paused instance says it lost its machines, and nothing else goes wrong.
        let expected = |l: &str| i == "b" && l.contains("cluster:");
        if i == "b" {
            assert!(
                log.contains("cluster: lease lost"),
                "b never noticed:\n{}",
                log_tails(root)
            );
        }
        let errors: Vec<&str> = log
            .lines()
            .filter(|l| l.contains(" ERROR ") && !expected(l))
            .collect();
        assert!(
            errors.is_empty(),
            "{i} logged errors:\n{}",
            errors.join("\n")
        );
    }
}
