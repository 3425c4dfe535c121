//! Running LinuxCNC's stand-alone interpreter `rs274` on a program and reading its
//! canonical moves.
//!
//! `rs274 -t <tool table> -g <file>` runs a program in batch mode and prints one canonical
//! call per line (`STRAIGHT_FEED(x, y, z, a, b, c)` with 4 decimals). Without an INI file
//! the interpreter's machine units are inches, so the tool table's diameter `D` is written
//! in inches while the program itself runs in mm (G21).

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::Mutex;

/// LinuxCNC 2.9 keeps the loaded tool data in shared memory, shared by every `rs274`
/// process on the machine: two runs at once see each other's tool (a 0.8 mm nose appeared in
/// a run that loaded none). The tests of one binary run their interpreters one at a time;
/// cargo runs test binaries one after another.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// A canonical move, positions in program units (mm, degrees).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Canon {
    Rapid {
        x: f64,
        y: f64,
        z: f64,
        a: f64,
        c: f64,
    },
    Feed {
        x: f64,
        y: f64,
        z: f64,
        a: f64,
        c: f64,
    },
    /// `ARC_FEED(first end, second end, first centre, second centre, turns, axis end, a, b, c)`
    /// in the plane's axes (X, Y in G17).
    Arc {
        e1: f64,
        e2: f64,
        c1: f64,
        c2: f64,
        turns: i32,
        c: f64,
    },
}

/// The interpreter, if installed.
pub fn rs274() -> Option<PathBuf> {
    ["/usr/bin/rs274", "/usr/local/bin/rs274"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
}

/// Runs `program` with tool 1 loaded (nose radius in mm) and returns the moves; the
/// interpreter's error text if it stops on one.
pub fn run_rs274(
    rs274: &PathBuf,
    program: &str,
    nose_radius_mm: f64,
) -> Result<Vec<Canon>, String> {
    run(rs274, program, nose_radius_mm, None)
}

/// [`run_rs274`] with the parameter file `var` (`-v`): the interpreter reads the parameters
/// listed in it before the program and writes them back when it exits, as LinuxCNC keeps
/// persistent parameters between runs.
pub fn run_rs274_with_var(
    rs274: &PathBuf,
    program: &str,
    nose_radius_mm: f64,
    var: &std::path::Path,
) -> Result<Vec<Canon>, String> {
    run(rs274, program, nose_radius_mm, Some(var))
}

fn run(
    rs274: &PathBuf,
    program: &str,
    nose_radius_mm: f64,
    var: Option<&std::path::Path>,
) -> Result<Vec<Canon>, String> {
    let dir = tempfile::tempdir().unwrap();
    let tbl = dir.path().join("tool.tbl");
    std::fs::write(
        &tbl,
        format!("T1 P1 D{:.8} ;\n", 2.0 * nose_radius_mm / 25.4),
    )
    .unwrap();
    // Tool 1 in the spindle before the program, so compensation has its radius.
    let body = program.replacen("%\n", "", 1);
    let text = format!("T1 M6\n{body}");
    let ngc = dir.path().join("prog.ngc");
    std::fs::write(&ngc, text).unwrap();
    let _turn = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut cmd = Command::new(rs274);
    if let Some(var) = var {
        cmd.arg("-v").arg(var);
    }
    let out = cmd
        .arg("-t")
        .arg(&tbl)
        .arg("-g")
        .arg(&ngc)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let mut moves = Vec::new();
    for line in stdout.lines() {
        let parse = |name: &str| {
            let start = line.find(&format!("{name}("))? + name.len() + 1;
            let inner = &line[start..line[start..].find(')')? + start];
            let v: Vec<f64> = inner
                .split(',')
                .map(|s| s.trim().parse().unwrap())
                .collect();
            Some(v)
        };
        if let Some(v) = parse("STRAIGHT_FEED") {
            moves.push(Canon::Feed {
                x: v[0],
                y: v[1],
                z: v[2],
                a: v[3],
                c: v[5],
            });
        } else if let Some(v) = parse("STRAIGHT_TRAVERSE") {
            moves.push(Canon::Rapid {
                x: v[0],
                y: v[1],
                z: v[2],
                a: v[3],
                c: v[5],
            });
        } else if let Some(v) = parse("ARC_FEED") {
            moves.push(Canon::Arc {
                e1: v[0],
                e2: v[1],
                c1: v[2],
                c2: v[3],
                turns: v[4] as i32,
                c: v[8],
            });
        }
    }
    let error = stdout.lines().chain(stderr.lines()).find(|l| {
        let l = l.to_ascii_lowercase();
        l.contains("error") || l.contains("unknown") || l.contains("bad ")
    });
    // A program the interpreter ran to its end says so; anything else (its messages, such
    // as "Command too long", name no "error") is a refusal.
    match error {
        Some(e) => Err(format!("rs274: {e}\n{stdout}")),
        None if !stdout.contains("PROGRAM_END()") => {
            Err(format!("rs274 stopped before the end:\n{stdout}\n{stderr}"))
        }
        None => Ok(moves),
    }
}
