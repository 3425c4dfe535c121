//! The lease keeper: renewal and heartbeat on a thread and a runtime of their own, on their
//! own timer (as Kafka's consumers moved the heartbeat off the poll loop, KIP-62). Opening a
//! machine, stopping one after the part in hand, or any CPU-bound work of the machine loops
//! on the service's runtime can never delay a renewal: the leases this instance holds stay
//! live for exactly as long as this thread can reach the database.
//!
//! What it shares with the cluster task is [`Holdings`]: the leases held, each with its
//! epoch, its phase and the time by which it must be renewed. The keeper renews every one
//! of them (opening, waiting for a busy fence, running, stopping) every quarter lease; one
//! the database no longer gives to this instance, or one not renewed within half a lease,
//! is dropped here and its machine told to stop at once, before another instance may take
//! it.

use super::metrics::Metrics;
use super::runner::Runner;
use crate::cluster::{LeaseError, Leases};
use crate::names::MachineName;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tokio::sync::watch;
use tracing::{error, info, warn};

/// Where a held machine is in its life on this instance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Phase {
    /// Its fence is being claimed and its loop opened.
    Opening,
    /// Its fence stayed locked (the last owner is mid-write or paused): the lease is kept
    /// and the opening tried again at the next round.
    FenceBusy,
    Running,
    /// Handed over: stopping after the part in hand, then released.
    Stopping,
}

/// One lease this instance holds.
#[derive(Debug, Clone)]
pub(super) struct Holding {
    pub(super) epoch: crate::cluster::Epoch,
    /// Stopped by then unless renewed: half a lease after the last renewal was asked for,
    /// so before the database lets another instance take it.
    pub(super) deadline: Instant,
    pub(super) phase: Phase,
}

/// The leases of this instance, shared by the keeper and the cluster task. The lock is
/// never held across an `await`.
#[derive(Debug, Default)]
pub(super) struct Holdings {
    pub(super) held: BTreeMap<MachineName, Holding>,
    /// The service is stopping: nothing more is opened.
    pub(super) closing: bool,
}

pub(super) type SharedHoldings = Arc<Mutex<Holdings>>;

pub(super) fn lock(holdings: &SharedHoldings) -> MutexGuard<'_, Holdings> {
    // Every change under the lock is a few map operations: a panic cannot leave it torn.
    holdings.lock().unwrap_or_else(|p| p.into_inner())
}

/// What the keeper needs; it connects to the database itself, on its own runtime.
pub(super) struct Keeper {
    pub(super) url: String,
    pub(super) instance: String,
    pub(super) lease: Duration,
    pub(super) holdings: SharedHoldings,
    pub(super) runner: Arc<Runner>,
    pub(super) metrics: Arc<Metrics>,
    /// The service's runtime, where a stopped machine's task is awaited.
    pub(super) service: tokio::runtime::Handle,
}

/// The running keeper; [`KeeperHandle::stop`] ends it.
pub(super) struct KeeperHandle {
    stop: watch::Sender<bool>,
    thread: std::thread::JoinHandle<()>,
}

impl KeeperHandle {
    /// Ends the keeper (after the renewal in hand) and waits for its thread.
    pub(super) async fn stop(self) {
        let _ = self.stop.send(true);
        let thread = self.thread;
        let _ = tokio::task::spawn_blocking(move || thread.join()).await;
    }
}

impl Keeper {
    /// Starts the keeper's thread.
    pub(super) fn spawn(self) -> std::io::Result<KeeperHandle> {
        let (stop, stopped) = watch::channel(false);
        let thread = std::thread::Builder::new()
            .name("camloop-leases".into())
            .spawn(move || {
                let runtime = tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build();
                match runtime {
                    Ok(rt) => rt.block_on(self.run(stopped)),
                    Err(e) => error!(error = %e, "cluster: the lease keeper cannot start its runtime; no lease is renewed"),
                }
            })?;
        Ok(KeeperHandle { stop, thread })
    }

    async fn run(self, mut stopped: watch::Receiver<bool>) {
        let Some(leases) = self.connect(&mut stopped).await else {
            return;
        };
        let mut tick = tokio::time::interval(self.lease / 4);
        // After a pause (a stopped process) one renewal, not one per tick missed.
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut said = String::new();
        loop {
            tokio::select! {
                _ = tick.tick() => {}
                _ = stopped.changed() => break,
            }
            // No statement may hold the keeper longer than a quarter lease.
            let outcome = tokio::time::timeout(self.lease / 4, self.renew(&leases)).await;
            match outcome {
                Ok(Ok(())) => said.clear(),
                Ok(Err(e)) => self.say_once(&mut said, e.to_string()),
                Err(_) => self.say_once(&mut said, "no answer within a quarter lease".into()),
            }
            self.stop_overdue();
        }
    }

    /// The keeper's own connection, tried every quarter lease until it works.
    async fn connect(&self, stopped: &mut watch::Receiver<bool>) -> Option<Leases> {
        let mut said = String::new();
        loop {
            match Leases::connect_keeper(&self.url, &self.instance, self.lease).await {
                Ok(l) => return Some(l),
                Err(e) => self.say_once(&mut said, e.to_string()),
            }
            tokio::select! {
                _ = tokio::time::sleep(self.lease / 4) => {}
                _ = stopped.changed() => return None,
            }
        }
    }

    fn say_once(&self, said: &mut String, text: String) {
        if text != *said {
            error!(error = %text, "cluster: lease database unavailable; machines held stop before their leases run out");
            *said = text;
        }
    }

    /// Renews every lease held and says this instance is alive. A lease the database did
    /// not renew under the epoch it was asked for is lost: its machine stops.
    async fn renew(&self, leases: &Leases) -> Result<(), LeaseError> {
        let asked = Instant::now();
        let mine: Vec<(MachineName, crate::cluster::Epoch)> = {
            let h = lock(&self.holdings);
            h.held.iter().map(|(m, x)| (m.clone(), x.epoch)).collect()
        };
        let answer = leases.renew(&mine).await?;
        for m in &answer.leftovers {
            warn!(machine = %m, "cluster: a lease under this instance's name that runs nowhere (an earlier process, a stop while the database was away) released");
        }
        let renewed: BTreeMap<MachineName, crate::cluster::Epoch> =
            answer.renewed.into_iter().collect();
        let mut lost = Vec::new();
        {
            let mut h = lock(&self.holdings);
            for (m, epoch) in &mine {
                match h.held.get_mut(m) {
                    // Taken again or raised since it was asked for: the next round renews it.
                    Some(x) if x.epoch != *epoch => {}
                    Some(x) if renewed.get(m) == Some(epoch) => x.deadline = asked + self.lease / 2,
                    Some(_) => {
                        h.held.remove(m);
                        lost.push(m.clone());
                    }
                    None => {}
                }
            }
        }
        for m in lost {
            self.lose(&m, "cluster: lease lost; machine stopped on this instance");
        }
        leases.heartbeat().await?;
        Ok(())
    }

    /// Stops the machines whose lease could not be renewed in time.
    fn stop_overdue(&self) {
        let now = Instant::now();
        let overdue: Vec<MachineName> = {
            let mut h = lock(&self.holdings);
            let late: Vec<MachineName> = h
                .held
                .iter()
                .filter(|(_, x)| x.deadline <= now)
                .map(|(m, _)| m.clone())
                .collect();
            for m in &late {
                h.held.remove(m);
            }
            late
        };
        for m in overdue {
            self.lose(&m, "cluster: lease not renewed in time; machine stopped before another instance may take it");
        }
    }

    /// A lease is gone: its machine is told to stop now, and its task awaited on the
    /// service's runtime (the keeper never waits for a part in hand).
    fn lose(&self, machine: &MachineName, why: &str) {
        error!(machine = %machine, "{why}");
        self.metrics.update(machine, |m| m.leases_lost_total += 1);
        if let Some(task) = self.runner.signal_stop(machine) {
            let name = machine.to_string();
            self.service.spawn(async move {
                let _ = task.await;
                info!(machine = %name, "machine stopped on this instance");
            });
        }
    }
}
