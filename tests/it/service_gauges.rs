//! The service fed by its other gauge sources: a CAN bus that is not there is reported, not
//! fatal; a serial gauge on a pseudo-terminal feeds the loop; a dropped dressing report
//! regenerates the table. The machine set-up is `service_run`'s.

use crate::service_run::{one_machine, unavailable_can};
use crate::service_support::{get, json};
use camloop::service::{self, RunOptions};
use std::path::Path;
use tokio::io::AsyncWriteExt;

/// A CAN gauge on an interface that cannot be opened (this kernel has no SocketCAN at all):
/// the service starts, reports the machine's gauge as unavailable, keeps serving and stops
/// cleanly. Nothing panics.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unavailable_can_bus_is_reported_not_fatal() {
    let dir = tempfile::tempdir().unwrap();
    let config = one_machine(dir.path(), "CAN1", "", &unavailable_can());
    let running = service::start(config, RunOptions::default()).await.unwrap();
    let (status, body) = get(running.http_addr, "/healthz").await;
    assert_eq!(status, 200, "{body}");
    // The nominal table is on the share even though no part has been measured.
    assert!(dir.path().join("share/CAN1/DEMO_CAM_TABLE.SPF").exists());
    running.stop().await;
}

/// A serial gauge on a real pseudo-terminal: the measurement written on the other end is
/// learned from, recorded and shows in the history.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_serial_gauge_feeds_the_loop_through_a_pseudo_terminal() {
    use camloop::core::geometry::{CamGeometry, Follower};
    use camloop::sim::{CommandedTable, GrinderConfig, PartLabels, SimGrinder, Workpiece};
    use tokio_serial::SerialPort;

    let (mut master, slave) = tokio_serial::SerialStream::pair().expect("pty pair");
    let port = slave.name().expect("the slave end has a device path");
    // pair() locks the slave end; the service opens the device by its path instead.
    drop(slave);
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = one_machine(
        dir.path(),
        "TTY1",
        "",
        &format!("kind = \"serial\"\nport = \"{port}\"\nbaud = 115200"),
    );
    let running = service::start(config, RunOptions::default()).await.unwrap();

    // One simulated part of the demo lobe, sent in the serial line protocol.
    let lift = camloop::core::lift::LiftTable::parse_csv(
        &std::fs::read_to_string(root.join("config/parts/demo-intake-lobe.csv")).unwrap(),
        "demo",
    )
    .unwrap();
    let geometry = CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: 250.0,
    };
    let part =
        camloop::core::geometry::Part::cam(geometry, camloop::core::lift::LiftCurve::new(&lift))
            .unwrap();
    let mut sim = SimGrinder::new(GrinderConfig::default(), Workpiece::Cam(geometry), 2).unwrap();
    let table = CommandedTable::nominal(&part, 360, camloop::core::fit::TableForm::Poly).unwrap();
    let ground = sim.grind(&table).unwrap();
    let raw = sim.measure(
        &ground,
        &PartLabels {
            machine: "TTY1".into(),
            part: "77".into(),
            lobe: "IN1".into(),
        },
    );
    let wire = camloop::gauge::serial::encode_serial_measurement(&raw).unwrap();
    let writer = tokio::spawn(async move {
        master.write_all(wire.as_bytes()).await.unwrap();
        master.flush().await.unwrap();
        master
    });

    // Poll the API (bounded) until the part's records are all in: the learned table is
    // written after the measurement, so wait for it.
    let mut tables = 0;
    for _ in 0..200 {
        let (status, body) = get(running.http_addr, "/api/v1/machines/TTY1/lobes/IN1/tables").await;
        tables = if status == 200 {
            json(&body)["items"].as_array().map_or(0, Vec::len)
        } else {
            0
        };
        if tables == 2 {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    assert_eq!(tables, 2, "nominal + learned table within 10 s");
    let (_, body) = get(
        running.http_addr,
        "/api/v1/machines/TTY1/measurements?limit=5",
    )
    .await;
    let history = json(&body);
    assert_eq!(history["items"].as_array().unwrap().len(), 1, "{body}");
    assert_eq!(history["items"][0]["part"], "77");
    drop(writer.await.unwrap());
    running.stop().await;
}

/// A wheel dressing reported by a file dropped into the machine's drop folder: recorded with
/// its source, the table regenerated for the new radius, the file moved to processed/.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dropped_dressing_report_regenerates_the_table() {
    let dir = tempfile::tempdir().unwrap();
    let config = one_machine(
        dir.path(),
        "DROP1",
        "",
        "kind = \"drop\"\nfolder = \"inbox\"\npoll_ms = 20",
    );
    let running = service::start(config, RunOptions::default()).await.unwrap();
    let inbox = dir.path().join("inbox");
    std::fs::create_dir_all(&inbox).unwrap();
    // Written under a temporary name, ended with the `# end` marker and renamed, as the
    // drop-folder rules ask (so it is taken at once, not after the stability wait).
    std::fs::write(
        inbox.join(".dress.tmp"),
        "wheel_radius_mm = 249.9\ninfeed_um = 100.4\n# end\n",
    )
    .unwrap();
    std::fs::rename(inbox.join(".dress.tmp"), inbox.join("dress.dressing.toml")).unwrap();

    // Poll the API (bounded) until both the dressing and its table are in: the two are
    // separate records reaching the database one after the other, so the wait is for both.
    let mut dressings = serde_json::Value::Null;
    let mut tables = 0;
    for _ in 0..200 {
        let (_, body) = get(running.http_addr, "/api/v1/machines/DROP1/lobes/IN1/tables").await;
        tables = json(&body)["items"].as_array().map_or(0, Vec::len);
        let (_, body) = get(running.http_addr, "/api/v1/machines/DROP1/dressings").await;
        dressings = json(&body);
        let dressed = dressings["items"].as_array().is_some_and(|d| !d.is_empty());
        if tables == 2 && dressed {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    assert_eq!(tables, 2, "nominal + dressed table within 10 s");
    let d = &dressings["items"][0];
    assert_eq!(d["new_radius_mm"], 249.9, "{dressings}");
    assert_eq!(d["infeed_um"], 100.4, "{dressings}");
    let processed = inbox.join("processed/dress.dressing.toml");
    assert_eq!(
        d["source"].as_str().unwrap(),
        format!("drop file {}", processed.display())
    );
    assert!(processed.exists());
    assert!(!inbox.join("dress.dressing.toml").exists());
    running.stop().await;
}
