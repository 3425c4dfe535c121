//! The HTTP API's edges on a real listener (port 0): header and body timeouts and the
//! connection cap; the token checked before the body; writes that name an unknown lobe or
//! machine; typed command answers mapped to status and code; the machine list.

use crate::service_support;

use camloop::config::Secret;
use camloop::names::MachineName;
use camloop::service::http::{self, AppState, HttpLimits};
use camloop_loop::{CommandError, CommandOutcome, MachineCommand, TableVersion};
use service_support::exchange;
use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, oneshot, watch};

/// Where the fake machine answers.
type Reply = oneshot::Sender<Result<CommandOutcome, CommandError>>;

const TOKEN: &str = "let-me-write";

/// A fake machine loop: answers rollbacks by version (999: not found, 998: database down,
/// 997: refused, else delivered as version 7) and dressings as version 8.
fn fake_machine() -> mpsc::Sender<(MachineCommand, Reply)> {
    let (tx, mut rx) = mpsc::channel::<(MachineCommand, Reply)>(4);
    tokio::spawn(async move {
        while let Some((command, reply)) = rx.recv().await {
            let version = |n| TableVersion::new(n);
            let answer = match command {
                MachineCommand::Rollback { lobe, version: v } => match v.get() {
                    999 => Err(CommandError::VersionNotFound { lobe, version: v }),
                    998 => Err(CommandError::StoreUnavailable {
                        reason: "connection refused".into(),
                    }),
                    997 => Err(CommandError::Refused {
                        reason: "program of v997 unreadable".into(),
                    }),
                    _ => Ok(CommandOutcome {
                        version: version(7),
                        message: format!("{lobe} rolled back to v{v}"),
                    }),
                },
                MachineCommand::Freeze { lobe, .. } => Ok(CommandOutcome {
                    version: None,
                    message: format!("learning of {lobe} frozen"),
                }),
                MachineCommand::RollbackPart { versions } => {
                    let names: Vec<String> =
                        versions.iter().map(|(l, v)| format!("{l} v{v}")).collect();
                    Ok(CommandOutcome {
                        version: None,
                        message: format!("rolled back together: {}", names.join(", ")),
                    })
                }
                MachineCommand::Dressing {
                    wheel_radius_mm, ..
                } => Ok(CommandOutcome {
                    version: version(8),
                    message: format!("dressed to {wheel_radius_mm} mm"),
                }),
            };
            let _ = reply.send(answer);
        }
    });
    tx
}

struct Server {
    addr: SocketAddr,
    stop: watch::Sender<bool>,
    task: tokio::task::JoinHandle<()>,
}

/// The API on port 0 with `limits`, machine SIM1 grinding IN1 (a fake loop), and `store`.
async fn server(limits: HttpLimits, store: Option<camloop::store::Store>) -> Server {
    let mut machines = BTreeMap::new();
    machines.insert(
        MachineName::new("SIM1").unwrap(),
        vec!["IN1".parse().unwrap()],
    );
    let mut commands = HashMap::new();
    commands.insert(MachineName::new("SIM1").unwrap(), fake_machine());
    let state = AppState {
        store: Arc::new(tokio::sync::RwLock::new(store)),
        metrics: Arc::default(),
        machines: Arc::new(machines),
        commands: Arc::new(std::sync::RwLock::new(commands)),
        auth: Arc::new(http::AuthState::new(Some(Secret::new(TOKEN)), true)),
        body_timeout: limits.body_timeout,
        dashboard: Arc::default(),
        cluster: None,
    };
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stopped) = watch::channel(false);
    let task = tokio::spawn(http::serve(listener, http::router(state), limits, stopped));
    Server { addr, stop, task }
}

fn limits(max_connections: usize, header_ms: u64, body_ms: u64) -> HttpLimits {
    HttpLimits {
        max_connections,
        max_connections_per_client: max_connections,
        header_timeout: Duration::from_millis(header_ms),
        body_timeout: Duration::from_millis(body_ms),
    }
}

fn post_request(path: &str, body: &str, token: Option<&str>) -> String {
    let auth = token
        .map(|t| format!("Authorization: Bearer {t}\r\n"))
        .unwrap_or_default();
    format!(
        "POST {path} HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n{auth}Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
}

fn json(body: &str) -> serde_json::Value {
    let (start, end) = (body.find('{').unwrap(), body.rfind('}').unwrap());
    serde_json::from_str(&body[start..=end]).unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn half_sent_requests_are_cut_off_and_the_cap_holds_the_rest_until_slots_free() {
    let header_ms = 300;
    let s = server(limits(4, header_ms, 5_000), None).await;
    let started = Instant::now();
    // Four connections that send half a request and then nothing: they take every slot.
    let mut stalled = Vec::new();
    for _ in 0..4 {
        let mut c = TcpStream::connect(s.addr).await.unwrap();
        c.write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n")
            .await
            .unwrap();
        stalled.push(c);
    }
    // A fifth, complete request waits for a slot.
    let waiting = tokio::spawn(exchange(
        s.addr,
        "GET /healthz HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n",
    ));
    for mut c in stalled {
        let mut buf = Vec::new();
        let read = tokio::time::timeout(Duration::from_secs(5), c.read_to_end(&mut buf)).await;
        assert!(read.is_ok(), "a half-sent request still open after 5 s");
    }
    let closed_after = started.elapsed();
    assert!(
        closed_after >= Duration::from_millis(header_ms - 50)
            && closed_after < Duration::from_millis(header_ms + 2_000),
        "closed after {closed_after:?}, the header timeout is {header_ms} ms"
    );
    let (status, body) = tokio::time::timeout(Duration::from_secs(5), waiting)
        .await
        .expect("the request beyond the cap is served once slots free")
        .unwrap();
    assert_eq!((status, json(&body)["status"].clone()), (200, "ok".into()));
    // It could only be served once a half-sent one had been cut off.
    assert!(started.elapsed() >= Duration::from_millis(header_ms - 50));
    let _ = s.stop.send(true);
    tokio::time::timeout(Duration::from_secs(5), s.task)
        .await
        .expect("the server stops")
        .unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_write_without_the_token_is_refused_before_its_body_is_read() {
    // A long body timeout: if the body were waited for, these would hang.
    let s = server(limits(16, 5_000, 30_000), None).await;
    let path = "/api/v1/machines/SIM1/lobes/IN1/rollback";
    let (status, body) = exchange(s.addr, &post_request(path, "{not json", None)).await;
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (401, "unauthorized".into())
    );
    let (status, _) = exchange(
        s.addr,
        &post_request(path, "{not json", Some("let-me-writ")),
    )
    .await;
    assert_eq!(status, 401);
    // 10 MB announced, a few bytes sent, the rest never comes: 401 at once.
    let started = Instant::now();
    let request = format!(
        "POST {path} HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\nContent-Length: 10000000\r\n\r\n{{\"version\""
    );
    let (status, body) = tokio::time::timeout(Duration::from_secs(5), exchange(s.addr, &request))
        .await
        .expect("answered without waiting for the body");
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (401, "unauthorized".into())
    );
    assert!(started.elapsed() < Duration::from_secs(5));
    // With the token, malformed JSON is the body's problem.
    let (status, body) = exchange(s.addr, &post_request(path, "{not json", Some(TOKEN))).await;
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (400, "invalid_body".into())
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_body_that_does_not_arrive_in_time_gets_408() {
    let s = server(limits(16, 5_000, 300), None).await;
    let request = format!(
        "POST /api/v1/machines/SIM1/dressings HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\nAuthorization: Bearer {TOKEN}\r\nContent-Length: 100\r\n\r\n{{\"wheel"
    );
    let started = Instant::now();
    let (status, body) = tokio::time::timeout(Duration::from_secs(5), exchange(s.addr, &request))
        .await
        .expect("answered within the body timeout");
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (408, "body_timeout".into())
    );
    assert!(
        started.elapsed() >= Duration::from_millis(250),
        "{:?}",
        started.elapsed()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rollback_checks_the_lobe_and_maps_the_machines_answer() {
    let s = server(limits(16, 5_000, 5_000), None).await;
    let post = |path: &'static str, body: &'static str| {
        let addr = s.addr;
        async move {
            let (status, body) = exchange(addr, &post_request(path, body, Some(TOKEN))).await;
            (status, json(&body))
        }
    };
    let rollback = "/api/v1/machines/SIM1/lobes/IN1/rollback";
    let (status, reply) = post(rollback, r#"{"version":3}"#).await;
    assert_eq!(status, 200, "{reply}");
    assert_eq!(reply["version"], 7);
    assert_eq!(reply["message"], "IN1 rolled back to v3");
    let (status, reply) = post(
        "/api/v1/machines/SIM1/lobes/EX9/rollback",
        r#"{"version":3}"#,
    )
    .await;
    assert_eq!(
        (status, reply["code"].clone()),
        (404, "lobe_not_found".into())
    );
    let (status, reply) = post(
        "/api/v1/machines/SIM9/lobes/IN1/rollback",
        r#"{"version":3}"#,
    )
    .await;
    assert_eq!(
        (status, reply["code"].clone()),
        (404, "machine_not_found".into())
    );
    let (status, reply) = post(
        "/api/v1/machines/bad%20name/lobes/IN1/rollback",
        r#"{"version":3}"#,
    )
    .await;
    assert_eq!(
        (status, reply["code"].clone()),
        (400, "invalid_name".into())
    );
    for (version, code, expected) in [
        (r#"{"version":999}"#, 404, "table_version_not_found"),
        (r#"{"version":998}"#, 503, "store_unavailable"),
        (r#"{"version":997}"#, 409, "rollback_refused"),
    ] {
        let (status, reply) = post(rollback, version).await;
        assert_eq!(
            (status, reply["code"].clone()),
            (code, expected.into()),
            "{version}"
        );
    }
    let (status, reply) = post(
        "/api/v1/machines/SIM1/dressings",
        r#"{"wheel_radius_mm":249.5}"#,
    )
    .await;
    assert_eq!(
        (status, reply["version"].clone()),
        (200, 8.into()),
        "{reply}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_machine_list_shows_each_configured_machines_lobes() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.path().display());
    let store = camloop::store::Store::connect(&url).await.unwrap();
    let s = server(limits(16, 5_000, 5_000), Some(store)).await;
    let (status, body) = exchange(
        s.addr,
        "GET /api/v1/machines HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n",
    )
    .await;
    assert_eq!(status, 200, "{body}");
    let reply = json(&body);
    assert_eq!(reply["configured"], serde_json::json!(["SIM1"]));
    let machine = &reply["machines"][0];
    assert_eq!(machine["name"], "SIM1");
    assert_eq!(machine["configured"], true);
    assert_eq!(machine["lobes"][0]["lobe"], "IN1", "{reply}");
    assert_eq!(machine["lobes"].as_array().unwrap().len(), 1);

    // One instance alone: no cluster to show (`cluster_takeover` asks a cluster).
    let (status, body) = exchange(
        s.addr,
        "GET /api/v1/cluster HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n",
    )
    .await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(
        json(&body),
        serde_json::json!({"enabled": false, "instance": null, "machines": []})
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_whole_part_rollback_names_every_feature_it_takes_back() {
    let s = server(limits(16, 5_000, 30_000), None).await;
    let path = "/api/v1/machines/SIM1/rollback";
    let (status, _) = exchange(
        s.addr,
        &post_request(path, r#"{"versions": {"IN1": 3}}"#, None),
    )
    .await;
    assert_eq!(status, 401);
    let (status, body) = exchange(
        s.addr,
        &post_request(path, r#"{"versions": {"IN1": 3}}"#, Some(TOKEN)),
    )
    .await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(json(&body)["message"], "rolled back together: IN1 v3");
    let (status, body) = exchange(
        s.addr,
        &post_request(path, r#"{"versions": {"IN1": 3, "EX9": 2}}"#, Some(TOKEN)),
    )
    .await;
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (404, "lobe_not_found".into()),
        "{body}"
    );
    for bad in [r#"{"versions": {}}"#, r#"{"versions": {"IN1": 0}}"#] {
        let (status, body) = exchange(s.addr, &post_request(path, bad, Some(TOKEN))).await;
        assert_eq!(status, 400, "{bad}: {body}");
    }
}

/// A lobe or pin name off the rule, in a path or in a query, answers 400 `invalid_name`
/// with the rule's message (the typed extractors refuse it before a store or a machine is
/// asked: this server has no store); a bad machine name likewise.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_name_off_the_rule_in_a_path_or_query_answers_invalid_name() {
    let s = server(limits(16, 5_000, 5_000), None).await;
    let get =
        |path: &str| format!("GET {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n");
    let rule = "only letters, digits, '-' or '_' are allowed";
    let rollback = "/api/v1/machines/SIM1/lobes/IN%201/rollback";
    for (request, message) in [
        (
            get("/api/v1/machines/SIM1/lobes/IN%201/tables"),
            format!("lobe: name `IN 1` has ` ` at character 3: {rule}"),
        ),
        (
            get("/api/v1/machines/SIM1/lobes/IN.1/tables/3/program"),
            format!("lobe: name `IN.1` has `.` at character 3: {rule}"),
        ),
        (
            get("/api/v1/machines/SIM1/features/I%3BN/capability"),
            format!("lobe: name `I;N` has `;` at character 2: {rule}"),
        ),
        (
            get("/api/v1/machines/SIM1/measurements?lobe=IN%2B1"),
            format!("lobe: name `IN+1` has `+` at character 3: {rule}"),
        ),
        (
            post_request(rollback, r#"{"version":3}"#, Some(TOKEN)),
            format!("lobe: name `IN 1` has ` ` at character 3: {rule}"),
        ),
        (
            get("/api/v1/machines/S%20M1/measurements?lobe=IN1"),
            format!("machine: name `S M1` has ` ` at character 2: {rule}"),
        ),
    ] {
        let (status, body) = exchange(s.addr, &request).await;
        let reply = json(&body);
        assert_eq!(
            (status, reply["code"].as_str(), reply["message"].as_str()),
            (400, Some("invalid_name"), Some(message.as_str())),
            "{request}"
        );
    }
}
