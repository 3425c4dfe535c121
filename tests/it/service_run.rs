//! The service end to end: simulated machine → CAN frames through the real decoder → loop →
//! share → SQLite history → the HTTP API on a real listener (port 0). Also: a database that
//! is down keeps every record in the journal and the service running; a restart resumes; a
//! wheel dressing reported through the API regenerates the table; raw revolutions past the
//! retention are dropped. The other gauge sources are in `service_gauges`.

use crate::service_support;
use crate::store_support;

use service_support::{get, json, post, sim_config};

use camloop::config::Config;
use camloop::service::{self, RunOptions};
use std::path::Path;

fn config(dir: &Path, database_url: &str) -> Config {
    let env = |k: &str| (k == camloop::config::ENV_API_TOKEN).then(|| TOKEN.to_string());
    sim_config(dir, database_url, 20, 5, env)
}

const TOKEN: &str = "let-me-write-a-token-of-32-chars";

/// A service with one machine `name` on the demo lobe, its database in `dir` (plus any
/// `database_extra` keys), and the gauge section `gauge` (TOML lines).
pub(crate) fn one_machine(dir: &Path, name: &str, database_extra: &str, gauge: &str) -> Config {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"sqlite://{}/db.sqlite?mode=rwc\"\n{database_extra}\n\
         [http]\nlisten = \"127.0.0.1:0\"\n\
         [[machines]]\nname = \"{name}\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"share/{name}\"\n\
         [machines.gauge]\n{gauge}\n",
        dir.display(),
        root.join("config/parts/demo-lobe.toml").display(),
    );
    Config::parse(&text, &dir.join("camloop.toml"), |_| None).unwrap()
}

/// The gauge section of a CAN gauge on an interface this kernel cannot have.
pub(crate) fn unavailable_can() -> String {
    let dbc = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/gauge.dbc");
    format!(
        "kind = \"can\"\ninterface = \"camloopcan9\"\ndbc = \"{}\"",
        dbc.display()
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn parts_flow_from_the_simulated_gauge_to_the_api() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/var/camloop.db?mode=rwc", dir.path().display());
    let mut running = service::start(config(dir.path(), &url), RunOptions::parts(5))
        .await
        .unwrap();
    running.machines_done().await;
    let addr = running.http_addr;

    let (status, body) = get(addr, "/healthz").await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(json(&body)["database"], "up");

    let (status, body) = get(addr, "/api/v1/machines/SIM1/measurements?lobe=IN1&limit=10").await;
    assert_eq!(status, 200, "{body}");
    let history = json(&body);
    let items = history["items"].as_array().unwrap();
    assert_eq!(items.len(), 5, "{body}");
    // Newest first; the loop converges: the 5th part is far better than the 1st.
    let first = items[4]["max_profile_error_um"].as_f64().unwrap();
    let last = items[0]["max_profile_error_um"].as_f64().unwrap();
    assert!(last < first, "{first} → {last}");

    let id = items[0]["id"].as_i64().unwrap();
    let (status, body) = get(addr, &format!("/api/v1/measurements/{id}")).await;
    assert_eq!(status, 200);
    assert_eq!(
        json(&body)["averaged_lift_mm"].as_array().unwrap().len(),
        360
    );

    // Nominal table plus one per part; the newest is the program on the share.
    let (status, body) = get(addr, "/api/v1/machines/SIM1/lobes/IN1/tables?limit=10").await;
    assert_eq!(status, 200, "{body}");
    let tables = json(&body);
    let versions = tables["items"].as_array().unwrap();
    assert_eq!(versions.len(), 6, "{body}");
    assert!(versions.iter().all(|v| v["status"] == "pushed"));
    // Why, as the store's row says it (the text the API has always shown).
    assert!(
        versions
            .iter()
            .all(|v| v["status_why"] == "pushed to the share"),
        "{body}"
    );
    let newest = versions[0]["version"].as_i64().unwrap();
    let (status, program) = get(
        addr,
        &format!("/api/v1/machines/SIM1/lobes/IN1/tables/{newest}/program"),
    )
    .await;
    assert_eq!(status, 200);
    let on_share =
        std::fs::read_to_string(dir.path().join("share/SIM1/DEMO_CAM_TABLE.SPF")).unwrap();
    assert!(
        program.contains(on_share.lines().nth(7).unwrap()),
        "program differs from the share"
    );

    // The diff to the parent: the learned correction, a few µm at most, never zero.
    let (status, body) = get(
        addr,
        &format!("/api/v1/machines/SIM1/lobes/IN1/tables/{newest}/diff"),
    )
    .await;
    assert_eq!(status, 200, "{body}");
    let diff = json(&body);
    let max = diff["max_abs_delta_x_um"].as_f64().unwrap();
    assert!(max > 0.0 && max < 20.0, "{max}");
    assert_eq!(diff["points"].as_array().unwrap().len(), 360);
    let (status, _) = get(addr, "/api/v1/machines/SIM1/lobes/IN1/tables/1/diff").await;
    assert_eq!(status, 404, "the first version has no parent");

    let (status, body) = get(addr, "/metrics").await;
    assert_eq!(status, 200);
    assert!(
        body.contains("camloop_parts_total{machine=\"SIM1\"} 5"),
        "{body}"
    );

    // Errors carry a stable code, never SQL.
    let (status, body) = get(addr, "/api/v1/measurements/999999").await;
    assert_eq!(status, 404);
    assert_eq!(json(&body)["code"], "measurement_not_found");
    let (status, body) = get(addr, "/api/v1/machines/bad%20name/measurements").await;
    assert_eq!(status, 400, "{body}");
    let (status, body) = get(addr, "/api/v1/measurements/abc").await;
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (400, "invalid_path".into())
    );
    let (status, body) = get(addr, "/api/v1/machines/SIM1/events?limit=many").await;
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (400, "invalid_query".into())
    );
    running.stop().await;

    // A restart resumes from the stored learning state: part 6 is not an uncompensated part
    // (and is a new measurement, not a repeat of part 1 that the store would skip).
    let mut running = service::start(config(dir.path(), &url), RunOptions::parts(1))
        .await
        .unwrap();
    running.machines_done().await;
    let (_, body) = get(
        running.http_addr,
        "/api/v1/machines/SIM1/measurements?limit=10",
    )
    .await;
    assert_eq!(json(&body)["items"].as_array().unwrap().len(), 6, "{body}");
    let newest = json(&body)["items"][0]["max_profile_error_um"]
        .as_f64()
        .unwrap();
    assert!(
        newest < first / 2.0,
        "after restart {newest} vs uncompensated {first}"
    );
    let addr = running.http_addr;

    // Rollback to the nominal table (version 1): refused without the token, then delivered as
    // a new version whose program matches version 1 but for the table number.
    let path = "/api/v1/machines/SIM1/lobes/IN1/rollback";
    assert_eq!(post(addr, path, r#"{"version":1}"#, None).await.0, 401);
    assert_eq!(
        post(addr, path, r#"{"version":1}"#, Some("wrong")).await.0,
        401
    );
    // A version that does not exist: the machine's typed answer, 404 with a stable code.
    let (status, body) = post(addr, path, r#"{"version":999}"#, Some(TOKEN)).await;
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (404, "table_version_not_found".into())
    );
    // A lobe this machine does not grind is not rolled back in its place.
    let (status, body) = post(
        addr,
        "/api/v1/machines/SIM1/lobes/EX9/rollback",
        r#"{"version":1}"#,
        Some(TOKEN),
    )
    .await;
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (404, "lobe_not_found".into())
    );
    // The machine list names the lobe the machine grinds.
    let (status, body) = get(addr, "/api/v1/machines").await;
    assert_eq!(status, 200, "{body}");
    let lobes = json(&body)["machines"][0]["lobes"].clone();
    assert_eq!(lobes.as_array().map(Vec::len), Some(1), "{body}");
    assert_eq!(
        (lobes[0]["lobe"].clone(), lobes[0]["configured"].clone()),
        ("IN1".into(), true.into())
    );
    let (status, body) = post(addr, path, r#"{"version":1}"#, Some(TOKEN)).await;
    assert_eq!(status, 200, "{body}");
    let delivered = json(&body);
    assert!(
        delivered["version"].as_i64().is_some_and(|v| v > 1),
        "{body}"
    );
    let (_, body) = get(addr, "/api/v1/machines/SIM1/lobes/IN1/tables?limit=1").await;
    let rolled = json(&body)["items"][0].clone();
    assert_eq!(rolled["reason"], "rollback to v1", "{body}");
    let (_, v1) = get(addr, "/api/v1/machines/SIM1/lobes/IN1/tables/1/program").await;
    let on_share =
        std::fs::read_to_string(dir.path().join("share/SIM1/DEMO_CAM_TABLE.SPF")).unwrap();
    let blocks = |t: &str| {
        t.lines()
            .filter(|l| l.starts_with("PO["))
            .map(str::to_string)
            .collect::<Vec<_>>()
    };
    assert_eq!(
        blocks(&on_share),
        blocks(&v1),
        "the rolled-back program is version 1's table"
    );

    // A wheel dressing reported through the API: refused without the token or with an
    // implausible radius, then recorded and the table regenerated for the new radius.
    let path = "/api/v1/machines/SIM1/dressings";
    assert_eq!(
        post(addr, path, r#"{"wheel_radius_mm":249.95}"#, None)
            .await
            .0,
        401
    );
    let (status, body) = post(addr, path, r#"{"wheel_radius_mm":0.25}"#, Some(TOKEN)).await;
    assert_eq!(status, 400, "{body}");
    assert_eq!(json(&body)["code"], "invalid_wheel_radius");
    let (status, body) = post(addr, path, r#"{"radius":249.95}"#, Some(TOKEN)).await;
    assert!((400..500).contains(&status), "{status} {body}");
    assert_eq!(json(&body)["code"], "invalid_body", "{body}");
    let (status, body) = post(addr, path, r#"{"wheel_radius_mm":249.95}"#, Some(TOKEN)).await;
    assert_eq!(status, 200, "{body}");
    let (_, body) = get(addr, path).await;
    let dressing = json(&body)["items"][0].clone();
    assert_eq!(dressing["new_radius_mm"], 249.95, "{body}");
    assert_eq!(dressing["old_radius_mm"], 250.0, "{body}");
    // Who reported it: the caller (the deprecated shared token is named `api-token`).
    assert_eq!(dressing["source"], "api:admin");
    let (_, body) = get(addr, "/api/v1/machines/SIM1/lobes/IN1/tables?limit=1").await;
    let dressed = json(&body)["items"][0].clone();
    assert_eq!(dressed["reason"], "wheel dressed to 249.95 mm", "{body}");
    // Same correction as the rolled-back parent, wheel 50 µm smaller. Program X is
    // d − R − Rb (0 on the base circle), so the new radius cancels where the wheel touches
    // on the X line and X moves only where it touches off it, by 50 µm · (1/cos φ − 1) for a
    // contact angle φ: with a 250 mm wheel on this 20 mm lobe φ stays a few degrees, so
    // more than nothing and well under 1 µm.
    let (status, body) = get(
        addr,
        &format!(
            "/api/v1/machines/SIM1/lobes/IN1/tables/{}/diff",
            dressed["version"]
        ),
    )
    .await;
    assert_eq!(status, 200, "{body}");
    let max = json(&body)["max_abs_delta_x_um"].as_f64().unwrap();
    assert!(max > 0.01 && max < 1.0, "{max}");

    // A dressing with the dresser's measured infeed: an implausible one is refused; 52 µm
    // removed while the radius told drops by 50 µm makes parts 2 µm oversize, so the whole
    // correction moves by −2 µm: X by −2 µm where the wheel touches on the X line (exactly,
    // to the program's 0.1 µm), and by that plus under 1 µm of flank geometry elsewhere.
    let (status, body) = post(
        addr,
        path,
        r#"{"wheel_radius_mm":249.9,"infeed_um":-5}"#,
        Some(TOKEN),
    )
    .await;
    assert_eq!(
        (status, json(&body)["code"].clone()),
        (400, "invalid_infeed".into()),
        "{body}"
    );
    dressing_accepted(
        addr,
        r#"{"wheel_radius_mm":249.9,"infeed_um":52.0}"#,
        "249.95 → 249.9 mm (dresser infeed 52.00 µm: size step +2.00 µm)",
    )
    .await;
    let (_, body) = get(addr, path).await;
    assert_eq!(json(&body)["items"][0]["infeed_um"], 52.0, "{body}");
    assert!(json(&body)["items"][1]["infeed_um"].is_null(), "{body}");
    let (_, body) = get(addr, "/api/v1/machines/SIM1/lobes/IN1/tables?limit=1").await;
    let version = json(&body)["items"][0]["version"].clone();
    let (status, body) = get(
        addr,
        &format!("/api/v1/machines/SIM1/lobes/IN1/tables/{version}/diff"),
    )
    .await;
    assert_eq!(status, 200, "{body}");
    let diff = json(&body);
    let deltas: Vec<f64> = diff["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["delta_x_um"].as_f64().unwrap())
        .collect();
    let base = deltas.iter().fold(f64::MAX, |m, d| m.min(d.abs()));
    assert!((base - 2.0).abs() <= 0.11, "{base} µm\n{body}");
    assert!(deltas.iter().all(|d| *d < -1.89 && *d > -3.0), "{body}");
    // An infeed that cannot go with the radius change (0.4 mm less radius told, nothing
    // removed: a wheel change, or a wrong report) is not used: the size step would be beyond
    // the correction limit, so the wheel's share of the learned size is replaced instead.
    dressing_accepted(
        addr,
        r#"{"wheel_radius_mm":249.5,"infeed_um":0.0}"#,
        "(no usable infeed: the wheel's share of the learned size replaced)",
    )
    .await;

    running.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_database_that_is_down_loses_nothing() {
    let dir = tempfile::tempdir().unwrap();
    // Nothing listens on port 1 of localhost: the database is down for the whole run.
    let down = "postgres://camloop@127.0.0.1:1/camloop";
    let mut running = service::start(config(dir.path(), down), RunOptions::parts(3))
        .await
        .unwrap();
    running.machines_done().await;
    let (status, body) = get(running.http_addr, "/healthz").await;
    assert_eq!(status, 200);
    assert_eq!(json(&body)["database"], "down");
    let (status, body) = get(running.http_addr, "/api/v1/machines").await;
    assert_eq!(status, 503);
    assert_eq!(json(&body)["code"], "store_unavailable");
    running.stop().await;
    // A restart while the database is still down resumes from the local memory: the 4th
    // part is ground with the learned table (an uncompensated part has about 3 µm of
    // datum-fitted profile error, a compensated one well under 1.5 µm).
    let mut running = service::start(config(dir.path(), down), RunOptions::parts(1))
        .await
        .unwrap();
    running.machines_done().await;
    running.stop().await;
    let journal =
        camloop::service::journal::Journal::open(&dir.path().join("var/machines/SIM1/IN1"))
            .unwrap();
    let profile_errors: Vec<f64> = journal
        .pending()
        .iter()
        .filter_map(|p| match p {
            camloop::service::journal::Pending::Measurement { measurement, .. } => {
                Some(measurement.max_profile_error_um)
            }
            _ => None,
        })
        .collect();
    assert_eq!(profile_errors.len(), 4);
    assert!(
        profile_errors[0] > 2.0 && profile_errors[3] < 1.5,
        "{profile_errors:?}"
    );
    // Every record waits in the journal: 4 measurements, 5 tables (nominal + 4).
    let journal_dir = dir.path().join("var/machines/SIM1/IN1");
    let mut journal = camloop::service::journal::Journal::open(&journal_dir).unwrap();
    let pending = journal.pending().to_vec();
    let count = |kind: &str| {
        pending
            .iter()
            .filter(|p| format!("{p:?}").starts_with(&format!("{kind} ")))
            .count()
    };
    assert_eq!(count("Measurement"), 4);
    assert_eq!(count("Table"), 5);
    // When a database is there, the journal goes into it.
    let url = format!("sqlite://{}/late.db?mode=rwc", dir.path().display());
    let store = camloop::store::Store::connect(&url).await.unwrap();
    let written = journal.flush(&store).await.unwrap().written;
    assert_eq!(written, pending.len());
    assert!(journal.pending().is_empty());
    let stored = stored_counts(&store).await;
    // The store keeps a learning snapshot per change of the learning's mode (frozen or not,
    // best part, wheel, grid) and replaces the newest otherwise.
    let mut kept_learning = 0;
    let mut previous = None;
    for p in &pending {
        if let camloop::service::journal::Pending::Learning { state, .. } = p {
            let l = &state.learning;
            let mode = (
                state.schema,
                l.points_per_rev,
                l.frozen.clone(),
                l.best.as_ref().map(|b| b.iteration),
                state.wheel_radius_mm.to_bits(),
            );
            kept_learning += usize::from(previous.as_ref() != Some(&mode));
            previous = Some(mode);
        }
    }
    assert!(kept_learning >= 1);
    assert_eq!(
        stored,
        [4, 5, count("Event"), kept_learning],
        "measurements, tables, events, learning states"
    );
    assert!(count("Learning") >= 4);
    // A crash before the database confirmed durability: the reopened journal still holds
    // every record, and replaying it writes nothing twice.
    let mut replayed = camloop::service::journal::Journal::open(&journal_dir).unwrap();
    assert_eq!(replayed.pending().len(), pending.len());
    assert_eq!(replayed.flush(&store).await.unwrap().written, pending.len());
    assert_eq!(stored_counts(&store).await, stored);
    // Once the database says its copy is durable, the journal empties, on disk too, but
    // for the newest learning state, which a restart with the database down resumes from.
    assert_eq!(
        replayed.release_durable(&store).await.unwrap(),
        pending.len()
    );
    let reopened = camloop::service::journal::Journal::open(&journal_dir).unwrap();
    let newest_learning = pending
        .iter()
        .rev()
        .find(|p| matches!(p, camloop::service::journal::Pending::Learning { .. }))
        .cloned();
    assert_eq!(reopened.records().to_vec(), Vec::from_iter(newest_learning));
}

/// Reports a dressing of SIM1 (`body`) with the writer's token: it must be accepted with a
/// message that says `said`.
async fn dressing_accepted(addr: std::net::SocketAddr, body: &str, said: &str) {
    let (status, reply) = post(addr, "/api/v1/machines/SIM1/dressings", body, Some(TOKEN)).await;
    assert_eq!(status, 200, "{reply}");
    let message = json(&reply)["message"].as_str().unwrap().to_owned();
    assert!(message.contains(said), "{reply}");
}

/// Rows of machine SIM1 in the store: measurements, table versions, events, learning states.
async fn stored_counts(store: &camloop::store::Store) -> [usize; 4] {
    let camloop::store::RawPool::Sqlite(pool) = store.raw_pool() else {
        panic!("a SQLite store")
    };
    let mut counts = [0; 4];
    for (i, table) in [
        "measurements",
        "table_versions",
        "events",
        "learning_states",
    ]
    .iter()
    .enumerate()
    {
        let n: i64 = sqlx::query_scalar(&format!(
            "SELECT COUNT(*) FROM {table} WHERE machine = 'SIM1'"
        ))
        .fetch_one(pool)
        .await
        .unwrap();
        counts[i] = n as usize;
    }
    counts
}

/// Raw-revolution retention runs in the service: at start, measurements older than
/// `raw_retention_days` lose their raw revolutions and keep everything else; newer ones keep
/// theirs.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn raw_revolutions_past_the_retention_are_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.path().display());
    let store = camloop::store::Store::connect(&url).await.unwrap();
    let now = camloop::clock::now().as_millisecond();
    let day_ms = 86_400_000;
    let old = store
        .insert_measurement(&store_support::data::measurement(
            "OLD1",
            "in1",
            1,
            now - 3 * day_ms,
        ))
        .await
        .unwrap();
    let recent = store
        .insert_measurement(&store_support::data::measurement(
            "OLD1",
            "in1",
            2,
            now - day_ms,
        ))
        .await
        .unwrap();
    // A machine whose gauge never delivers (no SocketCAN here): only retention writes.
    let config = one_machine(
        dir.path(),
        "CAN1",
        "raw_retention_days = 2",
        &unavailable_can(),
    );
    let running = service::start(config, RunOptions::default()).await.unwrap();
    // Poll (bounded) until the start-up pass has run.
    let mut pruned = false;
    for _ in 0..200 {
        let detail = store.measurement(old).await.unwrap().unwrap();
        if detail.raw_lift_mm.is_none() {
            pruned = true;
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    running.stop().await;
    assert!(pruned, "the 3-day-old raw data is still there after 10 s");
    let old = store.measurement(old).await.unwrap().unwrap();
    assert_eq!(
        old.averaged_lift_mm.len(),
        36,
        "the summary and profile stay"
    );
    let recent = store.measurement(recent).await.unwrap().unwrap();
    assert_eq!(recent.raw_lift_mm.map(|r| r.len()), Some(3));
}
