//! The simulated machine as a gauge source: a simulated control runs the main program on the
//! share (which calls each feature's table program and couples the table it defines, tables
//! kept by number between parts as on the NC, from the feature the resume point names), the
//! grinder grinds the coupled table at the station where Z stands, and each measurement goes
//! out as CAN frames through the real DBC decoder and assembler in memory, exactly as a bus
//! would deliver it.

mod cycle;

pub(crate) use cycle::WholeCycle;

use super::machine::{GroundWith, MachineLoop, SourceEvent};
use super::offload;
use super::sources::Intake;
use crate::core::compensate::Feature;
use crate::gauge::{Assembled, Assembler, GaugeDbc};
use crate::names::{FeatureName, MachineName};
use crate::sim::{
    CommandedTable, Control, Coupled, GrinderConfig, PartLabels, SimGrinder, Workpiece,
    measurement_frames,
};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::watch;
use tracing::{error, warn};

/// The R parameter an operator sets to resume a shaft (the shaft program's default).
const RESUME_R_PARAM: u32 = 90;

/// A station ground at a Z this far from a feature's belongs to it, mm.
const STATION_WINDOW_MM: f64 = 0.5;

/// One feature of the simulated shaft: where it is and what it is.
pub(crate) struct SimStation {
    pub name: FeatureName,
    pub feature: Feature,
    pub z_mm: f64,
    /// The newest part (shaft) number this feature was ground for before this run.
    pub parts_done: u64,
    /// Wheel radius the feature's program on the share was made for.
    pub table_wheel_radius_bits: Arc<AtomicU64>,
    /// The nominal lift and where the feature's 0° is on the shaft: what a master reads.
    pub nominal: crate::core::lift::LiftTable,
    pub phase_deg: f64,
    /// The following axis' name in its programs (tells X's table from C's on the plan).
    pub x_axis: String,
}

pub(crate) struct SimSource {
    pub machine: MachineName,
    pub grinder: GrinderConfig,
    pub seed: u64,
    pub stations: Vec<SimStation>,
    /// The main program (what the control runs).
    pub main_program: PathBuf,
    pub part_interval: Duration,
    /// Stop after this many shafts (None: until shutdown).
    pub parts: Option<u64>,
    /// The recipe's whole cycle, when the main program runs it (`[cycle] program = "whole"`).
    pub cycle: Option<WholeCycle>,
}

impl SimSource {
    /// The simulated shaft of `machine`: its features at their stations.
    pub fn stations(machine: &MachineLoop) -> Vec<SimStation> {
        machine
            .features()
            .iter()
            .map(|f| SimStation {
                name: f.feature_name().clone(),
                feature: f.feature(),
                z_mm: f.setup().z_mm,
                parts_done: f.memory().last_part_number().unwrap_or(f.memory().parts),
                table_wheel_radius_bits: f.table_wheel_radius(),
                nominal: f.setup().nominal.clone(),
                phase_deg: f.setup().phase_deg,
                x_axis: f.setup().program.following_axis.clone(),
            })
            .collect()
    }

    /// Runs until shutdown (or the shaft count); each feature ground goes out as one event.
    pub async fn run(self, tx: Intake, mut shutdown: watch::Receiver<bool>) {
        let Some(first) = self.stations.first() else {
            return;
        };
        let Some(mut sim) = self.grinder(first.feature) else {
            return;
        };
        let dbc = GaugeDbc::builtin();
        let mut interval = tokio::time::interval(self.part_interval);
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let (mut runs, mut gauged) = (0u64, 0u64);
        // The shaft in the machine: a run that starts at the first feature loads a new one.
        let mut shaft = self
            .stations
            .iter()
            .map(|s| s.parts_done)
            .max()
            .unwrap_or(0);
        let mut control = Control::new();
        if self.cycle.is_some() {
            // The whole cycle superimposes the infeed on the coupled X: the PLC enables X's
            // overlay (DBX26.4) on a machine set up for it.
            control.enable_overlay();
        }
        // The operator resumes the shaft a stop interrupted (see the shaft program): the
        // first run grinds the rest of that shaft, not a new one.
        let mut resuming = self.resume_pending();
        if resuming {
            control.set_r_param(RESUME_R_PARAM, -1.0);
        }
        loop {
            tokio::select! {
                _ = interval.tick() => {}
                _ = shutdown.changed() => return,
            }
            if *shutdown.borrow() || self.parts.is_some_and(|n| runs >= n) {
                return;
            }
            let gauge = &self.grinder.gauge;
            if gauge.master_runs > 0
                && shaft + 1 == gauge.master_before_part
                && !self.gauge_study(&mut sim, &dbc, &tx, &shutdown).await
            {
                return;
            }
            if let Some(whole) = &self.cycle {
                // A resumed run (R90 < 0, the program starts at the resume point) finishes
                // the shaft in the machine; every other run grinds a new one.
                let next = if resuming { shaft.max(1) } else { shaft + 1 };
                let finished = offload::blocking(|| {
                    self.run_whole(whole, &mut control, &mut sim, &dbc, &tx, next)
                });
                let Some(finished) = finished else { continue };
                (runs, shaft, resuming) = (runs + 1, next, false);
                for (raw, ground_with) in finished {
                    // A stop between features interrupts the shaft: the resume point on the
                    // share names the first feature not gauged.
                    if *shutdown.borrow() || !send_and_wait(&tx, raw, ground_with).await {
                        return;
                    }
                }
                if let Some(d) = sim.after_part()
                    && !send_dressing(&tx, d).await
                {
                    return;
                }
                continue;
            }
            // The control runs the main program, which calls the table programs: the tables
            // it couples are what gets ground, at the stations where Z stands.
            let Some(grinds) = offload::blocking(|| self.run_control(&mut control)) else {
                continue;
            };
            runs += 1;
            if grinds.first().and_then(|(c, _)| self.station_at(c)) == Some(0) || shaft == 0 {
                shaft += 1;
            }
            let shaft_run = ShaftRun {
                tx: &tx,
                shutdown: &shutdown,
                dbc: &dbc,
                shaft,
            };
            if !self
                .grind_shaft(&mut sim, grinds, &shaft_run, &mut gauged)
                .await
            {
                return;
            }
            if let Some(d) = sim.after_part()
                && !send_dressing(&tx, d).await
            {
                return;
            }
        }
    }

    /// The operator puts the master in before this shaft: a type-1 gauge study, every
    /// station measured `master_runs` times. False when the run must end.
    async fn gauge_study(
        &self,
        sim: &mut SimGrinder,
        dbc: &GaugeDbc,
        tx: &Intake,
        shutdown: &watch::Receiver<bool>,
    ) -> bool {
        for k in 0..self.stations.len() {
            for _ in 0..self.grinder.gauge.master_runs {
                if *shutdown.borrow() {
                    return false;
                }
                if let Some(m) = self.master_run(sim, dbc, k)
                    && !send_and_wait(tx, m, None).await
                {
                    return false;
                }
            }
        }
        true
    }

    /// Grinds and gauges each feature the control coupled, in order. False when the run
    /// must end.
    async fn grind_shaft(
        &self,
        sim: &mut SimGrinder,
        grinds: Vec<(Coupled, Option<GroundWith>)>,
        run: &ShaftRun<'_>,
        gauged: &mut u64,
    ) -> bool {
        let last = grinds.len().saturating_sub(1);
        for (i, (coupled, ground_with)) in grinds.into_iter().enumerate() {
            if *run.shutdown.borrow() {
                // A stop between features interrupts the shaft: the resume point on the
                // share names the first feature not gauged.
                return false;
            }
            if let Some(k) = self.station_at(&coupled) {
                *gauged += 1;
                // The grinding is computed and the share's programs read off the async workers.
                let event = offload::blocking(|| {
                    self.grind_and_gauge(sim, run.dbc, &coupled, k, run.shaft, *gauged)
                });
                if let Some(m) = event
                    && !send_and_wait(run.tx, m, ground_with).await
                {
                    return false;
                }
            }
            if i < last {
                sim.after_feature();
            }
        }
        true
    }

    /// The resume point on the share names a feature after the first: a stop interrupted the
    /// shaft in the machine.
    fn resume_pending(&self) -> bool {
        let path = self
            .share_dir()
            .join(format!("{}.SPF", crate::core::program::RESUME_PROGRAM));
        std::fs::read_to_string(path)
            .ok()
            .and_then(|t| crate::core::program::parse_resume_program(&t))
            .is_some_and(|k| k > 1)
    }

    /// The station whose Z the control stood at while grinding (a one-feature program moves
    /// no Z: the one feature is where the wheel is).
    fn station_at(&self, coupled: &Coupled) -> Option<usize> {
        if self.stations.len() == 1 {
            return Some(0);
        }
        let k = self
            .stations
            .iter()
            .position(|s| (s.z_mm - coupled.z_mm).abs() <= STATION_WINDOW_MM);
        if k.is_none() {
            error!(machine = %self.machine, z_mm = coupled.z_mm, "simulator: the control ground at a Z where the shaft has no feature");
        }
        k
    }

    /// Grinds station `k` with the coupled table and gauges it as part `shaft`; the gauge's
    /// labels go wrong now and then when the config says so.
    fn grind_and_gauge(
        &self,
        sim: &mut SimGrinder,
        dbc: &GaugeDbc,
        coupled: &Coupled,
        k: usize,
        shaft: u64,
        gauged: u64,
    ) -> Option<crate::core::measure::RawMeasurement> {
        let station = &self.stations[k];
        let table = self.commanded(coupled, k);
        let errors = self.grinder.shaft.station(k + 1, station.z_mm);
        let ground = match sim.grind_station(&table, &workpiece(station.feature), &errors) {
            Ok(g) => g,
            Err(e) => {
                error!(machine = %self.machine, lobe = %station.name, error = %e, "simulator: the table cannot be ground");
                return None;
            }
        };
        self.gauge(sim, dbc, &ground, k, shaft, Some(gauged))
    }

    /// The table station `k` was ground with, as the grinder takes it: the coupled shape on
    /// the wheel the feature's program on the share was made for.
    fn commanded(&self, coupled: &Coupled, k: usize) -> CommandedTable {
        let mut table = self.commanded_shape(coupled.shape.clone(), k);
        table.plan = coupled.planned_speed();
        table
    }

    /// Table `shape` for station `k` on the wheel its program was made for, at constant C.
    fn commanded_shape(&self, shape: crate::sim::TableShape, k: usize) -> CommandedTable {
        let station = &self.stations[k];
        let table_r = f64::from_bits(station.table_wheel_radius_bits.load(Ordering::SeqCst));
        let feature = station.feature;
        CommandedTable {
            shape,
            x_zero_mm: table_r + feature.x_zero_mm() - feature.wheel_radius_mm(),
            wheel_radius_mm: table_r,
            plan: None,
        }
    }

    /// Measures `ground` (station `k`) as part `shaft` through the bus. With `gauged` (the
    /// count of features gauged so far), the labels go wrong now and then when the config
    /// says so; without, they are right.
    fn gauge(
        &self,
        sim: &mut SimGrinder,
        dbc: &GaugeDbc,
        ground: &crate::sim::GroundPart,
        k: usize,
        shaft: u64,
        gauged: Option<u64>,
    ) -> Option<crate::core::measure::RawMeasurement> {
        let every = |n: u32| n > 0 && gauged.is_some_and(|g| g.is_multiple_of(u64::from(n)));
        let n = self.stations.len();
        let lobe = if every(self.grinder.shaft.unknown_lobe_every) {
            n + 1
        } else if every(self.grinder.shaft.wrong_lobe_every) && n > 1 {
            (k + 1) % n + 1
        } else {
            k + 1
        };
        // The CAN layout carries numeric ids: machine 1, the lobe's position in the recipe.
        let labels = PartLabels {
            machine: "1".into(),
            part: shaft.to_string(),
            lobe: lobe.to_string(),
        };
        let raw = sim.measure(ground, &labels);
        self.through_the_bus(dbc, &raw)
    }

    /// One gauge run of the master part at station `k`: the nominal lift, read in the shaft's
    /// frame with the gauge's noise, sent as part `MASTER` through the bus.
    fn master_run(
        &self,
        sim: &mut SimGrinder,
        dbc: &GaugeDbc,
        k: usize,
    ) -> Option<crate::core::measure::RawMeasurement> {
        let station = &self.stations[k];
        let curve = crate::core::lift::LiftCurve::new(&station.nominal);
        let n = self.grinder.gauge.points_per_rev;
        let truth: Vec<f64> = (0..n)
            .map(|j| curve.lift_mm(f64::from(j) * 360.0 / f64::from(n) - station.phase_deg))
            .collect();
        let labels = PartLabels {
            machine: "1".into(),
            part: crate::gauge::assemble::MASTER_PART.into(),
            lobe: (k + 1).to_string(),
        };
        let raw = sim.measure_master(&truth, &labels);
        self.through_the_bus(dbc, &raw)
    }

    fn grinder(&self, feature: Feature) -> Option<SimGrinder> {
        SimGrinder::new(self.grinder.clone(), workpiece(feature), self.seed)
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

    /// Runs the main program on the share through the simulated control; returns every
    /// grind with what the control reports of its table (a control alarm is logged and the
    /// shaft skipped).
    fn run_control(&self, control: &mut Control) -> Option<Vec<(Coupled, Option<GroundWith>)>> {
        let main = self.main_text()?;
        let dir = self.share_dir();
        // The texts the control read, as it read them: the share may change while it grinds.
        let read = std::cell::RefCell::new(std::collections::HashMap::new());
        let load = |name: &str| {
            let text = std::fs::read_to_string(dir.join(format!("{name}.SPF"))).ok();
            if let Some(t) = &text {
                read.borrow_mut().insert(name.to_string(), t.clone());
            }
            text
        };
        match control.run_all(&main, &load) {
            Ok(grinds) => {
                let read = read.borrow();
                Some(
                    grinds
                        .into_iter()
                        .map(|c| {
                            let g = read.get(&c.defined_by).and_then(|t| ground_with(t));
                            (c, g)
                        })
                        .collect(),
                )
            }
            Err(e) => {
                error!(machine = %self.machine, error = %e, "simulated control: alarm");
                None
            }
        }
    }

    /// The main program on the share, as the control loads it.
    fn main_text(&self) -> Option<String> {
        std::fs::read_to_string(&self.main_program)
            .map_err(|e| warn!(machine = %self.machine, error = %e, "simulator: no main program on the share yet"))
            .ok()
    }

    fn share_dir(&self) -> PathBuf {
        self.main_program
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default()
    }
}

/// What the control reports of the table that ground a part: the feature and version its
/// defining program's provenance names.
fn ground_with(text: &str) -> Option<GroundWith> {
    {
        let version = provenance_field(text, "table version:")?
            .trim()
            .strip_prefix('v')?
            .split(|c: char| !c.is_ascii_digit())
            .next()?
            .parse()
            .ok()?;
        let feature = provenance_field(text, "feature:").map(|f| f.trim().to_string());
        Some(GroundWith { feature, version })
    }
}

fn workpiece(feature: Feature) -> Workpiece {
    match feature {
        Feature::Cam(g) => Workpiece::Cam(g),
        Feature::Pin(g) => Workpiece::Crankpin(g),
    }
}

/// Sends one measurement and waits until the machine has its next table out, as a real
/// machine waits between parts. False when the machine is gone.
/// What grinding one shaft needs from the run.
struct ShaftRun<'a> {
    tx: &'a Intake,
    shutdown: &'a watch::Receiver<bool>,
    dbc: &'a GaugeDbc,
    /// The shaft's number.
    shaft: u64,
}

/// A dressing after the part: the machine regenerates every table before the next shaft,
/// as it would between parts. False when the receiver is gone.
async fn send_dressing(tx: &Intake, d: crate::sim::DressingEvent) -> bool {
    let (done, regenerated) = tokio::sync::oneshot::channel();
    let event = SourceEvent::Dressing {
        wheel_radius_mm: d.believed_wheel_radius_mm,
        infeed_um: d.measured_infeed_um,
        source: "sim".into(),
        done: Some(done),
    };
    if tx.send(event).await.is_err() {
        return false;
    }
    let _ = regenerated.await;
    true
}

async fn send_and_wait(
    tx: &Intake,
    raw: crate::core::measure::RawMeasurement,
    ground_with: Option<GroundWith>,
) -> bool {
    let (done, processed) = tokio::sync::oneshot::channel();
    let event = SourceEvent::Measurement {
        raw,
        ground_with,
        done: Some(done),
    };
    if tx.send(event).await.is_err() {
        return false;
    }
    let _ = processed.await;
    true
}

/// The rest of the provenance comment line that starts with `key` (`; <key>…`).
fn provenance_field<'t>(text: &'t str, key: &str) -> Option<&'t str> {
    text.lines()
        .find_map(|l| l.strip_prefix(';')?.trim().strip_prefix(key))
}
