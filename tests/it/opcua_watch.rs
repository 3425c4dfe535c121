//! The OPC UA server of the real `camloop run` watched by Python's `asyncua`
//! (`tests/opcua/watch_checks.py`), as `opcua_node` watches it with node-opcua: events on
//! `Server`, `Machines` and a machine, and every feature's `PartId`, `Time` and
//! `LatestResult`. It fails when an event came twice to an item, when an event of the
//! machine is missing on `Server` or `Machines`, or when a result is torn (values of one
//! SourceTimestamp naming different parts or times).
//!
//! Skipped like `opcua_asyncua` without asyncua. `CAMLOOP_OPCUA_WATCH_MACHINES` and
//! `CAMLOOP_OPCUA_WATCH_SECONDS` size a longer run (default: 2 machines for 8 s), and
//! `CAMLOOP_OPCUA_BIN` runs another build of camloop.

use std::process::Command;
use std::time::Duration;

use crate::cli_support;
use crate::opcua_asyncua::asyncua_present;
use crate::opcua_node::{FEATURES, env_or, start_plant};
use crate::process_support::run_to_end;

#[test]
fn asyncua_sees_every_event_once_and_no_torn_result() {
    if !asyncua_present() {
        eprintln!("SKIP opcua_watch: Python asyncua not installed");
        return;
    }
    let count = env_or("CAMLOOP_OPCUA_WATCH_MACHINES", 2) as usize;
    let seconds = env_or("CAMLOOP_OPCUA_WATCH_SECONDS", 8);
    let plant = start_plant(count);
    let certs = plant.dir.path().join("client-certs");
    std::fs::create_dir_all(&certs).unwrap();
    let made = Command::new("python3")
        .arg(cli_support::repo("tests/opcua/client_checks.py"))
        .args(["certs", &certs.display().to_string()])
        .output()
        .unwrap();
    assert!(made.status.success(), "{}", cli_support::stderr(&made));
    let params = serde_json::json!({
        "endpoint": format!("opc.tcp://localhost:{}/", plant.opcua),
        "cert_dir": certs.display().to_string(),
        "admin_password": plant.admin_password,
        "machines": plant.machines,
        "features": FEATURES,
        "duration_s": seconds,
    });
    let params_file = plant.dir.path().join("watch.json");
    std::fs::write(&params_file, params.to_string()).unwrap();
    // Connecting to a loaded service and subscribing take a while: a failure bound.
    let bound = Duration::from_secs(300 + seconds * 3);
    let run = run_to_end(
        Command::new("python3")
            .arg(cli_support::repo("tests/opcua/watch_checks.py"))
            .arg(&params_file)
            .current_dir(cli_support::repo("tests/opcua")),
        bound,
    );
    let out = &run.stdout;
    println!("{out}");
    assert!(run.success(), "asyncua watch failed: {}", run.report());
    let summary: serde_json::Value = serde_json::from_str(out.trim().lines().last().unwrap())
        .unwrap_or_else(|e| panic!("{e}: {out}"));
    assert!(
        summary["events"]["Server"]["received"].as_u64() > Some(0),
        "{summary}"
    );
}
