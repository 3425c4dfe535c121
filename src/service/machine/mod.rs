//! One machine in the service: it grinds every lobe or pin of its recipe, each with its own
//! loop ([`FeatureLoop`]). A measurement goes to the loop of the feature the gauge names; a
//! feature the recipe does not have, or a part the control ground with another feature's
//! table, is rejected with the reason and disturbs nothing. Events of the wheel (dressing)
//! act on every feature; a rollback on one feature or on the whole part.
//!
//! Each feature's decisions are its [`camloop_loop::FeatureMachine`] (the loop crate): a part
//! takes one [`crate::core::turn`] there, and the machine asks for the journal writes, the
//! rendering, the share's submit and delivery in write-ahead order. This module is the shell
//! that carries those effects out and feeds back what happened.
//!
//! - `feature`: one feature's loop and what it owns (journal, share, plan, metrics);
//! - `executor`: the machine's effects carried out, its inputs fed back;
//! - `ingest`: a measurement's routing, handed to the machine, the part's line;
//! - `delivery`: table orders handed to the machine, the share's request, retries;
//! - `rollback`, `dressing`, `freeze`: the operator's and the wheel's events;
//! - `error`: why a write (a delivery, a dressing) did not happen, typed for the API;
//! - `records`: the loop's records in the journal's format, and the reject folder;
//! - `memory`: the loop crate's memory, re-exported where the journal finds it;
//! - `reconcile`: journal, share and memory settled at start;
//! - `shaft`: the main program of the whole part and the resume point;
//! - `coast`: a part ground but not gauged moves the table on by the learned drift;
//! - `planned`: the C speed plan's two-table program and its X check over the virtual axis.
//! - `table_memo`: tables computed once per distinct input (a plant's machines of one recipe
//!   open with the same nominal tables).
//!
//! The version in force is the newest one the share confirmed. A step always starts from its
//! learning state: a table computed while the share refused it never becomes the base of the
//! next step, so an outage cannot wind the correction up.

mod charts;
mod coast;
mod delivery;
mod dressing;
mod error;
mod executor;
mod feature;
mod freeze;
mod guards;
mod in_process;
mod ingest;
pub mod memory;
mod planned;
mod reconcile;
mod records;
mod rollback;
mod shaft;
mod table_memo;

use super::metrics::Metrics;
use crate::clock::now;
use crate::core::ids::TableVersion;
use crate::core::turn::measurement_sha256;
use crate::names::{FeatureName, MachineName};
use crate::recipe::FeatureSetup;
use crate::store::Store;
use anyhow::Context;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
use tracing::{error, info, warn};

pub use dressing::Dressed;
pub use error::MachineError;
pub use feature::FeatureLoop;
pub use in_process::InProcessOutcome;
pub use ingest::GaugeIds;
pub use rollback::{RollbackError, RolledBack};
pub(crate) use shaft::MainProgram;

/// The database, once it can be reached (a background task connects and reconnects).
pub type StoreHandle = Arc<tokio::sync::RwLock<Option<Store>>>;

/// The table a part was ground with, as the control reports it (the simulated control reads
/// it from the program's provenance).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GroundWith {
    /// The feature whose table program defined the table, when the report says.
    pub feature: Option<String>,
    pub version: u64,
}

/// What a gauge adapter hands the machine.
#[derive(Debug)]
pub enum SourceEvent {
    /// A measurement. `ground_with` is the table the control reports having ground the part
    /// with, where it can say; otherwise the delivery record decides. `done` is answered once
    /// the next table is out, so a simulated machine grinds the next part with it, as a real
    /// one does between parts.
    Measurement {
        raw: crate::core::measure::RawMeasurement,
        ground_with: Option<GroundWith>,
        done: Option<tokio::sync::oneshot::Sender<Ingested>>,
    },
    /// The wheel was dressed; the control now believes this radius, and the dresser measured
    /// this infeed (radius removed, µm) when it reports one. `done` is answered once every
    /// feature's table for it is out.
    Dressing {
        wheel_radius_mm: f64,
        infeed_um: Option<f64>,
        source: String,
        done: Option<tokio::sync::oneshot::Sender<()>>,
    },
    /// A measurement before the finish, stock still on (`[cycle] program = "whole"`): this
    /// part's finish table, never learned from. `part` is the part the control grinds, where
    /// the source knows it (else the measurement's own). `done` is answered once the table
    /// and the handshake's count are on the share, or with why not.
    InProcess {
        raw: crate::core::measure::RawMeasurement,
        part: Option<String>,
        /// When the source had it: the control's wait runs from then.
        received: std::time::Instant,
        done: Option<tokio::sync::oneshot::Sender<InProcessOutcome>>,
    },
}

/// What became of a measurement, for the source that sent it (a drop file is moved to
/// `processed/` or `rejected/` by it).
#[derive(Debug, Clone, PartialEq)]
pub enum Ingested {
    /// Checked, analysed and recorded (learned from, or held with a reason in the history).
    Recorded,
    /// A master part's run of a gauge study: analysed and recorded for the study, never
    /// learned from, never counted as a production part.
    Master,
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

/// How a machine opens at a plant's start (see [`MachineLoop::start_owned`]); the default
/// asks the store per feature and writes to it as it opens.
#[derive(Debug, Clone, Default)]
pub(crate) struct Opening {
    /// The features the store holds a learning state for, read once for the whole plant
    /// (`None`: each feature asks the store).
    pub known_states: Option<Arc<std::collections::HashSet<(MachineName, FeatureName)>>>,
    /// Leave the opening's store writes to the machine's first retry: its records are in
    /// the journal (durable), and the opening does not queue on the database's writer
    /// behind every other machine's parts.
    pub defer_store: bool,
}

/// A machine: the loops of its features and the main program that grinds them in turn.
pub struct MachineLoop {
    pub name: MachineName,
    features: Vec<FeatureLoop>,
    ids: GaugeIds,
    main: Arc<MainProgram>,
    metrics: Arc<Metrics>,
    /// The resume point could not be written (the share refuses): said once, not per part.
    resume_failing: bool,
    /// In a cluster: the owner's fence, which every feature's writes check.
    fence: Option<crate::share::Fence>,
}

impl MachineLoop {
    /// Sets the machine up: each feature's loop in recipe order (its memory from its journal,
    /// else the store; a restart resumes where each was), the resume point, and the main
    /// program once every table is on the share.
    pub async fn start(
        name: MachineName,
        setups: Vec<FeatureSetup>,
        paths: MachinePaths,
        store: StoreHandle,
        metrics: Arc<Metrics>,
    ) -> anyhow::Result<Self> {
        Self::start_owned(
            name,
            setups,
            paths,
            None,
            &Opening::default(),
            store,
            metrics,
        )
        .await
    }

    /// [`Self::start`] for an owner in a cluster: every feature's share state is fenced
    /// with the owner's epoch (see [`crate::share::Fence`]); `opening` says what a plant's
    /// start already knows.
    pub(crate) async fn start_owned(
        name: MachineName,
        setups: Vec<FeatureSetup>,
        paths: MachinePaths,
        fence: Option<crate::share::Fence>,
        opening: &Opening,
        store: StoreHandle,
        metrics: Arc<Metrics>,
    ) -> anyhow::Result<Self> {
        let main = Arc::new(MainProgram::for_features(&setups)?);
        shaft::adopt_single_feature_layout(&paths.state_dir, &setups);
        let ids = GaugeIds::new(&name, &setups);
        let mut features = Vec::with_capacity(setups.len());
        for setup in setups {
            let feature_paths = MachinePaths {
                share_dir: paths.share_dir.clone(),
                state_dir: paths.state_dir.join(&setup.name),
            };
            let feature = FeatureLoop::start(
                name.clone(),
                setup,
                feature_paths,
                (fence.clone(), opening),
                store.clone(),
                metrics.clone(),
                main.clone(),
            )
            .await
            .with_context(|| format!("machine {name}"))?;
            features.push(feature);
        }
        let machine = Self {
            name,
            fence,
            features,
            ids,
            main,
            metrics,
            resume_failing: false,
        };
        machine.write_resume_point_from_memory();
        machine.write_ready_at_start();
        Ok(machine)
    }

    /// Where every feature's loop sends plant events (MQTT).
    pub fn set_plant_events(&mut self, events: Option<crate::service::plant::EventSender>) {
        for f in &mut self.features {
            f.plant_events = events.clone();
        }
    }

    /// The loops of the features, in recipe (grinding) order.
    pub fn features(&self) -> &[FeatureLoop] {
        &self.features
    }

    /// The main program's file on the share.
    pub(crate) fn main_program_path(&self) -> PathBuf {
        self.share_dir().join(&self.main.file)
    }

    fn share_dir(&self) -> &std::path::Path {
        self.features[0].share_dir()
    }

    /// In a cluster: another instance has claimed this machine since it started here (its
    /// fence holds a newer epoch), so nothing more may be done for it on this instance.
    pub(crate) fn fenced_out(&self) -> bool {
        self.fence
            .as_ref()
            .is_some_and(|f| matches!(f.hold(), Err(crate::share::StateError::Fenced { .. })))
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
                infeed_um,
                source,
                done,
            } => {
                let r = self
                    .dress(wheel_radius_mm, infeed_um, &source)
                    .await
                    .map(|_| ())
                    .map_err(anyhow::Error::from);
                if let Some(done) = done {
                    let _ = done.send(());
                }
                r
            }
            SourceEvent::InProcess {
                raw,
                part,
                received,
                done,
            } => {
                let part = part.unwrap_or_else(|| raw.header.part.clone());
                let r = self.on_in_process(raw, &part, received).await;
                if let Some(done) = done {
                    let _ = done.send(match &r {
                        Ok(o) => o.clone(),
                        Err(e) => InProcessOutcome::Refused {
                            reason: e.to_string(),
                        },
                    });
                }
                r.map(|_| ()).map_err(anyhow::Error::from)
            }
        };
        if let Err(e) = result {
            if self.fenced_out() {
                warn!(machine = %self.name, error = format!("{e:#}"), "cluster: another instance owns this machine now; part not processed here");
            } else {
                error!(machine = %self.name, error = format!("{e:#}"), "part not processed");
            }
        }
        self.metrics.update(&self.name, |m| {
            m.processing_seconds_sum += started.elapsed().as_secs_f64();
            m.processing_seconds_count += 1;
        });
    }

    /// A measurement to the loop of the feature it names; rejected here when the machine or
    /// the feature is not this one's, or the control ground it with another feature's table.
    async fn on_measurement(
        &mut self,
        raw: crate::core::measure::RawMeasurement,
        ground_with: Option<GroundWith>,
    ) -> anyhow::Result<Ingested> {
        let (index, part) = match self.ids.route(&raw.header, ground_with.as_ref()) {
            Ok(routed) => routed,
            Err(reason) => {
                // The part was ground all the same: when the control says which feature it
                // was, the resume point moves past it.
                if let Some(k) = ground_with
                    .as_ref()
                    .and_then(|g| g.feature.as_ref())
                    .and_then(|f| self.features.iter().position(|x| x.feature_name() == f))
                {
                    self.write_resume_point(k + 2);
                    self.features[k].coast(&raw.header.part).await;
                }
                // Kept and recorded by the first feature's loop: it belongs to none.
                let sha = measurement_sha256(&raw);
                let first = &mut self.features[0];
                first.reject(&raw, &sha, &reason, now()).await;
                return Ok(Ingested::Rejected { reason });
            }
        };
        if part.is_master() {
            // Nothing was ground: no resume point moves, no shaft line.
            return self.features[index].on_master(raw, part).await;
        }
        let version = ground_with.map(|g| g.version);
        let ingested = self.features[index]
            .on_measurement(raw, part, version)
            .await;
        // Ground and gauged, whatever the loop made of it.
        self.write_resume_point(index + 2);
        let ingested = ingested?;
        if ingested == Ingested::Recorded
            && index + 1 == self.features.len()
            && self.features.len() > 1
        {
            self.shaft_line();
        }
        Ok(ingested)
    }

    /// One line per shaft, said when its last feature is gauged: the worst feature, and what
    /// became of the tables.
    fn shaft_line(&self) {
        let Some(part) = self
            .features
            .last()
            .and_then(|f| f.last_line.as_ref())
            .map(|l| l.part.clone())
        else {
            return;
        };
        let lines: Vec<&ingest::PartLine> = self
            .features
            .iter()
            .filter_map(|f| f.last_line.as_ref())
            .filter(|l| l.part == part)
            .collect();
        let Some(worst) = lines
            .iter()
            .max_by(|a, b| a.max_error_um.total_cmp(&b.max_error_um))
        else {
            return;
        };
        let worst_timing = lines
            .iter()
            .map(|l| l.timing_error_deg.abs())
            .fold(0.0f64, f64::max);
        let pushed = lines.iter().filter(|l| l.pushed).count();
        let others: Vec<String> = lines
            .iter()
            .filter(|l| !l.pushed)
            .map(|l| format!("{}: {}", l.feature, l.text))
            .collect();
        let tables = if others.is_empty() {
            format!("{pushed} tables pushed")
        } else {
            format!("{pushed} tables pushed; {}", others.join("; "))
        };
        info!(
            machine = %self.name,
            part = %part,
            worst_lobe = %worst.feature,
            max_error_um = format!("{:.2}", worst.max_error_um),
            "{} shaft {part}: {} of {} features, worst {} {:.2} µm (profile {:.2} µm, size {:+.2} µm), worst timing {:.4}° → {tables}",
            self.name,
            lines.len(),
            self.features.len(),
            worst.feature,
            worst.max_error_um,
            worst.profile_error_um,
            worst.size_error_um,
            worst_timing,
        );
    }

    /// A wheel dressing acts on every feature: each regenerates its table for the new radius.
    /// `infeed_um` is the dresser's measured infeed, when it reports one (see
    /// [`crate::core::learn::after_measured_dressing`]).
    pub async fn dress(
        &mut self,
        wheel_radius_mm: f64,
        infeed_um: Option<f64>,
        source: &str,
    ) -> Result<Dressed, MachineError> {
        let mut summary = Vec::new();
        let mut dressed = None;
        // The wheel's share of the size corrections, what every feature has in common: used
        // only when the dresser gave no infeed.
        let wheel_size_um = self
            .features
            .iter()
            .map(|f| crate::core::learn::size_correction_um(f.memory().newest_learning()))
            .sum::<f64>()
            / self.features.len() as f64;
        let wheel = dressing::Wheel {
            radius_mm: wheel_radius_mm,
            infeed_um,
            share_um: wheel_size_um,
        };
        for (i, feature) in self.features.iter_mut().enumerate() {
            let d = feature.dress(&wheel, source, i == 0).await?;
            summary.push(format!("{}: {}", feature.feature_name(), d.summary));
            dressed.get_or_insert(d);
        }
        let mut d = dressed.ok_or_else(|| MachineError::Failed {
            reason: "a machine has at least one feature".into(),
        })?;
        if self.features.len() > 1 {
            d.summary = summary.join("; ");
        }
        Ok(d)
    }

    /// Rolls feature `lobe` back to its `version`.
    pub async fn rollback(
        &mut self,
        lobe: &FeatureName,
        version: TableVersion,
    ) -> Result<RolledBack, RollbackError> {
        let Some(feature) = self.features.iter_mut().find(|f| f.feature_name() == lobe) else {
            return Err(RollbackError::UnknownFeature {
                machine: self.name.clone(),
                grinds: self.feature_names().join(", "),
                asked: lobe.clone(),
            });
        };
        feature.rollback(lobe, version).await
    }

    /// Freezes (with a reason) or unfreezes the learning of feature `lobe`: the reason before,
    /// or `None` when the machine does not grind `lobe`.
    pub(crate) async fn set_frozen(
        &mut self,
        lobe: &FeatureName,
        frozen: Option<String>,
    ) -> Option<Option<String>> {
        let feature = self
            .features
            .iter_mut()
            .find(|f| f.feature_name() == lobe)?;
        Some(feature.set_frozen(frozen).await)
    }

    /// Rolls several features back together (a whole part: one version of each). Every
    /// version is checked first; nothing is pushed unless all of them can be.
    pub async fn rollback_part(
        &mut self,
        versions: &[(FeatureName, TableVersion)],
    ) -> Result<Vec<RolledBack>, RollbackError> {
        for (lobe, version) in versions {
            let names = self.feature_names().join(", ");
            let Some(feature) = self.features.iter_mut().find(|f| f.feature_name() == lobe) else {
                return Err(RollbackError::UnknownFeature {
                    machine: self.name.clone(),
                    grinds: names,
                    asked: lobe.clone(),
                });
            };
            feature.rollback_program(lobe, *version).await?;
        }
        let mut done = Vec::new();
        for (lobe, version) in versions {
            done.push(self.rollback(lobe, *version).await?);
        }
        Ok(done)
    }

    pub(crate) fn feature_names(&self) -> Vec<&str> {
        self.features
            .iter()
            .map(|f| f.feature_name().as_str())
            .collect()
    }

    /// Retries what waits, feature by feature.
    pub async fn retry(&mut self) {
        for feature in &mut self.features {
            feature.retry().await;
        }
    }

    /// Writes the resume point: `next` is the feature after the one just gauged (from 1;
    /// past the last, the shaft is finished and a resume would start a new one at 1). Only a
    /// shaft program reads it, and only when the operator asks for a resume.
    fn write_resume_point(&mut self, next: usize) {
        if self.features.len() < 2 {
            return;
        }
        let first = if next > self.features.len() { 1 } else { next };
        match shaft::write_resume(self.share_dir(), first) {
            Ok(()) if self.resume_failing => {
                self.resume_failing = false;
                info!(machine = %self.name, "resume point written to the share again");
            }
            Ok(()) => {}
            Err(e) if !self.resume_failing => {
                self.resume_failing = true;
                warn!(machine = %self.name, error = %e, "resume point not written to the share (said once until it can be)");
            }
            Err(_) => {}
        }
    }

    /// The resume point from what each feature's loop remembers, at start: the shaft in the
    /// machine is the newest part any feature was ground for, and its first feature not
    /// ground for it is where a resume starts (1 when none is missing). Derived rather than
    /// read back, so a stop between a record and the file's rewrite never grinds a feature
    /// twice.
    fn write_resume_point_from_memory(&self) {
        if self.features.len() < 2 {
            return;
        }
        let last: Vec<Option<u64>> = self
            .features
            .iter()
            .map(|f| f.memory().last_part_number())
            .collect();
        let first = match last.iter().flatten().max() {
            None => 1,
            Some(shaft) => last
                .iter()
                .position(|l| *l != Some(*shaft))
                .map_or(1, |k| k + 1),
        };
        match shaft::write_resume(self.share_dir(), first) {
            Ok(()) => {
                info!(machine = %self.name, first_feature = first, "resume point written from the features' records")
            }
            Err(e) => {
                warn!(machine = %self.name, error = %e, "resume point not written to the share")
            }
        }
    }
}
