//! The config's parsing and checks: sections, environment overrides, secrets never shown.

use super::*;

const MINIMAL: &str = r#"
[[machines]]
name = "SIM1"
recipe = "parts/demo-lobe.toml"
lobe = "IN1"
share = "../var/share/SIM1"
[machines.gauge]
kind = "sim"
"#;

#[test]
fn a_cluster_needs_postgres_and_a_shared_folder_and_names_its_mqtt_client() {
    let alone = format!("{MINIMAL}[cluster]\nenabled = true\n");
    let e = Config::parse(&alone, Path::new("config/camloop.toml"), |_| None).unwrap_err();
    let text = e.to_string();
    assert!(text.contains("cluster.state_dir: required"), "{text}");
    assert!(text.contains("must be postgres://"), "{text}");

    let text = format!(
        "[database]\nurl = \"postgres://db/camloop\"\n[mqtt]\nenabled = true\n\
         [cluster]\nenabled = true\ninstance = \"line2-a\"\nstate_dir = \"/mnt/camloop\"\n{MINIMAL}"
    );
    let c = Config::parse(&text, Path::new("config/camloop.toml"), |_| None).unwrap();
    assert_eq!(c.machines_dir(), Path::new("/mnt/camloop/machines"));
    // Two instances with one client id would knock each other off the broker.
    assert_eq!(c.mqtt_settings().client_id, "camloop-line2-a");
    assert_eq!(c.cluster.lease_ms, 6000);

    let c = Config::parse(MINIMAL, Path::new("config/camloop.toml"), |_| None).unwrap();
    assert_eq!(c.mqtt_settings().client_id, "camloop");
    assert_eq!(c.machines_dir(), Path::new("config/../var/machines"));
}

#[test]
fn environment_overrides_the_url_and_supplies_the_token_which_never_shows() {
    let token = "s3cret-s3cret-s3cret-s3cret-s3cret";
    let env = |k: &str| match k {
        ENV_DATABASE_URL => Some("postgres://camloop:hunter2@db/camloop".to_string()),
        ENV_API_TOKEN => Some(token.to_string()),
        _ => None,
    };
    let c = Config::parse(MINIMAL, Path::new("config/camloop.toml"), env).unwrap();
    assert_eq!(c.database.url, "postgres://camloop:hunter2@db/camloop");
    assert_eq!(c.api_token.as_ref().map(Secret::expose), Some(token));
    let shown = format!("{c:?}");
    assert!(
        !shown.contains("hunter2") && !shown.contains("s3cret"),
        "{shown}"
    );
}

#[test]
fn a_short_api_token_is_refused_naming_the_minimum() {
    let env = |k: &str| (k == ENV_API_TOKEN).then(|| "x".to_string());
    let e = Config::parse(MINIMAL, Path::new("config/camloop.toml"), env).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("CAMLOOP_API_TOKEN has 1 characters; at least 32 are needed"),
        "{text}"
    );
}

#[test]
fn relative_paths_resolve_against_the_config_folder() {
    let c = Config::parse(MINIMAL, Path::new("config/camloop.toml"), |_| None).unwrap();
    assert_eq!(
        c.database_url(),
        "sqlite://config/../var/camloop.db?mode=rwc"
    );
    assert_eq!(
        c.resolve(Path::new("parts/x.toml")),
        PathBuf::from("config/parts/x.toml")
    );
}

#[test]
fn every_problem_is_reported_at_once() {
    // A bad name is refused as the file is read, so that entry is dropped (as any entry
    // with a wrongly typed value); the other entries are still checked.
    let text = r#"
[database]
url = "mysql://x"
[[machines]]
name = "G1"
recipe = "r.toml"
lobe = "IN1"
share = "s"
[machines.gauge]
kind = "sim"
part_interval_ms = 0
[[machines]]
name = "G1"
recipe = "r.toml"
lobe = "IN1"
share = "s"
[machines.gauge]
kind = "drop"
folder = "in"
[[machines]]
name = "bad name"
recipe = "r.toml"
share = "s"
[machines.gauge]
kind = "sim"
"#;
    let e = Config::parse(text, Path::new("c.toml"), |_| None)
        .unwrap_err()
        .to_string();
    for expected in [
        "database.url",
        "line 21: name `bad name` has ` ` at character 4",
        "line 13: machines.G1: duplicate machine name (first at line 5)",
        "line 11: machines.G1.gauge.part_interval_ms = 0: must be 1 to",
    ] {
        assert!(e.contains(expected), "`{expected}` missing from `{e}`");
    }
    let e = Config::parse("colour = 1\n", Path::new("c.toml"), |_| None)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("c.toml: line 1: unknown field `colour`"),
        "{e}"
    );
}

#[test]
fn a_bad_value_drops_only_its_own_section_and_the_rest_is_still_checked() {
    let text = format!(
        "[http]\nlisten = \"nowhere\"\n[database]\nurl = \"mysql://x\"\n\
         [[machines]]\nname = \"NOGAUGE\"\nrecipe = \"r.toml\"\nlobe = \"IN1\"\nshare = \"s\"\n\
         {MINIMAL}colour = 2\n"
    );
    let e = Config::parse(&text, Path::new("c.toml"), |_| None).unwrap_err();
    let shown: Vec<String> = e.problems.iter().map(ToString::to_string).collect();
    assert_eq!(e.problems.len(), 4, "{shown:?}");
    assert!(
        shown[0].starts_with("line 2: invalid socket address"),
        "{shown:?}"
    );
    assert!(shown[1].starts_with("line 4: database.url"), "{shown:?}");
    assert!(
        shown[2].starts_with("line 5: missing field `gauge`"),
        "{shown:?}"
    );
    assert!(
        shown[3].starts_with("line 18: unknown field `colour`"),
        "{shown:?}"
    );
    let e = Config::parse("machines = 5\n", Path::new("c.toml"), |_| None).unwrap_err();
    assert_eq!(e.problems.len(), 1, "{e}");
    assert!(
        e.to_string()
            .starts_with("c.toml: line 1: invalid type: integer `5`"),
        "{e}"
    );
}

#[test]
fn every_unknown_key_is_reported_with_its_line() {
    let text = format!("colour = 1\n{MINIMAL}seed = 2\nflavour = 3\n[http]\nport = 80\n");
    let e = Config::parse(&text, Path::new("c.toml"), |_| None).unwrap_err();
    let lines: Vec<(Option<usize>, &str)> = e
        .problems
        .iter()
        .map(|p| (p.line, p.message.split(',').next().unwrap_or("")))
        .collect();
    assert_eq!(
        lines,
        [
            (Some(1), "unknown field `colour`"),
            (Some(11), "unknown field `flavour`"),
            (Some(13), "unknown field `port`"),
        ],
        "{e}"
    );
}

/// The `[opcua]` section (its checks are the OPC UA crate's) in a whole config file.
fn parse_opcua(text: &str) -> Result<Config, ConfigError> {
    Config::parse(text, Path::new("c.toml"), |_| None)
}

#[test]
fn opcua_is_off_by_default_secure_by_default_and_none_only_when_named() {
    let section = |text: &str| toml::from_str::<OpcUaSection>(text);
    let c = section("").unwrap();
    assert!(!c.enabled);
    assert_eq!(c.security, OpcUaSecurity::Basic256Sha256);
    assert!(!c.accept_unknown_clients && !c.anonymous_read);
    let c = section("enabled = true\nsecurity = \"Basic256Sha256+None\"\n").unwrap();
    assert_eq!(c.security, OpcUaSecurity::Basic256Sha256AndNone);
    let e = section("enabled = true\nsecurity = \"None\"\n").unwrap_err();
    assert!(e.to_string().contains("unknown variant `None`"), "{e}");
    // In a whole config the line is named.
    let e = parse_opcua("[opcua]\nenabled = true\nsecurity = \"None\"\n").unwrap_err();
    assert!(e.to_string().contains("line 3"), "{e}");
}

#[test]
fn an_opcua_port_of_zero_and_a_bad_host_name_are_refused_with_their_lines() {
    let e = parse_opcua("[opcua]\nenabled = true\nlisten = \"127.0.0.1:0\"\nhost_name = \"a b\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 3: opcua.listen"), "{e}");
    assert!(e.contains("line 4: opcua.host_name"), "{e}");
}

#[test]
fn the_opcua_certificate_subject_is_checked_with_its_lines() {
    let e = parse_opcua(
        "[opcua]\nenabled = true\ncertificate_organization = \"A, B\"\ncertificate_country = \"Germany\"\ncertificate_days = 0\n",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("line 3: opcua.certificate_organization"), "{e}");
    assert!(e.contains("line 4: opcua.certificate_country"), "{e}");
    assert!(e.contains("line 5: opcua.certificate_days"), "{e}");
    // A good subject: the only problem left is the missing machines.
    let e = parse_opcua(
        "[opcua]\nenabled = true\ncertificate_organization = \"Werk Süd\"\ncertificate_country = \"DE\"\n",
    )
    .unwrap_err()
    .to_string();
    assert!(!e.contains("opcua."), "{e}");
}
