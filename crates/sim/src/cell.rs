//! A simulated grinding cell: the grinder and gauge of this module driven part after part by
//! camloop's loop (learning in the lift domain through the exact geometry) or by the naive
//! hand method (each lift error written 1:1 into X at the same table index), with the
//! figures that judge them.

use super::delivered::DeliveredTables;
use super::{
    CommandedTable, GrinderConfig, PartLabels, SimError, SimGrinder, TableShape, Workpiece,
};
use camloop_core::analysis::{AnalysisError, LobeOptions, analyse_lobe};
use camloop_core::compensate::{
    self, AxisLimits, CycleError, Feature, GuardError, GuardedTable, LobeLoop, TableRequest,
};
use camloop_core::fit::{TableForm, fit_poly};
use camloop_core::learn::{self, LearningParams, LearningState, StepOutcome};
use camloop_core::lift::{LiftCurve, LiftTable};
use camloop_core::measure::{AssemblyLimits, AveragedMeasurement, MeasurementError};
use camloop_core::speed_plan::{self, SpeedPlanError, SpeedPlanSettings, TimeLaw};
use camloop_core::turn::{self, Decision, TurnError, TurnSetup};

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
    let mut feature = setup.feature;
    let workpiece = match feature {
        Feature::Cam(g) => Workpiece::Cam(g),
        Feature::Pin(g) => Workpiece::Crankpin(g),
    };
    let mut sim = SimGrinder::new(setup.grinder.clone(), workpiece, setup.seed)?;
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
    let points_per_rev = setup.grinder.gauge.points_per_rev;
    let mut state = LearningState::new(points_per_rev);
    // The X-domain methods' own memory: the X added at each table point, mm.
    let mut naive_dx_mm = vec![0.0; setup.request.points];
    let mut x_state = LearningState::new(points_per_rev);
    let mut previous = None;
    // camloop's tables reach the grinder as the service delivers them: rendered, and coupled
    // by the simulated control running the main program.
    let mut control = DeliveredTables::default();
    let mut law = plan_law(setup, feature)?;
    let mut table = make_table(
        setup,
        feature,
        &state,
        method,
        &naive_dx_mm,
        law.as_ref(),
        &mut control,
    )?;
    let mut figures = Vec::with_capacity(parts as usize);
    for part in 1..=parts {
        let ground = match sim.grind(&table) {
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
        let raw = sim.measure(&ground, &labels);
        let lobe = lobe_loop(setup, feature);
        let turn_setup = TurnSetup {
            lobe,
            bands: &[],
            assembly: AssemblyLimits::default(),
            phase_deg: 0.0,
        };
        let action = match method {
            Method::Camloop => {
                // The cell delivers every table at once, so the part just measured was always
                // ground with the table of `state`: the turn learns from it.
                let done = turn::turn(&turn_setup, &state, &raw, None, previous)?;
                previous = Some(done.measured.as_previous());
                match done.decision {
                    Decision::Table {
                        outcome,
                        next,
                        table: next_table,
                    } => {
                        state = *next;
                        let law = law.as_ref();
                        table = deliver(setup, feature, &state, &next_table, law, &mut control)?;
                        outcome_text(&outcome)
                    }
                    // A refused table is never used: the machine keeps the previous one.
                    Decision::Refused(e) => format!("refused, previous table kept: {e}"),
                    Decision::Held(reason) => format!("held: {reason}"),
                }
            }
            Method::NaiveX => {
                let report = turn::measure(&turn_setup, &raw)?.report;
                let step = setup.request.points / points_per_rev as usize;
                for (j, e) in report.error_um.iter().enumerate() {
                    if let Some(dx) = naive_dx_mm.get_mut(j * step.max(1)) {
                        *dx -= e / 1000.0;
                    }
                }
                "X -= e at each index".to_string()
            }
            Method::XDomainIlc => {
                let measured = turn::measure(&turn_setup, &raw)?;
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
                let outcome = learn::step(&mut x_state, &part, &setup.params);
                x_from_correction(&x_state, &mut naive_dx_mm);
                match outcome {
                    Ok(o) => outcome_text(&o),
                    Err(e) => format!("refused: {e}"),
                }
            }
        };
        if method != Method::Camloop {
            // The hand methods command their X offsets directly: one table from them.
            table = make_table(
                setup,
                feature,
                &state,
                method,
                &naive_dx_mm,
                law.as_ref(),
                &mut control,
            )?;
        }
        let dressed = match sim.after_part() {
            Some(event) => {
                let old_radius_mm = feature.wheel_radius_mm();
                feature = feature.with_wheel_radius(event.believed_wheel_radius_mm);
                for s in [&mut state, &mut x_state] {
                    after_dressing(s, old_radius_mm, &event);
                }
                // The correction is kept (lift domain); the plan is made for the new wheel.
                law = plan_law(setup, feature)?;
                if method == Method::XDomainIlc {
                    // Its X follows its learning state, moved for the dressing like camloop's.
                    x_from_correction(&x_state, &mut naive_dx_mm);
                } else {
                    // The hand method drops what it added to the size.
                    let mean = naive_dx_mm.iter().sum::<f64>() / naive_dx_mm.len() as f64;
                    naive_dx_mm.iter_mut().for_each(|d| *d -= mean);
                }
                table = make_table(
                    setup,
                    feature,
                    &state,
                    method,
                    &naive_dx_mm,
                    law.as_ref(),
                    &mut control,
                )?;
                true
            }
            None => false,
        };
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

/// What the loop does with a dressing, as the service does: with the dresser's measured
/// infeed the size step is known and the whole correction moves by it; without it the
/// wheel's share of the size correction (here all of it: one feature) is replaced by the
/// dressing offset.
fn after_dressing(state: &mut LearningState, old_radius_mm: f64, event: &super::DressingEvent) {
    match event.measured_infeed_um {
        Some(infeed_um) => {
            let step_um = learn::dressing_size_step_um(
                old_radius_mm,
                event.believed_wheel_radius_mm,
                infeed_um,
            );
            learn::after_measured_dressing(state, step_um);
        }
        None => {
            let own = learn::size_correction_um(state);
            learn::after_dressing(state, own);
        }
    }
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

fn make_table(
    setup: &CellSetup,
    feature: Feature,
    state: &LearningState,
    method: Method,
    naive_dx_mm: &[f64],
    law: Option<&TimeLaw>,
    control: &mut DeliveredTables,
) -> Result<CommandedTable, CellError> {
    match method {
        Method::Camloop => {
            let table = compensate::current_table(state, &lobe_loop(setup, feature))?;
            deliver(setup, feature, state, &table, law, control)
        }
        Method::NaiveX | Method::XDomainIlc => {
            let part = feature.part(&setup.nominal)?;
            let mut points = part.wheel_table(setup.request.points)?;
            for (p, dx) in points.iter_mut().zip(naive_dx_mm) {
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

/// The planned C speed for `feature` (its nominal part on the wheel believed now) when the
/// setup asks for one. It stays fixed between dressings, so the servo lag it leaves is a
/// repeatable shape the loop learns like any other.
fn plan_law(setup: &CellSetup, feature: Feature) -> Result<Option<TimeLaw>, CellError> {
    if !setup.speed_plan.enabled {
        return Ok(None);
    }
    let part = feature.part(&setup.nominal)?;
    let plan = speed_plan::plan(&part, &setup.speed_plan.limits(&setup.limits))?;
    Ok(Some(plan.law))
}

/// Delivers camloop's guarded `table` for `state`: the constant-speed programs, or with
/// `law` the two-table programs of the commanded part.
fn deliver(
    setup: &CellSetup,
    feature: Feature,
    state: &LearningState,
    table: &GuardedTable,
    law: Option<&TimeLaw>,
    control: &mut DeliveredTables,
) -> Result<CommandedTable, CellError> {
    let Some(law) = law else {
        return Ok(control.deliver(table, feature)?);
    };
    let lift = compensate::commanded_lift(&setup.nominal, &state.correction_um)
        .map_err(GuardError::from)?;
    let commanded = feature.part(&lift)?;
    let tolerance_um = setup.request.poly_tolerance_um;
    Ok(control.deliver_planned(table, &commanded, law, tolerance_um)?)
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

fn outcome_text(outcome: &StepOutcome) -> String {
    match outcome {
        StepOutcome::Updated {
            max_correction_um, ..
        } => format!("learned, correction ≤ {max_correction_um:.2} µm"),
        StepOutcome::Limited { bound, .. } => format!("learned, {bound}"),
        StepOutcome::InTolerance { .. } => "in tolerance, table kept".to_string(),
        StepOutcome::Frozen { .. } => "frozen".to_string(),
        StepOutcome::Reverted { to_iteration, .. } => {
            format!("ALARM: reverted to iteration {to_iteration}")
        }
    }
}
