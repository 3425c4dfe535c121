//! HTTPS on the real binary: `camloop tls self-signed` makes the pair, `camloop run` serves
//! it; a rustls client and curl (`--cacert`) verify the certificate; HSTS is sent; a
//! SIGHUP after the pair was replaced serves the new certificate to new connections while
//! an open connection goes on; and the start-up rule refuses a network address without TLS
//! unless `allow_insecure_network = true`, which warns.

use crate::cli_support;
use crate::process_support;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use process_support::{KillOnDrop, camloop_run, free_port};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_rustls::TlsConnector;
use tokio_rustls::client::TlsStream;
use tokio_rustls::rustls;
use tokio_rustls::rustls::pki_types::{CertificateDer, ServerName, pem::PemObject};

/// Longest wait for the service to come up or take a new certificate; a failure, not a pace.
const DEADLINE: Duration = Duration::from_secs(30);

fn config(listen: &str, http_extra: &str) -> String {
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n\
         [http]\nlisten = \"{listen}\"\n{http_extra}\n\
         [[machines]]\nname = \"SIM1\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"share/SIM1\"\n\
         [machines.gauge]\nkind = \"sim\"\npart_interval_ms = 500\n",
        recipe.display()
    )
}

fn run(dir: &Path, log: Stdio) -> KillOnDrop {
    KillOnDrop::spawn(camloop_run(dir).stdout(log)).unwrap()
}

/// A client trusting only the certificate in `cert_pem`.
fn connector(cert_pem: &str) -> TlsConnector {
    TlsConnector::from(Arc::new(trusting(cert_pem)))
}

/// A rustls client configuration (ring) that trusts only the certificates in `cert_pem`:
/// the HTTP and the MQTT tests check the server's certificate with it.
pub(crate) fn trusting(cert_pem: &str) -> rustls::ClientConfig {
    let mut roots = rustls::RootCertStore::empty();
    for c in CertificateDer::pem_slice_iter(cert_pem.as_bytes()) {
        roots.add(c.unwrap()).unwrap();
    }
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .unwrap()
        .with_root_certificates(roots)
        .with_no_client_auth()
}

async fn tls(port: u16, trusted: &str) -> std::io::Result<TlsStream<TcpStream>> {
    let tcp = TcpStream::connect(("127.0.0.1", port)).await?;
    let name = ServerName::try_from("localhost").unwrap();
    connector(trusted).connect(name, tcp).await
}

/// One GET /healthz on `s` (kept alive unless `close`); the response head.
async fn healthz(s: &mut TlsStream<TcpStream>, close: bool) -> String {
    let connection = if close { "close" } else { "keep-alive" };
    let request =
        format!("GET /healthz HTTP/1.1\r\nHost: localhost\r\nConnection: {connection}\r\n\r\n");
    s.write_all(request.as_bytes()).await.unwrap();
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    // The body is small JSON: the response is complete once its closing brace arrives.
    while !got.ends_with(b"}") {
        let n = tokio::time::timeout(DEADLINE, s.read(&mut buf))
            .await
            .unwrap()
            .unwrap();
        assert!(n > 0, "closed early: {}", String::from_utf8_lossy(&got));
        got.extend_from_slice(&buf[..n]);
    }
    String::from_utf8_lossy(&got).to_ascii_lowercase()
}

/// Waits until a client trusting `cert` completes a handshake.
async fn until_trusted(port: u16, cert: &str) -> TlsStream<TcpStream> {
    let started = Instant::now();
    loop {
        match tls(port, cert).await {
            Ok(s) => return s,
            Err(e) if started.elapsed() > DEADLINE => panic!("no TLS within {DEADLINE:?}: {e}"),
            Err(_) => tokio::time::sleep(Duration::from_millis(50)).await,
        }
    }
}

fn self_signed(dir: &Path, force: bool) -> String {
    let mut args = vec!["tls", "self-signed", "--out", "tls"];
    if force {
        args.push("--force");
    }
    let out = cli_support::camloop(&args, dir);
    assert!(out.status.success(), "{}", cli_support::stderr(&out));
    std::fs::read_to_string(dir.join("tls/cert.pem")).unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_verify_the_certificate_and_a_hangup_reloads_it_without_dropping_the_loop() {
    let dir = tempfile::tempdir().unwrap();
    let old_cert = self_signed(dir.path(), false);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(dir.path().join("tls/key.pem"))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o600, "the key is its owner's only");
    }
    // A second run does not overwrite the pair without --force.
    let again = cli_support::camloop(&["tls", "self-signed", "--out", "tls"], dir.path());
    assert!(!again.status.success());

    let port = free_port();
    let tls_keys = "tls_cert = \"tls/cert.pem\"\ntls_key = \"tls/key.pem\"";
    let text = config(&format!("127.0.0.1:{port}"), tls_keys);
    std::fs::write(dir.path().join("camloop.toml"), text).unwrap();
    let service = run(dir.path(), Stdio::null());

    // rustls verifies the chain and the name; the answer carries HSTS.
    let mut kept = until_trusted(port, &old_cert).await;
    let head = healthz(&mut kept, false).await;
    assert!(head.starts_with("http/1.1 200"), "{head}");
    assert!(
        head.contains("strict-transport-security: max-age=31536000"),
        "{head}"
    );
    // A client that trusts another certificate refuses this one.
    let stranger = camloop::service::http::self_signed(&["localhost".into()])
        .unwrap()
        .0;
    let refused = tls(port, &stranger).await;
    assert!(
        refused.is_err(),
        "a certificate nobody vouched for was accepted"
    );
    // Plain HTTP on the TLS port gets no answer.
    let mut plain = TcpStream::connect(("127.0.0.1", port)).await.unwrap();
    plain
        .write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n\r\n")
        .await
        .unwrap();
    let mut buf = Vec::new();
    let _ = tokio::time::timeout(DEADLINE, plain.read_to_end(&mut buf)).await;
    assert!(!String::from_utf8_lossy(&buf).contains("200 OK"));

    // The listener serves while the machines still open: any of the service's states.
    let body = curl(port, dir.path());
    assert!(
        body.as_ref().is_none_or(|b| b.contains(r#""status":""#)),
        "{body:?}"
    );

    // The certificate's days to expiry: `camloop tls self-signed` makes it valid to 4096.
    let days = expiry_days(port, &old_cert).await;
    assert!(days > 365.0 * 2000.0, "{days}");

    // A new pair in place, then SIGHUP: new connections get it, the open one goes on.
    let new_cert = self_signed(dir.path(), true);
    assert_ne!(new_cert, old_cert);
    service.signal("-HUP");
    let mut fresh = until_trusted(port, &new_cert).await;
    assert!(healthz(&mut fresh, true).await.starts_with("http/1.1 200"));
    assert!(
        tls(port, &old_cert).await.is_err(),
        "the old certificate is still served"
    );
    assert!(healthz(&mut kept, true).await.starts_with("http/1.1 200"));
    // The loop was not dropped by the reload: the service comes to "ok" with its machine.
    let deadline = std::time::Instant::now() + DEADLINE;
    loop {
        match curl(port, dir.path()) {
            None => break,
            Some(b) if b.contains(r#""status":"ok""#) => break,
            Some(b) => {
                assert!(std::time::Instant::now() < deadline, "never ok: {b}");
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    }
    drop(service);
}

/// `camloop_tls_certificate_expiry_days` from /metrics, over TLS.
async fn expiry_days(port: u16, cert: &str) -> f64 {
    let mut s = until_trusted(port, cert).await;
    s.write_all(b"GET /metrics HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n")
        .await
        .unwrap();
    let mut text = Vec::new();
    // A close_notify-less end is fine here: the whole answer came before it.
    let _ = tokio::time::timeout(DEADLINE, s.read_to_end(&mut text)).await;
    let text = String::from_utf8_lossy(&text);
    text.lines()
        .find_map(|l| l.strip_prefix("camloop_tls_certificate_expiry_days "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no expiry in /metrics:\n{text}"))
}

/// A key that is not the certificate's stops the start before anything is made: no var
/// folder, no database, no first admin.
#[test]
fn a_mismatched_pair_is_refused_before_the_database_or_an_admin_is_made() {
    let dir = tempfile::tempdir().unwrap();
    self_signed(dir.path(), false);
    let (_, other_key) = camloop::service::http::self_signed(&["localhost".into()]).unwrap();
    std::fs::write(dir.path().join("tls/other-key.pem"), other_key).unwrap();
    let keys = "tls_cert = \"tls/cert.pem\"\ntls_key = \"tls/other-key.pem\"";
    let text = config("127.0.0.1:0", keys);
    std::fs::write(dir.path().join("camloop.toml"), text).unwrap();
    let out = cli_support::camloop(&["run", "--config", "camloop.toml"], dir.path());
    let err = cli_support::stderr(&out);
    assert!(!out.status.success());
    assert!(err.contains("do not make a pair"), "{err}");
    for left in ["var/camloop.db", "var/admin-password", "var/audit-key"] {
        assert!(!dir.path().join(left).exists(), "{left} was made: {err}");
    }
}

/// curl trusting `tls/cert.pem` fetches /healthz and returns the body; `None`, with a line,
/// when curl is missing.
fn curl(port: u16, dir: &Path) -> Option<String> {
    let Ok(out) = Command::new("curl")
        .args([
            "--silent",
            "--show-error",
            "--fail",
            "--cacert",
            "tls/cert.pem",
        ])
        .arg(format!("https://localhost:{port}/healthz"))
        .current_dir(dir)
        .output()
    else {
        eprintln!("SKIPPED: curl not installed; the rustls client checked the certificate");
        return None;
    };
    assert!(
        out.status.success(),
        "curl: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(String::from_utf8_lossy(&out.stdout).into_owned())
}

#[test]
fn a_network_address_without_tls_is_refused_unless_allowed_and_then_warns() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let open = config(&format!("0.0.0.0:{port}"), "");
    std::fs::write(dir.path().join("camloop.toml"), &open).unwrap();
    let out = cli_support::camloop(&["run", "--config", "camloop.toml"], dir.path());
    let err = cli_support::stderr(&out);
    assert!(!out.status.success());
    assert!(
        err.contains("is not a loopback address and TLS is off")
            && err.contains("allow_insecure_network = true"),
        "{err}"
    );
    let allowed = config(&format!("0.0.0.0:{port}"), "allow_insecure_network = true");
    std::fs::write(dir.path().join("camloop.toml"), allowed).unwrap();
    let mut service = run(dir.path(), Stdio::piped());
    let log = BufReader::new(service.stdout.take().unwrap());
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in log.lines().map_while(Result::ok) {
            if line.contains("serving insecurely") {
                let _ = tx.send(line);
            }
        }
    });
    let warned = rx
        .recv_timeout(DEADLINE)
        .expect("the warning is logged at start");
    assert!(
        warned.contains("WARN") && warned.contains("0.0.0.0"),
        "{warned}"
    );
    drop(service);
}
