//! The cluster task: every quarter lease, renew what this instance holds, stop what it lost,
//! shed what is beyond its fair share and take free machines (see [`crate::cluster`]). A
//! machine is started only after its fence is raised to the lease's epoch, and released
//! only after its loop has stopped.

use super::runner::{Opened, Runner};
use crate::cluster::{Leases, fair_share, plan};
use crate::share::{Fence, StateError};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;
use tokio::sync::watch;
use tokio::time::Instant;
use tracing::{error, info, warn};

/// How soon an instance below its share looks again for machines being handed over.
const HUNGRY_LOOK: Duration = Duration::from_millis(250);

/// A machine this instance holds.
struct Held {
    epoch: u64,
    /// Stop it by then if the lease could not be renewed: before the database lets another
    /// instance take it.
    deadline: Instant,
}

pub(super) struct ClusterTask {
    pub(super) leases: Leases,
    pub(super) lease: Duration,
    pub(super) machines_dir: PathBuf,
    pub(super) runner: Runner,
}

impl ClusterTask {
    /// Runs until shutdown; then stops every machine, releases its leases and leaves.
    pub(super) async fn run(mut self, mut shutdown: watch::Receiver<bool>) {
        let mut held: BTreeMap<String, Held> = BTreeMap::new();
        // The first round only says this instance is here, so instances started together
        // count each other before anyone takes machines.
        if let Err(e) = self.leases.heartbeat().await {
            warn!(error = %e, "cluster: first heartbeat failed");
        }
        let mut said = String::new();
        let mut hungry = false;
        loop {
            // Below its share while others hand machines over: look again soon, so a machine
            // released between parts is running again within a fraction of a second.
            let wait = match hungry {
                true => (self.lease / 4).min(HUNGRY_LOOK),
                false => self.lease / 4,
            };
            tokio::select! {
                _ = tokio::time::sleep(wait) => {}
                _ = shutdown.changed() => break,
            }
            hungry = match self.round(&mut held).await {
                Ok(hungry) => {
                    said.clear();
                    hungry
                }
                Err(e) => {
                    let text = e.to_string();
                    if text != said {
                        error!(error = %text, "cluster: lease database unavailable; machines held stop before their leases run out");
                        said = text;
                    }
                    false
                }
            };
            self.stop_overdue(&mut held).await;
        }
        self.runner.stop_all().await;
        for (machine, h) in &held {
            if let Err(e) = self.leases.release(machine, h.epoch).await {
                warn!(machine = %machine, error = %e, "cluster: lease not released (it expires)");
            }
        }
        let _ = self.leases.leave().await;
        info!(instance = %self.leases.instance(), "cluster: left");
    }

    /// One round: renew, heartbeat, shed, take. Returns whether this instance is still below
    /// its fair share while machines are free or others hold more than theirs.
    async fn round(
        &mut self,
        held: &mut BTreeMap<String, Held>,
    ) -> Result<bool, crate::cluster::LeaseError> {
        let asked = Instant::now();
        self.renew(held).await?;
        let live = self.leases.heartbeat().await?;
        let all = self.runner.names();
        let rows = self.leases.all().await?;
        let free: Vec<String> = all
            .iter()
            .filter(|m| !rows.iter().any(|r| r.machine == **m && r.live))
            .cloned()
            .collect();
        let mine: Vec<String> = held.keys().cloned().collect();
        let p = plan(self.leases.instance(), &all, &mine, &free, live);
        for m in p.shed {
            info!(machine = %m, live_instances = live, "cluster: handing the machine over (rebalance)");
            self.runner.stop(&m).await;
            if let Some(h) = held.remove(&m) {
                self.leases.release(&m, h.epoch).await?;
            }
        }
        self.take(p.take, held).await?;
        if asked.elapsed() > self.lease / 4 {
            // Taking machines took a while: renew now rather than a quarter lease later.
            self.renew(held).await?;
        }
        let me = self.leases.instance();
        let mut others: BTreeMap<&str, usize> = BTreeMap::new();
        for r in rows.iter().filter(|r| r.live && r.owner != me) {
            *others.entry(r.owner.as_str()).or_default() += 1;
        }
        let fair = fair_share(all.len(), live);
        let unowned = all.len() > held.len() + others.values().sum::<usize>();
        let overfull = others.values().any(|&n| n > fair);
        Ok(held.len() < fair && (unowned || overfull))
    }

    /// Renews every lease held; stops the machines whose lease another instance has now.
    async fn renew(
        &mut self,
        held: &mut BTreeMap<String, Held>,
    ) -> Result<(), crate::cluster::LeaseError> {
        let asked = Instant::now();
        let mine: Vec<(String, u64)> = held.iter().map(|(m, h)| (m.clone(), h.epoch)).collect();
        let answer = self.leases.renew(&mine).await?;
        for m in &answer.leftovers {
            warn!(machine = %m, "cluster: a lease under this instance's name that runs nowhere (an earlier process, a stop while the database was away) released");
        }
        let renewed: BTreeMap<String, u64> = answer.renewed.into_iter().collect();
        let lost: Vec<String> = held
            .iter()
            .filter(|(m, h)| renewed.get(*m) != Some(&h.epoch))
            .map(|(m, _)| m.clone())
            .collect();
        self.stop_held(
            held,
            lost,
            "cluster: lease lost; machine stopped on this instance",
        )
        .await;
        for h in held.values_mut() {
            h.deadline = asked + self.lease / 2;
        }
        Ok(())
    }

    /// Takes the planned machines: every lease first, then the fences are claimed and the
    /// loops opened all at once (a dead instance's machines start together, not in turn).
    async fn take(
        &mut self,
        machines: Vec<String>,
        held: &mut BTreeMap<String, Held>,
    ) -> Result<(), crate::cluster::LeaseError> {
        let mut won = Vec::new();
        for m in machines {
            if let Some(epoch) = self.leases.acquire(&m).await? {
                won.push((m, epoch, Instant::now()));
            }
        }
        let opening = won.iter().map(|(m, epoch, _)| self.open(m, *epoch));
        let opened = futures_util::future::join_all(opening).await;
        for ((m, lease_epoch, acquired), result) in won.into_iter().zip(opened) {
            let launched = result.and_then(|(epoch, o)| self.runner.launch(o).map(|_| epoch));
            match launched {
                Ok(epoch) => {
                    info!(machine = %m, epoch, "cluster: machine taken");
                    let deadline = acquired + self.lease / 2;
                    held.insert(m, Held { epoch, deadline });
                }
                Err(e) => {
                    let busy = matches!(e.downcast_ref(), Some(StateError::FenceBusy { .. }));
                    if busy {
                        // Its last owner is paused mid-write: tried again at the next round.
                        warn!(machine = %m, error = format!("{e:#}"), "cluster: machine not started yet; lease released");
                    } else {
                        error!(machine = %m, error = format!("{e:#}"), "cluster: machine not started; lease released");
                    }
                    self.leases.release(&m, lease_epoch).await?;
                }
            }
        }
        Ok(())
    }

    /// Raises the machine's fence to the lease's epoch (or past a higher one found there,
    /// raising the lease to match) and opens its loop. Returns the epoch it runs under.
    async fn open(&self, machine: &str, epoch: u64) -> anyhow::Result<(u64, Opened)> {
        let dir = self.machines_dir.join(machine);
        let instance = self.leases.instance().to_string();
        // Never longer than an eighth of a lease: the round must go on renewing.
        let wait = self.lease / 8;
        let claim = |epoch: u64| {
            let dir = dir.clone();
            let instance = instance.clone();
            tokio::task::spawn_blocking(move || Fence::claim(&dir, epoch, &instance, wait))
        };
        let fence = match claim(epoch).await? {
            Ok(f) => f,
            Err(StateError::Fenced { current, .. }) => {
                // The lease table was made again (a new database): continue above the fence.
                warn!(machine = %machine, lease_epoch = epoch, fence_epoch = current, "cluster: the machine's fence is ahead of its lease; lease raised past it");
                let raised = self
                    .leases
                    .raise_epoch(machine, epoch, current + 1)
                    .await?
                    .ok_or_else(|| anyhow::anyhow!("lease lost while raising its epoch"))?;
                claim(raised).await??
            }
            Err(e) => return Err(e.into()),
        };
        let epoch = fence.epoch();
        Ok((epoch, self.runner.open(machine, Some(fence)).await?))
    }

    /// Stops machines whose lease could not be renewed in time.
    async fn stop_overdue(&mut self, held: &mut BTreeMap<String, Held>) {
        let now = Instant::now();
        let overdue: Vec<String> = held
            .iter()
            .filter(|(_, h)| h.deadline <= now)
            .map(|(m, _)| m.clone())
            .collect();
        let why = "cluster: lease not renewed in time; machine stopped before another instance may take it";
        self.stop_held(held, overdue, why).await;
    }

    /// Stops `machines` on this instance (after the part in hand) and forgets them, saying
    /// `why` for each.
    async fn stop_held(
        &mut self,
        held: &mut BTreeMap<String, Held>,
        machines: Vec<String>,
        why: &str,
    ) {
        for m in machines {
            error!(machine = %m, "{why}");
            self.runner.stop(&m).await;
            held.remove(&m);
        }
    }
}
