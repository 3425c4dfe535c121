//! The in-process cell: one feature ground part after part through the whole cycle. The
//! simulated control runs camloop's cycle program (overlay and handshake included); the
//! grinder removes the stock pass by pass ([`crate::stock`]); before the finish the gauge
//! measures with stock on, camloop makes this part's finish table
//! ([`camloop_core::cycle::finish::finish_table`]) and answers the handshake after a set
//! number of polls; the finished part is judged on the fine grid and learned from once.

use super::cell::{CellError, CellSetup, JUDGE_POINTS, after_dressing, judge, plan_law};
use super::stock::{Pass, PlanPass, STOCK_POINTS, Stock, StockModel};
use super::{
    CommandedTable, Control, ControlError, Coupled, CycleEvent, CycleRun, PartLabels, SimGrinder,
    StationErrors, Workpiece,
};
use camloop_core::compensate::{self, Feature, GuardedTable, LobeLoop};
use camloop_core::cycle::finish::{InProcess, finish_table};
use camloop_core::cycle::{CycleSettings, StageKind};
use camloop_core::learn::LearningState;
use camloop_core::lift::{LiftCurve, LiftTable};
use camloop_core::measure::AssemblyLimits;
use camloop_core::program::{
    CycleMachine, CyclePlan, CycleProgramError, CycleStation, MainProgramSettings, ProgramSettings,
    READY_PROGRAM, TableError, clear_x_mm, next_table_number, render_cycle_program,
    render_ready_program,
};
use camloop_core::speed_plan::ProfileSamples;
use camloop_core::speed_plan::render::{
    VaProgramError, VaProgramSettings, render_va_table_program,
};
use camloop_core::speed_plan::tables::VaTables;
use camloop_core::turn::{self, Decision, TurnSetup};
use std::cell::Cell;

const TABLE_PROGRAM: &str = "CELL_TABLE";
const TABLE_PAIR: (u32, u32) = (1, 2);
/// With the speed plan (`cell.speed_plan.enabled`): the plan's table program and the pairs
/// its X and C tables alternate in.
const PLAN_PROGRAM: &str = "CELL_PLAN";
const PLAN_PAIRS: [(u32, u32); 2] = [(3, 4), (5, 6)];

/// How the in-process cell runs.
#[derive(Debug, Clone)]
pub struct CycleCellSetup {
    pub cell: CellSetup,
    pub cycle: CycleSettings,
    /// Measure before the finish and grind the finish with this part's table.
    pub measure_before_finish: bool,
    /// Polls of the handshake camloop's answer takes (its latency over the 0.1 s poll).
    pub answer_polls: u32,
    /// The feature's own errors on a shaft ([`super::ShaftErrors::station`]); default none.
    pub station: StationErrors,
}

/// The in-process cell's file (`config/in-process-cell.toml`): which recipe and feature, how many
/// parts, and the simulated machine. Paths are relative to the file.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CycleCellConfig {
    /// The recipe, with its `[cycle]`.
    pub recipe: String,
    pub feature: String,
    #[serde(default = "default_parts")]
    pub parts: u32,
    #[serde(default = "default_true")]
    pub measure_before_finish: bool,
    /// Polls of the handshake (0.1 s each) camloop's answer takes.
    #[serde(default = "default_answer_polls")]
    pub answer_polls: u32,
    #[serde(default)]
    pub seed: u64,
    /// The simulated grinder and gauge ([`super::GrinderConfig`], with `[grinder.stock]`).
    #[serde(default)]
    pub grinder: super::GrinderConfig,
}

fn default_parts() -> u32 {
    12
}
fn default_true() -> bool {
    true
}
fn default_answer_polls() -> u32 {
    2
}

/// One finished part.
#[derive(Debug, Clone, PartialEq)]
pub struct CyclePart {
    pub part: u32,
    /// Max |lift error| of the finished part on the 0.1° grid, nothing fitted, µm.
    pub max_lift_error_um: f64,
    pub max_profile_error_um: f64,
    /// What the measurement before the finish gave (`none` without one).
    pub in_process: String,
    /// C turning coupled (approach, stages, spark-out), the measurement's revolutions, the
    /// dwells (handshake included), s.
    pub grind_s: f64,
    pub measure_s: f64,
    pub dwell_s: f64,
    /// What the part-to-part loop did with the finished part.
    pub action: String,
}

#[derive(Debug, thiserror::Error)]
pub enum CycleCellError {
    #[error("{0}")]
    Cell(#[from] CellError),
    #[error("cycle program: {0}")]
    Program(#[from] CycleProgramError),
    #[error("table program: {0}")]
    Table(#[from] TableError),
    #[error("plan table program: {0}")]
    Plan(#[from] VaProgramError),
    #[error("control: {0}")]
    Control(#[from] ControlError),
}

impl From<camloop_core::compensate::GuardError> for CycleCellError {
    fn from(e: camloop_core::compensate::GuardError) -> Self {
        Self::Cell(e.into())
    }
}

impl From<super::SimError> for CycleCellError {
    fn from(e: super::SimError) -> Self {
        Self::Cell(e.into())
    }
}

/// Grinds `parts` parts through the cycle and returns each finished part's figures.
pub fn run(setup: &CycleCellSetup, parts: u32) -> Result<Vec<CyclePart>, CycleCellError> {
    let cell = &setup.cell;
    let mut feature = cell.feature;
    let workpiece = match feature {
        Feature::Cam(g) => Workpiece::Cam(g),
        Feature::Pin(g) => Workpiece::Crankpin(g),
    };
    let mut sim = SimGrinder::new(cell.grinder.clone(), workpiece, cell.seed)?;
    let surface = stock_surface(feature, &cell.nominal)?;
    let mut in_force = LearningState::new(cell.grinder.gauge.points_per_rev);
    let mut previous = None;
    let mut control = Control::new();
    control.enable_overlay();
    let mut number = 0;
    let mut plan_numbers = (0, 0);
    let mut law = plan_law(cell, feature)?;
    let mut ready = 0u64;
    let curve = LiftCurve::new(&cell.nominal);
    let nominal = |psi_deg: f64| {
        let s = curve.eval(psi_deg.to_radians());
        (s.h_mm, s.dh_mm.to_radians())
    };
    let mut out = Vec::new();
    for part in 1..=parts {
        let lobe = LobeLoop {
            nominal: &cell.nominal,
            feature,
            request: cell.request,
            limits: &cell.limits,
            params: &cell.params,
        };
        let turn_setup = TurnSetup {
            lobe,
            bands: &[],
            assembly: AssemblyLimits::default(),
            phase_deg: 0.0,
            plan: law.as_ref(),
        };
        number = next_table_number(number, TABLE_PAIR);
        plan_numbers = next_plan_numbers(plan_numbers);
        let in_force_table = compensate::current_table(&in_force, &lobe)?;
        let in_force_plan = match &law {
            Some(l) => Some(turn::planned_tables(&lobe, l, &in_force, &in_force_table)?),
            None => None,
        };
        let main = main_program(
            setup,
            feature.wheel_radius_mm(),
            in_force_plan.as_ref().map(|t| t.va_speed_rpm),
        )?;
        let in_force_text = Texts {
            table: table_text(&in_force_table, number)?,
            plan: plan_text(in_force_plan.as_ref(), plan_numbers)?,
        };
        let labels = PartLabels {
            machine: "SIM".into(),
            part: part.to_string(),
            lobe: "IN1".into(),
        };
        // The control's run up to the measurement does not depend on the answer: a dry run
        // on a copy of it gives the passes the gauge measures after.
        let dry = control.clone().run_cycle(&main, &|name: &str| {
            serve(name, &in_force_text, None, ready)
        })?;
        let mut in_process = "none".to_string();
        let mut finish = None;
        if setup.measure_before_finish && setup.cycle.measure_stage().is_some() {
            let (stock, table) = stock_until_measured(setup, &dry, &surface, feature)?;
            let errors = with_station(&setup.station, stock.as_errors(cell.grinder.stock.orders));
            let mid = sim.grind_station(&table, &workpiece, &errors)?;
            let raw = sim.measure_in_process(&mid, &labels);
            let input = InProcess {
                setup: &turn_setup,
                in_force: &in_force,
                raw: &raw,
                part: &labels.part,
                remaining_stock_mm: stock_after_measure(&setup.cycle),
                gain: setup.cycle.same_part_gain,
            };
            match finish_table(&input, "IN1") {
                Ok(f) => {
                    in_process = format!("finish table: {}", f.outcome);
                    let n = next_table_number(number, TABLE_PAIR);
                    let pn = next_plan_numbers(plan_numbers);
                    let planned = match &law {
                        Some(l) => Some(turn::planned_tables(&lobe, l, &f.state, &f.table)?),
                        None => None,
                    };
                    let texts = Texts {
                        table: table_text(&f.table, n)?,
                        plan: plan_text(planned.as_ref(), pn)?,
                    };
                    finish = Some((texts, f.state, (n, pn)));
                }
                Err(e) => in_process = format!("refused, table in force: {e}"),
            }
        }
        let answer = finish.as_ref().map(|(texts, _, _)| texts);
        let polls = Cell::new(0u32);
        let answered = || answer.is_some() && polls.get() > setup.answer_polls;
        let load = |name: &str| {
            if name == READY_PROGRAM {
                polls.set(polls.get() + 1);
            }
            let reply = answered().then_some(()).and(answer);
            serve(
                name,
                &in_force_text,
                reply,
                ready + u64::from(reply.is_some()),
            )
        };
        let run = control.run_cycle(&main, &load)?;
        let state_ground = match finish {
            Some((_, state, (n, pn))) if answered() => {
                ready += 1;
                number = n;
                plan_numbers = pn;
                state
            }
            // Made, but after the control's timeout: camloop delivers nothing late, the
            // finish ground with the table in force, and nothing is learned from it.
            Some(_) => {
                in_process = "too late: the finish ground with the table in force".into();
                in_force.clone()
            }
            None => in_force.clone(),
        };
        let (stock, table) = stock_after(setup, &run, &surface, feature, usize::MAX)?;
        let ground = sim.grind_station(
            &table,
            &workpiece,
            &with_station(&setup.station, stock.as_errors(cell.grinder.stock.orders)),
        )?;
        let (max_profile_error_um, max_lift_error_um, _) =
            judge(&ground.lift_on_grid(JUDGE_POINTS), &nominal).map_err(CellError::from)?;
        let raw = sim.measure(&ground, &labels);
        let done = turn::turn(&turn_setup, &state_ground, &raw, None, previous)
            .map_err(CellError::from)?;
        previous = Some(done.measured.as_previous());
        let action = match done.decision {
            Decision::Table { outcome, next, .. } => {
                in_force = *next;
                outcome.to_string()
            }
            Decision::Refused(e) => {
                in_force = state_ground;
                format!("refused: {e}")
            }
            Decision::Held(r) => {
                in_force = state_ground;
                format!("held: {r}")
            }
        };
        let (grind_s, measure_s, dwell_s) = times(&run);
        out.push(CyclePart {
            part,
            max_lift_error_um,
            max_profile_error_um,
            in_process,
            grind_s,
            measure_s,
            dwell_s,
            action,
        });
        sim.after_feature();
        if let Some(event) = sim.after_part() {
            let old = feature.wheel_radius_mm();
            feature = feature.with_wheel_radius(event.believed_wheel_radius_mm);
            after_dressing(&mut in_force, cell.params.max_correction_um, old, &event);
            // The plan is made for the wheel the control believes.
            law = plan_law(cell, feature)?;
        }
    }
    Ok(out)
}

/// The feature's own errors with the stock's on top.
fn with_station(station: &StationErrors, stock: StationErrors) -> StationErrors {
    let mut harmonics = station.harmonics.clone();
    harmonics.extend(stock.harmonics);
    StationErrors {
        size_um: station.size_um + stock.size_um,
        lag_deg: station.lag_deg + stock.lag_deg,
        harmonics,
    }
}

/// The cycle program; `va_speed_rpm`: the plan's, for stages on it.
fn main_program(
    setup: &CycleCellSetup,
    wheel_radius_mm: f64,
    va_speed_rpm: Option<f64>,
) -> Result<String, CycleProgramError> {
    let table = ProgramSettings {
        name: TABLE_PROGRAM.into(),
        ..ProgramSettings::default()
    };
    let plan_settings = plan_settings(PLAN_PAIRS.map(|p| p.0).into());
    let machine = CycleMachine {
        cycle: &setup.cycle,
        c_speed_rpm: setup.cell.limits.c_speed_rpm,
        wheel_radius_mm,
        // The cell's table has no X offset: its X is the lift.
        clear_x_mm: clear_x_mm(
            setup
                .cell
                .nominal
                .lifts_mm()
                .iter()
                .copied()
                .fold(0.0, f64::max),
            setup.cycle.lift_off_mm,
        ),
    };
    let stations = [CycleStation {
        table: &table,
        label: "IN1",
        z_mm: 0.0,
        plan: va_speed_rpm.map(|va_speed_rpm| CyclePlan {
            table: &plan_settings,
            va_speed_rpm,
        }),
    }];
    render_cycle_program(&MainProgramSettings::default(), &machine, &stations)
}

/// The table programs the share holds for the feature: the constant-speed one and, with the
/// plan, the plan's.
struct Texts {
    table: String,
    plan: Option<String>,
}

/// The next numbers of the plan's X and C tables (each alternating in its pair).
fn next_plan_numbers((x, c): (u32, u32)) -> (u32, u32) {
    (
        next_table_number(x, PLAN_PAIRS[0]),
        next_table_number(c, PLAN_PAIRS[1]),
    )
}

fn plan_settings((x_table, c_table): (u32, u32)) -> VaProgramSettings {
    VaProgramSettings {
        name: PLAN_PROGRAM.into(),
        x_table,
        c_table,
        ..VaProgramSettings::default()
    }
}

fn plan_text(
    tables: Option<&VaTables>,
    numbers: (u32, u32),
) -> Result<Option<String>, VaProgramError> {
    tables
        .map(|t| render_va_table_program(t, &plan_settings(numbers)))
        .transpose()
}

fn table_text(table: &GuardedTable, number: u32) -> Result<String, TableError> {
    table.render(&ProgramSettings {
        name: TABLE_PROGRAM.into(),
        table_number: number,
        ..ProgramSettings::default()
    })
}

/// The share as the control reads it: the table programs (this part's finish tables once
/// camloop answered) and the handshake's count.
fn serve(name: &str, in_force: &Texts, answer: Option<&Texts>, ready: u64) -> Option<String> {
    let texts = answer.unwrap_or(in_force);
    match name {
        READY_PROGRAM => Some(render_ready_program(ready)),
        TABLE_PROGRAM => Some(texts.table.clone()),
        PLAN_PROGRAM => texts.plan.clone(),
        _ => None,
    }
}

/// The stock after the passes before the measurement, and the table they coupled.
fn stock_until_measured(
    setup: &CycleCellSetup,
    run: &CycleRun,
    surface: &[f64],
    feature: Feature,
) -> Result<(Stock, CommandedTable), super::SimError> {
    let turned = run
        .events
        .iter()
        .position(|e| matches!(e, CycleEvent::Turned { .. }))
        .unwrap_or(run.events.len());
    stock_after(setup, run, surface, feature, turned)
}

/// The stock after the passes among the run's first `until` events, and the last table
/// coupled (what the part's outline follows under its stock).
fn stock_after(
    setup: &CycleCellSetup,
    run: &CycleRun,
    surface: &[f64],
    feature: Feature,
    until: usize,
) -> Result<(Stock, CommandedTable), super::SimError> {
    let (stock, last) = passes_stock(
        &setup.cell.grinder.stock,
        &setup.cycle,
        run,
        surface,
        feature.wheel_radius_mm(),
        until,
        &|_| true,
    )?;
    let shape = last
        .map(|g| g.shape.clone())
        .unwrap_or(super::TableShape::G1(Vec::new()));
    let table = CommandedTable {
        shape,
        x_zero_mm: feature.x_zero_mm(),
        wheel_radius_mm: feature.wheel_radius_mm(),
        // On the plan: X over VA, with C's table (the lag is the plan's).
        plan: last.and_then(Coupled::planned_speed),
    };
    Ok((stock, table))
}

/// The contact's arc per radian of C at each of the stock's points ([`Stock::grind`]'s
/// `surface_mm_rad`) for `feature` with lift `nominal`.
pub fn stock_surface(feature: Feature, nominal: &LiftTable) -> Result<Vec<f64>, CellError> {
    let part = feature.part(nominal).map_err(CellError::from)?;
    let samples = ProfileSamples::new(&part).map_err(CellError::from)?;
    let step = samples.samples.len() / STOCK_POINTS;
    Ok(samples
        .samples
        .iter()
        .step_by(step.max(1))
        .map(|s| s.surface_mm_rad)
        .collect())
}

/// The stock that the grinds among `run`'s first `until` events which `pick` accepts leave
/// on one feature (C turns through every event, so each pass starts where C stands), and
/// the last of those grinds: the table the feature's outline follows under its stock.
pub fn passes_stock<'r>(
    model: &StockModel,
    cycle: &CycleSettings,
    run: &'r CycleRun,
    surface: &[f64],
    wheel_radius_mm: f64,
    until: usize,
    pick: &dyn Fn(&Coupled) -> bool,
) -> Result<(Stock, Option<&'r Coupled>), super::SimError> {
    let mut stock = Stock::new(cycle.stock_mm);
    let mut wheel_m_s = cycle.wheel_speed_m_s;
    let mut c_deg = 0.0f64;
    let mut last = None;
    for event in run.events.iter().take(until) {
        match event {
            CycleEvent::Spindle { rpm, .. } if *rpm > 0.0 => {
                wheel_m_s = rpm * std::f64::consts::TAU * wheel_radius_mm / 60_000.0;
            }
            CycleEvent::Turned { revolutions, .. } => c_deg += 360.0 * revolutions,
            CycleEvent::Ground(i) => {
                let g = &run.ground[*i];
                if pick(g) {
                    let pass = Pass {
                        x_offset_mm: g.x_offset_mm,
                        x_infeed_mm: g.x_infeed_mm,
                        revolutions: g.revolutions,
                        c_speed_rpm: g.c_speed_rpm,
                        wheel_speed_m_s: wheel_m_s,
                    };
                    let start = c_deg.rem_euclid(360.0).round() as usize % STOCK_POINTS;
                    let plan = g.planned_speed().map(|p| PlanPass::new(&p)).transpose()?;
                    stock.grind_planned(model, surface, &pass, start, plan.as_ref());
                    last = Some(g);
                }
                c_deg += 360.0 * g.revolutions;
            }
            _ => {}
        }
    }
    Ok((stock, last))
}

/// The infeed of the stages after the measurement: the stock on when the gauge reads, mm.
pub fn stock_after_measure(cycle: &CycleSettings) -> f64 {
    let stages = cycle.resolved(1.0);
    let at = stages
        .iter()
        .position(|s| s.kind == StageKind::Measure)
        .unwrap_or(stages.len());
    stages[at..].iter().map(|s| s.infeed_mm).sum()
}

/// Coupled grinding, measurement revolutions and dwells of a run, s.
pub fn times(run: &CycleRun) -> (f64, f64, f64) {
    let grind = run
        .ground
        .iter()
        .map(|g| 60.0 * g.revolutions / g.c_speed_rpm)
        .sum();
    let (mut measure, mut dwell) = (0.0, 0.0);
    for e in &run.events {
        match e {
            CycleEvent::Turned {
                revolutions,
                c_speed_rpm,
            } => measure += 60.0 * revolutions / c_speed_rpm,
            CycleEvent::Dwell(s) => dwell += s,
            _ => {}
        }
    }
    (grind, measure, dwell)
}
