//! The hardened listener on a real socket (port 0): a forged `Host` (DNS rebinding) is
//! refused, every response carries the security headers, one client holding its connection
//! cap leaves `/healthz` to the others, and path parameters are checked with error bodies
//! that quote at most 64 characters of what was sent.

use crate::service_support;

use camloop::names::MachineName;
use camloop::service::http::{self, AppState, HostAllowList, HttpLimits, Policy};
use service_support::{exchange, json};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};
use tokio::sync::watch;

struct Server {
    addr: SocketAddr,
    _stop: watch::Sender<bool>,
}

/// The API (no store, no machine loops: the checks under test come first) on 127.0.0.1:0.
async fn server(max_connections: usize, per_client: usize) -> Server {
    let mut machines = BTreeMap::new();
    machines.insert(
        MachineName::new("SIM1").unwrap(),
        vec!["IN1".parse().unwrap()],
    );
    let limits = HttpLimits {
        max_connections,
        max_connections_per_client: per_client,
        header_timeout: Duration::from_secs(10),
        body_timeout: Duration::from_secs(10),
    };
    let state = AppState {
        store: Arc::new(tokio::sync::RwLock::new(None)),
        metrics: Arc::default(),
        machines: Arc::new(machines),
        commands: Arc::default(),
        auth: Arc::new(camloop::service::http::AuthState::new(None, true)),
        body_timeout: limits.body_timeout,
        dashboard: Arc::default(),
        cluster: None,
    };
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let policy = Policy {
        hosts: HostAllowList::new(addr, &["camloop.plant".into()]),
        tls: false,
    };
    let (stop, stopped) = watch::channel(false);
    tokio::spawn(http::serve_with(
        listener,
        http::router(state),
        limits,
        policy,
        None,
        stopped,
    ));
    Server { addr, _stop: stop }
}

/// One GET with `host` as the Host header; the status, the response's head and its body.
async fn get_as(addr: SocketAddr, host: &str, path: &str) -> (u16, String, String) {
    let mut s = TcpStream::connect(addr).await.unwrap();
    let request = format!("GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n");
    s.write_all(request.as_bytes()).await.unwrap();
    let mut text = String::new();
    let _ = s.read_to_string(&mut text).await;
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head.split(' ').nth(1).and_then(|s| s.parse().ok());
    (
        status.unwrap_or(0),
        head.to_ascii_lowercase(),
        body.to_string(),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_forged_host_is_refused_and_allowed_names_are_served() {
    let s = server(16, 8).await;
    let port = s.addr.port();
    // A page on attacker.example whose name now resolves to 127.0.0.1: the browser sends
    // the attacker's name as the Host.
    for forged in [
        "attacker.example".to_string(),
        format!("attacker.example:{port}"),
        format!("localhost.attacker.example:{port}"),
        format!("localhost:{}", port.wrapping_add(1)),
    ] {
        for path in ["/api/v1/machines", "/", "/healthz", "/metrics"] {
            let (status, head, body) = get_as(s.addr, &forged, path).await;
            assert_eq!(status, 421, "{forged} {path}: {head}");
            assert_eq!(json(&body)["code"], "host_not_allowed", "{body}");
            assert!(head.contains("content-security-policy"), "{head}");
        }
    }
    for allowed in [
        format!("localhost:{port}"),
        format!("127.0.0.1:{port}"),
        "localhost".to_string(),
        "camloop.plant".to_string(),
    ] {
        let (status, _, body) = get_as(s.addr, &allowed, "/healthz").await;
        assert_eq!(status, 200, "{allowed}: {body}");
    }
    // HTTP/1.0 without a Host names no host at all: refused too.
    let (status, _) = exchange(s.addr, "GET /healthz HTTP/1.0\r\n\r\n").await;
    assert_eq!(status, 421);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_response_carries_the_security_headers_and_api_pages_and_programs_are_not_stored() {
    let s = server(16, 8).await;
    let program = "/api/v1/machines/SIM1/lobes/IN1/tables/1/program";
    for (path, cache) in [
        ("/healthz", "no-store"),
        ("/api/v1/machines", "no-store"),
        (program, "no-store"),
        ("/", "no-store"),
        ("/machines/SIM1/features/IN1", "no-store"),
        ("/no/such/page", "no-store"),
        // The assets choose their own caching (revalidated, not stored blind).
        ("/assets/app.js", "no-cache"),
    ] {
        let (status, head, _) = get_as(s.addr, "localhost", path).await;
        assert!(status > 0, "{path}");
        for expected in [
            format!("content-security-policy: {}", http::CONTENT_SECURITY_POLICY),
            "x-content-type-options: nosniff".into(),
            "x-frame-options: deny".into(),
            "referrer-policy: no-referrer".into(),
            format!("cache-control: {cache}"),
        ] {
            assert!(
                head.contains(&expected.to_ascii_lowercase()),
                "{path} ({status}) lacks `{expected}`:\n{head}"
            );
        }
        // No TLS here: no HSTS (a browser would pin HTTPS on a plain-HTTP service).
        assert!(!head.contains("strict-transport-security"), "{head}");
    }
    for part in [
        "frame-ancestors 'none'",
        "default-src 'self'",
        "script-src 'self'",
    ] {
        assert!(http::CONTENT_SECURITY_POLICY.contains(part));
    }
    assert!(!http::CONTENT_SECURITY_POLICY.contains("unsafe-inline"));
}

/// A socket from `source` (another loopback address) to `to`.
async fn connect_from(source: &str, to: SocketAddr) -> TcpStream {
    let socket = TcpSocket::new_v4().unwrap();
    socket.bind(format!("{source}:0").parse().unwrap()).unwrap();
    socket.connect(to).await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_client_holding_its_cap_does_not_lock_the_others_out() {
    // The probe: 20 half-open sockets on a 20-connection instance held /healthz for
    // the 10 s header timeout. Here one client (127.0.0.2) opens all 20.
    let (global, per_client) = (20, 5);
    let s = server(global, per_client).await;
    let mut hog = Vec::new();
    for _ in 0..global {
        let mut c = connect_from("127.0.0.2", s.addr).await;
        c.write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n")
            .await
            .unwrap();
        hog.push(c);
    }
    // Those beyond its cap are closed at once: each read waits at most 200 ms, far below
    // the 10 s header timeout that would otherwise close them.
    let mut closed = 0;
    for c in &mut hog {
        let mut buf = [0u8; 64];
        // Closed with the request unread: an end of stream or a reset.
        let read = tokio::time::timeout(Duration::from_millis(200), c.read(&mut buf)).await;
        if let Ok(Ok(0) | Err(_)) = read {
            closed += 1;
        }
    }
    assert_eq!(
        closed,
        global - per_client,
        "connections closed beyond the cap"
    );
    // Another client is served at once (bound: 2 s; before the cap it waited 9.5 s).
    let started = Instant::now();
    let answer = tokio::time::timeout(
        Duration::from_secs(2),
        get_as(s.addr, "localhost", "/healthz"),
    )
    .await
    .expect("/healthz answers while one client holds its cap");
    assert_eq!(answer.0, 200, "{}", answer.2);
    assert!(started.elapsed() < Duration::from_secs(2));
    // And the same client's own extra connection is refused, not queued.
    let mut extra = connect_from("127.0.0.2", s.addr).await;
    extra
        .write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n\r\n")
        .await
        .unwrap();
    let mut buf = Vec::new();
    let read = tokio::time::timeout(Duration::from_secs(2), extra.read_to_end(&mut buf)).await;
    assert!(matches!(read, Ok(Ok(0)) | Ok(Err(_))), "{buf:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn path_parameters_are_checked_and_errors_quote_at_most_64_characters() {
    let s = server(16, 8).await;
    let long = "A".repeat(10_000);
    let cases = [
        "/api/v1/machines/SIM1/parts/..%2F..".to_string(),
        "/api/v1/machines/SIM1/parts/%2E%2E%2F%2E%2E%2Fetc%2Fpasswd".to_string(),
        "/api/v1/machines/SIM1/parts/P%0042".to_string(),
        "/api/v1/machines/SIM1/parts/%3Cscript%3E".to_string(),
        format!("/api/v1/machines/SIM1/parts/{long}"),
        format!("/api/v1/machines/{long}/parts/P1"),
        format!("/api/v1/machines/SIM1/lobes/{long}/tables"),
        format!(
            "/api/v1/machines/SIM1/lobes/IN1/tables/{}/program",
            "9".repeat(10_000)
        ),
        format!("/api/v1/measurements/{}", "9".repeat(10_000)),
        format!("/machines/SIM1/features/{long}"),
        format!("/api/v1/machines/SIM1/measurements?lobe={long}"),
    ];
    for path in &cases {
        let (status, _, body) = get_as(s.addr, "localhost", path).await;
        assert!(
            matches!(status, 400 | 404),
            "{status} for {:.80}: {body:.200}",
            path
        );
        let code = json(&body)["code"].as_str().unwrap_or("").to_string();
        assert!(
            ["invalid_name", "invalid_path", "invalid_query"].contains(&code.as_str()),
            "{code} for {path:.80}"
        );
        assert!(body.len() < 400, "{} bytes back for {path:.80}", body.len());
        for sent in ["A", "9"] {
            assert!(
                !body.contains(&sent.repeat(65)),
                "more than 64 characters quoted back: {body}"
            );
        }
        assert!(!body.contains('\0'), "{body}");
    }
    // A plain part identifier passes the check (and then finds no database here).
    let (status, _, body) =
        get_as(s.addr, "localhost", "/api/v1/machines/SIM1/parts/SN-0042.A").await;
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (503, "store_unavailable".into())
    );
}

/// A path that exists, with a method it does not take: 405 with `Allow`, not 500.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_wrong_method_gets_405_naming_the_methods_allowed() {
    let s = server(16, 8).await;
    for (method, path, allow) in [
        ("DELETE", "/healthz", "GET"),
        ("POST", "/api/v1/machines", "GET"),
        ("PUT", "/api/v1/machines/SIM1/dressings", "GET, POST"),
        ("GET", "/signout", "POST"),
    ] {
        let request = format!(
            "{method} {path} HTTP/1.1\r\nHost: localhost\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
        );
        let mut stream = TcpStream::connect(s.addr).await.unwrap();
        stream.write_all(request.as_bytes()).await.unwrap();
        let mut answer = String::new();
        let _ = stream.read_to_string(&mut answer).await;
        let status = answer.split(' ').nth(1).unwrap_or_default();
        assert_eq!(status, "405", "{method} {path}: {answer}");
        let allowed = answer
            .lines()
            .find_map(|l| l.strip_prefix("allow: "))
            .unwrap_or_default();
        assert_eq!(allowed, allow, "{method} {path}: {answer}");
        let body = answer.split_once("\r\n\r\n").map(|(_, b)| b).unwrap_or("");
        assert_eq!(json(body)["code"], "method_not_allowed", "{answer}");
    }
}
