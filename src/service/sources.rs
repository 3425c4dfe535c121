//! The gauge sources a machine can have: the simulated machine, a drop folder, a live CAN bus
//! or serial port. Each runs as its own task and hands the machine [`SourceEvent`]s.

use super::machine::{MachineLoop, SourceEvent};
use super::{drop_source, sim_source};
use crate::config::{Config, GaugeSection, MachineSection};
use crate::names::MachineName;
use anyhow::Context;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tracing::{error, info, warn};

/// Where a gauge source hands its events to the machine's loop: the loop's channel, with
/// every measurement counted into the backlog (see [`super::backlog`]) from the moment it
/// is handed over, so a loop that cannot keep up shows as lag.
#[derive(Clone)]
pub(crate) struct Intake {
    tx: mpsc::Sender<SourceEvent>,
    machine: MachineName,
    metrics: Arc<super::metrics::Metrics>,
}

impl Intake {
    pub(crate) fn new(
        tx: mpsc::Sender<SourceEvent>,
        machine: MachineName,
        metrics: Arc<super::metrics::Metrics>,
    ) -> Self {
        Self {
            tx,
            machine,
            metrics,
        }
    }

    /// Hands `event` to the loop, waiting while its channel is full (backpressure).
    pub(crate) async fn send(
        &self,
        event: SourceEvent,
    ) -> Result<(), mpsc::error::SendError<SourceEvent>> {
        let measurement = matches!(event, SourceEvent::Measurement { .. });
        if measurement {
            // Stamped before the wait for a slot: a full channel is lag too.
            self.metrics
                .backlog
                .received(&self.machine, std::time::Instant::now());
        }
        let sent = self.tx.send(event).await;
        if sent.is_err() && measurement {
            // The loop has stopped: the event stays with its source.
            self.metrics.backlog.forget(&self.machine);
        }
        sent
    }
}

/// Starts the source of machine `m` feeding `tx`.
pub(super) fn spawn(
    config: &Config,
    m: &MachineSection,
    machine: &MachineLoop,
    sim_c_speed_explicit: bool,
    tx: Intake,
    parts: Option<u64>,
    shutdown: watch::Receiver<bool>,
) -> anyhow::Result<()> {
    match &m.gauge {
        GaugeSection::Sim {
            part_interval_ms,
            seed,
            grinder,
        } => {
            let mut grinder = grinder.clone();
            let recipe_rpm = machine
                .features()
                .first()
                .map_or(grinder.c_speed_rpm, |f| f.setup().limits.c_speed_rpm);
            if !sim_c_speed_explicit {
                // One C speed: the simulator grinds at the recipe's (or the machine's).
                grinder.c_speed_rpm = recipe_rpm;
            } else if grinder.c_speed_rpm != recipe_rpm {
                warn!(machine = %m.name, sim_rpm = grinder.c_speed_rpm, recipe_rpm, "the simulator grinds at its own C speed (gauge.grinder.c_speed_rpm), not the recipe's");
            }
            let source = sim_source::SimSource {
                machine: machine.name.clone(),
                grinder: *grinder,
                seed: *seed,
                stations: sim_source::SimSource::stations(machine),
                main_program: machine.main_program_path(),
                part_interval: Duration::from_millis(*part_interval_ms),
                parts,
                cycle: whole_cycle(machine)?,
            };
            tokio::spawn(source.run(tx, shutdown));
        }
        GaugeSection::Drop {
            folder, poll_ms, ..
        } => {
            tokio::spawn(drop_source::run(
                machine.name.clone(),
                config.resolve(folder),
                *poll_ms,
                m.gauge.drop_options().unwrap_or_default(),
                tx,
                shutdown,
            ));
        }
        GaugeSection::Can { interface, dbc } => {
            let names = crate::gauge::GaugeSignalNames::default();
            let dbc = crate::gauge::GaugeDbc::load(&config.resolve(dbc), &names)
                .with_context(|| format!("machine {}: gauge DBC", m.name))?;
            let spec = LiveSpec::Can {
                interface: interface.clone(),
                dbc: Box::new(dbc),
            };
            tokio::spawn(live_source(machine.name.clone(), spec, tx, shutdown));
        }
        GaugeSection::Serial { port, baud } => {
            let spec = LiveSpec::Serial {
                port: port.clone(),
                baud: *baud,
            };
            tokio::spawn(live_source(machine.name.clone(), spec, tx, shutdown));
        }
    }
    Ok(())
}

/// A live gauge connection: a SocketCAN bus through the DBC, or a serial port speaking the
/// line protocol.
enum LiveGauge {
    Can(Box<crate::gauge::CanGauge<crate::gauge::CanBus>>),
    Serial(Box<crate::gauge::SerialGauge<tokio_serial::SerialStream>>),
}

/// How to open a live gauge again after it failed.
#[derive(Clone)]
enum LiveSpec {
    Can {
        interface: String,
        dbc: Box<crate::gauge::GaugeDbc>,
    },
    Serial {
        port: String,
        baud: u32,
    },
}

impl LiveSpec {
    fn name(&self) -> &str {
        match self {
            LiveSpec::Can { interface, .. } => interface,
            LiveSpec::Serial { port, .. } => port,
        }
    }

    fn open(&self) -> Result<LiveGauge, String> {
        match self {
            LiveSpec::Can { interface, dbc } => {
                crate::gauge::CanGauge::open(interface, (**dbc).clone())
                    .map(|g| LiveGauge::Can(Box::new(g)))
                    .map_err(|e| e.to_string())
            }
            LiveSpec::Serial { port, baud } => crate::gauge::SerialGauge::open(port, *baud)
                .map(|g| LiveGauge::Serial(Box::new(g)))
                .map_err(|e| e.to_string()),
        }
    }
}

impl LiveGauge {
    /// The next measurement, a problem to log, or `None` when the connection ended.
    async fn next(
        &mut self,
    ) -> std::io::Result<Option<Result<crate::core::measure::RawMeasurement, String>>> {
        Ok(match self {
            LiveGauge::Can(g) => g.next_event().await?.map(|e| match e {
                crate::gauge::CanEvent::Measurement(m) => Ok(m),
                other => Err(format!("{other:?}")),
            }),
            LiveGauge::Serial(g) => g.next_event().await?.map(|e| match e {
                crate::gauge::SerialEvent::Measurement(m) => Ok(m),
                crate::gauge::SerialEvent::Problem(p) => Err(format!("{p:?}")),
            }),
        })
    }
}

/// A live gauge. One that cannot be opened (missing device, a kernel without SocketCAN) or
/// that fails is an ERROR naming it, retried every 10 s; never a panic, never fatal.
async fn live_source(
    machine: MachineName,
    spec: LiveSpec,
    tx: Intake,
    mut shutdown: watch::Receiver<bool>,
) {
    loop {
        match spec.open() {
            Ok(mut gauge) => {
                info!(machine = %machine, gauge = %spec.name(), "gauge listening");
                loop {
                    let event = tokio::select! {
                        e = gauge.next() => e,
                        _ = shutdown.changed() => return,
                    };
                    match event {
                        Ok(Some(Ok(m))) => {
                            if tx
                                .send(SourceEvent::Measurement {
                                    raw: m,
                                    ground_with: None,
                                    done: None,
                                })
                                .await
                                .is_err()
                            {
                                return;
                            }
                        }
                        Ok(Some(Err(problem))) => {
                            warn!(machine = %machine, problem = %problem, "gauge data discarded")
                        }
                        Ok(None) => break,
                        Err(e) => {
                            error!(machine = %machine, gauge = %spec.name(), error = %e, "gauge read failed");
                            break;
                        }
                    }
                }
            }
            Err(e) => error!(machine = %machine, error = %e, "gauge unavailable; retrying in 10 s"),
        }
        tokio::select! {
            _ = tokio::time::sleep(Duration::from_secs(10)) => {}
            _ = shutdown.changed() => return,
        }
    }
}

/// The machine's whole cycle for the simulator, when its main program runs one.
fn whole_cycle(machine: &MachineLoop) -> anyhow::Result<Option<sim_source::WholeCycle>> {
    let Some(cycle) = machine
        .features()
        .first()
        .and_then(|f| f.setup().cycle.clone())
        .filter(|c| c.program == crate::core::cycle::CycleProgram::Whole)
    else {
        return Ok(None);
    };
    let surfaces = machine
        .features()
        .iter()
        .map(|f| {
            crate::sim::cycle_cell::stock_surface(f.feature(), &f.setup().nominal)
                .with_context(|| format!("machine {}: {}", machine.name, f.setup().name))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(Some(sim_source::WholeCycle { cycle, surfaces }))
}
