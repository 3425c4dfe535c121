//! The speed plan in the real service: `camloop run` (the binary) grinds the demo camshaft
//! with `[speed_plan] enabled = true` on the simulated machine. The share holds each lobe's
//! two-table program over the virtual axis (with the constant-speed program's provenance)
//! and the shaft program that couples C and X to it; the simulated control runs exactly
//! those, and the shaft converges as at constant speed. And a corrected table whose X over
//! the virtual axis exceeds an X limit is refused, never delivered.

use crate::cli_support::repo;
use crate::process_support::{KillOnDrop, camloop_run};
use std::path::Path;
use std::process::Stdio;
use std::time::Duration;

/// The demo camshaft's recipe with the plan on (and the table numbers it needs), lift files
/// found where the repository keeps them.
fn planned_recipe(dir: &Path, file: &str) -> String {
    let text = std::fs::read_to_string(repo(&format!("config/parts/{file}"))).unwrap();
    let text = text
        .replace("enabled = false", "enabled = true")
        .replace("table_numbers = [1, 16]", "table_numbers = [1, 32]")
        .replace("table_numbers = [1, 2]", "table_numbers = [1, 4]")
        .replace(
            "lift = \"demo-",
            &format!("lift = \"{}/demo-", repo("config/parts")),
        );
    let path = dir.join("recipe.toml");
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

/// Runs `camloop run` in `dir` for `parts` and returns its log (stdout and stderr), waiting
/// at most `bound` for it to finish.
fn run(dir: &Path, config: &str, parts: u32, bound: Duration) -> String {
    std::fs::write(dir.join("camloop.toml"), config).unwrap();
    let (out, err) = (dir.join("out.log"), dir.join("err.log"));
    let mut child = KillOnDrop::spawn(
        camloop_run(dir)
            .args(["--parts", &parts.to_string()])
            .stdout(Stdio::from(std::fs::File::create(&out).unwrap()))
            .stderr(Stdio::from(std::fs::File::create(&err).unwrap())),
    )
    .unwrap();
    let what = format!("camloop run of {parts} parts");
    let status = child.exit_within(bound, Duration::from_millis(200), &what);
    let log = std::fs::read_to_string(&out).unwrap() + &std::fs::read_to_string(&err).unwrap();
    assert!(status.success(), "{log}");
    log
}

fn config(recipe: &str, grinder: &str) -> String {
    format!(
        "[service]\nvar_dir = \"var\"\n[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n\
         [http]\nlisten = \"127.0.0.1:0\"\n[[machines]]\nname = \"SIM8\"\nrecipe = \"{recipe}\"\n\
         share = \"share/SIM8\"\n[machines.gauge]\nkind = \"sim\"\npart_interval_ms = 1\nseed = 8\n\
         [machines.gauge.grinder]\n{grinder}\n"
    )
}

/// (shaft, features gauged, worst max lift error µm) of each "shaft N:" line.
fn shaft_lines(log: &str) -> Vec<(u64, u32, f64)> {
    log.lines()
        .filter_map(|l| {
            let rest = &l[l.find("SIM8 shaft ")? + "SIM8 shaft ".len()..];
            let (shaft, rest) = rest.split_once(": ")?;
            let (gauged, rest) = rest.split_once(" of ")?;
            let worst = rest.split(" worst ").nth(1)?.split_whitespace().nth(1)?;
            Some((
                shaft.parse().ok()?,
                gauged.parse().ok()?,
                worst.parse().ok()?,
            ))
        })
        .collect()
}

/// 10 shafts, the wheel dressed after the 6th (the plans are made again for the new radius,
/// the corrections kept): from the 4th shaft on every lobe stays below 1.3 µm max lift
/// error with nothing fitted, as at constant speed (the constant-speed shaft test's bound).
#[test]
fn the_camshaft_converges_with_the_plan_and_the_share_holds_the_two_table_programs() {
    let dir = tempfile::tempdir().unwrap();
    let recipe = planned_recipe(dir.path(), "demo-camshaft.toml");
    let grinder = "dress_at_parts = [6]\ndress_every_parts = 0\nwear_um_per_part = 0.05\n\
                   dressing_error_um = 0.5\ndressing_error_sigma_um = 0.25\n";
    // 80 features in a debug build: about a minute here; 15 minutes is a hang.
    let log = run(
        dir.path(),
        &config(&recipe, grinder),
        10,
        Duration::from_secs(900),
    );
    let shafts = shaft_lines(&log);
    let report: Vec<String> = shafts
        .iter()
        .map(|(s, n, e)| format!("shaft {s}: {n} lobes, worst {e:.2} µm"))
        .collect();
    println!("{}", report.join("\n"));
    assert_eq!(shafts.len(), 10, "{log}");
    assert!(shafts.iter().all(|s| s.1 == 8), "{report:?}");
    assert!(
        shafts[0].2 > 5.0,
        "the first shaft is ground uncorrected: {report:?}"
    );
    for (shaft, _, worst_um) in &shafts[3..] {
        assert!(*worst_um < 1.3, "shaft {shaft}: {worst_um} µm\n{report:?}");
    }
    assert!(!log.contains("refused"), "{log}");

    let share = dir.path().join("share/SIM8");
    let table = std::fs::read_to_string(share.join("DEMO_CAM_IN1.SPF")).unwrap();
    for line in [
        "PROC DEMO_CAM_IN1(VAR INT CL_TNO, VAR INT CL_TNO_C) SAVE",
        "; table version: v",
        "; recipe: DEMO-CAM",
        "; feature: IN1",
        "; correction sha256: ",
        "; reason: wheel dressed",
        "CTABDEF(X,VA,",
        "CTABDEF(C,VA,",
    ] {
        assert!(
            table.contains(line)
                || (line.starts_with("; reason") && table.contains("; reason: part")),
            "{line}\n{table}"
        );
    }
    // The lobe's numbers: X from its pair (1, 2), C from its pair after all X pairs (17, 18).
    assert!(
        table.contains("CL_TNO_C=17") || table.contains("CL_TNO_C=18"),
        "{table}"
    );
    let main = std::fs::read_to_string(share.join("CAMLOOP_GRIND.MPF")).unwrap();
    assert_eq!(main.matches("LEADON(C,VA,CL_TNO_C)").count(), 8, "{main}");
    assert_eq!(main.matches("FA[VA]=").count(), 8, "{main}");
    assert!(
        main.contains("EXTERN DEMO_CAM_EX4(VAR INT, VAR INT)"),
        "{main}"
    );
}

/// A plan bound by X velocity on the flanks (X velocity 40 mm/s; the demo plan reaches 59)
/// on a machine with a 30th-order error of 4 µm: the nominal table keeps the limit with the
/// plan's 0.5 % margin, but the correction of that error (slope up to 0.8·4 µm·30 ≈ 0.1 mm
/// per radian, about 1.5 % of the flank's) steepens the flank where the plan already uses
/// nearly all of it, so the corrected X table over VA exceeds the limit and is refused with
/// the lobe and angle named; the share keeps the nominal table.
#[test]
fn a_corrected_table_over_an_x_limit_with_the_plan_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let recipe = planned_recipe(dir.path(), "demo-lobe.toml");
    let text = std::fs::read_to_string(&recipe)
        .unwrap()
        .replace("velocity_mm_s = 200.0", "velocity_mm_s = 40.0");
    std::fs::write(&recipe, text).unwrap();
    let config = config(&recipe, "").replace(
        "share = \"share/SIM8\"",
        "lobe = \"IN1\"\nshare = \"share/SIM8\"",
    );
    let config = config.replace(
        "[machines.gauge.grinder]\n",
        "[machines.gauge.grinder]\n[[machines.gauge.grinder.harmonics]]\norder = 30\namplitude_um = 4.0\nphase_deg = 0.0\n",
    );
    // 3 parts of one lobe: seconds here; 5 minutes is a hang.
    let log = run(dir.path(), &config, 3, Duration::from_secs(300));
    let refusals: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("with the speed plan, X velocity"))
        .collect();
    assert!(!refusals.is_empty(), "{log}");
    println!("{}", refusals[0]);
    assert!(
        refusals[0].contains("exceeds the axis limit 40 mm/s") && refusals[0].contains("C = "),
        "{}",
        refusals[0]
    );
    assert!(log.contains("table refused, previous kept"), "{log}");
    let table = std::fs::read_to_string(dir.path().join("share/SIM8/DEMO_CAM_TABLE.SPF")).unwrap();
    assert!(
        table.contains("; table version: v1\n") && table.contains("CTABDEF(X,VA,"),
        "{table}"
    );
}

/// A rollback with the plan on: the two-table program has two numbers, so it is made again
/// from the version's correction and timing for the plan in force (not retargeted), under
/// the free X number and the C number in step with it. Rolled back to the nominal v1, its
/// X and C blocks are v1's exactly, only the numbers and the provenance differ.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rollback_with_the_plan_makes_the_two_tables_again() {
    use crate::service_support::{get, json, post};
    use camloop::config::Config;
    use camloop::service::{self, RunOptions};
    const TOKEN: &str = "let-me-write-a-token-of-32-chars";
    let dir = tempfile::tempdir().unwrap();
    let recipe = planned_recipe(dir.path(), "demo-lobe.toml");
    let text = config(&recipe, "")
        .replace(
            "share = \"share/SIM8\"",
            "lobe = \"IN1\"\nshare = \"share/SIM8\"",
        )
        .replace(
            "sqlite://var/camloop.db",
            &format!("sqlite://{}/var/camloop.db", dir.path().display()),
        );
    let env = |k: &str| (k == camloop::config::ENV_API_TOKEN).then(|| TOKEN.to_string());
    let config = Config::parse(&text, &dir.path().join("camloop.toml"), env).unwrap();
    let mut running = service::start(config, RunOptions::parts(3)).await.unwrap();
    running.machines_done().await;
    let addr = running.http_addr;
    let path = "/api/v1/machines/SIM8/lobes/IN1/rollback";
    let (status, body) = post(addr, path, r#"{"version":1}"#, Some(TOKEN)).await;
    assert_eq!(status, 200, "{body}");
    let new_version = json(&body)["version"].as_u64().unwrap();
    assert_eq!(new_version, 5, "{body}");
    let (_, v1) = get(addr, "/api/v1/machines/SIM8/lobes/IN1/tables/1/program").await;
    let share = std::fs::read_to_string(dir.path().join("share/SIM8/DEMO_CAM_TABLE.SPF")).unwrap();
    let blocks = |t: &str| -> Vec<String> {
        t.lines()
            .filter(|l| l.starts_with("PO[") || l.starts_with("G1 "))
            .map(str::to_string)
            .collect()
    };
    // Both tables: 400 pieces each on the demo lobe (3 ms pieces, see the planner's
    // `shortest_piece_s`), X's refined where it strays.
    assert!(blocks(&v1).len() > 800, "{v1}");
    assert_eq!(blocks(&share), blocks(&v1));
    for line in [
        "; table version: v5",
        "; reason: rollback to v1",
        "CTABDEF(X,VA,",
        "CTABDEF(C,VA,",
    ] {
        assert!(share.contains(line), "{line}\n{share}");
    }
    // v4 defined X 2 and C 4; the rollback the free ones: X 1, C 3.
    assert!(
        share.contains("CL_TNO=1 ") && share.contains("CL_TNO_C=3 "),
        "{share}"
    );
    drop(running);
}
