//! The OPC UA server of the real `camloop run` driven by node-opcua, a second independent
//! client library (`tools/opcua-node/checks.js`, pinned by its lock file), as a plant's
//! integrator would use it: simulated machines of 8 features, one part a second each; the
//! client reads at the advertised MaxNodesPerRead, and for a while watches events on
//! `Server`, `Machines` and a machine, and every feature's result. It fails when an event
//! came twice or missed a notifier, when a publish carried part of a result or values whose
//! times disagree, or when a part's Time is not its time in the history.
//!
//! Skipped with a line saying so when node-opcua is not installed (`npm ci` in
//! `tools/opcua-node`), unless `CAMLOOP_REQUIRE_NODE_OPCUA=1` (CI sets it and installs it).
//! `CAMLOOP_OPCUA_NODE_MACHINES` and `CAMLOOP_OPCUA_NODE_SECONDS` size a longer run for the
//! manual's figures (default: 3 machines for 12 s), and `CAMLOOP_OPCUA_BIN` runs another
//! build of camloop (a release build for a plant's size) instead of the test's own.

use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::cli_support;
use crate::process_support::{KillOnDrop, camloop_run, free_port, run_to_end};

/// The longest the service may take to start on a loaded 2-core machine: a failure bound.
const START_BOUND: Duration = Duration::from_secs(120);

/// How long the client waits past its watching time for its first results: a failure bound
/// for a loaded machine, not a pace.
const WAIT_BOUND: Duration = Duration::from_secs(240);

pub(crate) const FEATURES: [&str; 8] = ["IN1", "EX1", "IN2", "EX2", "IN3", "EX3", "IN4", "EX4"];

fn node_opcua_present() -> bool {
    let dir = cli_support::repo("tools/opcua-node/node_modules/node-opcua-client");
    let node = Command::new("node")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let found = node && std::path::Path::new(&dir).is_dir();
    if !found && std::env::var("CAMLOOP_REQUIRE_NODE_OPCUA").as_deref() == Ok("1") {
        panic!(
            "CAMLOOP_REQUIRE_NODE_OPCUA=1 but node-opcua is not installed (npm ci in tools/opcua-node)"
        );
    }
    found
}

pub(crate) fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn wait_for(what: &str, mut ready: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ready() {
        assert!(
            start.elapsed() < START_BOUND,
            "{what} not within {START_BOUND:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn config(http: u16, opcua: u16, machines: &[String]) -> String {
    let recipe = cli_support::repo("config/parts/demo-camshaft.toml");
    let features = FEATURES.map(|f| format!("\"{f}\"")).join(", ");
    let mut text = format!(
        "[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n[service]\nvar_dir = \"var\"\n\
         [http]\nlisten = \"127.0.0.1:{http}\"\n\
         [opcua]\nenabled = true\nlisten = \"127.0.0.1:{opcua}\"\nhost_name = \"localhost\"\naccept_unknown_clients = true\n"
    );
    for (i, m) in machines.iter().enumerate() {
        text.push_str(&format!(
            "[[machines]]\nname = \"{m}\"\nrecipe = \"{recipe}\"\nfeatures = [{features}]\nshare = \"share/{m}\"\n\
             [machines.gauge]\nkind = \"sim\"\npart_interval_ms = 1000\nseed = {}\n",
            i + 1
        ));
    }
    text
}

/// The real service of simulated machines with `[opcua]` on, answering on both ports.
pub(crate) struct Plant {
    pub(crate) dir: tempfile::TempDir,
    _service: KillOnDrop,
    pub(crate) http: u16,
    pub(crate) opcua: u16,
    pub(crate) admin_password: String,
    pub(crate) machines: Vec<String>,
}

/// Starts `count` simulated machines of [`FEATURES`], one part a second each, with the
/// test's camloop or the one `CAMLOOP_OPCUA_BIN` names.
pub(crate) fn start_plant(count: usize) -> Plant {
    let machines: Vec<String> = (1..=count).map(|i| format!("SIM{i:02}")).collect();
    let dir = tempfile::tempdir().unwrap();
    let (http, opcua) = (free_port(), free_port());
    std::fs::write(
        dir.path().join("camloop.toml"),
        config(http, opcua, &machines),
    )
    .unwrap();
    let mut command = match std::env::var_os("CAMLOOP_OPCUA_BIN") {
        Some(bin) => {
            let mut c = Command::new(bin);
            c.args(["run", "--config", "camloop.toml"])
                .current_dir(dir.path())
                .stdout(Stdio::null())
                .stderr(Stdio::null());
            c
        }
        None => camloop_run(dir.path()),
    };
    let service = KillOnDrop::spawn(&mut command).unwrap();
    let password_file = dir.path().join("var/admin-password");
    wait_for("the admin password file", || password_file.exists());
    for port in [http, opcua] {
        wait_for(&format!("a listener on port {port}"), || {
            TcpStream::connect(("127.0.0.1", port)).is_ok()
        });
    }
    let admin_password = std::fs::read_to_string(&password_file)
        .unwrap()
        .trim()
        .to_string();
    Plant {
        dir,
        _service: service,
        http,
        opcua,
        admin_password,
        machines,
    }
}

#[test]
fn node_opcua_sees_every_event_once_and_no_torn_result() {
    if !node_opcua_present() {
        eprintln!(
            "SKIP opcua_node: node-opcua not installed (cd tools/opcua-node && npm ci; CAMLOOP_REQUIRE_NODE_OPCUA=1 makes this a failure)"
        );
        return;
    }
    let count = env_or("CAMLOOP_OPCUA_NODE_MACHINES", 3) as usize;
    let seconds = env_or("CAMLOOP_OPCUA_NODE_SECONDS", 12);
    let plant = start_plant(count);
    let dir = &plant.dir;
    let params = serde_json::json!({
        "endpoint": format!("opc.tcp://localhost:{}/", plant.opcua),
        "http": format!("http://127.0.0.1:{}", plant.http),
        "admin_password": plant.admin_password,
        "client_pki": dir.path().join("node-pki").display().to_string(),
        "machines": plant.machines,
        "features": FEATURES,
        "duration_s": seconds,
        "history_sample": 40,
        "min_results": 10,
        "bound_s": WAIT_BOUND.as_secs(),
    });
    let params_file = dir.path().join("params.json");
    std::fs::write(&params_file, params.to_string()).unwrap();
    let bound = START_BOUND * 2 + WAIT_BOUND + Duration::from_secs(seconds * 3);
    let run = run_to_end(
        Command::new("node")
            .arg(cli_support::repo("tools/opcua-node/checks.js"))
            .arg(&params_file)
            .current_dir(cli_support::repo("tools/opcua-node")),
        bound,
    );
    let out = &run.stdout;
    println!("{out}");
    assert!(run.success(), "node-opcua checks failed: {}", run.report());
    let summary: serde_json::Value = serde_json::from_str(out.trim().lines().last().unwrap())
        .unwrap_or_else(|e| panic!("{e}: {out}"));
    assert!(
        summary["events"]["Server"]["received"].as_u64() > Some(0),
        "{summary}"
    );
}
