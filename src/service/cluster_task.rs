//! The cluster task: every half second (a quarter lease at most) it follows the plan (see
//! [`crate::cluster`]): it hands over what is beyond this instance's fair share and takes
//! free machines. Renewal is not its work: the [`lease_keeper`](super::lease_keeper) renews
//! every lease held on a thread of its own, so opening and stopping machines (a few at a
//! time, beside each other) can take as long as they take.
//!
//! A machine is started only after its fence is raised to the lease's epoch, and released
//! only after its loop has stopped. A lease won is held (and renewed) from the moment it is
//! won: while the machine opens, and while its fence is busy under a paused last owner, in
//! which case the opening is tried again at the next round without letting the lease go.

use super::lease_keeper::{self, Holding, Keeper, Phase, SharedHoldings};
use super::metrics::Metrics;
use super::runner::{Opened, Runner};
use crate::cluster::{Epoch, LeaseError, Leases, fair_share, plan};
use crate::names::MachineName;
use crate::share::{Fence, StateError};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::{Semaphore, watch};
use tokio::task::JoinSet;
use tracing::{error, info, warn};

/// How soon an instance below its share looks again for machines being handed over.
const HUNGRY_LOOK: Duration = Duration::from_millis(250);

/// The longest between two rounds (a quarter lease when that is shorter). A round is two
/// small queries; every half second an instance notices one that joined, and hands over
/// its machines, without waiting up to a quarter lease (1.5 s at the default).
const ROUND_EVERY: Duration = Duration::from_millis(500);

/// Machines opened or stopped at once: enough that a dead instance's machines start
/// together, few enough that 30 openings do not crowd out the running machines' parts.
const AT_ONCE: usize = 8;

/// Why a machine won could not be opened.
#[derive(Debug, thiserror::Error)]
enum OpenError {
    #[error(transparent)]
    Fence(#[from] StateError),
    #[error(transparent)]
    Lease(#[from] LeaseError),
    #[error("the lease was lost while its epoch was raised")]
    LostWhileRaising,
    #[error("the fence claim did not finish: {0}")]
    Claim(#[from] tokio::task::JoinError),
    #[error("{0:#}")]
    Machine(anyhow::Error),
}

/// What the cluster task and the work it spawns share.
#[derive(Clone)]
struct Ctx {
    leases: Leases,
    lease: Duration,
    machines_dir: Arc<PathBuf>,
    runner: Arc<Runner>,
    holdings: SharedHoldings,
    gate: Arc<Semaphore>,
    metrics: Arc<Metrics>,
}

pub(super) struct ClusterTask {
    pub(super) leases: Leases,
    pub(super) url: String,
    pub(super) lease: Duration,
    pub(super) machines_dir: PathBuf,
    pub(super) runner: Runner,
    pub(super) metrics: Arc<Metrics>,
}

impl ClusterTask {
    /// Runs until shutdown; then stops every machine, releases its leases and leaves.
    pub(super) async fn run(self, mut shutdown: watch::Receiver<bool>) {
        let ctx = Ctx {
            leases: self.leases,
            lease: self.lease,
            machines_dir: Arc::new(self.machines_dir),
            runner: Arc::new(self.runner),
            holdings: SharedHoldings::default(),
            gate: Arc::new(Semaphore::new(AT_ONCE)),
            metrics: self.metrics,
        };
        let keeper = Keeper {
            url: self.url,
            instance: ctx.leases.instance().to_string(),
            lease: ctx.lease,
            holdings: ctx.holdings.clone(),
            runner: ctx.runner.clone(),
            metrics: ctx.metrics.clone(),
            service: tokio::runtime::Handle::current(),
        };
        // The keeper's first act is a heartbeat, so instances started together count each
        // other before the first round (a quarter lease later) takes machines.
        let keeper = match keeper.spawn() {
            Ok(k) => k,
            Err(e) => {
                error!(error = %e, "cluster: the lease keeper's thread cannot start; no machine is taken");
                return;
            }
        };
        let mut work = JoinSet::new();
        let mut said = String::new();
        let mut hungry = false;
        let mut first = true;
        loop {
            // Below its share while others hand machines over: look again soon, so a machine
            // released between parts is running again within a fraction of a second.
            let wait = match (first, hungry) {
                // Instances started together count each other before anyone takes machines.
                (true, _) => ctx.lease / 4,
                (false, true) => (ctx.lease / 4).min(HUNGRY_LOOK),
                (false, false) => (ctx.lease / 4).min(ROUND_EVERY),
            };
            first = false;
            tokio::select! {
                _ = tokio::time::sleep(wait) => {}
                _ = shutdown.changed() => break,
            }
            while work.try_join_next().is_some() {}
            hungry = match ctx.round(&mut work).await {
                Ok(hungry) => {
                    said.clear();
                    hungry
                }
                Err(e) => {
                    let text = e.to_string();
                    if text != said {
                        warn!(error = %text, "cluster: this round's plan could not be read; the leases held are still renewed");
                        said = text;
                    }
                    false
                }
            };
        }
        ctx.leave(work).await;
        keeper.stop().await;
        info!(instance = %ctx.leases.instance(), "cluster: left");
    }
}

impl Ctx {
    fn holdings(&self) -> std::sync::MutexGuard<'_, lease_keeper::Holdings> {
        lease_keeper::lock(&self.holdings)
    }

    /// One round: read the leases, hand over what is beyond the fair share, try again the
    /// machines whose fence was busy, take free ones. Returns whether this instance is still
    /// below its fair share while machines are free or others hold more than theirs.
    async fn round(&self, work: &mut JoinSet<()>) -> Result<bool, LeaseError> {
        let live = self.leases.live_instances().await?;
        let rows = self.leases.all().await?;
        let all = self.runner.names();
        // A set, not a scan of the rows per machine: at 1,500 machines that was 2.25 M name
        // comparisons a round, every half second, on each instance.
        let leased: std::collections::HashSet<&MachineName> =
            rows.iter().filter(|r| r.live).map(|r| &r.machine).collect();
        let free: Vec<MachineName> = all
            .iter()
            .filter(|m| !leased.contains(m))
            .cloned()
            .collect();
        let mine: Vec<MachineName> = self.holdings().held.keys().cloned().collect();
        let p = plan(self.leases.instance(), &all, &mine, &free, live);
        for m in p.shed {
            self.shed(m, live, work).await?;
        }
        self.retry_busy(work);
        for m in p.take {
            self.take(m, work).await?;
        }
        let me = self.leases.instance();
        let mut others: BTreeMap<&str, usize> = BTreeMap::new();
        for r in rows.iter().filter(|r| r.live && r.owner != me) {
            *others.entry(r.owner.as_str()).or_default() += 1;
        }
        let fair = fair_share(all.len(), live);
        let held = self.holdings().held.len();
        let unowned = all.len() > held + others.values().sum::<usize>();
        let overfull = others.values().any(|&n| n > fair);
        Ok(held < fair && (unowned || overfull))
    }

    /// Hands `machine` over: a running one stops after the part in hand (beside the rest of
    /// the round) and is released then; one never started is released now.
    async fn shed(
        &self,
        m: MachineName,
        live: usize,
        work: &mut JoinSet<()>,
    ) -> Result<(), LeaseError> {
        let unstarted = {
            let mut h = self.holdings();
            match h.held.get_mut(&m) {
                Some(x) if x.phase == Phase::Running => {
                    x.phase = Phase::Stopping;
                    None
                }
                Some(x) if x.phase == Phase::FenceBusy => {
                    let epoch = x.epoch;
                    h.held.remove(&m);
                    Some(epoch)
                }
                // Opening or already stopping: a later round decides.
                _ => return Ok(()),
            }
        };
        info!(machine = %m, live_instances = live, "cluster: handing the machine over (rebalance)");
        if let Some(epoch) = unstarted {
            return self.leases.release(&m, epoch).await;
        }
        let ctx = self.clone();
        work.spawn(async move {
            let _permit = ctx.gate.acquire().await;
            ctx.runner.stop(&m).await;
            let epoch = {
                let mut h = ctx.holdings();
                match h.held.get(&m) {
                    Some(x) if x.phase == Phase::Stopping => {
                        let epoch = x.epoch;
                        h.held.remove(&m);
                        Some(epoch)
                    }
                    _ => None,
                }
            };
            if let Some(epoch) = epoch
                && let Err(e) = ctx.leases.release(&m, epoch).await
            {
                warn!(machine = %m, error = %e, "cluster: lease not released (it expires)");
            }
        });
        Ok(())
    }

    /// Machines whose fence was busy at their opening: opened again, under the same lease.
    fn retry_busy(&self, work: &mut JoinSet<()>) {
        let busy: Vec<(MachineName, Epoch)> = {
            let mut h = self.holdings();
            h.held
                .iter_mut()
                .filter(|(_, x)| x.phase == Phase::FenceBusy)
                .map(|(m, x)| {
                    x.phase = Phase::Opening;
                    (m.clone(), x.epoch)
                })
                .collect()
        };
        for (m, epoch) in busy {
            self.spawn_open(m, epoch, work);
        }
    }

    /// Tries to win `machine`'s lease; once won it is held (and renewed by the keeper)
    /// while the machine opens beside the rest of the round.
    async fn take(&self, m: MachineName, work: &mut JoinSet<()>) -> Result<(), LeaseError> {
        let asked = Instant::now();
        if let Some(epoch) = self.leases.acquire(&m).await? {
            let deadline = asked + self.lease / 2;
            let phase = Phase::Opening;
            let holding = Holding {
                epoch,
                deadline,
                phase,
            };
            self.holdings().held.insert(m.clone(), holding);
            self.metrics.update(&m, |x| x.leases_taken_total += 1);
            self.spawn_open(m, epoch, work);
        }
        Ok(())
    }

    fn spawn_open(&self, m: MachineName, epoch: Epoch, work: &mut JoinSet<()>) {
        let ctx = self.clone();
        work.spawn(async move {
            let _permit = ctx.gate.acquire().await;
            let result = ctx.open(&m, epoch).await;
            ctx.opened(&m, result);
        });
    }

    /// Launches an opened machine if its lease is still held; otherwise keeps the lease for
    /// another try (busy fence) or gives it up (any other failure).
    fn opened(&self, m: &MachineName, result: Result<(Epoch, Opened), OpenError>) {
        let mut h = self.holdings();
        let closing = h.closing;
        let Some(x) = h.held.get_mut(m) else {
            warn!(machine = %m, "cluster: the lease ran out while the machine opened; not started");
            return;
        };
        // Launched under the holdings' lock: the keeper cannot drop the lease in between.
        let failed = match result {
            Ok((epoch, _)) if closing || x.epoch != epoch => return,
            Ok((epoch, opened)) => match self.runner.launch(opened) {
                Ok(_) => {
                    x.phase = Phase::Running;
                    info!(machine = %m, epoch = epoch.0, "cluster: machine taken");
                    return;
                }
                Err(e) => format!("{e:#}"),
            },
            Err(OpenError::Fence(e @ StateError::FenceBusy { .. })) => {
                // Its last owner is mid-write or paused: tried again at the next round, under
                // the same lease.
                warn!(machine = %m, error = %e, "cluster: machine not started yet; lease kept, opened again at the next round");
                x.phase = Phase::FenceBusy;
                return;
            }
            Err(e) => e.to_string(),
        };
        error!(machine = %m, error = %failed, "cluster: machine not started; lease released");
        let epoch = x.epoch;
        h.held.remove(m);
        drop(h);
        let leases = self.leases.clone();
        let m = m.clone();
        tokio::spawn(async move { leases.release(&m, epoch).await });
    }

    /// Raises the machine's fence to the lease's epoch (or past a higher one found there,
    /// raising the lease to match) and opens its loop. Returns the epoch it runs under.
    async fn open(
        &self,
        machine: &MachineName,
        epoch: Epoch,
    ) -> Result<(Epoch, Opened), OpenError> {
        let dir = self.machines_dir.join(machine);
        let instance = self.leases.instance().to_string();
        // A claim waits at most an eighth of a lease for a write under way; a busy fence is
        // tried again at the next round.
        let wait = self.lease / 8;
        let claim = |epoch: Epoch| {
            let dir = dir.clone();
            let instance = instance.clone();
            tokio::task::spawn_blocking(move || Fence::claim(&dir, epoch, &instance, wait))
        };
        let fence = match claim(epoch).await? {
            Ok(f) => f,
            Err(StateError::Fenced { current, .. }) => {
                // The lease table was made again (a new database): continue above the fence.
                warn!(machine = %machine, lease_epoch = epoch.0, fence_epoch = current.0, "cluster: the machine's fence is ahead of its lease; lease raised past it");
                let raised = self
                    .leases
                    .raise_epoch(machine, epoch, current.next())
                    .await?
                    .ok_or(OpenError::LostWhileRaising)?;
                if let Some(x) = self.holdings().held.get_mut(machine)
                    && x.epoch == epoch
                {
                    x.epoch = raised;
                }
                claim(raised).await??
            }
            Err(e) => return Err(e.into()),
        };
        let epoch = fence.epoch();
        let opened =
            super::offload::drive(self.runner.open(machine, Some(fence), &Default::default()))
                .await;
        Ok((epoch, opened.map_err(OpenError::Machine)?))
    }

    /// Shutdown: nothing more opens, the work under way ends, every machine stops after the
    /// part in hand (the keeper renews meanwhile), and every lease is released.
    async fn leave(&self, mut work: JoinSet<()>) {
        self.holdings().closing = true;
        while work.join_next().await.is_some() {}
        self.runner.stop_all().await;
        let held: Vec<(MachineName, Epoch)> = std::mem::take(&mut self.holdings().held)
            .into_iter()
            .map(|(m, x)| (m, x.epoch))
            .collect();
        for (machine, epoch) in held {
            if let Err(e) = self.leases.release(&machine, epoch).await {
                warn!(machine = %machine, error = %e, "cluster: lease not released (it expires)");
            }
        }
        let _ = self.leases.leave().await;
    }
}
