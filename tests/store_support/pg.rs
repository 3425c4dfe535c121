//! A throwaway PostgreSQL server: `initdb` into a tempdir, `pg_ctl start` on a free port on
//! 127.0.0.1 with the unix socket in the tempdir, one database `camloop`; stopped on drop.
//! As root, the server binaries run as the `postgres` OS user (initdb refuses root).
//! [`TempPostgres::start_at`] keeps the data folder for reuse (the benchmark's cache).

use std::path::{Path, PathBuf};
use std::process::Command;

pub enum StartError {
    /// No `initdb`/`pg_ctl` on this machine.
    NoBinaries(String),
    /// Binaries present but the server did not come up.
    Failed(String),
}

pub struct TempPostgres {
    bin: PathBuf,
    data: PathBuf,
    as_postgres: bool,
    port: u16,
    root: PathBuf,
    _dir: Option<tempfile::TempDir>,
}

fn find_bin_dir() -> Option<PathBuf> {
    let mut found: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path().join("bin"))
        .filter(|b| b.join("initdb").is_file() && b.join("pg_ctl").is_file())
        .collect();
    // Highest major version first.
    found.sort_by_key(|p| {
        p.parent()
            .and_then(|v| v.file_name())
            .and_then(|v| v.to_str())
            .and_then(|v| v.parse::<u32>().ok())
            .unwrap_or(0)
    });
    found.pop()
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
        .unwrap_or(false)
}

fn free_port() -> std::io::Result<u16> {
    // The port is free now; another process could take it before the server binds, which
    // makes the start fail loudly rather than connect to something else.
    let listener = std::net::TcpListener::bind("127.0.0.1:0")?;
    Ok(listener.local_addr()?.port())
}

/// A fresh server, or `None` (with a skip line) when the server binaries are missing and
/// `CAMLOOP_REQUIRE_POSTGRES` is not `1`.
pub fn start_or_skip(test: &str) -> Option<TempPostgres> {
    let server = match TempPostgres::start() {
        Ok(server) => server,
        Err(StartError::NoBinaries(why)) => {
            if std::env::var("CAMLOOP_REQUIRE_POSTGRES").as_deref() == Ok("1") {
                panic!("CAMLOOP_REQUIRE_POSTGRES=1 but {why}");
            }
            eprintln!("SKIP {test} on postgres: {why} (set CAMLOOP_REQUIRE_POSTGRES=1 to fail)");
            return None;
        }
        Err(StartError::Failed(why)) => panic!("temporary postgres failed: {why}"),
    };
    Some(server)
}

impl TempPostgres {
    /// A server in a fresh tempdir, removed on drop.
    pub fn start() -> Result<Self, StartError> {
        let dir = tempfile::tempdir().map_err(|e| StartError::Failed(format!("tempdir: {e}")))?;
        let root = dir.path().to_path_buf();
        Self::start_in(root, Some(dir))
    }

    /// A server whose folder `root` is kept: initdb only when it holds no cluster yet.
    pub fn start_at(root: &Path) -> Result<Self, StartError> {
        std::fs::create_dir_all(root)
            .map_err(|e| StartError::Failed(format!("create {}: {e}", root.display())))?;
        Self::start_in(root.to_path_buf(), None)
    }

    fn start_in(root: PathBuf, dir: Option<tempfile::TempDir>) -> Result<Self, StartError> {
        let bin = find_bin_dir().ok_or_else(|| {
            StartError::NoBinaries("no initdb and pg_ctl under /usr/lib/postgresql/*/bin".into())
        })?;
        let failed =
            |what: &str, e: &dyn std::fmt::Display| StartError::Failed(format!("{what}: {e}"));
        let as_postgres = is_root();
        let data = root.join("data");
        if as_postgres {
            run(Command::new("chown").arg("-R").arg("postgres:").arg(&root))
                .map_err(|e| failed("chown folder to postgres", &e))?;
        }
        let port = free_port().map_err(|e| failed("free port", &e))?;
        let me = TempPostgres {
            bin,
            data,
            as_postgres,
            port,
            root,
            _dir: dir,
        };
        let fresh = !me.data.join("PG_VERSION").is_file();
        if fresh {
            me.run_bin(
                "initdb",
                &[
                    "-D",
                    path_str(&me.data),
                    "-A",
                    "trust",
                    "-U",
                    "postgres",
                    "-E",
                    "UTF8",
                    "--no-sync",
                ],
            )
            .map_err(|e| failed("initdb", &e))?;
        }
        let socket_dir = me.root.display().to_string();
        let opts = format!(
            "-p {port} -h 127.0.0.1 -k {socket_dir} -F -c fsync=off -c full_page_writes=off"
        );
        let log = me.root.join("server.log");
        me.run_bin(
            "pg_ctl",
            &[
                "start",
                "-w",
                "-D",
                path_str(&me.data),
                "-l",
                path_str(&log),
                "-o",
                &opts,
            ],
        )
        .map_err(|e| {
            let tail = std::fs::read_to_string(&log).unwrap_or_default();
            failed("pg_ctl start", &format!("{e}\n{tail}"))
        })?;
        if fresh {
            let port = port.to_string();
            me.run_bin(
                "createdb",
                &["-h", "127.0.0.1", "-p", &port, "-U", "postgres", "camloop"],
            )
            .map_err(|e| failed("createdb", &e))?;
        }
        Ok(me)
    }

    /// Stops the server now (`pg_ctl stop -m immediate`), as a crash or a pulled cable
    /// would take it away; dropping it later is harmless.
    pub fn stop(&self) {
        let _ = self.run_bin(
            "pg_ctl",
            &["stop", "-m", "immediate", "-w", "-D", path_str(&self.data)],
        );
    }

    pub fn url(&self) -> String {
        format!("postgres://postgres@127.0.0.1:{}/camloop", self.port)
    }

    fn run_bin(&self, name: &str, args: &[&str]) -> Result<(), String> {
        let exe = self.bin.join(name);
        let mut cmd = if self.as_postgres {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(&exe);
            c
        } else {
            Command::new(&exe)
        };
        cmd.args(args);
        run(&mut cmd)
    }
}

fn path_str(p: &Path) -> &str {
    p.to_str().expect("tempdir paths are UTF-8")
}

fn run(cmd: &mut Command) -> Result<(), String> {
    let out = cmd
        .output()
        .map_err(|e| format!("cannot run {cmd:?}: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "{cmd:?} exited with {}: {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        ))
    }
}

impl Drop for TempPostgres {
    fn drop(&mut self) {
        let _ = self.run_bin(
            "pg_ctl",
            &["stop", "-m", "immediate", "-w", "-D", path_str(&self.data)],
        );
    }
}
