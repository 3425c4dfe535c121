//! Child processes a test starts (the real `camloop` binary, a broker, a driver): each is
//! held by a guard that kills and reaps it when dropped, so a test that fails or panics
//! half-way never leaves processes running behind it.

#![allow(dead_code)]

use std::process::{Child, Command};

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
