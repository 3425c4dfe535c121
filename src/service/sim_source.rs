//! The simulated machine as a gauge source: a simulated control runs the main program on the
//! share (which calls the table program and couples the table it defines, tables kept by
//! number between parts as on the NC), the grinder grinds the coupled table, and the
//! measurement goes out as CAN frames through the real DBC decoder and assembler in memory,
//! exactly as a bus would deliver it.

use super::machine::SourceEvent;
use crate::core::compensate::Feature;
use crate::gauge::{Assembled, Assembler, GaugeDbc};
use crate::sim::{
    CommandedTable, Control, GrinderConfig, PartLabels, SimGrinder, TableShape, Workpiece,
    measurement_frames,
};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tracing::{error, warn};

pub struct SimSource {
    pub machine: String,
    pub grinder: GrinderConfig,
    pub seed: u64,
    pub feature: Feature,
    pub program: PathBuf,
    /// The main program that calls it (what the control runs).
    pub main_program: PathBuf,
    /// Wheel radius the program on the share was made for.
    pub table_wheel_radius_bits: Arc<AtomicU64>,
    pub part_interval: Duration,
    /// Stop after this many parts (None: until shutdown).
    pub parts: Option<u64>,
}

impl SimSource {
    /// Runs until shutdown (or the part count); each part goes out as one event.
    pub async fn run(self, tx: mpsc::Sender<SourceEvent>, mut shutdown: watch::Receiver<bool>) {
        let Some(mut sim) = self.grinder() else {
            return;
        };
        let dbc = GaugeDbc::builtin();
        let x_zero_offset = self.feature.x_zero_mm() - self.feature.wheel_radius_mm();
        let mut interval = tokio::time::interval(self.part_interval);
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut made = 0u64;
        let mut control = Control::new();
        loop {
            tokio::select! {
                _ = interval.tick() => {}
                _ = shutdown.changed() => return,
            }
            if *shutdown.borrow() || self.parts.is_some_and(|n| made >= n) {
                return;
            }
            // The control runs the main program, which calls the table program: the table
            // it couples is what gets ground, whatever the files say on their own.
            let Some((shape, ground_with)) = self.run_control(&mut control) else {
                continue;
            };
            let table_r = f64::from_bits(self.table_wheel_radius_bits.load(Ordering::SeqCst));
            let table = CommandedTable {
                shape,
                x_zero_mm: table_r + x_zero_offset,
                wheel_radius_mm: table_r,
            };
            let ground = match sim.grind(&table) {
                Ok(g) => g,
                Err(e) => {
                    error!(machine = %self.machine, error = %e, "simulator: the table cannot be ground");
                    continue;
                }
            };
            // The CAN layout carries numeric ids.
            let labels = PartLabels {
                machine: "1".into(),
                part: (made + 1).to_string(),
                lobe: "1".into(),
            };
            let raw = sim.measure(&ground, &labels);
            let measurement = self.through_the_bus(&dbc, &raw);
            made += 1;
            if let Some(m) = measurement {
                let (done, processed) = tokio::sync::oneshot::channel();
                if tx
                    .send(SourceEvent::Measurement {
                        raw: m,
                        ground_with,
                        done: Some(done),
                    })
                    .await
                    .is_err()
                {
                    return;
                }
                // Wait for the next table, as the machine does between parts.
                let _ = processed.await;
            }
            if let Some(d) = sim.after_part()
                && tx
                    .send(SourceEvent::Dressing {
                        wheel_radius_mm: d.believed_wheel_radius_mm,
                        source: "sim".into(),
                    })
                    .await
                    .is_err()
            {
                return;
            }
        }
    }
}

impl SimSource {
    fn grinder(&self) -> Option<SimGrinder> {
        let workpiece = match self.feature {
            Feature::Cam(g) => Workpiece::Cam(g),
            Feature::Pin(g) => Workpiece::Crankpin(g),
        };
        SimGrinder::new(self.grinder.clone(), workpiece, self.seed)
            .map_err(|e| error!(machine = %self.machine, error = %e, "simulator cannot start"))
            .ok()
    }

    /// The measurement as the machine receives it: encoded as CAN frames with the gauge's
    /// DBC, then decoded and assembled by the real decoder.
    fn through_the_bus(
        &self,
        dbc: &GaugeDbc,
        raw: &crate::core::measure::RawMeasurement,
    ) -> Option<crate::core::measure::RawMeasurement> {
        let frames = match measurement_frames(dbc, raw) {
            Ok(frames) => frames,
            Err(e) => {
                error!(machine = %self.machine, error = %e, "simulator: measurement not encodable");
                return None;
            }
        };
        let mut assembler = Assembler::new(format!("sim:{}", self.machine));
        let mut out = None;
        for (id, data) in frames {
            if let Ok(frame) = dbc.decode(id, &data)
                && let Some(Assembled::Measurement(m)) = assembler.push(frame)
            {
                out = Some(m);
            }
        }
        out
    }

    /// Runs the main program on the share through the simulated control; returns the coupled
    /// table and the version its program's provenance names (what a control would report
    /// with the part).
    fn run_control(&self, control: &mut Control) -> Option<(TableShape, Option<u64>)> {
        let main = match std::fs::read_to_string(&self.main_program) {
            Ok(t) => t,
            Err(e) => {
                warn!(machine = %self.machine, error = %e, "simulator: no main program on the share yet");
                return None;
            }
        };
        let dir = self
            .main_program
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        let load = |name: &str| std::fs::read_to_string(dir.join(format!("{name}.SPF"))).ok();
        match control.run(&main, &load) {
            Ok(coupled) => {
                let version = std::fs::read_to_string(&self.program)
                    .ok()
                    .and_then(|t| provenance_version(&t));
                Some((coupled.shape, version))
            }
            Err(e) => {
                error!(machine = %self.machine, error = %e, "simulated control: alarm");
                None
            }
        }
    }
}

/// The table version a program's provenance names (`; table version: vN`).
fn provenance_version(text: &str) -> Option<u64> {
    text.lines().find_map(|l| {
        let rest = l
            .strip_prefix(';')?
            .trim()
            .strip_prefix("table version v")?;
        rest.split(|c: char| !c.is_ascii_digit())
            .next()?
            .parse()
            .ok()
    })
}
