//! One feature's loop (a lobe or a pin of the machine's recipe), with everything it owns:
//! its journal, learning memory, share state, table program and numbers. Features of a
//! machine share nothing but the share folder and the main program, so no feature's state
//! can mix with another's.

use super::super::journal::{EventKind, Journal, Pending};
use super::super::metrics::Metrics;
use super::memory::LoopMemory;
use super::{MachinePaths, MainProgram, StoreHandle, records};
use crate::clock::now;
use crate::core::compensate::{self, LobeLoop};
use crate::core::digest::Sha256;
use crate::names::{FeatureName, MachineName};
use crate::recipe::FeatureSetup;
use crate::share::{RealFs, Share, ShareConfig};
use crate::store::{EventLevel, FeatureKind, Store};
use anyhow::Context;
use camloop_loop::FeatureMachine;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use tracing::{error, warn};

/// One feature's loop with everything it owns.
pub struct FeatureLoop {
    /// The machine's name (records and metrics are the machine's, with the feature).
    pub name: MachineName,
    pub(super) setup: FeatureSetup,
    /// The loop's decisions and its memory ([`camloop_loop::FeatureMachine`]); this struct
    /// carries out its effects (`executor`).
    pub(super) machine: FeatureMachine,
    pub(super) share: Share,
    pub(super) program_file: String,
    pub(super) journal: Journal,
    pub(super) store: StoreHandle,
    pub(super) metrics: Arc<Metrics>,
    pub(super) main: Arc<MainProgram>,
    /// The newest part's line, for the machine's line per shaft.
    pub(super) last_line: Option<super::ingest::PartLine>,
    /// PLANT EVENTS HOOK (MQTT, OPC UA): set by the service after `start`; every record the
    /// journal takes is offered to it (never blocks), once the store has had its write.
    pub(super) plant_events: Option<crate::service::plant::EventSender>,
    /// Events of records the journal took, held until the store's write after them: an
    /// event is sent once its part's history row is there (or the store was tried and is
    /// down), so a client that reads the API on an event finds the part.
    pub(super) unpublished: Vec<camloop_loop::PlantEvent>,
    /// Wheel radius the program on the share was made for (the simulator reads it).
    pub(super) table_wheel_radius_bits: Arc<AtomicU64>,
    /// The disk-full alarm was raised and not yet cleared.
    pub(super) disk_alarm: bool,
    /// The control charts' run rules (events only: learning never reads them).
    pub(super) charts: super::charts::ChartWatch,
    /// The speed plan's law, tables and the VA speed being delivered (plan on).
    pub(super) plan: super::planned::PlanState,
    /// While a plant's start opens it: records stay in the journal for the first retry.
    pub(super) defer_store: bool,
}

impl FeatureLoop {
    /// Sets the machine up: its journal, memory (newest from the journal, else the store:
    /// a restart resumes where the loop was), and share. Delivers the table of the current
    /// correction (and the main program) when the share lacks them.
    pub(super) async fn start(
        name: MachineName,
        setup: FeatureSetup,
        paths: MachinePaths,
        (fence, opening): (Option<crate::share::Fence>, &super::Opening),
        store: StoreHandle,
        metrics: Arc<Metrics>,
        main: Arc<MainProgram>,
    ) -> anyhow::Result<Self> {
        let mut journal =
            Journal::open(&paths.state_dir).with_context(|| format!("machine {name}: journal"))?;
        // The journal's newest memory (it holds what the store may not have yet), else the
        // store's: a restart resumes where the loop was.
        let kept = super::reconcile::kept(&name, &setup.name, journal.records());
        let fallback = match LoopMemory::resume(&kept) {
            Some(_) => LoopMemory::new(setup.feature.wheel_radius_mm()),
            None => stored_memory(&name, &setup, &store, opening).await?,
        };
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
        let (mut share, report) = Share::open(config, Box::new(RealFs), Box::new(now))
            .with_context(|| format!("machine {name}: cannot open the share state"))?;
        if let Some(fence) = fence {
            // Every write for this feature (journal, store, share) is fenced from here on.
            journal.set_fence(fence.clone());
            share.set_fence(fence);
        }
        if let Some(e) = &report.share_unavailable {
            error!(machine = %name, error = %e, "controller share unavailable; tables wait until it is back");
        }
        let program_file = format!("{}.SPF", setup.program.name);
        let charts =
            super::charts::ChartWatch::new(&crate::quality::FeatureLimits::from_setup(&setup));
        let view = super::reconcile::share_view(&share);
        let feature_machine =
            super::reconcile::resumed_machine(&name, &setup, kept, fallback, view, &store).await;
        let mut machine = Self {
            name,
            setup,
            machine: feature_machine,
            share,
            program_file,
            journal,
            store,
            metrics,
            main,
            last_line: None,
            charts,
            plant_events: None,
            unpublished: Vec::new(),
            table_wheel_radius_bits: Arc::new(AtomicU64::new(0)),
            disk_alarm: false,
            plan: Default::default(),
            defer_store: opening.defer_store,
        };
        machine.after_start(&report).await?;
        machine.defer_store = false;
        Ok(machine)
    }

    /// Reconciles the memory with the share, reports a quarantined journal, and makes sure
    /// the share holds a table.
    async fn after_start(&mut self, report: &crate::share::OpenReport) -> anyhow::Result<()> {
        let at = now();
        self.setup.feature = self
            .setup
            .feature
            .with_wheel_radius(self.machine.memory().wheel_radius_mm);
        self.table_wheel_radius_bits.store(
            self.machine.memory().wheel_radius_mm.to_bits(),
            Ordering::SeqCst,
        );
        self.reconcile_share().await?;
        let plan_changed = self.plan_at_start()?;
        let mut records = vec![self.recipe_snapshot(at)];
        for q in self.journal.quarantined() {
            error!(machine = %self.name, line = q.line, reason = %q.reason, "journal line unreadable: moved to the quarantine file");
            records.push(records::event(
                &self.name,
                at,
                EventLevel::Error,
                EventKind::JournalQuarantined,
                format!(
                    "journal line {} unreadable ({}): kept in {}",
                    q.line,
                    q.reason,
                    super::super::journal::QUARANTINE_FILE
                ),
            ));
        }
        self.record(records).await;
        self.publish_start_status();
        let _ = report;
        // The share lacks the table, or its main program is not the one this camloop writes
        // (a first start, or an upgrade): the current table goes with the main program.
        if self.machine.memory().waiting.is_some() {
            self.deliver_waiting().await;
        }
        let stale = !self.program_path().exists()
            || plan_changed
            || self.main_program_if_changed()?.is_some();
        if stale && self.machine.memory().waiting.is_none() {
            // Machines of one recipe open with the same tables: computed once.
            let table = super::table_memo::TableMemo::global()
                .current_table(self.machine.memory().newest_learning(), &self.lobe_loop())?;
            let reason = if self.machine.memory().parts == 0 {
                "nominal table"
            } else {
                "table restored at start"
            };
            let next = self.machine.memory().newest_learning().clone();
            let mut records = self.deliver(&table, next, reason, None).await?;
            records.push(self.learning_record(at));
            self.record(records).await;
        }
        Ok(())
    }

    /// What this machine grinds, as the store keeps it (skipped there when unchanged).
    fn recipe_snapshot(&self, at: jiff::Timestamp) -> Pending {
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
            created_at: at,
        }
    }

    pub(crate) fn program_path(&self) -> PathBuf {
        self.share.config().share_dir.join(&self.program_file)
    }

    /// The share folder.
    pub fn share_dir(&self) -> &std::path::Path {
        &self.share.config().share_dir
    }

    /// What the feature's loop remembers (for status and tests).
    pub fn memory(&self) -> &LoopMemory {
        self.machine.memory()
    }

    pub fn setup(&self) -> &FeatureSetup {
        &self.setup
    }

    pub(crate) fn table_wheel_radius(&self) -> Arc<AtomicU64> {
        self.table_wheel_radius_bits.clone()
    }

    pub fn feature(&self) -> compensate::Feature {
        self.setup.feature
    }

    /// The lobe or pin this loop grinds.
    pub(crate) fn feature_name(&self) -> &FeatureName {
        &self.setup.name
    }

    pub(super) fn lobe_loop(&self) -> LobeLoop<'_> {
        self.setup.lobe_loop()
    }

    /// Appends records to the journal (durable), then tries to write them to the store.
    /// Returns whether the journal took them: when it cannot (disk full), the records are
    /// lost to history, so the caller must not act on what they describe.
    pub(super) async fn record(&mut self, records: Vec<Pending>) -> bool {
        self.record_or_why(records).await.is_ok()
    }

    /// [`Self::record`], with why the journal did not take them.
    pub(super) async fn record_or_why(&mut self, records: Vec<Pending>) -> Result<(), String> {
        let kept = self.journal_or_why(records);
        self.flush_journal().await;
        kept
    }

    /// Appends records to the journal (durable); the store gets them, and the plant their
    /// events, at the next [`Self::flush_journal`].
    pub(super) fn journal_or_why(&mut self, records: Vec<Pending>) -> Result<(), String> {
        if records.is_empty() {
            return Ok(());
        }
        let kept = match self.journal.append(&records) {
            Ok(()) => Ok(()),
            Err(e) if self.journal.fenced_out() => {
                // Not a fault here: the machine moved while this instance was paused; the
                // loop stops before its next event, and the part stays with its source.
                warn!(machine = %self.name, error = format!("{e:#}"), "cluster: another instance owns this machine now; records not written here");
                return Err(format!("{e:#}"));
            }
            Err(e) => {
                error!(machine = %self.name, error = format!("{e:#}"), "journal cannot be written: records not kept, learning holds");
                self.metrics.update(&self.name, |m| {
                    m.alarms_total += 1;
                    m.journal_failing = 1;
                });
                Err(format!("{e:#}"))
            }
        };
        if self.plant_events.is_some() && kept.is_ok() {
            let events = records.iter().filter_map(crate::service::plant::of_record);
            self.unpublished.extend(events);
        }
        let failing = u64::from(kept.is_err() || self.journal.on_reserve());
        self.metrics
            .update(&self.name, |m| m.journal_failing = failing);
        kept
    }

    /// The disk is full (the journal runs on its reserve: measurements are still kept,
    /// learning holds, the feature's machine decides that): said once when it starts.
    pub(super) async fn disk_full_alarm(&mut self, at: jiff::Timestamp) {
        if self.disk_alarm {
            return;
        }
        self.disk_alarm = true;
        error!(machine = %self.name, "disk full: the journal runs on its reserve; measurements are kept, learning stops until space is freed");
        self.metrics.update(&self.name, |m| m.alarms_total += 1);
        let message = format!(
            "disk full: the journal runs on its {} MiB reserve (about 100 parts); measurements are kept, nothing is learned until space is freed",
            super::super::journal::RESERVE_BYTES / (1024 * 1024)
        );
        let e = records::event(
            &self.name,
            at,
            EventLevel::Error,
            EventKind::DiskFull,
            message,
        );
        self.record(vec![e]).await;
    }

    pub(super) async fn flush_journal(&mut self) {
        let store = if self.defer_store {
            None
        } else {
            self.store.read().await.clone()
        };
        if let Some(store) = store {
            match self.journal.flush(&store).await {
                Ok(f) if !f.refused.is_empty() => self.note_refused(&f.refused, &store).await,
                Ok(_) => {}
                Err(e) => {
                    warn!(machine = %self.name, error = format!("{e:#}"), "database unavailable: records kept in the journal")
                }
            }
        }
        let pending = self.journal.pending().len() as u64;
        self.metrics
            .update(&self.name, |m| m.journal_pending = pending);
        // After the store's write, whether it went or not: a store that is down delays the
        // history, never the plant's events (their rows follow from the journal).
        if let Some(events) = &self.plant_events {
            self.unpublished.drain(..).for_each(|e| events.send(e));
        }
    }

    /// Records the store refused for good were set aside (see [`Journal::flush`]): an alarm
    /// each, and an event in the history saying where the record is kept.
    async fn note_refused(&mut self, refused: &[super::super::journal::Refused], store: &Store) {
        let at = now();
        let events: Vec<Pending> = refused
            .iter()
            .map(|r| {
                error!(machine = %self.name, lobe = %self.setup.name, record = r.kind, reason = %r.reason, "the database refuses a journal record: kept aside, the records after it go on");
                records::event(
                    &self.name,
                    at,
                    EventLevel::Error,
                    EventKind::JournalQuarantined,
                    format!(
                        "{} {} record refused by the database ({}): kept in {}",
                        self.setup.name,
                        r.kind,
                        r.reason,
                        super::super::journal::REFUSED_FILE
                    ),
                )
            })
            .collect();
        let count = refused.len() as u64;
        self.metrics.update(&self.name, |m| m.alarms_total += count);
        if self.journal.append(&events).is_ok()
            && let Err(e) = self.journal.flush(store).await
        {
            warn!(machine = %self.name, error = format!("{e:#}"), "database unavailable: records kept in the journal");
        }
    }

    /// The loop's memory as a record; through the journal it is also what a restart resumes
    /// from.
    pub(super) fn learning_record(&self, at: jiff::Timestamp) -> Pending {
        Pending::Learning {
            machine: self.name.clone(),
            lobe: self.setup.name.clone(),
            state: Box::new(self.machine.memory().clone()),
            saved_at: at,
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
    nominal_sha256: Sha256,
    wheel_radius_mm: f64,
    x_zero_mm: f64,
    program: &'a str,
    table_pair: (u32, u32),
    table_points: usize,
    params: &'a crate::core::learn::LearningParams,
    limits: &'a compensate::AxisLimits,
}

/// The store's memory of the feature, for a journal that holds none. A store that answers
/// with an error is an error here, never "no state": starting from nominal would silently
/// forget the loop.
async fn stored_memory(
    name: &MachineName,
    setup: &FeatureSetup,
    store: &StoreHandle,
    opening: &super::Opening,
) -> anyhow::Result<LoopMemory> {
    let known_none = opening
        .known_states
        .as_ref()
        .is_some_and(|k| !k.contains(&(name.clone(), setup.name.clone())));
    let Some(store) = store.read().await.clone().filter(|_| !known_none) else {
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
