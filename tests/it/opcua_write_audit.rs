//! The service's one write path (`command.rs`), which OPC UA's `Rollback` and
//! `AcknowledgeEvent` share with the HTTP API, driven over HTTP: a rollback's audit row
//! records, after it, the table now in force (not the one before); the events list carries
//! the id an acknowledgement takes; a repeated acknowledgement is audited as such.

use crate::service_support::{get, json, post, sim_config};
use camloop::auth::{new_token, token_digest};
use camloop::service::{self, RunOptions};
use camloop::store::{NewToken, Role, Store};

async fn token(store: &Store, role: Role) -> String {
    let now = camloop::clock::now();
    let hash = camloop::auth::hash_password("a-password-of-the-right-length").unwrap();
    let user = store
        .add_user(&format!("audit-{role}"), role, &hash, now)
        .await
        .unwrap();
    let secret = new_token().unwrap();
    let t = NewToken {
        user,
        label: "audit".into(),
        sha256: token_digest(&secret),
        role,
        created_at: now,
        expires_at: now + jiff::SignedDuration::from_hours(1),
    };
    store.add_token(&t).await.unwrap();
    secret
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rollback_audits_what_is_in_force_after_it_and_acks_are_audited_as_they_were() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let config = sim_config(dir.path(), &url, 20, 3, |_| None);
    let mut running = service::start(config, RunOptions::parts(2)).await.unwrap();
    running.machines_done().await;
    let addr = running.http_addr;
    let store = Store::connect(&url).await.unwrap();
    let engineer = token(&store, Role::Engineer).await;
    let operator = token(&store, Role::Operator).await;

    let path = "/api/v1/machines/SIM1/lobes/IN1/rollback";
    let (status, body) = post(addr, path, r#"{"version":1}"#, Some(&engineer)).await;
    assert_eq!(status, 200, "{body}");
    let new_version = json(&body)["version"].as_i64().unwrap();
    let rows = store
        .audit(jiff::Timestamp::UNIX_EPOCH, 0, 100, false)
        .await
        .unwrap();
    let row = rows
        .iter()
        .find(|r| r.entry.action == "rollback")
        .expect("the rollback's audit row");
    let in_force = |text: &Option<String>| -> i64 {
        let v: serde_json::Value = serde_json::from_str(text.as_deref().unwrap()).unwrap();
        v["in_force"]["IN1"].as_i64().unwrap()
    };
    assert_eq!(in_force(&row.entry.after), new_version, "{:?}", row.entry);
    assert_ne!(in_force(&row.entry.before), new_version, "{:?}", row.entry);
    // The API's status says the same.
    let (_, machines) = get(addr, "/api/v1/machines").await;
    let lobe = &json(&machines)["machines"][0]["lobes"][0];
    assert_eq!(
        lobe["status"]["in_force_version"].as_i64(),
        Some(new_version),
        "{machines}"
    );

    // The events list carries each event's id: the rollback's own event is acknowledged by
    // it, twice; the trail tells the first from the repeat.
    let (status, body) = get(addr, "/api/v1/machines/SIM1/events?limit=10").await;
    assert_eq!(status, 200, "{body}");
    let events = json(&body)["items"].as_array().unwrap().clone();
    let rollback = events
        .iter()
        .find(|e| e["kind"] == "rollback")
        .unwrap_or_else(|| panic!("no rollback event: {body}"));
    let id = rollback["id"].as_i64().expect("an id");
    let ack = format!("/api/v1/machines/SIM1/events/{id}/ack");
    for _ in 0..2 {
        let (status, body) = post(addr, &ack, "", Some(&operator)).await;
        assert_eq!(status, 200, "{body}");
    }
    let rows = store
        .audit(jiff::Timestamp::UNIX_EPOCH, 0, 100, false)
        .await
        .unwrap();
    let reasons: Vec<&str> = rows
        .iter()
        .filter(|r| r.entry.action == "acknowledge")
        .map(|r| r.entry.reason.as_str())
        .collect();
    assert_eq!(reasons, ["acknowledged", "acknowledged before"]);
    store.close().await;
    running.stop().await;
}
