//! Child processes a test starts (the real `camloop` binary, a broker, a driver): each is
//! held by a guard that kills and reaps it when dropped, so a test that fails or panics
//! half-way never leaves processes running behind it.

#![allow(dead_code)]

use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// Polls `ready` every 100 ms until it holds; a failure naming `what` after `bound`.
pub fn wait_for(what: &str, bound: Duration, mut ready: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ready() {
        assert!(start.elapsed() < bound, "{what} not within {bound:?}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A free TCP port on localhost, for a process the test starts to listen on.
pub fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("a free port");
    l.local_addr().expect("its address").port()
}

/// The service as a user starts it: `camloop run --config camloop.toml` in `dir`, its output
/// discarded (a caller may set its own, or an environment, before spawning it).
pub fn camloop_run(dir: &Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_camloop"));
    command
        .args(["run", "--config", "camloop.toml"])
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    command
}

/// A running child, killed (SIGKILL) and reaped when dropped unless it has been waited for.
#[derive(Debug)]
pub struct KillOnDrop(Child);

impl KillOnDrop {
    /// Starts `command` under the guard.
    pub fn spawn(command: &mut Command) -> std::io::Result<Self> {
        command.spawn().map(Self)
    }

    /// Sends `signal` (`-STOP`, `-CONT`, `-TERM`, …) to the child, through `kill(1)`.
    pub fn signal(&self, signal: &str) {
        let status = Command::new("kill")
            .args([signal, &self.0.id().to_string()])
            .status();
        assert!(
            status.is_ok_and(|s| s.success()),
            "kill {signal} {} failed",
            self.0.id()
        );
    }
}

impl KillOnDrop {
    /// Waits for the child to exit, polling every `poll` (the exit is the condition); a
    /// failure saying `what` did not finish when it runs past `bound`.
    pub fn exit_within(&mut self, bound: Duration, poll: Duration, what: &str) -> ExitStatus {
        let started = Instant::now();
        loop {
            if let Some(status) = self.0.try_wait().expect("the child's status") {
                return status;
            }
            assert!(
                started.elapsed() < bound,
                "{what}: still running after {bound:?}"
            );
            std::thread::sleep(poll);
        }
    }
}

/// What a checking program printed, and how it ended.
pub struct Finished {
    /// Its exit status; `None` when it ran past its bound and was killed.
    pub status: Option<ExitStatus>,
    /// Its standard output.
    pub stdout: String,
    /// Its standard error.
    pub stderr: String,
}

impl Finished {
    /// Its exit was a success.
    pub fn success(&self) -> bool {
        self.status.is_some_and(|s| s.success())
    }

    /// Both outputs, with how it ended, for a failure message.
    pub fn report(&self) -> String {
        let ended = match self.status {
            Some(status) => format!("{status}"),
            None => "ran past its bound and was killed".to_owned(),
        };
        format!(
            "{ended}\n--- stdout\n{}\n--- stderr\n{}",
            self.stdout, self.stderr
        )
    }
}

/// Runs `command` to its end, bounded by `bound` (polling every 200 ms: the exit is the
/// condition). Its output goes to files, not pipes, so a chatty program never blocks on a
/// full pipe, and what it printed is kept when it is killed at the bound.
pub fn run_to_end(command: &mut Command, bound: Duration) -> Finished {
    let out = tempfile::NamedTempFile::new().expect("a file for stdout");
    let err = tempfile::NamedTempFile::new().expect("a file for stderr");
    command
        .stdout(out.reopen().expect("stdout's file"))
        .stderr(err.reopen().expect("stderr's file"));
    let mut child = KillOnDrop::spawn(command).expect("the program starts");
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("the child's status") {
            break Some(status);
        }
        if started.elapsed() > bound {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let read = |f: &tempfile::NamedTempFile| {
        String::from_utf8_lossy(&std::fs::read(f.path()).unwrap_or_default()).into_owned()
    };
    Finished {
        status,
        stdout: read(&out),
        stderr: read(&err),
    }
}

impl std::ops::Deref for KillOnDrop {
    type Target = Child;
    fn deref(&self) -> &Child {
        &self.0
    }
}

impl std::ops::DerefMut for KillOnDrop {
    fn deref_mut(&mut self) -> &mut Child {
        &mut self.0
    }
}

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        // Already reaped: std remembers its status and sends nothing (the pid may be reused).
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}
