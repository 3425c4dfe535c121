//! What an OPC UA client holds across a real restart of `camloop run`, with Python's
//! `asyncua` (`tests/opcua/restart_checks.py`): the EventId of an event received before the
//! restart still acknowledges that event after it, and each feature's result variables show
//! the newest stored result with its own time (a feature with none:
//! `BadWaitingForInitialData`), not an empty value until the next part.
//!
//! The first run grinds with the simulator; the restart takes its parts from an empty drop
//! folder, so no part replaces what the history gives at start. Skipped with a line saying
//! so when `asyncua` is not installed, unless `CAMLOOP_REQUIRE_OPCUA=1`.

use std::net::TcpStream;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use crate::cli_support;
use crate::opcua_asyncua::asyncua_present;
use crate::process_support::{KillOnDrop, camloop_run, free_port, run_to_end, wait_for};

/// The longest a start may take on a loaded 2-core machine: a failure, not a pace.
const START_BOUND: Duration = Duration::from_secs(90);

/// The longest a script may run (each of its waits is bounded by itself too).
const SCRIPT_BOUND: Duration = Duration::from_secs(180);

/// When the script prints its own tasks' stacks and stops: before the bound, so a hang
/// says where it waited.
const SCRIPT_WATCHDOG: Duration = Duration::from_secs(170);

/// The service's config: `gauge` is the machine's gauge section, `features` its features.
fn config(http: u16, opcua: u16, features: &str, gauge: &str) -> String {
    let recipe = cli_support::repo("config/parts/demo-camshaft.toml");
    format!(
        "[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n[service]\nvar_dir = \"var\"\n\
         [http]\nlisten = \"127.0.0.1:{http}\"\n\
         [opcua]\nenabled = true\nlisten = \"127.0.0.1:{opcua}\"\nhost_name = \"localhost\"\n\
         accept_unknown_clients = true\n\
         [[machines]]\nname = \"M1\"\nrecipe = \"{recipe}\"\nfeatures = [{features}]\nshare = \"share/M1\"\n\
         [machines.gauge]\n{gauge}\n"
    )
}

/// Starts the service in `dir` (its log in `log`) and waits for both listeners.
fn start(dir: &Path, ports: [u16; 2], log: &str) -> KillOnDrop {
    let log = dir.join(log);
    let mut command = camloop_run(dir);
    command.stderr(std::fs::File::create(&log).unwrap());
    let mut service = KillOnDrop::spawn(&mut command).unwrap();
    for port in ports {
        let started = Instant::now();
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            let gone = service.try_wait().unwrap();
            if gone.is_some() || started.elapsed() > START_BOUND {
                let text = std::fs::read_to_string(&log).unwrap_or_default();
                panic!("no listener on port {port} ({gone:?}):\n{text}");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
    service
}

/// Runs `restart_checks.py <step>`; its output, or a failure with it and the service's log.
fn script(step: &str, params: &Path, out: &Path, service_log: &Path) -> String {
    let script = cli_support::repo("tests/opcua/restart_checks.py");
    let run = run_to_end(
        Command::new("python3")
            .arg(&script)
            .args([
                step,
                &params.display().to_string(),
                &out.display().to_string(),
                &SCRIPT_WATCHDOG.as_secs().to_string(),
            ])
            .current_dir(cli_support::repo("tests/opcua")),
        SCRIPT_BOUND,
    );
    if !run.success() {
        let log = std::fs::read_to_string(service_log).unwrap_or_default();
        panic!(
            "restart checks ({step}): {}\n--- the service's log\n{log}",
            run.report()
        );
    }
    println!("{}{}", run.stdout, run.stderr);
    run.stdout
}

/// Parts of `feature` in the history, read from the store the service writes.
fn parts_of(dir: &Path, feature: &str) -> usize {
    let url = format!("sqlite://{}/var/camloop.db", dir.display());
    tokio::runtime::Runtime::new().unwrap().block_on(async {
        let Ok(store) = camloop::store::Store::connect(&url).await else {
            return 0;
        };
        let filter = camloop::store::HistoryFilter {
            lobe: Some(camloop::names::FeatureName::new(feature).unwrap()),
            ..camloop::store::HistoryFilter::new(camloop::names::MachineName::new("M1").unwrap(), 5)
        };
        let n = store
            .measurement_history(&filter)
            .await
            .map_or(0, |p| p.items.len());
        store.close().await;
        n
    })
}

#[test]
fn asyncua_keeps_event_ids_and_sees_stored_results_across_a_restart() {
    if !asyncua_present() {
        eprintln!(
            "SKIP opcua_restart: Python asyncua not installed (CAMLOOP_REQUIRE_OPCUA=1 makes this a failure)"
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let certs = dir.path().join("client-certs");
    std::fs::create_dir_all(&certs).unwrap();
    let made = Command::new("python3")
        .arg(cli_support::repo("tests/opcua/client_checks.py"))
        .args(["certs", &certs.display().to_string()])
        .output()
        .unwrap();
    assert!(made.status.success(), "{}", cli_support::stderr(&made));
    let (http, opcua) = (free_port(), free_port());
    let sim = "kind = \"sim\"\npart_interval_ms = 1000";
    let ground = "\"IN1\", \"EX1\"";
    std::fs::write(
        dir.path().join("camloop.toml"),
        config(http, opcua, ground, sim),
    )
    .unwrap();
    let service = start(dir.path(), [http, opcua], "first.log");
    let password = std::fs::read_to_string(dir.path().join("var/admin-password")).unwrap();
    // Two parts of IN1: a table beyond the first to roll back from.
    for (feature, parts) in [("IN1", 2), ("EX1", 1)] {
        wait_for(
            &format!("{parts} stored parts of {feature}"),
            START_BOUND,
            || parts_of(dir.path(), feature) >= parts,
        );
    }
    let params = serde_json::json!({
        "endpoint": format!("opc.tcp://localhost:{opcua}/"),
        "http": format!("http://127.0.0.1:{http}"),
        "cert_dir": certs.display().to_string(),
        "admin_password": password.trim(),
        "machine": "M1",
        "feature": "IN1",
        // IN2 was never ground: it has no stored result after the restart.
        "features": ["IN1", "EX1", "IN2"],
    });
    let params_file = dir.path().join("params.json");
    std::fs::write(&params_file, params.to_string()).unwrap();
    let kept = dir.path().join("kept.json");
    script("before", &params_file, &kept, &dir.path().join("first.log"));

    // A real restart: the service is stopped as an operator stops it, and started again.
    service.signal("-TERM");
    let mut service = service;
    let stopped = service.exit_within(START_BOUND, Duration::from_millis(100), "the stop");
    assert!(stopped.success(), "the service's stop: {stopped:?}");
    std::fs::create_dir_all(dir.path().join("inbox")).unwrap();
    let idle = "kind = \"drop\"\nfolder = \"inbox\"";
    let all = "\"IN1\", \"EX1\", \"IN2\"";
    std::fs::write(
        dir.path().join("camloop.toml"),
        config(http, opcua, all, idle),
    )
    .unwrap();
    let _again = start(dir.path(), [http, opcua], "again.log");
    let text = script("after", &params_file, &kept, &dir.path().join("again.log"));
    assert!(text.contains("after: restart checks passed"), "{text}");
}
