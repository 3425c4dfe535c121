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
use crate::service::machine::{GroundWith, InProcessOutcome, SourceEvent};
use crate::service::sources::Intake;
use crate::sim::cycle_cell::passes_stock;
use crate::sim::{Control, CycleEvent, CycleRun, SimGrinder, StationErrors};
use std::cell::{Cell, RefCell};
use std::collections::HashMap;
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

impl SimSource {
    /// Runs the whole-cycle program once (one shaft, `shaft`), sending each in-process
    /// measurement to the service and waiting for its answer at the control's first poll.
    /// Called off the async workers; None when the control alarms or the program is missing.
    pub(super) fn run_whole(
        &self,
        whole: &WholeCycle,
        control: &mut Control,
        sim: &mut SimGrinder,
        dbc: &crate::gauge::GaugeDbc,
        tx: &Intake,
        shaft: u64,
    ) -> Option<Finished> {
        let main = self.main_text()?;
        let dir = self.share_dir();
        let read = RefCell::new(HashMap::new());
        let load = |name: &str| {
            let text = std::fs::read_to_string(dir.join(format!("{name}.SPF"))).ok();
            if let Some(t) = &text {
                read.borrow_mut().insert(name.to_string(), t.clone());
            }
            text
        };
        // The control's run up to a measurement does not depend on its answer (each
        // feature's passes before it couple that feature's table in force): a dry run on a
        // copy gives the passes the gauge measures after.
        let dry = match control.clone().run_cycle(&main, &load) {
            Ok(run) => run,
            Err(e) => {
                error!(machine = %self.machine, error = %e, "simulated control: alarm");
                return None;
            }
        };
        let turned: Vec<usize> = (0..dry.events.len())
            .filter(|&i| matches!(dry.events[i], CycleEvent::Turned { .. }))
            .collect();
        let sim = RefCell::new(sim);
        let (state, measured) = (Cell::new(Handshake::Fresh), Cell::new(0usize));
        let answering = |name: &str| {
            if name != READY_PROGRAM {
                state.set(Handshake::Fresh);
            } else if state.get() == Handshake::Fresh {
                state.set(Handshake::Seen);
            } else if state.get() == Handshake::Seen {
                state.set(Handshake::Polling);
                if let Some(&at) = turned.get(measured.get()) {
                    let mut sim = sim.borrow_mut();
                    self.in_process(whole, &dry, at, &mut sim, tx, shaft);
                }
                measured.set(measured.get() + 1);
            }
            load(name)
        };
        let run = match control.run_cycle(&main, &answering) {
            Ok(run) => run,
            Err(e) => {
                error!(machine = %self.machine, error = %e, "simulated control: alarm");
                return None;
            }
        };
        let read = read.into_inner();
        let sim = sim.into_inner();
        Some(self.finish_shaft(whole, &run, &read, sim, dbc, shaft))
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
    ) {
        let Some(k) = dry.events[..at].iter().rev().find_map(|e| match e {
            CycleEvent::Ground(i) => self.station_at(&dry.ground[*i]),
            _ => None,
        }) else {
            return;
        };
        let Some(ground) = self.ground_from_passes(whole, dry, at, sim, k) else {
            return;
        };
        // Named as a drop folder's `*.in-process.csv` names it (machine and feature by
        // name), not through the CAN layout: its frames carry no stage.
        let labels = crate::sim::PartLabels {
            machine: self.machine.to_string(),
            part: shaft.to_string(),
            lobe: self.stations[k].name.to_string(),
        };
        let raw = sim.measure(&ground, &labels);
        let (done, verdict) = tokio::sync::oneshot::channel();
        let event = SourceEvent::InProcess {
            raw,
            part: None,
            received: std::time::Instant::now(),
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
    }

    /// Station `k` ground by its passes among `run`'s first `until` events: the outline of
    /// the last table they coupled with the stock and deflection they left.
    fn ground_from_passes(
        &self,
        whole: &WholeCycle,
        run: &CycleRun,
        until: usize,
        sim: &mut SimGrinder,
        k: usize,
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
        );
        let table = self.commanded(last?, k);
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

    /// Every feature the run finished, ground from all its passes and gauged, in order.
    fn finish_shaft(
        &self,
        whole: &WholeCycle,
        run: &CycleRun,
        read: &HashMap<String, String>,
        sim: &mut SimGrinder,
        dbc: &crate::gauge::GaugeDbc,
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
                .and_then(|g| read.get(&g.defined_by))
                .and_then(|t| super::ground_with(t));
            let ground = self.ground_from_passes(whole, run, usize::MAX, sim, k);
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
