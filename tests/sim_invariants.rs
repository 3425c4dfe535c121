//! The simulator is pure like the core: no file system, network, clock, environment or
//! logging, so that a seed and the inputs fix every result.

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

#[test]
fn sim_does_no_io_and_reads_no_clock() {
    let sim = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/sim");
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
    ];
    let files = rust_files(&sim);
    assert!(files.len() >= 7, "found only {} sim files", files.len());
    let mut violations = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        for (n, line) in text.lines().enumerate() {
            // Doc examples may read the shipped demo file; code may not.
            let code = line.split("//").next().unwrap_or("");
            for word in forbidden {
                if code.contains(word) {
                    violations.push(format!("{}:{}: {word}", file.display(), n + 1));
                }
            }
        }
    }
    assert!(violations.is_empty(), "{}", violations.join("\n"));
}
