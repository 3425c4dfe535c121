//! One machine's loop in the service: measurement in → checks → analysis → learning →
//! guarded table → delivery to the share → records through the journal into the store.

use super::journal::{Journal, Pending};
use super::metrics::Metrics;
use crate::clock::{now_ms, now_ms_u64};
use crate::core::analysis::{LobeOptions, analyse_lobe};
use crate::core::compensate::{self, GuardedTable, LobeLoop};
use crate::core::learn::{self, LearningState, StepOutcome};
use crate::core::lift::LiftCurve;
use crate::core::measure::{AssemblyLimits, RawMeasurement, check_and_average};
use crate::core::program::{comment_text, render_g1_table, render_poly_table};
use crate::recipe::FeatureSetup;
use crate::share::{ProgramFile, PushRequest, RealFs, Share, ShareConfig, lower_hex};
use crate::store::Store;
use anyhow::Context;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;
use tracing::{error, info, warn};

/// The database, once it can be reached (a background task connects and reconnects).
pub type StoreHandle = Arc<tokio::sync::RwLock<Option<Store>>>;

/// What a gauge adapter hands the machine.
#[derive(Debug)]
pub enum SourceEvent {
    /// A measurement; `done` is answered once the next table is out, so a simulated machine
    /// grinds the next part with it, as a real one does between parts.
    Measurement(RawMeasurement, Option<tokio::sync::oneshot::Sender<()>>),
    /// The wheel was dressed; the control now believes this radius.
    Dressing {
        wheel_radius_mm: f64,
        source: String,
    },
}

/// What the machine remembers between parts (stored as a learning-state snapshot).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LoopMemory {
    pub learning: LearningState,
    pub wheel_radius_mm: f64,
    pub parts: u64,
}

/// The machine's loop with everything it owns.
pub struct MachineLoop {
    pub name: String,
    setup: FeatureSetup,
    memory: LoopMemory,
    share: Share,
    program_file: String,
    journal: Journal,
    store: StoreHandle,
    metrics: Arc<Metrics>,
    /// Wheel radius the program on the share was made for (the simulator reads it).
    table_wheel_radius_bits: Arc<AtomicU64>,
}

impl MachineLoop {
    /// Sets the machine up: its share, journal and memory (from the store if it has one, so
    /// a restart resumes where the loop was). Delivers the table of the current correction
    /// when the share holds none yet.
    pub async fn start(
        name: String,
        setup: FeatureSetup,
        share_dir: PathBuf,
        state_dir: PathBuf,
        store: StoreHandle,
        metrics: Arc<Metrics>,
    ) -> anyhow::Result<Self> {
        let journal = Journal::open(&state_dir)?;
        let lobe = lobe_name(&setup);
        // The journal holds every record the store may not have durably, so its newest
        // learning state is the newest there is, even after parts made while the database was
        // down; otherwise the store's copy is.
        let local = journal.records().iter().rev().find_map(|r| match r {
            Pending::Learning {
                machine,
                lobe: l,
                state_json,
                ..
            } if *machine == name && *l == lobe => {
                serde_json::from_str::<LoopMemory>(state_json).ok()
            }
            _ => None,
        });
        let stored = match (&local, store.read().await.as_ref()) {
            (None, Some(s)) => s
                .load_learning_state(&name, &lobe)
                .await
                .ok()
                .flatten()
                .and_then(|s| serde_json::from_str::<LoopMemory>(&s.state_json).ok()),
            _ => None,
        };
        let memory = local.or(stored).unwrap_or_else(|| LoopMemory {
            learning: LearningState::new(360),
            wheel_radius_mm: setup.feature.wheel_radius_mm(),
            parts: 0,
        });
        std::fs::create_dir_all(&share_dir).ok();
        let config = ShareConfig {
            share_dir: share_dir.clone(),
            state_dir: state_dir.join("share"),
            table_pair: setup.table_pair,
            keep_versions: 50,
        };
        let (share, report) = Share::open(config, Box::new(RealFs), Box::new(now_ms_u64))
            .with_context(|| format!("machine {name}: cannot open the share state"))?;
        if let Some(e) = report.share_unavailable {
            error!(machine = %name, error = %e, "controller share unavailable; tables wait until it is back");
        }
        let program_file = format!("{}.SPF", setup.program.name);
        let mut machine = Self {
            name,
            setup,
            memory,
            share,
            program_file,
            journal,
            store,
            metrics,
            table_wheel_radius_bits: Arc::new(AtomicU64::new(0)),
        };
        machine.setup.feature = machine
            .setup
            .feature
            .with_wheel_radius(machine.memory.wheel_radius_mm);
        machine
            .table_wheel_radius_bits
            .store(machine.memory.wheel_radius_mm.to_bits(), Ordering::SeqCst);
        if !share_dir.join(&machine.program_file).exists() {
            let table = compensate::current_table(&machine.memory.learning, &machine.lobe_loop())?;
            let reason = if machine.memory.parts == 0 {
                "nominal table"
            } else {
                "table restored at start"
            };
            machine.deliver(&table, reason, None).await?;
        }
        Ok(machine)
    }

    pub fn program_path(&self) -> PathBuf {
        self.share.config().share_dir.join(&self.program_file)
    }

    pub fn table_wheel_radius(&self) -> Arc<AtomicU64> {
        self.table_wheel_radius_bits.clone()
    }

    pub fn feature(&self) -> crate::core::compensate::Feature {
        self.setup.feature
    }

    fn lobe_loop(&self) -> LobeLoop<'_> {
        LobeLoop {
            nominal: &self.setup.nominal,
            feature: self.setup.feature,
            request: self.setup.request,
            limits: &self.setup.limits,
            params: &self.setup.params,
        }
    }

    /// Handles one event from the gauge side. Errors are logged and recorded, never fatal:
    /// the machine goes on with the next part.
    pub async fn handle(&mut self, event: SourceEvent) {
        let started = Instant::now();
        let result = match event {
            SourceEvent::Measurement(raw, done) => {
                let r = self.on_measurement(raw).await;
                if let Some(done) = done {
                    let _ = done.send(());
                }
                r
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

    async fn on_measurement(&mut self, raw: RawMeasurement) -> anyhow::Result<()> {
        let at_ms = now_ms();
        let lobe = lobe_name(&self.setup);
        let sha = measurement_sha(&raw);
        let avg = match check_and_average(&raw, &AssemblyLimits::default()) {
            Ok(avg) => avg,
            Err(e) => {
                // Kept among the rejects with the reason; never used for compensation.
                warn!(machine = %self.name, lobe = %lobe, reason = %e, "measurement rejected");
                self.keep_reject(&raw, &sha, &e.to_string())?;
                self.metrics
                    .update(&self.name, |m| m.measurements_rejected_total += 1);
                self.record(vec![event(
                    &self.name,
                    at_ms,
                    "warn",
                    "measurement_rejected",
                    e.to_string(),
                )])
                .await?;
                return Ok(());
            }
        };
        let curve = LiftCurve::new(&self.setup.nominal);
        let nominal = |psi: f64| {
            let s = curve.eval(psi.to_radians());
            (s.h_mm, s.dh_mm.to_radians())
        };
        let options = LobeOptions {
            bands: self.setup.bands.clone(),
            ..LobeOptions::default()
        };
        let report = analyse_lobe(&avg, &nominal, &options).context("analysis")?;
        let max_error_um = report.error_um.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        let mut records = vec![Pending::Measurement {
            machine: self.name.clone(),
            part: raw.header.part.clone(),
            lobe: lobe.clone(),
            received_at_ms: at_ms,
            pass: report.verdict.pass,
            max_profile_error_um: report
                .profile_error_max_um
                .abs()
                .max(report.profile_error_min_um.abs()),
            base_radius_error_um: report.base_radius_error_um,
            phase_error_deg: report.phase_error_deg,
            revolutions_used: avg.revolutions_used.len() as u32,
            points_per_rev: avg.points_per_rev,
            origin: raw.origin.clone(),
            sha256: sha.clone(),
            raw_lift_mm: raw_revolutions(&raw),
            averaged_lift_mm: avg.mean_lift_mm.clone(),
            analysis_json: serde_json::to_string(&report)?,
        }];
        self.memory.parts += 1;
        let part = self.memory.parts;
        if avg.points_per_rev != self.memory.learning.points_per_rev
            && self.memory.learning.iteration == 0
        {
            self.memory.learning = LearningState::new(avg.points_per_rev);
        }
        let revolutions = avg.revolutions_used.len() as u32;
        let lobe_loop = LobeLoop {
            nominal: &self.setup.nominal,
            feature: self.setup.feature,
            request: self.setup.request,
            limits: &self.setup.limits,
            params: &self.setup.params,
        };
        let step = compensate::learn_and_regenerate(
            &mut self.memory.learning,
            &report.error_um,
            &report.repeatability_um,
            revolutions,
            &lobe_loop,
        );
        let version_text = match step {
            Ok((outcome, table)) => {
                if let StepOutcome::Reverted { reason, .. } = &outcome {
                    error!(machine = %self.name, lobe = %lobe, reason = %reason, "learning reverted and frozen: operator action needed");
                    self.metrics.update(&self.name, |m| m.alarms_total += 1);
                    records.push(event(
                        &self.name,
                        at_ms,
                        "error",
                        "learning_reverted",
                        reason.clone(),
                    ));
                }
                let reason = format!("part {part}: {}", outcome_text(&outcome));
                let (version, number, pushed, mut more) = self
                    .deliver_records(&table, &reason, Some(sha.clone()))
                    .await?;
                records.append(&mut more);
                format!(
                    "table v{version} (T{number}) {}",
                    if pushed {
                        "pushed"
                    } else {
                        "waiting for the share"
                    }
                )
            }
            Err(e) => {
                warn!(machine = %self.name, lobe = %lobe, reason = %e, "table refused, previous table stays in force");
                self.metrics
                    .update(&self.name, |m| m.tables_refused_total += 1);
                records.push(event(
                    &self.name,
                    at_ms,
                    "warn",
                    "table_refused",
                    e.to_string(),
                ));
                "table refused, previous kept".to_string()
            }
        };
        records.push(self.learning_record(at_ms)?);
        self.record(records).await?;
        self.metrics.update(&self.name, |m| {
            m.parts_total += 1;
            m.last_max_error_um = max_error_um;
        });
        info!(
            machine = %self.name,
            lobe = %lobe,
            part,
            max_error_um = format!("{max_error_um:.2}"),
            profile_error_um = format!("{:.2}", report.profile_error_max_um.abs().max(report.profile_error_min_um.abs())),
            "{} {} part {part}: max error {max_error_um:.2} µm → {version_text}",
            self.name,
            lobe
        );
        Ok(())
    }

    /// A wheel dressing, from the gauge/controller feed, a dropped report or the API: the
    /// dressing is recorded and the table regenerated from the same correction for the new
    /// radius (the learned size is dropped). Returns what happened, for the API's answer; a
    /// radius outside [`compensate::WHEEL_RADIUS_RANGE_MM`] changes nothing.
    pub async fn dress(&mut self, wheel_radius_mm: f64, source: &str) -> anyhow::Result<String> {
        let wheel_radius_mm = compensate::check_wheel_radius(wheel_radius_mm)?;
        let at_ms = now_ms();
        let old = self.memory.wheel_radius_mm;
        info!(machine = %self.name, old_radius_mm = old, new_radius_mm = wheel_radius_mm, source, "wheel dressed: table regenerated for the new radius");
        self.memory.wheel_radius_mm = wheel_radius_mm;
        self.setup.feature = self.setup.feature.with_wheel_radius(wheel_radius_mm);
        learn::after_dressing(&mut self.memory.learning);
        let mut records = vec![
            Pending::Dressing {
                machine: self.name.clone(),
                at_ms,
                old_radius_mm: old,
                new_radius_mm: wheel_radius_mm,
                source: source.to_string(),
            },
            event(
                &self.name,
                at_ms,
                "info",
                "wheel_dressed",
                format!("wheel radius {old} → {wheel_radius_mm} mm ({source})"),
            ),
        ];
        let outcome = match compensate::current_table(&self.memory.learning, &self.lobe_loop()) {
            Ok(table) => {
                let reason = format!("wheel dressed to {wheel_radius_mm} mm");
                let (version, number, pushed, mut more) =
                    self.deliver_records(&table, &reason, None).await?;
                records.append(&mut more);
                format!(
                    "wheel radius {old} → {wheel_radius_mm} mm: table v{version} (T{number}) {}",
                    if pushed {
                        "pushed"
                    } else {
                        "waiting for the share"
                    }
                )
            }
            Err(e) => {
                error!(machine = %self.name, reason = %e, "no table for the dressed wheel: previous table stays in force");
                self.metrics.update(&self.name, |m| m.alarms_total += 1);
                records.push(event(
                    &self.name,
                    at_ms,
                    "error",
                    "table_refused",
                    e.to_string(),
                ));
                format!(
                    "wheel radius {old} → {wheel_radius_mm} mm recorded; table refused, previous kept: {e}"
                )
            }
        };
        records.push(self.learning_record(at_ms)?);
        self.record(records).await?;
        Ok(outcome)
    }

    async fn deliver(
        &mut self,
        table: &GuardedTable,
        reason: &str,
        measurement: Option<String>,
    ) -> anyhow::Result<()> {
        let (_, _, _, records) = self.deliver_records(table, reason, measurement).await?;
        self.record(records).await
    }

    /// Renders and delivers a table; returns version, table number, whether it reached the
    /// share, and the records to keep.
    async fn deliver_records(
        &mut self,
        table: &GuardedTable,
        reason: &str,
        measurement: Option<String>,
    ) -> anyhow::Result<(u64, u32, bool, Vec<Pending>)> {
        let at_ms = now_ms();
        let mut settings = self.setup.program.clone();
        settings.table_number = self.share.next_table_number();
        settings.comment_lines = vec![comment_text(&self.setup.label), comment_text(reason)];
        let text = match &table.segments {
            Some(s) => render_poly_table(s, &settings),
            None => render_g1_table(&table.points, &settings),
        }?;
        let learning_json = serde_json::json!({
            "iteration": self.memory.learning.iteration,
            "params": self.setup.params,
            "wheel_radius_mm": self.memory.wheel_radius_mm,
            // Kept with every version so a rollback restores the correction it was made from.
            "correction_um": self.memory.learning.correction_um,
        })
        .to_string();
        let request = PushRequest {
            files: vec![ProgramFile {
                name: self.program_file.clone(),
                text: text.clone(),
            }],
            table_number: settings.table_number,
            reason: reason.to_string(),
            measurement_id: measurement,
            learning: manifest_learning(&learning_json),
            rollback_of: None,
            created_at_unix_ms: at_ms as u64,
        };
        let mut records = Vec::new();
        let (version, pushed, why) = match self.share.push_once(request) {
            Ok(p) => {
                self.table_wheel_radius_bits
                    .store(self.memory.wheel_radius_mm.to_bits(), Ordering::SeqCst);
                self.metrics.update(&self.name, |m| {
                    m.tables_pushed_total += 1;
                    m.share_waiting = 0;
                });
                (p.version, true, "pushed to the share".to_string())
            }
            Err(e) => {
                // The version is kept in the share state and goes when the share is back.
                error!(machine = %self.name, error = %e, "controller share: table not delivered, will retry");
                self.metrics.update(&self.name, |m| {
                    m.alarms_total += 1;
                    m.share_waiting = 1;
                });
                records.push(event(
                    &self.name,
                    at_ms,
                    "error",
                    "share_unavailable",
                    e.to_string(),
                ));
                let version = self
                    .share
                    .history()
                    .versions()
                    .last()
                    .map_or(0, |v| v.record.version);
                (version, false, format!("waiting: {e}"))
            }
        };
        records.push(Pending::Table {
            machine: self.name.clone(),
            lobe: lobe_name(&self.setup),
            table_number: settings.table_number,
            program_text: text,
            learning_params_json: learning_json,
            reason: reason.to_string(),
            status: if pushed { "pushed" } else { "waiting" }.to_string(),
            status_why: why,
            created_at_ms: at_ms,
        });
        Ok((version, settings.table_number, pushed, records))
    }

    /// Delivers the program of stored version `version` again, as a new version under the
    /// table number not in use, and restores the correction it was made from. History is
    /// appended: the rollback is a new version with the reason "rollback to vN".
    pub async fn rollback(&mut self, version: i64) -> anyhow::Result<String> {
        let at_ms = now_ms();
        let lobe = lobe_name(&self.setup);
        let store = self
            .store
            .read()
            .await
            .clone()
            .context("history store unavailable: cannot read the stored version")?;
        let old = store
            .table_version(&self.name, &lobe, version)
            .await?
            .with_context(|| format!("version {version} of {} {lobe} not found", self.name))?;
        let number = self.share.next_table_number();
        let text = renumber_table(&old.program_text, old.table_number, number)
            .with_context(|| format!("version {version}: no CTABDEF line to renumber"))?;
        if let Ok(learning) = serde_json::from_str::<serde_json::Value>(&old.learning_params_json)
            && let Some(correction) = learning["correction_um"].as_array()
            && correction.len() == self.memory.learning.correction_um.len()
        {
            self.memory.learning.correction_um = correction
                .iter()
                .map(|v| v.as_f64().unwrap_or(0.0))
                .collect();
            self.memory.learning.recent_max_error_um.clear();
        }
        let reason = format!("rollback to v{version}");
        let request = PushRequest {
            files: vec![ProgramFile {
                name: self.program_file.clone(),
                text: text.clone(),
            }],
            table_number: number,
            reason: reason.clone(),
            measurement_id: None,
            learning: manifest_learning(&old.learning_params_json),
            rollback_of: None,
            created_at_unix_ms: now_ms_u64(),
        };
        let (status, why) = match self.share.push_once(request) {
            Ok(_) => ("pushed", "pushed to the share".to_string()),
            Err(e) => ("waiting", format!("waiting: {e}")),
        };
        info!(machine = %self.name, lobe = %lobe, version, table_number = number, status, "rollback");
        let records = vec![
            event(
                &self.name,
                at_ms,
                "info",
                "rollback",
                format!("{reason} as table {number}: {why}"),
            ),
            Pending::Table {
                machine: self.name.clone(),
                lobe,
                table_number: number,
                program_text: text,
                learning_params_json: old.learning_params_json.clone(),
                reason: reason.clone(),
                status: status.to_string(),
                status_why: why.clone(),
                created_at_ms: at_ms,
            },
            self.learning_record(at_ms)?,
        ];
        self.record(records).await?;
        Ok(format!("{reason} delivered as table {number} ({why})"))
    }

    /// Retries what waits: a version for the share, records for the database; and drops
    /// from the journal what the database now holds durably.
    pub async fn retry(&mut self) {
        match self.share.deliver() {
            Ok(Some(p)) => {
                info!(machine = %self.name, version = p.version, "controller share back: waiting table delivered");
                self.table_wheel_radius_bits
                    .store(self.memory.wheel_radius_mm.to_bits(), Ordering::SeqCst);
                self.metrics.update(&self.name, |m| {
                    m.tables_pushed_total += 1;
                    m.share_waiting = 0;
                });
            }
            Ok(None) => {}
            Err(e) => warn!(machine = %self.name, error = %e, "controller share still unavailable"),
        }
        self.flush_journal().await;
        let store = self.store.read().await.clone();
        if let Some(store) = store
            && let Err(e) = self.journal.release_durable(&store).await
        {
            warn!(machine = %self.name, error = format!("{e:#}"), "database not confirmed durable: records stay in the journal");
        }
    }

    /// Appends records to the journal (durable), then tries to write them to the store.
    async fn record(&mut self, records: Vec<Pending>) -> anyhow::Result<()> {
        self.journal.append(&records)?;
        self.flush_journal().await;
        Ok(())
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
    fn learning_record(&self, at_ms: i64) -> anyhow::Result<Pending> {
        Ok(Pending::Learning {
            machine: self.name.clone(),
            lobe: lobe_name(&self.setup),
            state_json: serde_json::to_string(&self.memory)?,
            saved_at_ms: at_ms,
        })
    }

    /// A rejected measurement is kept as CSV with its reason beside it.
    fn keep_reject(&self, raw: &RawMeasurement, sha: &str, reason: &str) -> anyhow::Result<()> {
        let dir = self
            .share
            .config()
            .state_dir
            .parent()
            .unwrap_or(Path::new("."))
            .join("rejected");
        std::fs::create_dir_all(&dir)?;
        let mut csv = format!(
            "# machine={} part={} lobe={}\n# points_per_rev={} revolutions={}\nrev,angle_deg,lift_mm\n",
            raw.header.machine,
            raw.header.part,
            raw.header.lobe,
            raw.header.points_per_rev,
            raw.header.revolutions
        );
        for s in &raw.samples {
            let angle =
                f64::from(s.angle_index) * 360.0 / f64::from(raw.header.points_per_rev.max(1));
            csv.push_str(&format!("{},{angle},{}\n", s.revolution, s.lift_mm));
        }
        let stem = &sha[..16.min(sha.len())];
        std::fs::write(dir.join(format!("{stem}.csv")), csv)?;
        std::fs::write(
            dir.join(format!("{stem}.reason.txt")),
            format!("{reason}\n"),
        )?;
        Ok(())
    }
}

/// The same program defining table `to` instead of `from` (the CTABDEF line only).
fn renumber_table(text: &str, from: u32, to: u32) -> Option<String> {
    let mut found = false;
    let lines: Vec<String> = text
        .lines()
        .map(|line| {
            if let Some(args) = line.strip_prefix("CTABDEF(") {
                let mut parts: Vec<String> = args.split(',').map(str::to_string).collect();
                if parts.len() >= 4 && parts[2].trim() == from.to_string() {
                    parts[2] = to.to_string();
                    found = true;
                    return format!("CTABDEF({}", parts.join(","));
                }
            }
            line.to_string()
        })
        .collect();
    found.then(|| lines.join("\n") + "\n")
}

/// What the share's manifest keeps of a version's learning: everything but the correction
/// itself (360+ numbers per version; the history store keeps it, and rollback takes it
/// from there), so the manifest and the share's memory stay small.
fn manifest_learning(learning_json: &str) -> serde_json::Value {
    let mut value: serde_json::Value =
        serde_json::from_str(learning_json).unwrap_or(serde_json::Value::Null);
    if let Some(map) = value.as_object_mut() {
        map.remove("correction_um");
    }
    value
}

fn lobe_name(setup: &FeatureSetup) -> String {
    setup.name.clone()
}

fn event(machine: &str, at_ms: i64, level: &str, kind: &str, message: String) -> Pending {
    Pending::Event {
        machine: machine.to_string(),
        at_ms,
        level: level.to_string(),
        kind: kind.to_string(),
        message,
    }
}

fn outcome_text(outcome: &StepOutcome) -> String {
    match outcome {
        StepOutcome::Updated { max_error_um, .. } => {
            format!("learned from max error {max_error_um:.2} µm")
        }
        StepOutcome::InTolerance { max_error_um } => format!("in tolerance ({max_error_um:.2} µm)"),
        StepOutcome::Frozen { .. } => "learning frozen".to_string(),
        StepOutcome::Reverted { to_iteration, .. } => {
            format!("reverted to iteration {to_iteration}")
        }
    }
}

/// Raw lifts per revolution, in revolution order (samples are complete after the checks).
fn raw_revolutions(raw: &RawMeasurement) -> Vec<Vec<f64>> {
    let n = raw.header.points_per_rev as usize;
    let revs = raw.header.revolutions as usize;
    let mut out = vec![vec![0.0; n]; revs];
    for s in &raw.samples {
        if let Some(slot) = out
            .get_mut(s.revolution as usize)
            .and_then(|r| r.get_mut(s.angle_index as usize))
        {
            *slot = s.lift_mm;
        }
    }
    out
}

/// SHA-256 of a measurement as received: header fields (length-prefixed, so no two headers
/// hash alike), every sample's revolution, index and exact lift bits in order, then the
/// origin. Binary rather than text: formatting 1,000+ floats per part cost more than the
/// rest of the identity check.
pub fn measurement_sha(raw: &RawMeasurement) -> String {
    use sha2::Digest as _;
    let h = &raw.header;
    let mut hasher = sha2::Sha256::new();
    for field in [&h.machine, &h.part, &h.lobe] {
        hasher.update((field.len() as u64).to_le_bytes());
        hasher.update(field.as_bytes());
    }
    hasher.update(h.revolutions.to_le_bytes());
    hasher.update(h.points_per_rev.to_le_bytes());
    let mut samples = Vec::with_capacity(raw.samples.len() * 16);
    for s in &raw.samples {
        samples.extend_from_slice(&s.revolution.to_le_bytes());
        samples.extend_from_slice(&s.angle_index.to_le_bytes());
        samples.extend_from_slice(&s.lift_mm.to_bits().to_le_bytes());
    }
    hasher.update((raw.samples.len() as u64).to_le_bytes());
    hasher.update(&samples);
    hasher.update(raw.origin.as_bytes());
    lower_hex(&hasher.finalize())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::measure::{MeasurementHeader, RawSample};

    fn measurement(machine: &str, part: &str, lifts: &[f64]) -> RawMeasurement {
        RawMeasurement {
            header: MeasurementHeader {
                machine: machine.into(),
                part: part.into(),
                lobe: "IN1".into(),
                revolutions: 1,
                points_per_rev: lifts.len() as u32,
            },
            samples: lifts
                .iter()
                .enumerate()
                .map(|(i, &lift_mm)| RawSample {
                    revolution: 0,
                    angle_index: i as u32,
                    lift_mm,
                })
                .collect(),
            origin: "test".into(),
        }
    }

    /// The identity that makes measurements idempotent in the store: equal for the same
    /// reading, different for any change a gauge could make, including the smallest lift
    /// change a float can carry and a character moved from one header field to the next.
    #[test]
    fn measurement_identity_tells_apart_every_change() {
        let base = measurement("M1", "P7", &[0.0, 1.25, 2.5]);
        let sha = measurement_sha(&base);
        assert_eq!(sha.len(), 64);
        assert_eq!(sha, measurement_sha(&base.clone()));
        let nudged = measurement("M1", "P7", &[0.0, 1.25f64.next_up(), 2.5]);
        assert_ne!(sha, measurement_sha(&nudged));
        let moved = measurement("M1P", "7", &[0.0, 1.25, 2.5]);
        assert_ne!(sha, measurement_sha(&moved));
        let mut other_origin = base.clone();
        other_origin.origin = "can0".into();
        assert_ne!(sha, measurement_sha(&other_origin));
    }
}
