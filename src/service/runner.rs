//! Starting and stopping machines: every configured machine at start for one instance; in a
//! cluster, the machines this instance holds a lease on, as leases come and go. A machine
//! stops as at shutdown: it finishes the part in hand, retries what waits, and its gauge
//! source stops (a drop folder's unsettled files stay for the next owner).
//!
//! The runner is shared (`&self` everywhere): in a cluster several machines open and stop at
//! once, beside the lease keeper, and none waits for another.

use super::command::{CommandRoutes, Mailbox};
use super::machine::{self, MachineLoop, SourceEvent};
use super::{Shared, machine_task};
use crate::config::{CheckedMachine, Config};
use crate::names::MachineName;
use anyhow::Context;
use std::collections::HashMap;
use std::sync::Arc;
use tokio::sync::{mpsc, oneshot, watch};
use tracing::info;

/// One machine's running tasks.
struct RunningMachine {
    stop: Arc<watch::Sender<bool>>,
    task: tokio::task::JoinHandle<()>,
}

/// A machine whose loop is open, not yet running.
pub(super) struct Opened {
    name: MachineName,
    machine: MachineLoop,
}

/// The machines of this instance.
pub(super) struct Runner {
    config: Config,
    checked: HashMap<MachineName, CheckedMachine>,
    shared: Shared,
    commands: CommandRoutes,
    running: std::sync::Mutex<HashMap<MachineName, RunningMachine>>,
}

impl Runner {
    pub(super) fn new(
        config: Config,
        checked: Vec<CheckedMachine>,
        shared: Shared,
        commands: CommandRoutes,
    ) -> Self {
        let checked = checked.into_iter().map(|m| (m.name.clone(), m)).collect();
        Self {
            config,
            checked,
            shared,
            commands,
            running: std::sync::Mutex::default(),
        }
    }

    /// Every configured machine's name.
    pub(super) fn names(&self) -> Vec<MachineName> {
        let mut names: Vec<MachineName> = self.checked.keys().cloned().collect();
        names.sort();
        names
    }

    /// Opens machine `name`'s loop (journal, share state, memory): the slow part of a start,
    /// which several machines may do at once.
    pub(super) async fn open(
        &self,
        name: &str,
        fence: Option<crate::share::Fence>,
        opening: &machine::Opening,
    ) -> anyhow::Result<Opened> {
        let checked = self
            .checked
            .get(name)
            .with_context(|| format!("machine {name} is not configured"))?;
        let section = self.section(name)?;
        let paths = machine::MachinePaths {
            share_dir: self.config.resolve(&section.share),
            state_dir: self.config.machines_dir().join(name),
        };
        let mut machine = MachineLoop::start_owned(
            checked.name.clone(),
            checked.setups.clone(),
            paths,
            fence,
            opening,
            self.shared.store.clone(),
            self.shared.metrics.clone(),
        )
        .await?;
        machine.set_plant_events(self.shared.plant_events.clone());
        Ok(Opened {
            name: checked.name.clone(),
            machine,
        })
    }

    /// How every machine of this instance opens at its start: the store's learning states
    /// listed once, and the opening's records left in the journals for each machine's first
    /// retry. Only for a start where this instance alone writes these machines (not in a
    /// cluster, whose machines open as leases come, beside other writers).
    pub(super) async fn plant_opening(&self) -> machine::Opening {
        let store = self.shared.store.read().await.clone();
        let known_states = match store {
            Some(store) => match store.learning_state_keys().await {
                Ok(keys) => Some(Arc::new(keys.into_iter().collect())),
                // Each feature asks, and says what went wrong.
                Err(_) => None,
            },
            None => None,
        };
        machine::Opening {
            known_states,
            defer_store: true,
        }
    }

    /// Starts an opened machine's gauge source and loop.
    pub(super) fn launch(&self, opened: Opened) -> anyhow::Result<oneshot::Receiver<()>> {
        let Opened { name, machine } = opened;
        let section = self.section(&name)?;
        let checked = self
            .checked
            .get(&name)
            .context("an opened machine is configured")?;
        let (stop, stopped) = watch::channel(false);
        let stop = Arc::new(stop);
        let mut global = self.shared.shutdown.clone();
        let forward = stop.clone();
        // The service's shutdown stops every machine too.
        tokio::spawn(async move {
            if global.changed().await.is_ok() {
                let _ = forward.send(true);
            }
        });
        let (tx, rx) = mpsc::channel::<SourceEvent>(16);
        let (command_tx, command_rx): (Mailbox, _) = mpsc::channel(4);
        let intake = super::sources::Intake::new(tx, name.clone(), self.shared.metrics.clone());
        super::sources::spawn(
            &self.config,
            section,
            &machine,
            checked.sim_c_speed_explicit,
            intake,
            self.shared.parts,
            stopped.clone(),
        )?;
        let (done_tx, done_rx) = oneshot::channel();
        let metrics = self.shared.metrics.clone();
        let task = tokio::spawn(async move {
            let name = machine.name.clone();
            machine_task(machine, rx, command_rx, done_tx, stopped, &metrics).await;
            // What the loop did not take stays with its source.
            metrics.backlog.forget(&name);
        });
        if let Ok(mut routes) = self.commands.write() {
            routes.insert(name.clone(), command_tx);
        }
        self.running_map()
            .insert(name, RunningMachine { stop, task });
        Ok(done_rx)
    }

    fn section(&self, name: &str) -> anyhow::Result<&crate::config::MachineSection> {
        self.config
            .machines
            .iter()
            .find(|c| c.name == name)
            .context("a checked machine is in the config")
    }

    fn running_map(&self) -> std::sync::MutexGuard<'_, HashMap<MachineName, RunningMachine>> {
        // A panic elsewhere cannot leave the map half-changed: every change is one call.
        self.running.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Tells machine `name` to stop after the part in hand and returns at once with its
    /// task, to be awaited by whoever wants to know it has stopped (`None`: not running).
    pub(super) fn signal_stop(&self, name: &str) -> Option<tokio::task::JoinHandle<()>> {
        if let Ok(mut routes) = self.commands.write() {
            routes.remove(name);
        }
        let m = self.running_map().remove(name)?;
        let _ = m.stop.send(true);
        Some(m.task)
    }

    /// Stops machine `name` after the part in hand; returns once it has stopped.
    pub(super) async fn stop(&self, name: &str) {
        if let Some(task) = self.signal_stop(name) {
            let _ = task.await;
            info!(machine = %name, "machine stopped on this instance");
        }
    }

    /// Stops every machine, all at once.
    pub(super) async fn stop_all(&self) {
        let names = self.names();
        futures_util::future::join_all(names.iter().map(|n| self.stop(n))).await;
    }
}
