//! `camloop run` as an operator starts it (the real binary, a config file, a port of its own),
//! then `camloop history` and `camloop export` on the store it wrote.

use crate::cli_support;

use cli_support::{camloop, camloop_ok, json_file, refusal};
use std::path::Path;

#[test]
fn the_service_runs_its_parts_and_the_history_shows_them() {
    let dir = tempfile::tempdir().unwrap();
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let config = format!(
        "[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n[service]\nvar_dir = \"var\"\n[http]\nlisten = \"127.0.0.1:0\"\n\
         [[machines]]\nname = \"M7\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"share/M7\"\n[machines.gauge]\nkind = \"sim\"\npart_interval_ms = 10\n",
        recipe.display()
    );
    std::fs::write(dir.path().join("camloop.toml"), config).unwrap();
    let out = camloop(
        &["run", "--config", "camloop.toml", "--parts", "4"],
        dir.path(),
    );
    let log = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{log}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // One line per part: machine, lobe, max error, table version pushed.
    let parts: Vec<&str> = log.lines().filter(|l| l.contains("M7 IN1 part")).collect();
    assert_eq!(parts.len(), 4, "{log}");
    assert!(
        parts[3].contains("max error") && parts[3].contains("(T") && parts[3].contains("pushed"),
        "{}",
        parts[3]
    );
    assert!(dir.path().join("share/M7/DEMO_CAM_TABLE.SPF").exists());

    let db = "sqlite://var/camloop.db";
    let out = camloop_ok(
        &[
            "history",
            "--machine",
            "M7",
            "--format",
            "csv",
            "--database",
            db,
        ],
        dir.path(),
    );
    let csv = String::from_utf8_lossy(&out.stdout);
    assert_eq!(csv.lines().count(), 5, "{csv}");
    assert!(csv.starts_with("id,received_at_ms,machine,part,lobe,verdict,"));

    camloop_ok(
        &[
            "export",
            "--format",
            "json",
            "--since",
            "1h",
            "--database",
            db,
            "--out",
            "all.json",
        ],
        dir.path(),
    );
    let json: serde_json::Value = json_file(&dir.path().join("all.json"));
    assert_eq!(json.as_array().unwrap().len(), 4);

    let out = camloop(
        &[
            "history",
            "--machine",
            "M7",
            "--since",
            "soon",
            "--database",
            db,
        ],
        dir.path(),
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("time `soon`"));
}

#[test]
fn a_bad_configuration_is_refused_with_every_problem() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("bad.toml"),
        "[database]\nurl = \"mysql://x\"\n[[machines]]\nname = \"a b\"\nrecipe = \"r.toml\"\nlobe = \"L\"\nshare = \"s\"\n[machines.gauge]\nkind = \"sim\"\n",
    )
    .unwrap();
    let out = camloop(&["run", "--config", "bad.toml"], dir.path());
    let err = refusal(&out);
    assert!(
        err.contains("bad.toml: line 2: database.url")
            && err.contains("line 4: name `a b` has ` ` at character 2"),
        "{err}"
    );
}

/// Unknown keys, a bad name, a duplicate, two missing recipes, two machines on one share
/// and a port in use: all in one line on stderr, each with its line, a non-zero exit, and
/// neither the database nor a share created.
#[test]
fn every_problem_is_reported_before_the_database_or_a_share_is_touched() {
    let dir = tempfile::tempdir().unwrap();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let recipe = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let machine = |name: &str, recipe: &str, share: &str| {
        format!(
            "[[machines]]\nname = \"{name}\"\nrecipe = \"{recipe}\"\nlobe = \"IN1\"\nshare = \"{share}\"\n[machines.gauge]\nkind = \"sim\"\n"
        )
    };
    let good = recipe.display().to_string();
    let config = format!(
        "[service]\nvar_dir = \"var\"\ncolor = 1\n[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n\
         [http]\nlisten = \"127.0.0.1:{port}\"\nlisten_backlog = 9\n{}{}{}{}{}{}",
        machine("M1", "nope-a.toml", "share/1"),
        machine("M2", "nope-b.toml", "share/2"),
        machine("M2", &good, "share/3"),
        machine("M4", &good, "share/5"),
        machine("M5", &good, "share/./5"),
        // Refused as the file is read: this entry is not checked further.
        machine("M 6", &good, "share/6"),
    );
    std::fs::write(dir.path().join("camloop.toml"), &config).unwrap();
    let out = camloop(
        &["run", "--config", "camloop.toml", "--parts", "1"],
        dir.path(),
    );
    let err = refusal(&out);
    let line = |marker: &str| config.lines().position(|l| l.contains(marker)).unwrap() + 1;
    let second_m2 = config
        .lines()
        .enumerate()
        .filter(|(_, l)| l.contains("\"M2\""))
        .nth(1)
        .unwrap()
        .0
        + 1;
    for expected in [
        format!("line {}: unknown field `color`", line("color")),
        format!(
            "line {}: unknown field `listen_backlog`",
            line("listen_backlog")
        ),
        format!("line {}: name `M 6` has ` `", line("\"M 6\"")),
        format!(
            "line {}: machines.M1.recipe: cannot read recipe",
            line("nope-a")
        ),
        format!(
            "line {}: machines.M2.recipe: cannot read recipe",
            line("nope-b")
        ),
        format!("line {second_m2}: machines.M2: duplicate machine name"),
        format!("line {}: machines.M5.share", line("share/./5")),
        format!(
            "line {}: http.listen: cannot listen on 127.0.0.1:{port}",
            line("listen =")
        ),
    ] {
        assert!(err.contains(&expected), "`{expected}` missing from {err}");
    }
    assert!(!dir.path().join("var").exists(), "the database was created");
    assert!(!dir.path().join("share").exists(), "a share was written");
}
