//! The database as a `/healthz` component: on a real PostgreSQL server, `/healthz` says the
//! database is up and its component ok; once the server is stopped, it says "down" with the
//! component degraded (and why) within a few of the service's probes, not when the next
//! write happens to fail.

use crate::service_support;
use crate::store_support;

use camloop::service::{self, RunOptions};
use service_support::{get, json, sim_config};
use std::time::{Duration, Instant};

/// The probe asks every 2 s and waits 2 s for an answer: down is said within 4 s. Three
/// times that, for a machine busy with other tests, is the bound; a failure, not a pace.
const SAID_WITHIN: Duration = Duration::from_secs(12);

/// `/healthz`'s database field and its component, once `want` says yes or the bound passed.
async fn healthz_until(
    addr: std::net::SocketAddr,
    want: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let started = Instant::now();
    loop {
        let (status, body) = get(addr, "/healthz").await;
        assert_eq!(status, 200, "{body}");
        let h = json(&body);
        if want(&h) {
            return h;
        }
        assert!(
            started.elapsed() < SAID_WITHIN,
            "not said within {SAID_WITHIN:?}: {h}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

fn database_component(h: &serde_json::Value) -> serde_json::Value {
    h["components"]
        .as_array()
        .and_then(|c| c.iter().find(|c| c["name"] == "database"))
        .cloned()
        .unwrap_or_default()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stopped_postgres_is_down_in_healthz_within_seconds() {
    let Some(server) = store_support::pg::start_or_skip("service_database_health") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let running = service::start(
        sim_config(dir.path(), &server.url(), 50, 1, |_| None),
        RunOptions::parts(1_000_000),
    )
    .await
    .unwrap();
    let addr = running.http_addr;
    let up = healthz_until(addr, |h| database_component(h)["state"] == "ok").await;
    assert_eq!(up["database"], "up", "{up}");

    server.stop();
    let down = healthz_until(addr, |h| h["database"] == "down").await;
    let c = database_component(&down);
    assert_eq!(c["state"], "degraded", "{down}");
    assert!(
        c["reason"].as_str().is_some_and(|r| !r.is_empty()),
        "{down}"
    );
    assert_eq!(down["status"], "degraded", "{down}");
    // Not stopped in order: a stop waits for the machines' writes, which wait out the
    // pool's timeouts with the server gone (not what this test is about); the runtime's
    // end drops every task, and the server's guard its data.
    drop(running);
}
