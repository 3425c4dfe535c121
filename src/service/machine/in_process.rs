//! Measure before the finish, the shell's half: the whole-cycle main program, the handshake's
//! count on the share (`CAMLOOP_READY.SPF`: 0 at start, then one more with each same-part
//! finish table, pushed after the table in the same request), and the in-process measurement
//! handed to the loop's decision ([`camloop_loop::in_process`]): its table order carried out,
//! or an event saying why the finish grinds with the table in force. The measurement is kept
//! in the history as a row of stage `in_process` (through the journal, with the table's
//! records), never learned from; the finished part's measurement learns as any part's.

use super::super::journal::EventKind;
use super::super::journal::Pending;
use super::records::{event, measurement};
use super::{FeatureLoop, MachineError, MachineLoop};
use crate::clock::now;
use crate::core::cycle::CycleSettings;
use crate::core::measure::RawMeasurement;
use crate::core::program::{
    CycleMachine, CyclePlan, CycleStation, MainProgramSettings, READY_PROGRAM,
    render_cycle_program, render_ready_program,
};
use crate::core::speed_plan::render::VaProgramSettings;
use crate::core::turn::{self, measurement_sha256};
use crate::recipe::FeatureSetup;
use crate::share::ProgramFile;
use crate::store::{EventLevel, MeasurementStage, VersionStatus};
use camloop_loop::in_process::{SamePart, same_part_order};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;
use tracing::{info, warn};

/// What became of an in-process measurement.
#[derive(Debug, Clone, PartialEq)]
pub enum InProcessOutcome {
    /// This part's finish table is on the share and the handshake's count moved to `ready`.
    Delivered { version: u64, ready: u64 },
    /// The table was made but could not reach the share: the control's wait times out and
    /// the finish grinds with the table in force.
    Waiting { version: u64 },
    /// No same-part table (an event says why): the finish grinds with the table in force.
    Refused { reason: String },
}

/// The handshake's count, shared by a machine's features (one file on the share).
#[derive(Debug, Default)]
pub(crate) struct Ready {
    state: Mutex<ReadyState>,
}

#[derive(Debug, Default)]
struct ReadyState {
    /// Same-part tables delivered since the service started (the file says 0 at start).
    count: u64,
    /// The feature whose same-part table is being pushed: its request carries the count.
    armed: Option<String>,
}

impl Ready {
    fn lock(&self) -> std::sync::MutexGuard<'_, ReadyState> {
        // The state is two plain fields, never half-written: a panic elsewhere leaves it whole.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The handshake's file for `feature`'s request, when its same-part table is the one
    /// being pushed: the next count, written after the table in the same push.
    pub(super) fn file_for(&self, feature: &str) -> Option<ProgramFile> {
        let state = self.lock();
        (state.armed.as_deref() == Some(feature)).then(|| ProgramFile {
            name: ready_file(),
            text: render_ready_program(state.count + 1),
        })
    }

    fn arm(&self, feature: &str) {
        self.lock().armed = Some(feature.to_string());
    }

    /// The push is over; `pushed`: the count reached the share with the table.
    fn disarm(&self, pushed: bool) -> u64 {
        let mut state = self.lock();
        state.armed = None;
        if pushed {
            state.count += 1;
        }
        state.count
    }
}

fn ready_file() -> String {
    format!("{READY_PROGRAM}.SPF")
}

/// The whole-cycle main program of `setups` (one or more features in turn). With the speed
/// plan in the whole cycle, `va_speeds_rpm` gives each feature's virtual-axis speed (the
/// plan of the table on the share), by feature name; every such feature must have one.
pub(super) fn render_whole(
    main: &MainProgramSettings,
    cycle: &CycleSettings,
    setups: &[FeatureSetup],
    clear_x_mm: f64,
    va_speeds_rpm: &BTreeMap<String, f64>,
) -> anyhow::Result<String> {
    let first = &setups[0];
    let machine = CycleMachine {
        cycle,
        c_speed_rpm: first.limits.c_speed_rpm,
        wheel_radius_mm: first.feature.wheel_radius_mm(),
        clear_x_mm,
    };
    // The plan's table programs by name and axes; their numbers come back from the call.
    let plans: Vec<Option<VaProgramSettings>> = setups
        .iter()
        .map(|s| {
            s.plan_in_whole_cycle().then(|| {
                let mut va = super::planned::va_settings(s, 1, 2);
                va.name = crate::recipe::plan_program_name(&s.program.name);
                va
            })
        })
        .collect();
    let mut stations = Vec::with_capacity(setups.len());
    for (s, plan) in setups.iter().zip(&plans) {
        let plan = match plan {
            Some(table) => {
                let Some(&va_speed_rpm) = va_speeds_rpm.get(s.name.as_str()) else {
                    anyhow::bail!("{}: the plan's speed is not known yet", s.label);
                };
                Some(CyclePlan {
                    table,
                    va_speed_rpm,
                })
            }
            None => None,
        };
        stations.push(CycleStation {
            table: &s.program,
            label: &s.name,
            z_mm: s.z_mm,
            plan,
        });
    }
    Ok(render_cycle_program(main, &machine, &stations)?)
}

/// Writes the handshake's count atomically (a temporary beside it, flushed, renamed).
fn write_ready(share_dir: &Path, count: u64) -> std::io::Result<()> {
    use std::io::Write as _;
    let tmp = share_dir.join(format!(
        "{}ready-{}",
        crate::share::TEMP_PREFIX,
        std::process::id()
    ));
    let mut f = std::fs::File::create(&tmp)?;
    f.write_all(render_ready_program(count).as_bytes())?;
    f.sync_all()?;
    drop(f);
    std::fs::rename(&tmp, share_dir.join(ready_file())).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })
}

impl MachineLoop {
    /// With the whole cycle: the handshake's count 0 on the share, so the control's first
    /// wait has a value to compare with. Not fatal: without the file the control's call
    /// fails at the measurement, which an operator sees; the share may come back.
    pub(super) fn write_ready_at_start(&self) {
        if self.main.ready.is_none() {
            return;
        }
        if let Err(e) = write_ready(self.share_dir(), 0) {
            warn!(machine = %self.name, error = %e, "handshake: CAMLOOP_READY.SPF not written");
        }
    }

    /// The in-process measurement of `part` (the part the control is grinding, as the gauge
    /// names it) to the feature it names: this part's finish table, or why none.
    pub async fn on_in_process(
        &mut self,
        raw: RawMeasurement,
        part: &str,
        received: Instant,
    ) -> Result<InProcessOutcome, MachineError> {
        let index = match self.ids.route(&raw.header, None) {
            Ok((i, _)) => i,
            Err(reason) => {
                // No feature of this machine: an event, and no row under a feature it is not.
                let feature = &mut self.features[0];
                return feature.refuse_in_process(&raw, reason, Vec::new()).await;
            }
        };
        self.features[index]
            .on_in_process(raw, part, received)
            .await
    }
}

impl FeatureLoop {
    /// See [`MachineLoop::on_in_process`].
    pub(super) async fn on_in_process(
        &mut self,
        raw: RawMeasurement,
        part: &str,
        received: Instant,
    ) -> Result<InProcessOutcome, MachineError> {
        // The part was ground so far with the table in force now, not with its finish table.
        let ground_with = self.machine.memory().in_force_version;
        // With the plan the finish table is guarded over VA, as every table of the plan is.
        self.refresh_plan();
        let turn_setup = super::planned::turn_setup(&self.setup, &self.plan);
        let decided = same_part_order(
            &SamePart {
                setup: &turn_setup,
                cycle: self.setup.cycle.as_ref(),
                memory: self.machine.memory(),
                feature: &self.setup.name,
                part,
                waited_s: received.elapsed().as_secs_f64(),
            },
            &raw,
            now(),
        );
        let order = match decided {
            Ok(order) => order,
            Err(e) => {
                let row = self.in_process_row(&raw, ground_with);
                return self.refuse_in_process(&raw, e.to_string(), row).await;
            }
        };
        let main = self.main.clone();
        let Some(ready) = main.ready.as_ref() else {
            let row = self.in_process_row(&raw, ground_with);
            return self
                .refuse_in_process(
                    &raw,
                    "the machine's main program has no handshake".into(),
                    row,
                )
                .await;
        };
        ready.arm(&self.setup.name);
        let delivered = self.deliver_order(order).await;
        let pushed = matches!(delivered, Ok((_, VersionStatus::Pushed { .. }, _)));
        let count = ready.disarm(pushed);
        let (version, _, mut records) = delivered?;
        // The row first: the finish table's version names this measurement.
        records.splice(0..0, self.in_process_row(&raw, ground_with));
        let version = version.get();
        let at = now();
        let outcome = if pushed {
            info!(machine = %self.name, part, version, ready = count, "same-part finish table on the share");
            InProcessOutcome::Delivered {
                version,
                ready: count,
            }
        } else {
            InProcessOutcome::Waiting { version }
        };
        records.push(self.learning_record(at));
        if !self.record(records).await {
            let reason = format!(
                "machine {}: the finish table's records were not kept",
                self.name
            );
            return Err(self.journal_failed(reason));
        }
        Ok(outcome)
    }

    /// No same-part table: an event says why, kept with `rows` (the measurement's history
    /// row, if any); nothing is learned, nothing delivered.
    async fn refuse_in_process(
        &mut self,
        raw: &RawMeasurement,
        reason: String,
        mut rows: Vec<Pending>,
    ) -> Result<InProcessOutcome, MachineError> {
        warn!(machine = %self.name, part = raw.header.part.as_str(), reason = reason.as_str(), "in-process measurement: no same-part finish table, the finish grinds with the table in force");
        let e = event(
            &self.name,
            now(),
            EventLevel::Warn,
            EventKind::MeasurementRejected,
            format!(
                "in-process measurement of part {}: no same-part finish table ({reason}); the finish grinds with the table in force, nothing learned",
                raw.header.part.trim()
            ),
        );
        rows.push(e);
        if !self.record(rows).await {
            let why = format!("machine {}: the refusal's event was not kept", self.name);
            return Err(self.journal_failed(why));
        }
        Ok(InProcessOutcome::Refused { reason })
    }
}

impl FeatureLoop {
    /// The in-process measurement as a history row of stage `in_process`, when it reads as
    /// a measurement of this feature (one that fails the checks has its event and no row).
    /// The row is never learned from: the loop's memory does not take its digest.
    fn in_process_row(
        &self,
        raw: &RawMeasurement,
        ground_with: Option<crate::core::ids::TableVersion>,
    ) -> Vec<Pending> {
        let Ok(measured) = turn::measure(&self.setup.turn_setup(), raw) else {
            return Vec::new();
        };
        // Routed, so its part is an id (`GaugeIds::route`).
        let Ok(part) = crate::core::ids::PartId::new(&raw.header.part) else {
            return Vec::new();
        };
        let sha = measurement_sha256(raw);
        let whose = (&self.name, &self.setup.name, part);
        let mut row = measurement(whose, raw, &sha, &measured, now());
        row.stage = MeasurementStage::InProcess;
        vec![Pending::Measurement {
            measurement: row,
            ground_with_version: ground_with,
        }]
    }
}
