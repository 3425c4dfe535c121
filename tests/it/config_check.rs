//! The service's config check: every problem in one error, each with its line, found before
//! the database or a share is touched; two machines may not share a folder.

use camloop::config::{self, ConfigError, ConfigProblem};
use std::path::Path;

/// The 1-based line of the first line of `text` containing `marker`.
fn line_of(text: &str, marker: &str) -> usize {
    text.lines()
        .position(|l| l.contains(marker))
        .unwrap_or_else(|| panic!("`{marker}` not in the config"))
        + 1
}

fn demo_recipe() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config/parts/demo-lobe.toml")
        .display()
        .to_string()
}

fn problems(e: &ConfigError) -> String {
    e.problems
        .iter()
        .map(ConfigProblem::to_string)
        .collect::<Vec<_>>()
        .join("\n")
}

/// Asserts that a problem on `line` contains every one of `parts`.
fn assert_problem(e: &ConfigError, line: usize, parts: &[&str]) {
    let found = e
        .problems
        .iter()
        .any(|p| p.line == Some(line) && parts.iter().all(|s| p.message.contains(s)));
    assert!(
        found,
        "no problem on line {line} with {parts:?} in:\n{}",
        problems(e)
    );
}

#[test]
fn every_problem_in_the_file_and_the_files_it_names_is_reported_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    // A port that is in use for the whole test.
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let recipe = demo_recipe();
    let text = format!(
        r#"colour = "blue"
[service]
var_dir = "var"
[database]
url = "sqlite://var/camloop.db?mode=rwc"
[http]
listen = "127.0.0.1:{port}"
backlog = 5
[[machines]]
name = "M1"
recipe = "missing-a.toml"
lobe = "IN1"
share = "share/A"
[machines.gauge]
kind = "sim"
speed = 3
[[machines]]
name = "M2"
recipe = "missing-b.toml"
lobe = "IN1"
share = "share/B"
[machines.gauge]
kind = "drop"
folder = "inbox"
stable_ms = 0
[[machines]]
name = "M2"
recipe = "{recipe}"
lobe = "EX9"
share = "share/C"
[machines.gauge]
kind = "can"
interface = "can0"
dbc = "nowhere.dbc"
[[machines]]
name = "M4"
recipe = "{recipe}"
lobe = "IN1"
share = "./share/x/../C"
[machines.gauge]
kind = "sim"
[[machines]]
name = "bad name"
recipe = "{recipe}"
share = "share/E"
[machines.gauge]
kind = "sim"
"#
    );
    let file = dir.path().join("camloop.toml");
    let e = config::load(&text, &file, |_| None).unwrap_err();
    assert_eq!(e.file, file.display().to_string());
    let at = |marker: &str| line_of(&text, marker);
    assert_problem(&e, 1, &["unknown field `colour`"]);
    assert_problem(&e, at("backlog"), &["unknown field `backlog`"]);
    assert_problem(&e, at("speed = 3"), &["unknown field `speed`"]);
    assert_problem(
        &e,
        at("name = \"bad name\""),
        &["name `bad name`", "` ` at character 4"],
    );
    assert_problem(
        &e,
        at("missing-a.toml"),
        &["machines.M1.recipe", "missing-a.toml"],
    );
    assert_problem(
        &e,
        at("missing-b.toml"),
        &["machines.M2.recipe", "missing-b.toml"],
    );
    assert_problem(
        &e,
        at("stable_ms = 0"),
        &["machines.M2.gauge.stable_ms = 0"],
    );
    let second_m2 = text
        .lines()
        .enumerate()
        .filter(|(_, l)| l.contains("name = \"M2\""))
        .nth(1)
        .unwrap()
        .0
        + 1;
    assert_problem(
        &e,
        second_m2,
        &["duplicate machine name", "first at line 18"],
    );
    assert_problem(
        &e,
        at("lobe = \"EX9\""),
        &["machines.M2.lobe", "no lobe or pin EX9 (has: IN1)"],
    );
    assert_problem(
        &e,
        at("nowhere.dbc"),
        &["machines.M2.gauge.dbc", "nowhere.dbc"],
    );
    assert_problem(
        &e,
        at("../C"),
        &["machines.M4.share", "also the share of machine M2"],
    );
    assert_problem(&e, at("listen"), &["http.listen", &format!(":{port}")]);
    // One line, every problem in it, and nothing was created.
    let shown = e.to_string();
    assert!(!shown.contains('\n'), "{shown}");
    assert!(e.problems.len() >= 12, "{}", problems(&e));
    assert!(!dir.path().join("var").exists());
    assert!(!dir.path().join("share").exists());
}

#[test]
fn two_machines_on_one_share_or_drop_folder_are_refused_naming_both() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("shares/common")).unwrap();
    let recipe = demo_recipe();
    let machine = |name: &str, share: &str, gauge: &str| {
        format!(
            "[[machines]]\nname = \"{name}\"\nrecipe = \"{recipe}\"\nlobe = \"IN1\"\nshare = \"{share}\"\n[machines.gauge]\n{gauge}\n"
        )
    };
    let sim = "kind = \"sim\"";
    let text = format!(
        "[http]\nlisten = \"127.0.0.1:0\"\n{}{}{}{}",
        machine("G1", "shares/common", sim),
        machine("G2", "shares/./other/../common/", sim),
        machine("G3", "shares/g3", "kind = \"drop\"\nfolder = \"in\""),
        machine("G4", "shares/g4", "kind = \"drop\"\nfolder = \"in/.\""),
    );
    let file = dir.path().join("camloop.toml");
    let e = config::load(&text, &file, |_| None).unwrap_err();
    let share = dir.path().join("shares/./other/../common/");
    assert_problem(
        &e,
        line_of(&text, "shares/./other"),
        &[
            "machines.G2.share",
            &share.display().to_string(),
            "also the share of machine G1",
        ],
    );
    assert_problem(
        &e,
        line_of(&text, "in/."),
        &[
            "machines.G4.gauge.folder",
            "also the drop folder of machine G3",
        ],
    );
    assert_eq!(e.problems.len(), 2, "{}", problems(&e));
    // The same check guards `service::start` for a config parsed on its own.
    let parsed = config::Config::parse(&text, &file, |_| None).unwrap();
    let e = config::check(parsed).unwrap_err();
    assert_eq!(e.problems.len(), 2, "{}", problems(&e));
}

#[test]
fn a_good_config_passes_with_its_listener_bound_and_its_lobes_loaded() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "[http]\nlisten = \"127.0.0.1:0\"\nmax_connections = 8\nheader_timeout_ms = 500\n\
         [[machines]]\nname = \"SIM1\"\nrecipe = \"{}\"\nlobe = \"IN1\"\nshare = \"share\"\n\
         [machines.gauge]\nkind = \"drop\"\nfolder = \"in\"\n",
        demo_recipe()
    );
    let checked = config::load(&text, &dir.path().join("c.toml"), |_| None).unwrap();
    assert_ne!(checked.listener.local_addr().unwrap().port(), 0);
    assert_eq!(checked.machines.len(), 1);
    assert_eq!(checked.machines[0].name.as_str(), "SIM1");
    let names: Vec<&str> = checked.machines[0]
        .setups
        .iter()
        .map(|s| s.name.as_str())
        .collect();
    assert_eq!(names, ["IN1"], "lobe = \"IN1\" grinds that lobe only");
    assert_eq!(checked.config.http.max_connections, 8);
    assert_eq!(checked.config.http.header_timeout_ms, 500);
    assert_eq!(checked.config.http.body_timeout_ms, 10_000);
    let config::GaugeSection::Drop {
        stable_ms,
        max_file_bytes,
        poll_ms,
        ..
    } = checked.config.machines[0].gauge
    else {
        panic!("a drop gauge")
    };
    assert_eq!(
        (poll_ms, stable_ms, max_file_bytes),
        (500, 10_000, 16_777_216)
    );
}

/// Machine and feature names are checked as the file is read (they name folders, URLs and
/// database rows): the message names the file, the line and the character at fault, and a
/// name with `/` never reaches the file system.
#[test]
fn a_bad_machine_or_feature_name_is_refused_naming_the_file_and_line() {
    let text = format!(
        "[[machines]]\nname = \"G1\"\nrecipe = \"{recipe}\"\nlobe = \"IN1\"\nshare = \"a\"\n\
         [machines.gauge]\nkind = \"sim\"\n\
         [[machines]]\nname = \"../G2\"\nrecipe = \"{recipe}\"\nshare = \"b\"\n\
         [machines.gauge]\nkind = \"sim\"\n",
        recipe = demo_recipe()
    );
    let e = config::Config::parse(&text, Path::new("conf/c.toml"), |_| None).unwrap_err();
    assert_eq!(
        e.to_string(),
        "conf/c.toml: line 9: name `../G2` has `.` at character 1: \
         only letters, digits, '-' or '_' are allowed"
    );
    // A lobe or pin chosen in the config follows the same rule, also in a list.
    for (chosen, at) in [
        ("lobe = \"IN 1\"", 4),
        ("features = [\"IN1\", \"EX/1\"]", 4),
    ] {
        let text = text.replacen("lobe = \"IN1\"", chosen, 1);
        let e = config::Config::parse(&text, Path::new("c.toml"), |_| None).unwrap_err();
        assert_problem(&e, at, &["only letters, digits, '-' or '_' are allowed"]);
        assert_problem(&e, 9, &["name `../G2`"]);
    }
}

#[test]
fn every_syntax_error_is_reported_with_its_line() {
    let text = "[http]\nlisten = \n[[machines]]\nname = \"A\nlobe = 'x'\n";
    let e = config::Config::parse(text, Path::new("c.toml"), |_| None).unwrap_err();
    assert!(
        e.problems.iter().any(|p| p.line == Some(2)),
        "{}",
        problems(&e)
    );
    assert!(
        e.problems.iter().any(|p| p.line == Some(4)),
        "{}",
        problems(&e)
    );
}

#[test]
fn the_shipped_config_parses_with_the_documented_http_limits() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/camloop.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let c = config::Config::parse(&text, &path, |_| None).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(c.http.max_connections, 256);
    assert_eq!(
        (c.http.header_timeout_ms, c.http.body_timeout_ms),
        (10_000, 10_000)
    );
    assert_eq!(
        c.line("http.max_connections"),
        Some(line_of(&text, "max_connections"))
    );
}
