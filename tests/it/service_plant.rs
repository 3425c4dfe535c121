//! The service at plant scale, held by what must stay true whatever the load: `/healthz`
//! answers from the first moment ("starting" until the machines are open) and while every
//! worker thread of the machines' runtime is busy, because the listener runs on threads of
//! its own.

use crate::service_run::one_machine;
use crate::service_support::{get, json};
use camloop::service::{self, RunOptions};
use std::io::{Read, Write};
use std::sync::mpsc;

/// The listener serves before the machines open, and says so: "starting", with the
/// machines' component counting them; "ok" once they are open.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn healthz_says_starting_until_the_machines_are_open() {
    let dir = tempfile::tempdir().unwrap();
    let config = one_machine(
        dir.path(),
        "SIM1",
        "",
        "kind = \"sim\"\npart_interval_ms = 60000",
    );
    let starting = service::start_serving(config, RunOptions::default())
        .await
        .unwrap();
    let (status, body) = get(starting.http_addr, "/healthz").await;
    assert_eq!(status, 200, "{body}");
    let health = json(&body);
    assert_eq!(health["status"], "starting", "{body}");
    let machines = health["components"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "machines")
        .unwrap_or_else(|| panic!("no machines component: {body}"));
    assert_eq!(machines["state"], "starting", "{body}");
    assert_eq!(machines["reason"], "0 of 1 machines open", "{body}");

    let running = starting.finish().await.unwrap();
    let (status, body) = get(running.http_addr, "/healthz").await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(json(&body)["status"], "ok", "{body}");
    running.stop().await;
}

/// Releases the blocked workers when dropped, so a failing assertion cannot leave the
/// runtime wedged.
struct Blockers(Option<mpsc::Sender<()>>);

impl Drop for Blockers {
    fn drop(&mut self) {
        self.0.take();
    }
}

/// One GET /healthz from a plain thread (the runtime's workers are blocked, so its own
/// client could not run); waits up to `limit` for the whole answer.
fn healthz_from_a_thread(
    addr: std::net::SocketAddr,
    limit: std::time::Duration,
) -> std::io::Result<String> {
    let mut s = std::net::TcpStream::connect(addr)?;
    s.set_read_timeout(Some(limit))?;
    s.write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n")?;
    let mut text = String::new();
    s.read_to_string(&mut text)?;
    Ok(text)
}

/// Both worker threads of the runtime the machines run on are held by work that never
/// yields (what a saturated loop does to them): `/healthz` still answers. Before the
/// listener had its own runtime it answered only once a worker came free, here never (the
/// 60 s bound is a liveness bound, not a speed limit).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn healthz_answers_while_every_worker_is_held() {
    let dir = tempfile::tempdir().unwrap();
    let config = one_machine(
        dir.path(),
        "SIM1",
        "",
        "kind = \"sim\"\npart_interval_ms = 60000",
    );
    let running = service::start(config, RunOptions::default()).await.unwrap();
    let addr = running.http_addr;

    let (release, held) = mpsc::channel::<()>();
    let held = std::sync::Arc::new(std::sync::Mutex::new(held));
    let blockers = Blockers(Some(release));
    let (started_tx, started) = mpsc::channel::<()>();
    for _ in 0..2 {
        let (held, started_tx) = (held.clone(), started_tx.clone());
        tokio::spawn(async move {
            started_tx.send(()).unwrap();
            // Blocks this worker until the test lets go (the sender is dropped).
            let _ = held.lock().map(|rx| rx.recv());
        });
    }
    // Both workers are held once both tasks have started: one holds the lock and waits in
    // recv, the other waits for the lock.
    for _ in 0..2 {
        started.recv().unwrap();
    }
    let answer =
        std::thread::spawn(move || healthz_from_a_thread(addr, std::time::Duration::from_secs(60)))
            .join()
            .unwrap();
    drop(blockers);
    let text = answer.expect("/healthz answers while the workers are held");
    assert!(text.starts_with("HTTP/1.1 200"), "{text}");
    let health = json(&text);
    assert_eq!(health["database"], "up", "{text}");
    assert!(
        ["ok", "degraded"].contains(&health["status"].as_str().unwrap()),
        "{text}"
    );
    running.stop().await;
}
