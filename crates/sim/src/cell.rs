//! A simulated grinding cell: the grinder and gauge of this module driven part after part by
//! camloop's loop (the service's `FeatureMachine`, run in memory: learning in the lift
//! domain through the exact geometry, its guards and its dressing policy) or by the naive
//! hand method (each lift error written 1:1 into X at the same table index), with the
//! figures that judge them.

use super::delivered::DeliveredTables;
use super::in_memory::{InMemoryLoop, Outcome};
use super::{
    CommandedTable, GrinderConfig, PartLabels, SimError, SimGrinder, TableShape, Workpiece,
};
use camloop_core::analysis::{AnalysisError, LobeOptions, analyse_lobe};
use camloop_core::compensate::{
    self, AxisLimits, CycleError, Feature, GuardError, GuardedTable, LobeLoop, TableRequest,
};
use camloop_core::fit::{TableForm, fit_poly};
use camloop_core::learn::{self, LearningParams, LearningState};
use camloop_core::lift::{LiftCurve, LiftTable};
use camloop_core::measure::{AssemblyLimits, AveragedMeasurement, MeasurementError};
use camloop_core::speed_plan::tables::VaTables;
use camloop_core::speed_plan::{self, SpeedPlanError, SpeedPlanSettings, TimeLaw};
use camloop_core::turn::{self, TurnError, TurnSetup};
use camloop_loop::dressing::{self, Dressing};
use camloop_loop::machine::{Dressed, FeatureConfig, Finished, Gauged, PartNote, Program};
use camloop_loop::{Input, LoopMemory};
use jiff::Timestamp;

/// Points of the fine grid the ground part is judged on (0.1°), not only the gauge's points.
pub const JUDGE_POINTS: usize = 3600;

/// How the next table is made from the last measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Learning in the lift domain, table regenerated through the exact geometry.
    Camloop,
    /// The published hand method: X_j ← X_j − e_j at the same index, gain 1.
    NaiveX,
    /// camloop's learning law (gain, low-pass, deadband) applied in X at the same index,
    /// as if ΔX = Δlift: isolates what learning in the lift domain is worth.
    XDomainIlc,
}

/// What one part came out like.
#[derive(Debug, Clone, PartialEq)]
pub struct PartFigures {
    pub part: u32,
    /// Max |profile error| on the 0.1° grid after the datum (base-circle offset and phase)
    /// is fitted, µm: the form error a cam gauge reports.
    pub max_profile_error_um: f64,
    /// Max |ground lift − nominal lift| on the 0.1° grid with nothing fitted, µm.
    pub max_lift_error_um: f64,
    /// Base-circle radius error from the same fit, µm (positive: oversize).
    pub base_radius_error_um: f64,
    /// What the loop did after measuring this part.
    pub action: String,
    /// The wheel was dressed after this part.
    pub dressed: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum CellError {
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("measurement: {0}")]
    Measurement(#[from] MeasurementError),
    #[error("analysis: {0}")]
    Analysis(#[from] AnalysisError),
    #[error("{0}")]
    Turn(#[from] TurnError),
    #[error("delivery: {0}")]
    Delivery(#[from] super::DeliveryError),
    #[error("loop: {0}")]
    Cycle(#[from] CycleError),
    #[error("table: {0}")]
    Guard(#[from] GuardError),
    #[error("geometry: {0}")]
    Geometry(#[from] camloop_core::geometry::GeometryError),
    #[error("{0}")]
    Plan(#[from] SpeedPlanError),
    /// camloop's loop refused the part or the dressing (its own words).
    #[error("loop: {0}")]
    Loop(String),
}

/// The cell's fixed settings.
#[derive(Debug, Clone)]
pub struct CellSetup {
    pub nominal: LiftTable,
    /// What is ground, with the wheel radius the control believes at the start. For a pin,
    /// `nominal` is its lift as the gauge reads it (`compensate::pin_nominal_lift`).
    pub feature: Feature,
    pub request: TableRequest,
    pub params: LearningParams,
    pub limits: AxisLimits,
    pub grinder: GrinderConfig,
    pub seed: u64,
    /// With `enabled`, camloop's tables are ground with the planned C speed (the plan of the
    /// nominal part on the wheel believed, made again after each dressing) through the
    /// two-table program; the X-domain methods keep the constant speed.
    pub speed_plan: SpeedPlanSettings,
}

/// The figures of a run, and why it stopped early if it did.
#[derive(Debug, Clone, PartialEq)]
pub struct CellRun {
    pub parts: Vec<PartFigures>,
    pub stopped: Option<String>,
}

/// Grinds `parts` parts with `method` and returns each part's figures.
pub fn run(setup: &CellSetup, method: Method, parts: u32) -> Result<CellRun, CellError> {
    let mut cell = Cell::new(setup, method)?;
    let nominal_curve = LiftCurve::new(&setup.nominal);
    let nominal = |psi_deg: f64| {
        let s = nominal_curve.eval(psi_deg.to_radians());
        (s.h_mm, s.dh_mm.to_radians())
    };
    let labels = PartLabels {
        machine: "SIM".into(),
        part: "DEMO".into(),
        lobe: "IN1".into(),
    };
    let mut figures = Vec::with_capacity(parts as usize);
    for part in 1..=parts {
        let ground = match cell.sim.grind(&cell.table) {
            Ok(ground) => ground,
            // The table asks for a wheel path the wheel cannot follow (tighter than the
            // wheel): that method has failed; report how far it got.
            Err(e) => {
                let stopped = Some(format!("part {part}: the table cannot be ground: {e}"));
                return Ok(CellRun {
                    parts: figures,
                    stopped,
                });
            }
        };
        let (max_profile_error_um, max_lift_error_um, base_radius_error_um) =
            judge(&ground.lift_on_grid(JUDGE_POINTS), &nominal)?;
        let raw = cell.sim.measure(&ground, &labels);
        let action = cell.learn(&raw)?;
        if method != Method::Camloop {
            // The hand methods command their X offsets directly: one table from them.
            cell.table = cell.make_table()?;
        }
        let dressed = cell.after_part()?;
        figures.push(PartFigures {
            part,
            max_profile_error_um,
            max_lift_error_um,
            base_radius_error_um,
            action,
            dressed,
        });
    }
    Ok(CellRun {
        parts: figures,
        stopped: None,
    })
}

/// The cell between parts: the grinder, what each method remembers, and the table the
/// control couples.
struct Cell<'s> {
    setup: &'s CellSetup,
    method: Method,
    feature: Feature,
    sim: SimGrinder,
    /// camloop's loop: the service's machine, run in memory.
    camloop: InMemoryLoop,
    /// The parts ground so far (each input's simulated time is taken from it).
    parts: u32,
    /// The X-domain methods' own memory: the X added at each table point, mm.
    naive_dx_mm: Vec<f64>,
    x_state: LearningState,
    // camloop's tables reach the grinder as the service delivers them: rendered, and
    // coupled by the simulated control running the main program.
    control: DeliveredTables,
    law: Option<TimeLaw>,
    table: CommandedTable,
}

impl<'s> Cell<'s> {
    fn new(setup: &'s CellSetup, method: Method) -> Result<Self, CellError> {
        let feature = setup.feature;
        let workpiece = match feature {
            Feature::Cam(g) => Workpiece::Cam(g),
            Feature::Pin(g) => Workpiece::Crankpin(g),
        };
        let points_per_rev = setup.grinder.gauge.points_per_rev;
        let mut memory = LoopMemory::new(feature.wheel_radius_mm());
        memory.learning = LearningState::new(points_per_rev);
        let config = FeatureConfig {
            feature: "IN1".parse().expect("a valid feature name"),
            params: setup.params.clone(),
        };
        let mut cell = Cell {
            setup,
            method,
            feature,
            sim: SimGrinder::new(setup.grinder.clone(), workpiece, setup.seed)?,
            camloop: InMemoryLoop::new(config, memory),
            parts: 0,
            naive_dx_mm: vec![0.0; setup.request.points],
            x_state: LearningState::new(points_per_rev),
            control: DeliveredTables::default(),
            law: plan_law(setup, feature)?,
            table: CommandedTable {
                shape: TableShape::G1(Vec::new()),
                x_zero_mm: 0.0,
                wheel_radius_mm: feature.wheel_radius_mm(),
                plan: None,
            },
        };
        cell.table = cell.make_table()?;
        Ok(cell)
    }

    /// What the method does with the part just measured; returns its word on it.
    fn learn(&mut self, raw: &camloop_core::measure::RawMeasurement) -> Result<String, CellError> {
        let (setup, feature) = (self.setup, self.feature);
        let turn_setup = TurnSetup {
            lobe: lobe_loop(setup, feature),
            bands: &[],
            assembly: AssemblyLimits::default(),
            phase_deg: 0.0,
            // The turn guards camloop's new table over VA when the cell grinds with a plan.
            plan: self.law.as_ref(),
        };
        Ok(match self.method {
            Method::Camloop => {
                self.parts += 1;
                let at = sim_time(self.parts);
                // The cell delivers every table at once, so the part just measured was always
                // ground with the table in force: the machine learns from it.
                let gauged = Gauged {
                    setup: turn_setup,
                    raw,
                    sha256: turn::measurement_sha256(raw),
                    part: None,
                    ground_with: None,
                    on_reserve: false,
                    at,
                };
                let outcome = self.camloop.run(Input::Gauged(Box::new(gauged)), at);
                self.part_learned(outcome)?
            }
            Method::NaiveX => {
                let report = turn::measure(&turn_setup, raw)?.report;
                let step = setup.request.points / setup.grinder.gauge.points_per_rev as usize;
                for (j, e) in report.error_um.iter().enumerate() {
                    if let Some(dx) = self.naive_dx_mm.get_mut(j * step.max(1)) {
                        *dx -= e / 1000.0;
                    }
                }
                "X -= e at each index".to_string()
            }
            Method::XDomainIlc => {
                let measured = turn::measure(&turn_setup, raw)?;
                // The raw error, timing and all, as the hand method sees it.
                let part = learn::PartError {
                    error_um: &measured.report.error_um,
                    repeatability_um: &measured.report.repeatability_um,
                    revolutions: measured.averaged.revolutions_used.len() as u32,
                    timing_error_deg: 0.0,
                    timing_sigma_deg: 0.0,
                    part_number: None,
                    previous: None,
                };
                let outcome = learn::step(&mut self.x_state, &part, &setup.params);
                x_from_correction(&self.x_state, &mut self.naive_dx_mm);
                match outcome {
                    Ok(o) => o.to_string(),
                    Err(e) => format!("refused: {e}"),
                }
            }
        })
    }

    /// After the part: a dressing, when the wheel was dressed, moves what each method
    /// remembers and makes the plan and the table again. True when it was dressed.
    fn after_part(&mut self) -> Result<bool, CellError> {
        let Some(event) = self.sim.after_part() else {
            return Ok(false);
        };
        let old_radius_mm = self.feature.wheel_radius_mm();
        self.feature = self
            .feature
            .with_wheel_radius(event.believed_wheel_radius_mm);
        let limit_um = self.setup.params.max_correction_um;
        after_dressing(&mut self.x_state, limit_um, old_radius_mm, &event);
        // The correction is kept (lift domain); the plan is made for the new wheel.
        self.law = plan_law(self.setup, self.feature)?;
        if self.method == Method::Camloop {
            self.table = self.dressed(old_radius_mm, &event)?;
            return Ok(true);
        }
        if self.method == Method::XDomainIlc {
            // Its X follows its learning state, moved for the dressing like camloop's.
            x_from_correction(&self.x_state, &mut self.naive_dx_mm);
        } else {
            // The hand method drops what it added to the size.
            let mean = self.naive_dx_mm.iter().sum::<f64>() / self.naive_dx_mm.len() as f64;
            self.naive_dx_mm.iter_mut().for_each(|d| *d -= mean);
        }
        self.table = self.make_table()?;
        Ok(true)
    }

    /// The table of the method's present memory, as the control couples it.
    fn make_table(&mut self) -> Result<CommandedTable, CellError> {
        let (setup, feature) = (self.setup, self.feature);
        match self.method {
            Method::Camloop => {
                let state = self.camloop.memory().learning.clone();
                let table = compensate::current_table(&state, &lobe_loop(setup, feature))?;
                self.deliver_guarded(&state, &table)
            }
            Method::NaiveX | Method::XDomainIlc => {
                let part = feature.part(&setup.nominal)?;
                let mut points = part.wheel_table(setup.request.points)?;
                for (p, dx) in points.iter_mut().zip(&self.naive_dx_mm) {
                    p.x_mm += dx;
                    p.d_mm += dx;
                }
                let shape = match setup.request.form {
                    TableForm::G1 => TableShape::G1(points),
                    TableForm::Poly => TableShape::Poly(fit_poly(&points)),
                };
                Ok(CommandedTable {
                    shape,
                    x_zero_mm: part.x_zero_mm(),
                    wheel_radius_mm: feature.wheel_radius_mm(),
                    plan: None,
                })
            }
        }
    }

    /// What the machine made of a part: the table it rendered goes to the control; returns
    /// its word on the part.
    fn part_learned(&mut self, outcome: Outcome) -> Result<String, CellError> {
        let mut word = None;
        for f in outcome.finished {
            match f {
                Finished::Recorded(report) => {
                    word = Some(match report.note {
                        PartNote::Table => String::new(),
                        // A refused table is never used: the machine keeps the previous one
                        // (with the plan, an X table over VA beyond an X limit is refused too).
                        PartNote::Refused { reason, .. } => {
                            format!("refused, previous table kept: {reason}")
                        }
                        PartNote::Held(reason) => format!("held: {reason}"),
                        PartNote::NotRecorded(e) => format!("not recorded: {e}"),
                    })
                }
                Finished::Rejected { reason } => return Err(CellError::Loop(reason.to_string())),
                Finished::Failed { reason } => return Err(CellError::Loop(reason)),
                _ => {}
            }
        }
        let word = word.ok_or_else(|| CellError::Loop("the part was not recorded".into()))?;
        let Some(order) = outcome.rendered else {
            return Ok(word);
        };
        let Program::Table { table, planned } = order.program else {
            return Err(CellError::Loop("a part's table is a table".into()));
        };
        self.table = self.deliver(&order.next, &table, planned.as_deref())?;
        Ok(order.reason)
    }

    /// The wheel was dressed: the machine moves the correction by the service's policy and
    /// makes the table again for the wheel the control believes now; returns that table.
    fn dressed(
        &mut self,
        old_radius_mm: f64,
        event: &super::DressingEvent,
    ) -> Result<CommandedTable, CellError> {
        let at = sim_time(self.parts);
        let dressing = Dressing {
            old_radius_mm,
            new_radius_mm: event.believed_wheel_radius_mm,
            infeed_um: event.measured_infeed_um,
            // One feature: the wheel's share of the size correction is all of it.
            share_um: learn::size_correction_um(&self.camloop.memory().learning),
        };
        let lobe = lobe_loop(self.setup, self.feature);
        let dressed = Dressed {
            dressing,
            lobe: &lobe,
            at,
        };
        let outcome = self.camloop.run(Input::Dressed(Box::new(dressed)), at);
        for f in &outcome.finished {
            match f {
                Finished::Dressed(d) if d.no_table.is_some() => {
                    return Err(CellError::Loop(d.no_table.clone().unwrap_or_default()));
                }
                Finished::Table(Err(e)) => return Err(CellError::Loop(e.to_string())),
                _ => {}
            }
        }
        let order = outcome
            .rendered
            .ok_or_else(|| CellError::Loop("no table for the dressed wheel".into()))?;
        let Program::Table { table, .. } = order.program else {
            return Err(CellError::Loop("a dressing's table is a table".into()));
        };
        self.deliver_guarded(&order.next, &table)
    }

    /// Delivers a table made again (the first, or after a dressing) with the plan's guard
    /// as the turn runs it: over an X limit it is an error here, the cell has no other.
    fn deliver_guarded(
        &mut self,
        state: &LearningState,
        table: &GuardedTable,
    ) -> Result<CommandedTable, CellError> {
        let lobe = lobe_loop(self.setup, self.feature);
        let tables = match &self.law {
            Some(law) => Some(turn::planned_tables(&lobe, law, state, table)?),
            None => None,
        };
        self.deliver(state, table, tables.as_ref())
    }

    /// Delivers camloop's guarded `table` for `state`: the constant-speed programs, or with
    /// a plan the two-table programs of `tables` (its tables over VA, guarded by
    /// [`turn::planned_tables`]) for the commanded part.
    fn deliver(
        &mut self,
        state: &LearningState,
        table: &GuardedTable,
        tables: Option<&VaTables>,
    ) -> Result<CommandedTable, CellError> {
        let (setup, feature) = (self.setup, self.feature);
        let Some(tables) = tables else {
            return Ok(self.control.deliver(table, feature)?);
        };
        let lift = compensate::commanded_lift(&setup.nominal, &state.correction_um)
            .map_err(GuardError::from)?;
        let commanded = feature.part(&lift)?;
        Ok(self.control.deliver_planned(tables, &commanded)?)
    }
}

/// The X-domain method's X at each table point: its correction, taken as ΔX at the same
/// index (mm).
fn x_from_correction(state: &LearningState, dx_mm: &mut [f64]) {
    let step = (dx_mm.len() / state.correction_um.len().max(1)).max(1);
    for (j, u) in state.correction_um.iter().enumerate() {
        if let Some(dx) = dx_mm.get_mut(j * step) {
            *dx = u / 1000.0;
        }
    }
}

/// What the loop does with a dressing: the service's policy, [`dressing::move_correction`].
/// With the dresser's measured infeed, when the size step it tells is within the correction
/// limit, the whole correction moves by it; otherwise the wheel's share of the size
/// correction (here all of it: one feature) is replaced by the dressing offset.
pub(crate) fn after_dressing(
    state: &mut LearningState,
    max_correction_um: f64,
    old_radius_mm: f64,
    event: &super::DressingEvent,
) {
    let dressed = Dressing {
        old_radius_mm,
        new_radius_mm: event.believed_wheel_radius_mm,
        infeed_um: event.measured_infeed_um,
        share_um: learn::size_correction_um(state),
    };
    dressing::move_correction([state], &dressed, max_correction_um);
}

/// A part's simulated time: a part a minute (the loop reads no clock; its records want one).
fn sim_time(part: u32) -> Timestamp {
    Timestamp::from_second(1_700_000_000 + i64::from(part) * 60).expect("a time within range")
}

fn lobe_loop(setup: &CellSetup, feature: Feature) -> LobeLoop<'_> {
    LobeLoop {
        nominal: &setup.nominal,
        feature,
        request: setup.request,
        limits: &setup.limits,
        params: &setup.params,
    }
}

/// The planned C speed for `feature` (its nominal part on the wheel believed now) when the
/// setup asks for one. It stays fixed between dressings, so the servo lag it leaves is a
/// repeatable shape the loop learns like any other.
pub(crate) fn plan_law(setup: &CellSetup, feature: Feature) -> Result<Option<TimeLaw>, CellError> {
    if !setup.speed_plan.enabled {
        return Ok(None);
    }
    let part = feature.part(&setup.nominal)?;
    let plan = speed_plan::plan(&part, &setup.speed_plan.limits(&setup.limits))?;
    Ok(Some(plan.law))
}

/// Max |profile error| (datum fitted), max |lift error| (nothing fitted) and the base-circle
/// radius error (all µm), from the true ground lift on the fine grid.
pub fn judge(
    lift_mm: &[f64],
    nominal: &dyn Fn(f64) -> (f64, f64),
) -> Result<(f64, f64, f64), AnalysisError> {
    let n = lift_mm.len();
    let truth = AveragedMeasurement {
        origin: "ground part".to_string(),
        points_per_rev: n as u32,
        mean_lift_mm: lift_mm.to_vec(),
        repeatability_std_um: vec![0.0; n],
        repeatability_range_um: vec![0.0; n],
        revolutions_used: vec![0],
        dropped_revolutions: Vec::new(),
    };
    let report = analyse_lobe(&truth, nominal, &LobeOptions::default())?;
    let max_abs = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    Ok((
        max_abs(&report.profile_error_um),
        max_abs(&report.error_um),
        report.base_radius_error_um,
    ))
}
