//! One machine's loop in the service. Each part takes one [`crate::core::turn`]: checks,
//! analysis, a learning step from the table that ground the part, the guarded next table;
//! the machine then records it through the journal and delivers the table to the share.
//!
//! - `ingest`: a measurement in (identity, repeats, the turn, its records);
//! - `delivery`: rendering with provenance, the push, retries, the version in force;
//! - `rollback`, `dressing`: the operator's and the wheel's events;
//! - `records`: the journal records and the reject folder;
//! - `memory`: what the loop remembers between parts.
//!
//! The version in force is the newest one the share confirmed. A step always starts from its
//! learning state: a table computed while the share refused it never becomes the base of the
//! next step, so an outage cannot wind the correction up.

mod delivery;
mod dressing;
mod ingest;
pub mod memory;
mod records;
mod rollback;

use super::journal::{EventKind, Journal, Pending};
use super::metrics::Metrics;
use crate::clock::{now_ms, now_ms_u64};
use crate::core::compensate::{self, LobeLoop};
use crate::core::turn::HoldReason;
use crate::recipe::FeatureSetup;
use crate::share::{RealFs, Share, ShareConfig};
use crate::store::{EventLevel, FeatureKind, Store};
use anyhow::Context;
use memory::LoopMemory;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;
use tracing::{error, info, warn};

pub use dressing::Dressed;
pub use ingest::GaugeIds;
pub use rollback::{RollbackError, RolledBack};

/// The database, once it can be reached (a background task connects and reconnects).
pub type StoreHandle = Arc<tokio::sync::RwLock<Option<Store>>>;

/// What a gauge adapter hands the machine.
#[derive(Debug)]
pub enum SourceEvent {
    /// A measurement. `ground_with` is the table version the control reports having ground
    /// the part with, where it can say (the simulated control reads it from the program's
    /// provenance); otherwise the delivery record decides. `done` is answered once the next
    /// table is out, so a simulated machine grinds the next part with it, as a real one does
    /// between parts.
    Measurement {
        raw: crate::core::measure::RawMeasurement,
        ground_with: Option<u64>,
        done: Option<tokio::sync::oneshot::Sender<Ingested>>,
    },
    /// The wheel was dressed; the control now believes this radius.
    Dressing {
        wheel_radius_mm: f64,
        source: String,
    },
}

/// What became of a measurement, for the source that sent it (a drop file is moved to
/// `processed/` or `rejected/` by it).
#[derive(Debug, Clone, PartialEq)]
pub enum Ingested {
    /// Checked, analysed and recorded (learned from, or held with a reason in the history).
    Recorded,
    /// A reading already used: not learned again.
    Repeated,
    /// Not this machine's, or failed the checks: never learned from.
    Rejected { reason: String },
    /// Could not be recorded (the journal cannot be written): neither learned nor kept by
    /// camloop, so the sender keeps it (a drop file stays in the inbox).
    NotRecorded,
    /// Could not be processed (e.g. the analysis failed); the reason is logged.
    Failed { reason: String },
}

/// Where a machine's files are.
#[derive(Debug, Clone)]
pub struct MachinePaths {
    pub share_dir: PathBuf,
    pub state_dir: PathBuf,
}

/// The machine's loop with everything it owns.
pub struct MachineLoop {
    pub name: String,
    setup: FeatureSetup,
    ids: GaugeIds,
    memory: LoopMemory,
    share: Share,
    program_file: String,
    journal: Journal,
    store: StoreHandle,
    metrics: Arc<Metrics>,
    /// Wheel radius the program on the share was made for (the simulator reads it).
    table_wheel_radius_bits: Arc<AtomicU64>,
    /// The disk-full alarm was raised and not yet cleared.
    disk_alarm: bool,
    /// PLANT EVENTS HOOK (MQTT): set by the service after `start`; every record passing
    /// through [`MachineLoop::record`] is offered to it (never blocks).
    pub plant_events: Option<crate::service::mqtt::EventSender>,
}

impl MachineLoop {
    /// Sets the machine up: its journal, memory (newest from the journal, else the store:
    /// a restart resumes where the loop was), and share. Delivers the table of the current
    /// correction (and the main program) when the share lacks them.
    pub async fn start(
        name: String,
        setup: FeatureSetup,
        paths: MachinePaths,
        store: StoreHandle,
        metrics: Arc<Metrics>,
    ) -> anyhow::Result<Self> {
        let journal =
            Journal::open(&paths.state_dir).with_context(|| format!("machine {name}: journal"))?;
        let memory = load_memory(&name, &setup, &journal, &store).await?;
        if let Err(e) = std::fs::create_dir_all(&paths.share_dir) {
            // Not fatal: the share may be a mount that comes back; deliveries wait for it. An
            // alarm all the same: nothing reaches the control until it is there.
            error!(machine = %name, folder = %paths.share_dir.display(), error = %e, "controller share folder cannot be created: tables wait until it can");
            metrics.update(&name, |m| m.alarms_total += 1);
        }
        let config = ShareConfig {
            share_dir: paths.share_dir.clone(),
            state_dir: paths.state_dir.join("share"),
            table_pair: setup.table_pair,
            keep_versions: 50,
        };
        let (share, report) = Share::open(config, Box::new(RealFs), Box::new(now_ms_u64))
            .with_context(|| format!("machine {name}: cannot open the share state"))?;
        if let Some(e) = &report.share_unavailable {
            error!(machine = %name, error = %e, "controller share unavailable; tables wait until it is back");
        }
        let program_file = format!("{}.SPF", setup.program.name);
        let ids = GaugeIds::for_machine(&name, &setup.name);
        let mut machine = Self {
            name,
            setup,
            ids,
            memory,
            share,
            program_file,
            journal,
            store,
            metrics,
            table_wheel_radius_bits: Arc::new(AtomicU64::new(0)),
            disk_alarm: false,
            plant_events: None,
        };
        machine.after_start(&report).await?;
        Ok(machine)
    }

    /// Reconciles the memory with the share, reports a quarantined journal, and makes sure
    /// the share holds a table.
    async fn after_start(&mut self, report: &crate::share::OpenReport) -> anyhow::Result<()> {
        let at_ms = now_ms();
        self.setup.feature = self
            .setup
            .feature
            .with_wheel_radius(self.memory.wheel_radius_mm);
        self.table_wheel_radius_bits
            .store(self.memory.wheel_radius_mm.to_bits(), Ordering::SeqCst);
        if let Some(pushed) = self.share.history().last_pushed().map(|v| v.record.version)
            && pushed != self.memory.in_force_version
        {
            // Killed between the push and the record of it: the share is the authority.
            info!(machine = %self.name, share_version = pushed, memory_version = self.memory.in_force_version, "version in force taken from the share's manifest");
            self.memory.delivered(pushed);
        }
        let mut records = vec![self.recipe_snapshot(at_ms)];
        for q in self.journal.quarantined() {
            error!(machine = %self.name, line = q.line, reason = %q.reason, "journal line unreadable: moved to the quarantine file");
            records.push(records::event(
                &self.name,
                at_ms,
                EventLevel::Error,
                EventKind::JournalQuarantined,
                format!(
                    "journal line {} unreadable ({}): kept in {}",
                    q.line,
                    q.reason,
                    super::journal::QUARANTINE_FILE
                ),
            ));
        }
        self.record(records).await;
        let _ = report;
        // The share lacks the table, or its main program is not the one this camloop writes
        // (a first start, or an upgrade): the current table goes with the main program.
        let stale = !self.program_path().exists() || self.main_program_if_changed()?.is_some();
        if stale && self.memory.waiting.is_none() {
            let table =
                compensate::current_table(self.memory.newest_learning(), &self.lobe_loop())?;
            let reason = if self.memory.parts == 0 {
                "nominal table"
            } else {
                "table restored at start"
            };
            let next = self.memory.newest_learning().clone();
            let mut records = self.deliver(&table, next, reason, None).await?;
            records.push(self.learning_record(at_ms));
            self.record(records).await;
        }
        Ok(())
    }

    /// What this machine grinds, as the store keeps it (skipped there when unchanged).
    fn recipe_snapshot(&self, at_ms: i64) -> Pending {
        let s = &self.setup;
        let recipe = RecipeRecord {
            label: &s.label,
            nominal_origin: s.nominal.origin(),
            nominal_points: s.nominal.angles_deg().len(),
            nominal_sha256: crate::core::turn::correction_sha256(s.nominal.lifts_mm()),
            wheel_radius_mm: s.feature.wheel_radius_mm(),
            x_zero_mm: s.feature.x_zero_mm(),
            program: &s.program.name,
            table_pair: s.table_pair,
            table_points: s.request.points,
            params: &s.params,
            limits: &s.limits,
        };
        let kind = match s.feature {
            compensate::Feature::Cam(_) => FeatureKind::Lobe,
            compensate::Feature::Pin(_) => FeatureKind::Pin,
        };
        Pending::RecipeSnapshot {
            machine: self.name.clone(),
            part: s.part.clone(),
            lobe: s.name.clone(),
            kind,
            recipe_json: serde_json::to_string(&recipe).unwrap_or_else(|_| "{}".into()),
            created_at_ms: at_ms,
        }
    }

    pub fn program_path(&self) -> PathBuf {
        self.share.config().share_dir.join(&self.program_file)
    }

    /// The main program's file on the share.
    pub fn main_program_path(&self) -> PathBuf {
        self.share
            .config()
            .share_dir
            .join(delivery::main_program_file(&self.setup))
    }

    pub fn table_wheel_radius(&self) -> Arc<AtomicU64> {
        self.table_wheel_radius_bits.clone()
    }

    pub fn feature(&self) -> compensate::Feature {
        self.setup.feature
    }

    /// The lobe or pin this machine grinds.
    pub fn feature_name(&self) -> &str {
        &self.setup.name
    }

    fn lobe_loop(&self) -> LobeLoop<'_> {
        self.setup.lobe_loop()
    }

    /// Handles one event from the gauge side. Errors are logged and recorded, never fatal:
    /// the machine goes on with the next part.
    pub async fn handle(&mut self, event: SourceEvent) {
        let started = Instant::now();
        let result = match event {
            SourceEvent::Measurement {
                raw,
                ground_with,
                done,
            } => {
                let r = self.on_measurement(raw, ground_with).await;
                if let Some(done) = done {
                    let outcome = match &r {
                        Ok(i) => i.clone(),
                        Err(e) => Ingested::Failed {
                            reason: format!("{e:#}"),
                        },
                    };
                    let _ = done.send(outcome);
                }
                r.map(|_| ())
            }
            SourceEvent::Dressing {
                wheel_radius_mm,
                source,
            } => self.dress(wheel_radius_mm, &source).await.map(|_| ()),
        };
        if let Err(e) = result {
            error!(machine = %self.name, error = format!("{e:#}"), "part not processed");
        }
        self.metrics.update(&self.name, |m| {
            m.processing_seconds_sum += started.elapsed().as_secs_f64();
            m.processing_seconds_count += 1;
        });
    }

    /// Appends records to the journal (durable), then tries to write them to the store.
    /// Returns whether the journal took them: when it cannot (disk full), the records are
    /// lost to history, so the caller must not act on what they describe.
    async fn record(&mut self, records: Vec<Pending>) -> bool {
        if records.is_empty() {
            return true;
        }
        let kept = match self.journal.append(&records) {
            Ok(()) => true,
            Err(e) => {
                error!(machine = %self.name, error = format!("{e:#}"), "journal cannot be written: records not kept, learning holds");
                self.metrics.update(&self.name, |m| {
                    m.alarms_total += 1;
                    m.journal_failing = 1;
                });
                false
            }
        };
        // PLANT EVENTS HOOK (MQTT): what the journal took, the plant hears of.
        if let Some(events) = self.plant_events.as_ref().filter(|_| kept) {
            records.iter().for_each(|r| events.record(r));
        }
        let failing = u64::from(!kept || self.journal.on_reserve());
        self.metrics
            .update(&self.name, |m| m.journal_failing = failing);
        self.flush_journal().await;
        kept
    }

    /// Whether learning must hold because the disk is full: the journal runs on its reserve
    /// (measurements are still kept), or could not write at all. Said once when it starts.
    async fn disk_full_hold(&mut self, at_ms: i64) -> Option<HoldReason> {
        if !self.journal.on_reserve() {
            return None;
        }
        if !self.disk_alarm {
            self.disk_alarm = true;
            error!(machine = %self.name, "disk full: the journal runs on its reserve; measurements are kept, learning stops until space is freed");
            self.metrics.update(&self.name, |m| m.alarms_total += 1);
            let message = format!(
                "disk full: the journal runs on its {} MiB reserve (about 100 parts); measurements are kept, nothing is learned until space is freed",
                super::journal::RESERVE_BYTES / (1024 * 1024)
            );
            let e = records::event(
                &self.name,
                at_ms,
                EventLevel::Error,
                EventKind::DiskFull,
                message,
            );
            self.record(vec![e]).await;
        }
        Some(HoldReason::DiskFull)
    }

    async fn flush_journal(&mut self) {
        let store = self.store.read().await.clone();
        if let Some(store) = store
            && let Err(e) = self.journal.flush(&store).await
        {
            warn!(machine = %self.name, error = format!("{e:#}"), "database unavailable: records kept in the journal");
        }
        let pending = self.journal.pending().len() as u64;
        self.metrics
            .update(&self.name, |m| m.journal_pending = pending);
    }

    /// The loop's memory as a record; through the journal it is also what a restart resumes
    /// from.
    fn learning_record(&self, at_ms: i64) -> Pending {
        Pending::Learning {
            machine: self.name.clone(),
            lobe: self.setup.name.clone(),
            state: self.memory.clone(),
            saved_at_ms: at_ms,
        }
    }
}

/// The recipe snapshot's content: what decides the tables of this feature.
#[derive(serde::Serialize)]
struct RecipeRecord<'a> {
    label: &'a str,
    nominal_origin: &'a str,
    nominal_points: usize,
    /// SHA-256 of the nominal lift values (exact bits).
    nominal_sha256: String,
    wheel_radius_mm: f64,
    x_zero_mm: f64,
    program: &'a str,
    table_pair: (u32, u32),
    table_points: usize,
    params: &'a crate::core::learn::LearningParams,
    limits: &'a compensate::AxisLimits,
}

/// The newest memory: the journal's (it holds what the store may not have yet, and always
/// the newest learning state), else the store's. A store that answers with an error is an
/// error here, never "no state": starting from nominal would silently forget the loop.
async fn load_memory(
    name: &str,
    setup: &FeatureSetup,
    journal: &Journal,
    store: &StoreHandle,
) -> anyhow::Result<LoopMemory> {
    let records = journal.records();
    let newest = records.iter().rposition(|r| {
        matches!(r, Pending::Learning { machine, lobe, .. } if machine == name && *lobe == setup.name)
    });
    if let Some(i) = newest
        && let Pending::Learning { state, .. } = &records[i]
    {
        // Measurements recorded after it (the process died before their learning record)
        // still count, and are still known, so a replay does not learn them again.
        let mut memory = state.clone();
        for r in &records[i + 1..] {
            if let Pending::Measurement { sha256, .. } = r {
                memory.parts += 1;
                memory.remember(sha256.clone());
            }
        }
        return Ok(memory);
    }
    let Some(store) = store.read().await.clone() else {
        return Ok(LoopMemory::new(setup.feature.wheel_radius_mm()));
    };
    let stored = store
        .load_learning_state(name, &setup.name)
        .await
        .with_context(|| format!("machine {name}: cannot read the stored learning state"))?;
    match stored {
        None => Ok(LoopMemory::new(setup.feature.wheel_radius_mm())),
        Some(s) => serde_json::from_str(&s.state_json).with_context(|| {
            format!(
                "machine {name} {}: the stored learning state is unreadable",
                setup.name
            )
        }),
    }
}
