//! The OPC UA server of `camloop run`, driven by a client nobody on the project wrote: the
//! Python `asyncua` package from PyPI (`tests/opcua/client_checks.py`). The real binary runs
//! one simulated machine with `[opcua]` on; the script browses, reads and compares with the
//! HTTP API, subscribes, receives an event, calls `Rollback` as a viewer (refused) and as
//! the admin (delivered, on the share), and is refused a `None` connection, a certificate
//! not yet trusted (then trusted as an operator would: moved from `rejected/` to `trusted/`),
//! another untrusted one and an anonymous session.
//!
//! Skipped with a line saying so when `asyncua` is not installed, unless
//! `CAMLOOP_REQUIRE_OPCUA=1` (CI sets it and installs the pinned version).

use std::io::Write as _;
use std::net::TcpStream;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use crate::cli_support;
use crate::process_support::{KillOnDrop, camloop_run, free_port, run_to_end, wait_for};

/// The longest the service may take to start (a first start makes the server's RSA key and
/// migrates the database; on a loaded 2-core machine seconds): a failure, not a pace.
const START_BOUND: Duration = Duration::from_secs(90);

/// The script's own bounds are per check (a minute at most each); this is the whole run's.
const SCRIPT_BOUND: Duration = Duration::from_secs(300);

/// Seconds between parts: slow enough that the rollback's table is still on the share when
/// it is read, fast enough that the next part comes soon.
const PART_INTERVAL_S: f64 = 2.0;

/// Whether the pinned client is importable; panics when CI requires it.
pub(crate) fn asyncua_present() -> bool {
    let found = Command::new("python3")
        .args(["-c", "import asyncua, cryptography"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !found && std::env::var("CAMLOOP_REQUIRE_OPCUA").as_deref() == Ok("1") {
        panic!("CAMLOOP_REQUIRE_OPCUA=1 but Python's asyncua is not installed");
    }
    found
}

fn config(http: u16, opcua: u16) -> String {
    let recipe = cli_support::repo("config/parts/demo-camshaft.toml");
    let interval_ms = (PART_INTERVAL_S * 1000.0) as u64;
    format!(
        "[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n[service]\nvar_dir = \"var\"\n\
         [http]\nlisten = \"127.0.0.1:{http}\"\n\
         [opcua]\nenabled = true\nlisten = \"127.0.0.1:{opcua}\"\nhost_name = \"localhost\"\n\
         [[machines]]\nname = \"M1\"\nrecipe = \"{recipe}\"\nfeatures = [\"IN1\", \"EX1\"]\nshare = \"share/M1\"\n\
         [machines.gauge]\nkind = \"sim\"\npart_interval_ms = {interval_ms}\n"
    )
}

/// A temporary folder holding the client certificates the script makes (`client-certs/`).
fn client_certs(script: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let certs = dir.path().join("client-certs");
    std::fs::create_dir_all(&certs).unwrap();
    let made = Command::new("python3")
        .arg(script)
        .arg("certs")
        .arg(&certs)
        .output()
        .unwrap();
    assert!(made.status.success(), "{}", cli_support::stderr(&made));
    (dir, certs)
}

/// The service run in `dir` (its `camloop.toml` written), once it has written the first
/// admin's password and listens on `ports`.
fn start(dir: &Path, ports: &[u16]) -> KillOnDrop {
    let service = KillOnDrop::spawn(&mut camloop_run(dir)).unwrap();
    let password_file = dir.join("var/admin-password");
    wait_for("the admin password file", START_BOUND, || {
        password_file.exists()
    });
    for &port in ports {
        wait_for(&format!("a listener on port {port}"), START_BOUND, || {
            TcpStream::connect(("127.0.0.1", port)).is_ok()
        });
    }
    service
}

fn add_viewer(dir: &Path, password: &str) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_camloop"))
        .args(["user", "add", "vera", "--role", "viewer"])
        .args(["--database", "sqlite://var/camloop.db"])
        .current_dir(dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    writeln!(stdin, "{password}").unwrap();
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", cli_support::stderr(&out));
}

/// `config` with unknown client certificates accepted (and `extra` lines) in `[opcua]`.
fn trusting(config: String, extra: &str) -> String {
    config.replace(
        "host_name = \"localhost\"\n",
        &format!("host_name = \"localhost\"\n{extra}accept_unknown_clients = true\n"),
    )
}

/// Runs the script's `mode` with `params` (written beside the service) to its end, bounded
/// by `SCRIPT_BOUND`; its exit status and what it printed, standard output then error.
fn run_checks(
    dir: &Path,
    script: &str,
    mode: &str,
    params: &serde_json::Value,
    what: &str,
) -> (std::process::ExitStatus, String) {
    let params_file = dir.join(format!("{mode}-params.json"));
    std::fs::write(&params_file, params.to_string()).unwrap();
    let run = run_to_end(
        Command::new("python3").args([script, mode, &params_file.display().to_string()]),
        SCRIPT_BOUND,
    );
    let Some(status) = run.status else {
        panic!("{what}: {}", run.report());
    };
    (status, format!("{}{}", run.stdout, run.stderr))
}

/// A skip line naming `what` when asyncua is missing (a failure when CI requires it).
fn skipped(what: &str) -> bool {
    let missing = !asyncua_present();
    if missing {
        eprintln!(
            "SKIP {what}: Python asyncua not installed (pip install asyncua==2.1.0; CAMLOOP_REQUIRE_OPCUA=1 makes this a failure)"
        );
    }
    missing
}

/// One test's service and what its scripts need.
struct Served {
    script: String,
    dir: tempfile::TempDir,
    certs: std::path::PathBuf,
    http: u16,
    opcua: u16,
    service: KillOnDrop,
}

/// Client certificates made, the config written (`trusted`: `None` for the plain one,
/// `Some(lines)` for one that accepts unknown clients, with those lines in `[opcua]`), the
/// service started and listening on OPC UA (and HTTP when `http_too`).
fn served(trusted: Option<&str>, http_too: bool) -> Served {
    let script = cli_support::repo("tests/opcua/client_checks.py");
    let (dir, certs) = client_certs(&script);
    let (http, opcua) = (free_port(), free_port());
    let text = match trusted {
        None => config(http, opcua),
        Some(extra) => trusting(config(http, opcua), extra),
    };
    std::fs::write(dir.path().join("camloop.toml"), text).unwrap();
    let ports: &[u16] = if http_too { &[http, opcua] } else { &[opcua] };
    let service = start(dir.path(), ports);
    Served {
        script,
        dir,
        certs,
        http,
        opcua,
        service,
    }
}

#[test]
fn asyncua_browses_reads_subscribes_and_calls_rollback_with_users() {
    if skipped("opcua_asyncua") {
        return;
    }
    let Served {
        script,
        dir,
        certs,
        http,
        opcua,
        service: _service,
    } = served(None, true);
    let password_file = dir.path().join("var/admin-password");
    let admin_password = std::fs::read_to_string(&password_file)
        .unwrap()
        .trim()
        .to_string();
    let viewer_password = "viewer-password-1234";
    add_viewer(dir.path(), viewer_password);

    let params = serde_json::json!({
        "endpoint": format!("opc.tcp://localhost:{opcua}/"),
        "http": format!("http://127.0.0.1:{http}"),
        "cert_dir": certs.display().to_string(),
        "pki": dir.path().join("var/opcua/pki").display().to_string(),
        "admin_password": admin_password,
        "viewer": "vera",
        "viewer_password": viewer_password,
        "machines": ["M1"],
        "machine": "M1",
        "features": ["EX1", "IN1"],
        "feature": "IN1",
        "share": dir.path().join("share/M1").display().to_string(),
        "part_interval_s": PART_INTERVAL_S,
    });
    let (status, out) = run_checks(dir.path(), &script, "check", &params, "the asyncua checks");
    println!("{out}");
    assert!(status.success(), "asyncua checks failed:\n{out}");
    assert!(out.contains("all OPC UA checks passed"), "{out}");
    // The viewer's refused acknowledgement and rollback are in the audit trail.
    let url = format!("sqlite://{}/var/camloop.db", dir.path().display());
    let refused = tokio::runtime::Runtime::new().unwrap().block_on(async {
        let store = camloop::store::Store::connect(&url).await.unwrap();
        let rows = store
            .audit(jiff::Timestamp::UNIX_EPOCH, 0, 1000, false)
            .await
            .unwrap();
        store.close().await;
        rows.into_iter()
            .filter(|r| r.entry.action == "refused" && r.entry.actor == "vera")
            .map(|r| r.entry.reason)
            .collect::<Vec<_>>()
    });
    assert_eq!(
        refused,
        [
            "OPC UA Rollback: BadUserAccessDenied",
            "OPC UA AcknowledgeEvent: BadUserAccessDenied",
        ],
        "{refused:?}"
    );
}

/// On a server with `security = "Basic256Sha256+None"`, a user name and password sent over
/// the None endpoint (in clear) are refused, and the None endpoint offers no user-name
/// policy; the same user signs in over the secure endpoint.
#[test]
fn asyncua_is_refused_a_clear_text_password_over_none() {
    if skipped("opcua_asyncua (clear-text password)") {
        return;
    }
    let Served {
        script,
        dir,
        certs,
        opcua,
        service,
        ..
    } = served(Some("security = \"Basic256Sha256+None\"\n"), false);
    let password_file = dir.path().join("var/admin-password");
    let params = serde_json::json!({
        "endpoint": format!("opc.tcp://localhost:{opcua}/"),
        "cert_dir": certs.display().to_string(),
        "admin_password": std::fs::read_to_string(&password_file).unwrap().trim(),
    });
    let (status, text) = run_checks(
        dir.path(),
        &script,
        "clear-password",
        &params,
        "the asyncua checks",
    );
    println!("{text}");
    assert!(status.success(), "asyncua checks failed:\n{text}");
    assert!(text.contains("clear-text password checks passed"), "{text}");
    drop(service);
    owner_only_and_a_readable_key_refused(dir.path());
}

/// The var folder is the service's account's only, and so is the OPC UA private key; a key
/// that others can read stops the next start.
fn owner_only_and_a_readable_key_refused(dir: &Path) {
    use std::os::unix::fs::PermissionsExt;
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    let key = dir.join("var/opcua/pki/private/private.pem");
    assert_eq!(mode(&dir.join("var")), 0o700);
    assert_eq!(mode(&key), 0o600);
    for file in ["camloop.db", "audit-key", "audit-head", "admin-password"] {
        assert_eq!(mode(&dir.join("var").join(file)), 0o600, "{file}");
    }
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).unwrap();
    let mut again = camloop_run(dir);
    again.stderr(Stdio::piped());
    let mut again = KillOnDrop::spawn(&mut again).unwrap();
    let status = again.exit_within(START_BOUND, Duration::from_millis(100), "a start refused");
    let mut err = String::new();
    use std::io::Read as _;
    again
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    assert!(!status.success(), "a start with a readable key");
    assert!(err.contains("can be read by other accounts"), "{err}");
}

/// Five wrong OPC UA passwords for a user lock that user's OPC UA sign-in only: the same
/// user's HTTP sign-in and valid API token are never refused (429) for them.
#[test]
fn an_opcua_lockout_leaves_the_user_s_http_sign_in_and_token_alone() {
    if skipped("opcua_asyncua (lockout)") {
        return;
    }
    let Served {
        script,
        dir,
        certs,
        http,
        opcua,
        service: _service,
    } = served(Some(""), true);
    let password = "viewer-password-1234";
    add_viewer(dir.path(), password);
    let params = serde_json::json!({
        "endpoint": format!("opc.tcp://localhost:{opcua}/"),
        "cert_dir": certs.display().to_string(),
        "user": "vera",
        "password": password,
    });
    let (status, text) = run_checks(
        dir.path(),
        &script,
        "lockout",
        &params,
        "the lockout checks",
    );
    assert!(status.success(), "asyncua checks failed:\n{text}");
    assert!(text.contains("OPC UA lockout checks passed"), "{text}");
    let url = format!("sqlite://{}/var/camloop.db", dir.path().display());
    tokio::runtime::Runtime::new().unwrap().block_on(async {
        use crate::access_lockout::{sign_in, with_token};
        let store = camloop::store::Store::connect(&url).await.unwrap();
        let vera = store.user("vera").await.unwrap().unwrap();
        let token = camloop::auth::new_token().unwrap();
        let now = camloop::clock::now();
        let grant = camloop::store::NewToken {
            user: vera.id,
            label: String::new(),
            sha256: camloop::auth::token_digest(&token),
            role: camloop::store::Role::Viewer,
            created_at: now,
            expires_at: now + jiff::SignedDuration::from_hours(1),
        };
        store.add_token(&grant).await.unwrap();
        store.close().await;
        let addr = std::net::SocketAddr::from(([127, 0, 0, 1], http));
        let here = std::net::IpAddr::from([127, 0, 0, 1]);
        assert_eq!(with_token(addr, here, &token).await, 200, "vera's token");
        assert_eq!(
            sign_in(addr, here, "vera", password).await,
            303,
            "vera over HTTP"
        );
    });
}

/// A viewer's open session (signed in, reading) reads nothing more once the user is disabled
/// with `camloop user disable` beside the running service: the service rechecks its OPC UA
/// users' state every 2 s (the script allows 20 s).
#[test]
fn a_disabled_user_s_open_session_stops_reading() {
    if skipped("opcua_asyncua (disabled user)") {
        return;
    }
    let Served {
        script,
        dir,
        certs,
        opcua,
        service: _service,
        ..
    } = served(Some(""), false);
    let password = "viewer-password-1234";
    add_viewer(dir.path(), password);
    let params = serde_json::json!({
        "endpoint": format!("opc.tcp://localhost:{opcua}/"),
        "cert_dir": certs.display().to_string(),
        "user": "vera",
        "password": password,
        "machine": "M1",
        "camloop": env!("CARGO_BIN_EXE_camloop"),
        "database": "sqlite://var/camloop.db",
        "dir": dir.path().display().to_string(),
    });
    let (status, text) = run_checks(
        dir.path(),
        &script,
        "disabled",
        &params,
        "the asyncua checks",
    );
    println!("{text}");
    assert!(status.success(), "asyncua checks failed:\n{text}");
    assert!(text.contains("disabled user checks passed"), "{text}");
}
