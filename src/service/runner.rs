//! Starting and stopping machines: every configured machine at start for one instance; in a
//! cluster, the machines this instance holds a lease on, as leases come and go. A machine
//! stops as at shutdown: it finishes the part in hand, retries what waits, and its gauge
//! source stops (a drop folder's unsettled files stay for the next owner).

use super::machine::{self, MachineLoop, SourceEvent};
use super::{Shared, http, machine_task};
use crate::config::{CheckedMachine, Config};
use anyhow::Context;
use std::collections::HashMap;
use std::sync::Arc;
use tokio::sync::{mpsc, oneshot, watch};
use tracing::info;

/// The HTTP side's way to each running machine.
pub type CommandRoutes = Arc<std::sync::RwLock<HashMap<String, mpsc::Sender<http::Command>>>>;

/// One machine's running tasks.
struct RunningMachine {
    stop: Arc<watch::Sender<bool>>,
    task: tokio::task::JoinHandle<()>,
}

/// A machine whose loop is open, not yet running.
pub(super) struct Opened {
    name: String,
    machine: MachineLoop,
}

/// The machines of this instance.
pub(super) struct Runner {
    config: Config,
    checked: HashMap<String, CheckedMachine>,
    shared: Shared,
    commands: CommandRoutes,
    running: HashMap<String, RunningMachine>,
}

impl Runner {
    pub(super) fn new(
        config: Config,
        checked: Vec<CheckedMachine>,
        shared: Shared,
        commands: CommandRoutes,
    ) -> Self {
        let checked = checked
            .into_iter()
            .map(|m| (m.name.to_string(), m))
            .collect();
        Self {
            config,
            checked,
            shared,
            commands,
            running: HashMap::new(),
        }
    }

    /// Every configured machine's name.
    pub(super) fn names(&self) -> Vec<String> {
        let mut names: Vec<String> = self.checked.keys().cloned().collect();
        names.sort();
        names
    }

    /// Starts machine `name` (fenced with `fence` in a cluster). The receiver says when its
    /// gauge source ended (a simulated run with a part count).
    pub(super) async fn start(
        &mut self,
        name: &str,
        fence: Option<crate::share::Fence>,
    ) -> anyhow::Result<oneshot::Receiver<()>> {
        let opened = self.open(name, fence).await?;
        self.launch(opened)
    }

    /// Opens machine `name`'s loop (journal, share state, memory): the slow part of a start,
    /// which several machines may do at once.
    pub(super) async fn open(
        &self,
        name: &str,
        fence: Option<crate::share::Fence>,
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
            name.to_string(),
            checked.setups.clone(),
            paths,
            fence,
            self.shared.store.clone(),
            self.shared.metrics.clone(),
        )
        .await?;
        machine.set_plant_events(self.shared.plant_events.clone());
        Ok(Opened {
            name: name.to_string(),
            machine,
        })
    }

    /// Starts an opened machine's gauge source and loop.
    pub(super) fn launch(&mut self, opened: Opened) -> anyhow::Result<oneshot::Receiver<()>> {
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
        let (command_tx, command_rx) = mpsc::channel::<http::Command>(4);
        super::sources::spawn(
            &self.config,
            section,
            &machine,
            checked.sim_c_speed_explicit,
            tx,
            self.shared.parts,
            stopped.clone(),
        )?;
        let (done_tx, done_rx) = oneshot::channel();
        let task = tokio::spawn(machine_task(machine, rx, command_rx, done_tx, stopped));
        if let Ok(mut routes) = self.commands.write() {
            routes.insert(name.clone(), command_tx);
        }
        self.running.insert(name, RunningMachine { stop, task });
        Ok(done_rx)
    }

    fn section(&self, name: &str) -> anyhow::Result<&crate::config::MachineSection> {
        self.config
            .machines
            .iter()
            .find(|c| c.name == name)
            .context("a checked machine is in the config")
    }

    /// Stops machine `name` after the part in hand; returns once it has stopped.
    pub(super) async fn stop(&mut self, name: &str) {
        if let Ok(mut routes) = self.commands.write() {
            routes.remove(name);
        }
        if let Some(m) = self.running.remove(name) {
            let _ = m.stop.send(true);
            let _ = m.task.await;
            info!(machine = %name, "machine stopped on this instance");
        }
    }

    /// Stops every machine.
    pub(super) async fn stop_all(&mut self) {
        for name in self.names() {
            self.stop(&name).await;
        }
    }
}
