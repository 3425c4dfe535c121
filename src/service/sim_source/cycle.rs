//! The whole grinding cycle on the simulated machine: the simulated control runs the
//! whole-cycle main program from the share; when it asks the handshake after a measure
//! stage, the simulated gauge has measured that feature with its stock still on and the
//! measurement has gone to the service as an in-process one (the drop folder's
//! `*.in-process.csv` way), so the share holds this part's finish table and the moved count
//! by the time the control reads them; the finish couples what the table program then
//! defines. Each finished feature is ground from its passes (stock and wheel-head deflection)
//! and gauged as any part, reporting the table its last coupling took.

use super::SimSource;
use crate::core::cycle::CycleSettings;
use crate::core::measure::RawMeasurement;
use crate::core::program::READY_PROGRAM;
use crate::gauge::GaugeDbc;
use crate::service::machine::{GroundWith, InProcessOutcome, SourceEvent};
use crate::service::sources::Intake;
use crate::sim::cycle_cell::passes_stock;
use crate::sim::{Control, CycleEvent, CycleRun, SimGrinder, StationErrors};
use std::cell::RefCell;
use tracing::{error, info, warn};

/// The whole cycle the machine's program runs, and what the grinder needs of each feature.
pub(crate) struct WholeCycle {
    pub cycle: CycleSettings,
    /// Per station: the contact's arc per radian of C ([`crate::sim::cycle_cell::stock_surface`]).
    pub surfaces: Vec<Vec<f64>>,
}

/// Where the control is in a feature's handshake, from its calls of the handshake program.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Handshake {
    /// No measurement yet since the last table call.
    Fresh,
    /// The count read before the gauge went in: the next call is the first poll after it.
    Seen,
    /// Polling: the in-process measurement has gone to the service.
    Polling,
}

/// What one whole-cycle run of a shaft gave: each finished feature's measurement with the
/// table its last coupling took, in the order ground.
pub(super) type Finished = Vec<(RawMeasurement, Option<GroundWith>)>;

/// What the answering control has done so far in one run.
struct Progress {
    handshake: Handshake,
    /// The station whose measurement went to the service last, not yet finished.
    measured: Option<usize>,
    /// The table text the control loaded after that station's handshake (its finish's).
    finish_text: Option<String>,
    /// Measurements sent so far (indexes the dry run's measure events).
    sent: usize,
    finished: Finished,
}

impl SimSource {
    /// Runs the whole-cycle program once (one shaft, `shaft`), sending each in-process
    /// measurement to the service and waiting for its answer at the control's first poll.
    /// Called off the async workers; None when the control alarms or the program is missing.
    ///
    /// The grinder works in the machine's order: feature k to size under its stock,
    /// measured, finished with the table the control loaded after the handshake, then the
    /// wheel's wear before feature k + 1. The passes come from a dry run of the same program
    /// on a copy of the control (their geometry does not depend on the answer, only the
    /// finish's table does), checked against the real run's afterwards.
    pub(super) fn run_whole(
        &self,
        whole: &WholeCycle,
        control: &mut Control,
        sim: &mut SimGrinder,
        dbc: &GaugeDbc,
        tx: &Intake,
        shaft: u64,
    ) -> Option<Finished> {
        let main = self.main_text()?;
        let dir = self.share_dir();
        let load = |name: &str| std::fs::read_to_string(dir.join(format!("{name}.SPF"))).ok();
        let alarm = |e: crate::sim::ControlError| {
            error!(machine = %self.machine, error = %e, "simulated control: alarm");
        };
        let dry = control
            .clone()
            .run_cycle(&main, &load)
            .map_err(alarm)
            .ok()?;
        if whole.cycle.measure_stage().is_none() {
            let run = control.run_cycle(&main, &load).map_err(alarm).ok()?;
            return Some(self.finish_after(whole, &run, &load, sim, dbc, shaft));
        }
        let turned: Vec<usize> = (0..dry.events.len())
            .filter(|&i| matches!(dry.events[i], CycleEvent::Turned { .. }))
            .collect();
        let sim = RefCell::new(sim);
        let progress = RefCell::new(Progress {
            handshake: Handshake::Fresh,
            measured: None,
            finish_text: None,
            sent: 0,
            finished: Vec::new(),
        });
        let answering = |name: &str| {
            let text = load(name);
            let mut p = progress.borrow_mut();
            let mut sim = sim.borrow_mut();
            match (name == READY_PROGRAM, p.handshake) {
                (false, Handshake::Polling) => {
                    p.finish_text.clone_from(&text);
                    p.handshake = Handshake::Fresh;
                }
                (false, _) => p.handshake = Handshake::Fresh,
                (true, Handshake::Fresh) => {
                    // A new feature's measurement is next: the last one is finished by now.
                    self.finish_measured(whole, &dry, &mut p, &mut sim, dbc, shaft);
                    p.handshake = Handshake::Seen;
                }
                (true, Handshake::Seen) => {
                    p.handshake = Handshake::Polling;
                    if let Some(&at) = turned.get(p.sent) {
                        p.measured = self.in_process(whole, &dry, at, &mut sim, tx, shaft);
                    }
                    p.sent += 1;
                }
                (true, Handshake::Polling) => {}
            }
            text
        };
        let run = control.run_cycle(&main, &answering).map_err(alarm).ok()?;
        let mut p = progress.into_inner();
        let sim = sim.into_inner();
        self.finish_measured(whole, &dry, &mut p, sim, dbc, shaft);
        let passes = |r: &CycleRun| -> Vec<(f64, f64, f64, f64)> {
            r.ground
                .iter()
                .map(|g| (g.x_offset_mm, g.x_infeed_mm, g.revolutions, g.z_mm))
                .collect()
        };
        if passes(&run) != passes(&dry) {
            error!(machine = %self.machine, "simulator: the control's passes differ from its dry run's; shaft not gauged");
            return None;
        }
        Some(p.finished)
    }

    /// Finishes the station measured last (if any): ground from all its passes with the
    /// finish's table, gauged, and the wheel's wear before the next feature.
    fn finish_measured(
        &self,
        whole: &WholeCycle,
        dry: &CycleRun,
        p: &mut Progress,
        sim: &mut SimGrinder,
        dbc: &GaugeDbc,
        shaft: u64,
    ) {
        let Some(k) = p.measured.take() else {
            return;
        };
        let text = p.finish_text.take();
        let shape = text
            .as_deref()
            .and_then(|t| finish_tables(t, &self.stations[k]));
        let ground_with = text.as_deref().and_then(super::ground_with);
        let ground = self.ground_from_passes(whole, dry, usize::MAX, sim, k, shape);
        if let Some(raw) = ground.and_then(|g| self.gauge(sim, dbc, &g, k, shaft, None)) {
            p.finished.push((raw, ground_with));
        }
        sim.after_feature();
    }

    /// The feature measured at event `at` of `dry`: ground from its passes so far, measured
    /// with stock on, sent as an in-process measurement; waits for what the service made of
    /// it (the table and the count on the share, or why not).
    fn in_process(
        &self,
        whole: &WholeCycle,
        dry: &CycleRun,
        at: usize,
        sim: &mut SimGrinder,
        tx: &Intake,
        shaft: u64,
    ) -> Option<usize> {
        let k = dry.events[..at].iter().rev().find_map(|e| match e {
            CycleEvent::Ground(i) => self.station_at(&dry.ground[*i]),
            _ => None,
        })?;
        let ground = self.ground_from_passes(whole, dry, at, sim, k, None)?;
        // Named as a drop folder's `*.in-process.csv` names it (machine and feature by
        // name), not through the CAN layout: its frames carry no stage.
        let labels = crate::sim::PartLabels {
            machine: self.machine.to_string(),
            part: shaft.to_string(),
            lobe: self.stations[k].name.to_string(),
        };
        let raw = sim.measure_in_process(&ground, &labels);
        let (done, verdict) = tokio::sync::oneshot::channel();
        // The gauge's handover: the reading reaches camloop that long after the control began
        // its wait (the control's time runs on while the gauge evaluates and sends).
        let now = std::time::Instant::now();
        // Validated within 0..=3600 s with the config.
        let handover =
            std::time::Duration::try_from_secs_f64(self.grinder.gauge.in_process.handover_s)
                .unwrap_or_default();
        let event = SourceEvent::InProcess {
            raw,
            part: None,
            received: now.checked_sub(handover).unwrap_or(now),
            done: Some(done),
        };
        // The control waits at its poll while the service answers; on the service's
        // multi-threaded runtime this thread has handed its async work on (`offload`).
        let outcome = super::super::offload::wait(async {
            tx.send(event).await.ok()?;
            verdict.await.ok()
        })
        .flatten();
        let lobe = &self.stations[k].name;
        match outcome {
            Some(InProcessOutcome::Delivered { version, ready }) => {
                info!(machine = %self.machine, lobe = %lobe, version, ready, "simulator: this part's finish table is on the share");
            }
            Some(other) => {
                warn!(machine = %self.machine, lobe = %lobe, outcome = ?other, "simulator: the finish grinds with the table in force");
            }
            None => {
                warn!(machine = %self.machine, lobe = %lobe, "simulator: no answer to the in-process measurement")
            }
        }
        Some(k)
    }

    /// Station `k` ground by its passes among `run`'s first `until` events: the outline of
    /// the last table they coupled (or `shape`, the one the control really loaded for the
    /// finish) with the stock and deflection they left.
    fn ground_from_passes(
        &self,
        whole: &WholeCycle,
        run: &CycleRun,
        until: usize,
        sim: &mut SimGrinder,
        k: usize,
        shape: Option<FinishTables>,
    ) -> Option<crate::sim::GroundPart> {
        let station = &self.stations[k];
        let (stock, last) = passes_stock(
            &self.grinder.stock,
            &whole.cycle,
            run,
            &whole.surfaces[k],
            station.feature.wheel_radius_mm(),
            until,
            &|g| self.station_at(g) == Some(k),
        )
        .map_err(|e| error!(machine = %self.machine, lobe = %station.name, error = %e, "simulator: the plan's C table cannot be run"))
        .ok()?;
        let table = match shape {
            Some(loaded) => {
                let mut table = self.commanded_shape(loaded.x, k);
                // On the plan: C's law from the tables loaded, at the speed the run's last
                // coupling gave the virtual axis (the main program's, not the table's).
                table.plan = match (loaded.c_law, last.and_then(|g| g.planned_speed())) {
                    (Some(c_law), Some(run)) => Some(crate::sim::PlannedSpeed {
                        c_law,
                        va_speed_rpm: run.va_speed_rpm,
                    }),
                    _ => None,
                };
                table
            }
            None => self.commanded(last?, k),
        };
        let own = self.grinder.shaft.station(k + 1, station.z_mm);
        let stock = stock.as_errors(self.grinder.stock.orders);
        let errors = StationErrors {
            size_um: own.size_um + stock.size_um,
            lag_deg: own.lag_deg + stock.lag_deg,
            harmonics: own.harmonics.into_iter().chain(stock.harmonics).collect(),
        };
        sim.grind_station(&table, &super::workpiece(station.feature), &errors)
            .map_err(|e| error!(machine = %self.machine, lobe = %station.name, error = %e, "simulator: the table cannot be ground"))
            .ok()
    }

    /// Without a measure stage: every feature the run finished, ground from all its passes
    /// and gauged in order, with the wheel's wear between features.
    fn finish_after(
        &self,
        whole: &WholeCycle,
        run: &CycleRun,
        load: &dyn Fn(&str) -> Option<String>,
        sim: &mut SimGrinder,
        dbc: &GaugeDbc,
        shaft: u64,
    ) -> Finished {
        let mut order: Vec<usize> = Vec::new();
        for g in &run.ground {
            if let Some(k) = self.station_at(g)
                && order.last() != Some(&k)
            {
                order.push(k);
            }
        }
        let mut out = Vec::new();
        for (i, &k) in order.iter().enumerate() {
            let last = run
                .ground
                .iter()
                .rev()
                .find(|g| self.station_at(g) == Some(k));
            let ground_with = last
                .and_then(|g| load(&g.defined_by))
                .and_then(|t| super::ground_with(&t));
            let ground = self.ground_from_passes(whole, run, usize::MAX, sim, k, None);
            if let Some(raw) = ground.and_then(|g| self.gauge(sim, dbc, &g, k, shaft, None)) {
                out.push((raw, ground_with));
            }
            if i + 1 < order.len() {
                sim.after_feature();
            }
        }
        out
    }
}

/// The finish's tables as the control loaded them: X's shape (over C, or over VA on the plan)
/// and, on the plan, C's law over VA.
pub(super) struct FinishTables {
    x: crate::sim::TableShape,
    c_law: Option<Vec<crate::core::table::PolySegment>>,
}

/// The tables of the program the finish called: the constant-speed table program (one
/// table), or the plan's (C's table, then X's, told apart by their following axis).
fn finish_tables(text: &str, station: &super::SimStation) -> Option<FinishTables> {
    use crate::core::program::{ParsedShape, parse_table_program, table_definitions};
    let tables: Vec<_> = table_definitions(text)
        .iter()
        .filter_map(|t| parse_table_program(t).ok())
        .collect();
    let x_axis = &station.x_axis;
    let x = tables
        .iter()
        .find(|t| t.following_axis.eq_ignore_ascii_case(x_axis))?;
    let c_law = tables
        .iter()
        .find(|t| !t.following_axis.eq_ignore_ascii_case(x_axis))
        .and_then(|t| match &t.shape {
            ParsedShape::Poly(segments) => Some(segments.clone()),
            ParsedShape::G1(_) => None,
        });
    Some(FinishTables {
        x: crate::sim::table_shape(&x.shape),
        c_law,
    })
}
