//! Architecture invariants that a test can hold (see ARCHITECTURE.md).

use std::path::{Path, PathBuf};

fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(rust_files(&path));
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    out
}

/// Places in the Rust files under `dir` (comments aside) that use one of `forbidden`.
fn uses_of(dir: &Path, forbidden: &[&str], min_files: usize) -> Vec<String> {
    let files = rust_files(dir);
    assert!(
        files.len() >= min_files,
        "found only {} files in {}",
        files.len(),
        dir.display()
    );
    let mut violations = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            for word in forbidden {
                if code.contains(word) {
                    violations.push(format!("{}:{}: {word}", file.display(), n + 1));
                }
            }
        }
    }
    violations
}

/// The pure crates (the core, the generators, the loop, the simulator) depend on nothing that
/// does I/O (the simulator takes the gauge crate without its `io` adapters): their
/// manifests name only these crates, so the compiler refuses a runtime, a database or
/// logging there, whatever the code says.
#[test]
fn the_pure_crates_depend_on_no_io_crate() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let allowed = [
        "base16ct",
        "camloop-core",
        "camloop-gauge",
        // The loop's pure state machine and decisions (the simulator runs them too).
        "camloop-loop",
        // Its `Timestamp` type only: the pure crates read no clock (checked below).
        "jiff",
        "serde",
        "sha2",
        // Pure arithmetic: the capability statistics' distribution functions.
        "statrs",
        "thiserror",
        // Text in, values out: the contour file (TOML) and its expression curves (exmex).
        "toml",
        "exmex",
    ];
    for krate in [
        "crates/core",
        "crates/generate",
        "crates/loop",
        "crates/sim",
    ] {
        let text = std::fs::read_to_string(root.join(krate).join("Cargo.toml")).unwrap();
        let manifest: toml::Table = text.parse().unwrap();
        let deps = manifest["dependencies"].as_table().unwrap();
        assert!(
            !deps.is_empty(),
            "{krate} lists no dependencies: is this its manifest?"
        );
        for (name, spec) in deps {
            // The generators' curves derive their command-line arguments behind `cli`,
            // which only the binary asks for: argument parsing, no I/O.
            let optional = spec.get("optional").and_then(|o| o.as_bool()) == Some(true);
            assert!(
                allowed.contains(&name.as_str()) || (optional && name == "clap"),
                "{krate} depends on {name}: a pure crate may use only {allowed:?} (and clap, optional)"
            );
        }
    }
    // The gauge crate's codecs come without a runtime: tokio, SocketCAN and the serial port
    // are optional, behind `io`, and the simulator does not ask for it.
    let text = std::fs::read_to_string(root.join("crates/gauge/Cargo.toml")).unwrap();
    let manifest: toml::Table = text.parse().unwrap();
    for (name, spec) in manifest["dependencies"].as_table().unwrap() {
        if ["tokio", "socketcan", "tokio-serial"].contains(&name.as_str()) {
            assert_eq!(
                spec.get("optional").and_then(|o| o.as_bool()),
                Some(true),
                "gauge: {name}"
            );
        }
    }
    let sim = std::fs::read_to_string(root.join("crates/sim/Cargo.toml")).unwrap();
    assert!(
        !sim.contains("\"io\""),
        "the simulator takes the gauge's adapters"
    );
}

/// The core is pure: no file system, network, async runtime, database, HTTP, clock or logging.
/// (The manifests already keep the I/O crates out; this also catches `std`'s own I/O.)
#[test]
fn core_does_no_io() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let forbidden = [
        "std::fs",
        "std::net",
        "std::io::",
        "tokio",
        "sqlx",
        "axum",
        "SystemTime",
        "Instant",
        "tracing",
        "println!",
        "eprintln!",
        "std::env",
        "std::process",
    ];
    let mut violations = uses_of(&root.join("crates/core/src"), &forbidden, 10);
    violations.extend(uses_of(&root.join("crates/generate/src"), &forbidden, 8));
    assert!(
        violations.is_empty(),
        "I/O in the core:\n{}",
        violations.join("\n")
    );
}

/// The simulator is pure like the core (no file system, network, clock, environment or
/// logging), so that a seed and the inputs fix every result.
#[test]
fn sim_does_no_io_and_reads_no_clock() {
    let sim = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/sim/src");
    let forbidden = [
        "std::fs",
        "std::net",
        "std::io::",
        "tokio",
        "SystemTime",
        "Instant",
        "thread_rng",
        "tracing",
        "println!",
        "eprintln!",
        "std::env",
        "std::process",
        "Timestamp::now",
    ];
    let violations = uses_of(&sim, &forbidden, 7);
    assert!(
        violations.is_empty(),
        "I/O in the simulator:\n{}",
        violations.join("\n")
    );
}

/// The loop is pure like the core: it does no I/O, logs nothing and reads no clock (every
/// time comes in with its input, as a `jiff::Timestamp`), so each decision it makes is
/// fixed by its inputs.
#[test]
fn loop_does_no_io_and_reads_no_clock() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/loop/src");
    let forbidden = [
        "std::fs",
        "std::net",
        "std::io::",
        "tokio",
        "sqlx",
        "axum",
        "SystemTime",
        "Instant",
        "Timestamp::now",
        "Zoned::now",
        "tracing",
        "println!",
        "eprintln!",
        "std::env",
        "std::process",
    ];
    let violations = uses_of(&dir, &forbidden, 4);
    assert!(
        violations.is_empty(),
        "I/O or a clock in the loop:\n{}",
        violations.join("\n")
    );
}

/// Every module says what it owns in a `//!` line at the top.
#[test]
fn every_module_starts_with_a_doc_line() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = rust_files(&root.join("src"));
    for krate in ["core", "gauge", "generate", "loop", "mqtt", "opcua", "sim"] {
        files.extend(rust_files(&root.join("crates").join(krate).join("src")));
    }
    let missing: Vec<String> = files
        .into_iter()
        .filter(|f| !std::fs::read_to_string(f).unwrap().starts_with("//!"))
        .map(|f| f.display().to_string())
        .collect();
    assert!(missing.is_empty(), "no //! line: {missing:?}");
}

/// Every shipped service configuration parses and names recipes and lobes that exist, and
/// every feature of them loads.
#[test]
fn shipped_service_configurations_parse() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for file in [
        "config/camloop.toml",
        "config/crankshaft.toml",
        "config/opcua.toml",
        "docker/camloop.toml",
        "docker/cluster.toml",
    ] {
        let path = root.join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        let config = camloop::config::Config::parse(&text, &path, |_| None)
            .unwrap_or_else(|e| panic!("{e}"));
        // The start-up rule lets each of them start (the docker ones say why they may).
        let anonymous = config.auth.anonymous_read(config.http.listen);
        camloop::config::network_exposure(&config.http, anonymous, &config.lines)
            .unwrap_or_else(|e| panic!("{file}: {e}"));
        for m in &config.machines {
            // The docker file expects the recipes copied beside it, as the image does.
            let recipe = root.join("config").join(&m.recipe);
            let r = camloop::recipe::Recipe::load(&recipe).unwrap();
            let features = camloop::config::machine_features(&r, m).unwrap();
            assert!(!features.is_empty(), "{file}: {}", m.name);
            r.feature_setups(&recipe)
                .unwrap_or_else(|e| panic!("{file}: {e:#}"));
        }
    }
}

/// Nothing in the tree names the machine it was developed on.
#[test]
fn no_paths_of_the_development_machine() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut offenders = Vec::new();
    for dir in [
        "src", "crates", "tests", "benches", "config", "docker", "tools",
    ] {
        let mut stack = vec![root.join(dir)];
        while let Some(d) = stack.pop() {
            for entry in std::fs::read_dir(&d).unwrap() {
                let p = entry.unwrap().path();
                // npm's installs (tools/opcua-node) are other projects' files, not the tree's.
                if p.is_dir() && p.file_name().is_some_and(|n| n == "node_modules") {
                    continue;
                }
                if p.is_dir() {
                    stack.push(p);
                } else if let Ok(text) = std::fs::read_to_string(&p)
                    && text.contains(concat!("/wo", "rk/"))
                {
                    offenders.push(p.display().to_string());
                }
            }
        }
    }
    assert!(offenders.is_empty(), "{offenders:?}");
}

/// The service never imports the CLI: the CLI is an edge that drives the service, and what
/// both need lives in a neutral place (`clock`, `quality`).
#[test]
fn the_service_never_imports_the_cli() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let violations = uses_of(
        &root.join("src/service"),
        &["crate::cli", "super::cli", "camloop::cli"],
        30,
    );
    assert!(
        violations.is_empty(),
        "the service imports the CLI:\n{}",
        violations.join("\n")
    );
}

/// HTTP is the service's front, a leaf: the loop's shell (the machines, their journal, the
/// command path every write takes, the plant's events, the gauge sources) never imports it,
/// so the machines' mailbox and the write path are HTTP's and OPC UA's alike. Only the
/// wiring (`mod.rs`, `app.rs`, the start-up and listener set-up, `/metrics`) names it.
#[test]
fn the_loops_shell_never_imports_http() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/service");
    let forbidden = ["http::", "super::http", "crate::service::http"];
    let mut violations = uses_of(&root.join("machine"), &forbidden, 15);
    violations.extend(uses_of(&root.join("journal"), &forbidden, 4));
    for file in [
        "command.rs",
        "action.rs",
        "plant.rs",
        "sources.rs",
        "drop_source.rs",
        "sim_source.rs",
        "runner.rs",
        "opcua_port.rs",
        "sign_in.rs",
    ] {
        let text = std::fs::read_to_string(root.join(file)).unwrap();
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            if forbidden.iter().any(|w| code.contains(w)) {
                violations.push(format!("{file}:{}: {}", n + 1, line.trim()));
            }
        }
    }
    assert!(
        violations.is_empty(),
        "the loop's shell imports the HTTP adapter:\n{}",
        violations.join("\n")
    );
}

/// `anyhow` carries text to a log line or an answer and is never matched: the root crate (the
/// only one whose manifest names it) never downcasts an error to find out what it was; a
/// caller that must tell errors apart gets a typed one (thiserror) instead.
#[test]
fn no_error_is_found_out_by_downcasting() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let forbidden = ["downcast", ".is::<"];
    let violations = uses_of(&root.join("src"), &forbidden, 100);
    assert!(
        violations.is_empty(),
        "an error is downcast:\n{}",
        violations.join("\n")
    );
}

/// Adapters do not reach into each other: OPC UA and MQTT import neither the HTTP adapter
/// nor one another, nor the service. What they share (the loop's types, `service::action`,
/// `service::command`, `service::plant`, `service::app`, the password sign-in
/// `service::sign_in`) belongs to none of them; both are crates (`crates/mqtt`,
/// `crates/opcua`), so the compiler already keeps the service out of them, and their code
/// is searched too, in case a path to them is ever added to a manifest.
#[test]
fn opcua_and_mqtt_never_import_http_nor_each_other() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // `http::`, not `http`: the OPC UA units' namespace is an `http://` URI.
    let mut violations = uses_of(
        &root.join("crates/opcua/src"),
        &["http::", "axum", "mqtt", "camloop::", "crate::service"],
        8,
    );
    violations.extend(uses_of(
        &root.join("crates/mqtt/src"),
        &["http", "axum", "opcua", "camloop::", "crate::service"],
        5,
    ));
    assert!(
        violations.is_empty(),
        "an adapter imports another:\n{}",
        violations.join("\n")
    );
}

/// One adapter crate's manifest rule: camloop's crates it may take, each beyond the loop's
/// types with the reason it needs it, and the stacks that are another adapter's or the
/// store's.
struct AdapterRule {
    dir: &'static str,
    camloop_allowed: &'static [&'static str],
    /// camloop's crates beyond core and loop, each with why this adapter takes it.
    beyond_the_loop: &'static [(&'static str, &'static str)],
    forbidden: &'static [&'static str],
}

const ADAPTERS: [AdapterRule; 2] = [
    AdapterRule {
        dir: "crates/mqtt",
        camloop_allowed: &["camloop-core", "camloop-loop"],
        beyond_the_loop: &[],
        forbidden: &["axum", "hyper", "async-opcua", "sqlx", "utoipa", "maud"],
    },
    AdapterRule {
        dir: "crates/opcua",
        camloop_allowed: &["camloop-core", "camloop-loop", "camloop-store"],
        beyond_the_loop: &[(
            "camloop-store",
            "it reads the history itself: the newest results at start, the result methods, \
             the event row an EventId names, the signed-in users' state",
        )],
        forbidden: &["axum", "hyper", "rumqttc", "sqlx", "utoipa", "maud"],
    },
];

/// An adapter crate depends on the loop's types (and the core's names beneath them), on
/// its own I/O crates, and never on the service that wires it or another adapter's stack:
/// so an adapter can be read, built and tested alone. Only OPC UA takes the store, for the
/// history it reads itself (its manifest says why, on the line above).
#[test]
fn adapter_crates_depend_on_the_loops_types_never_on_the_service_or_each_other() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for rule in &ADAPTERS {
        let text = std::fs::read_to_string(root.join(rule.dir).join("Cargo.toml")).unwrap();
        let manifest: toml::Table = text.parse().unwrap();
        let deps = manifest["dependencies"].as_table().unwrap();
        assert!(
            deps.contains_key("camloop-loop"),
            "{}'s manifest names {:?}: is this its manifest?",
            rule.dir,
            deps.keys().collect::<Vec<_>>()
        );
        for name in deps.keys() {
            assert!(
                !name.starts_with("camloop") || rule.camloop_allowed.contains(&name.as_str()),
                "{} depends on {name}: this adapter takes only {:?} of camloop's crates",
                rule.dir,
                rule.camloop_allowed
            );
            for forbidden in rule.forbidden {
                assert!(
                    !name.starts_with(forbidden),
                    "{} depends on {name}: another adapter's or the store's stack",
                    rule.dir
                );
            }
        }
        for (name, why) in rule.beyond_the_loop {
            assert!(deps.contains_key(*name), "{}: {name} ({why})", rule.dir);
            // The reason is written beside the dependency, not only here.
            let lines: Vec<&str> = text.lines().collect();
            let at = lines
                .iter()
                .position(|l| l.starts_with(&format!("{name} ")))
                .unwrap();
            assert!(
                lines[at - 1].trim_start().starts_with('#'),
                "{}: {name} needs a comment saying why ({why})",
                rule.dir
            );
        }
    }
}

/// The loop crate is pure: its manifest names no runtime, database, web framework or
/// logging, so the compiler keeps them out whatever the code says.
#[test]
fn the_loop_crate_names_no_io_crate() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("crates/loop/Cargo.toml")).unwrap();
    let manifest: toml::Table = text.parse().unwrap();
    let mut named: Vec<&str> = Vec::new();
    for section in ["dependencies", "dev-dependencies", "build-dependencies"] {
        if let Some(deps) = manifest.get(section).and_then(|d| d.as_table()) {
            named.extend(deps.keys().map(String::as_str));
        }
    }
    assert!(
        named.contains(&"camloop-core"),
        "the loop crate's manifest names {named:?}: is this its manifest?"
    );
    for forbidden in ["tokio", "sqlx", "axum", "tracing"] {
        assert!(
            !named.iter().any(|n| n.starts_with(forbidden)),
            "the loop crate depends on {forbidden}: {named:?}"
        );
    }
}
