//! A simulated SINUMERIK control that runs the main program camloop writes as the control
//! would: it calls the table subprogram, keeps every curve table it defines by number (across
//! runs, as the NC memory does), and reports the table `LEADON` actually couples.
//!
//! It interprets exactly the subset camloop writes, strictly; anything else is an error naming
//! the program and line. Alarms the real control raises are errors too: `LEADON` or `CTAB` on
//! an undefined table, redefining the coupled table, programming the coupled axis, a leading
//! value that does not increase in a table (10949). Every line is read by the one SINUMERIK
//! reader, [`camloop_core::program::syntax`], and table blocks by the same code as
//! [`camloop_core::program::parse_table_program`].
//!
//! Not modelled: modal G states (`G90`, `G71`, `SAVE` restore), feeds and timing, the
//! synchronising move of `LEADON`, work offsets (`$AA_IW` is the programmed setpoint).

mod cycle;
mod interpreter;
mod statements;

pub use cycle::CycleEvent;

use std::collections::BTreeMap;

use super::{PlannedSpeed, TableShape};
use camloop_core::program::{ParsedShape, ParsedTable};
use camloop_core::table::TablePoint;
use statements::{Frame, Run};

/// Deepest subprogram nesting accepted (camloop needs 1).
const MAX_CALL_DEPTH: usize = 8;
/// The axis along the shaft: its setpoint while grinding names the station ground.
const AXIAL_AXIS: &str = "Z";
/// The workpiece axis: following a virtual leading axis by its own table, it turns at the
/// speed plan's varying speed.
const C_AXIS: &str = "C";
/// `$AA_COUP_ACT` of a following axis in a master-value coupling [K].
const COUP_ACT_MASTER_VALUE: i64 = 16;

/// The simulated control: curve tables by number, the active coupling and axis setpoints
/// persist between runs; variables live for one program run.
#[derive(Debug, Clone, Default)]
pub struct Control {
    tables: BTreeMap<u32, ParsedTable>,
    /// Active couplings: at most one per following axis (X to C, or X and C to a virtual
    /// leading axis with a speed plan).
    couplings: Vec<Coupling>,
    /// Setpoints by axis name (mm or degrees); an axis never moved is at 0.
    positions: BTreeMap<String, f64>,
    /// R parameters (`R90` …), kept between runs as the NC keeps them; unset ones are 0.
    r_params: BTreeMap<u32, f64>,
    /// The coupling's output offset of each following axis (SD43106), mm.
    output_offset_mm: BTreeMap<String, f64>,
    /// X's overlay while coupled (incremental X programmed on the coupled axis), mm; reset
    /// at `LEADON`.
    overlay_mm: f64,
    /// The overlay is enabled for X (the PLC's DBX26.4): without it, programming the
    /// coupled X is the control's alarm.
    overlay_enabled: bool,
    /// What the last run ground before a fault stopped it (`None` after a run that ended).
    stopped: Option<CycleRun>,
}

/// What a cycle run did: every grind, and every event in program order.
#[derive(Debug, Clone, PartialEq)]
pub struct CycleRun {
    pub ground: Vec<Coupled>,
    pub events: Vec<CycleEvent>,
}

/// The number of an R parameter written `R<n>`.
fn r_param(text: &str) -> Option<u32> {
    text.trim()
        .strip_prefix('R')
        .filter(|d| !d.is_empty() && d.chars().all(|c| c.is_ascii_digit()))?
        .parse()
        .ok()
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct Coupling {
    following: String,
    leading: String,
    table: u32,
}

/// What one run ground: the table coupled while C turned, and how C turned.
#[derive(Debug, Clone, PartialEq)]
pub struct Coupled {
    pub table_number: u32,
    /// The program that defined the table (its provenance says which version it is).
    pub defined_by: String,
    /// Setpoint of the axial axis (`Z`) while grinding, mm: the station ground.
    pub z_mm: f64,
    /// In program axes, as [`table_shape`] builds it from the table's blocks.
    pub shape: TableShape,
    /// With a speed plan: the number and shape of C = f(VA), C following the virtual axis
    /// that leads X (`_mm` fields in degrees of C; `shape` is then X over VA). `None` when X
    /// follows C directly.
    pub c_table_number: Option<u32>,
    pub c_law: Option<TableShape>,
    /// Speed of the leading axis: C's at constant speed, the virtual axis' with a plan
    /// (one revolution of C per revolution of it), rev/min.
    pub c_speed_rpm: f64,
    pub revolutions: f64,
    /// How far X stands above the table's curve as the grind starts (the output offset plus
    /// the overlay so far), mm; 0 in the table-only program.
    pub x_offset_mm: f64,
    /// X's infeed superimposed during the grind (negative: towards the part), mm.
    pub x_infeed_mm: f64,
}

impl Coupled {
    /// The planned C speed the run ground with, when C followed a virtual axis by a POLY
    /// table (the only form camloop writes it in; a G1 C table is not run as a plan).
    pub fn planned_speed(&self) -> Option<PlannedSpeed> {
        match &self.c_law {
            Some(TableShape::Poly(segments)) => Some(PlannedSpeed {
                c_law: segments.clone(),
                va_speed_rpm: self.c_speed_rpm,
            }),
            _ => None,
        }
    }
}

/// A run stopped at `line` (1-based) of `program` (its name, or `main`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{program} line {line}: {fault}")]
pub struct ControlError {
    pub program: String,
    pub line: usize,
    pub fault: ControlFault,
}

/// What stopped a run. Variants starting with "alarm" are alarms of the real control.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ControlFault {
    #[error("`{statement}` is not in the subset camloop writes")]
    Unsupported { statement: String },
    #[error("{reason}")]
    Invalid { reason: String },
    #[error("column {column}: {reason}")]
    Syntax { column: usize, reason: String },
    #[error("variable {name} is not defined")]
    UndefinedVariable { name: String },
    #[error("program {name} not found")]
    ProgramNotFound { name: String },
    #[error("the program ends without {what}")]
    NoEnd { what: &'static str },
    #[error("the program ran to its end without turning C while coupled")]
    NotGround,
    #[error("alarm: curve table {number} is not defined")]
    UndefinedTable { number: i64 },
    #[error("alarm: curve table {number} is active in a coupling and cannot be redefined")]
    TableInUse { number: u32 },
    #[error("alarm: {axis} is already coupled")]
    AlreadyCoupled { axis: String },
    #[error("alarm: {axis} is coupled and cannot be programmed")]
    AxisCoupled { axis: String },
    #[error(
        "alarm 10949: the leading value does not increase at C={c_deg} in curve table {number}"
    )]
    LeadingNotIncreasing { number: u32, c_deg: f64 },
}

impl ControlFault {
    /// An alarm of the real control (rather than a statement outside the subset).
    pub fn is_alarm(&self) -> bool {
        matches!(
            self,
            ControlFault::UndefinedTable { .. }
                | ControlFault::TableInUse { .. }
                | ControlFault::AlreadyCoupled { .. }
                | ControlFault::AxisCoupled { .. }
                | ControlFault::LeadingNotIncreasing { .. }
        )
    }
}

/// The shape the simulated grinder runs for a table read from a program: POLY segments as
/// they are, G1 points without the closing point at first C + 360°.
pub fn table_shape(shape: &ParsedShape) -> TableShape {
    match shape {
        ParsedShape::Poly(segments) => TableShape::Poly(segments.clone()),
        ParsedShape::G1(points) => TableShape::G1(
            points
                .iter()
                .take(points.len().saturating_sub(1))
                .map(|&(c_deg, x_mm)| TablePoint {
                    c_deg,
                    d_mm: 0.0,
                    x_mm,
                })
                .collect(),
        ),
    }
}

impl Control {
    /// A control with no tables, nothing coupled, every axis at 0.
    pub fn new() -> Self {
        Self::default()
    }

    /// Runs main program text `main` as the control would; subprogram calls are resolved
    /// with `load(name)` → the text of that program file (name as called, e.g.
    /// `DEMO_CAM_TABLE`). Tables defined stay defined, whatever the outcome. Returns the
    /// last grind of the run (a one-feature program grinds once).
    pub fn run(
        &mut self,
        main: &str,
        load: &dyn Fn(&str) -> Option<String>,
    ) -> Result<Coupled, ControlError> {
        let mut all = self.run_all(main, load)?;
        Ok(all.pop().expect("run_all returns at least one grind"))
    }

    /// Runs `main` like [`Control::run`] and returns every grind, in order (a whole shaft:
    /// one per station the program reaches).
    pub fn run_all(
        &mut self,
        main: &str,
        load: &dyn Fn(&str) -> Option<String>,
    ) -> Result<Vec<Coupled>, ControlError> {
        Ok(self.run_cycle(main, load)?.ground)
    }

    /// Enables X's overlay (the PLC's DBX26.4), which the whole-cycle program needs to
    /// superimpose the infeed on the coupled X.
    pub fn enable_overlay(&mut self) {
        self.overlay_enabled = true;
    }

    /// Runs `main` like [`Control::run_all`] and returns every grind and every event of the
    /// cycle (spindle, coolant, measurement, dwells) in order.
    pub fn run_cycle(
        &mut self,
        main: &str,
        load: &dyn Fn(&str) -> Option<String>,
    ) -> Result<CycleRun, ControlError> {
        let mut run = Run {
            control: self,
            load,
            ground: Vec::new(),
            events: Vec::new(),
            jumps: 0,
        };
        let mut frame = Frame::new(program_name(main, "MPF").unwrap_or("main"), Vec::new());
        let result = run.program(main, &mut frame, 0);
        let done = CycleRun {
            ground: run.ground,
            events: run.events,
        };
        let end_line = match result {
            Ok(line) => line,
            Err(e) => {
                // The machine keeps what it ground before the alarm: a shaft stopped mid-way.
                self.stopped = Some(done);
                return Err(e);
            }
        };
        self.stopped = None;
        if done.ground.is_empty() {
            return Err(ControlError {
                program: frame.program,
                line: end_line,
                fault: ControlFault::NotGround,
            });
        }
        Ok(done)
    }

    /// What the last run ground, and its events, up to the fault that stopped it (a shaft
    /// interrupted after some features); `None` when the last run ended normally.
    pub fn stopped_run(&self) -> Option<&CycleRun> {
        self.stopped.as_ref()
    }

    /// R parameter `n` (0 when never set).
    pub(crate) fn r_param(&self, n: u32) -> f64 {
        self.r_params.get(&n).copied().unwrap_or(0.0)
    }

    /// Sets R parameter `n`, as an operator does on the HMI.
    pub fn set_r_param(&mut self, n: u32, value: f64) {
        self.r_params.insert(n, value);
    }

    /// Where `axis` was last sent by an absolute move or an uncoupled incremental one, mm or
    /// degrees (0 when never moved). While X is coupled its motion is the table's, not this.
    pub fn position(&self, axis: &str) -> f64 {
        self.positions.get(axis).copied().unwrap_or(0.0)
    }

    /// Numbers of the curve tables in memory, ascending.
    pub fn defined_tables(&self) -> Vec<u32> {
        self.tables.keys().copied().collect()
    }
}

/// `NAME` of a first line `%_N_NAME_<kind>`.
fn program_name<'t>(text: &'t str, kind: &str) -> Option<&'t str> {
    text.lines()
        .next()?
        .trim()
        .strip_prefix("%_N_")?
        .strip_suffix(kind)?
        .strip_suffix('_')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_the_reader_cannot_read_is_refused_naming_line_and_column() {
        let main = "%_N_T_MPF\nDEF INT N\nLEADON(X,C,N ; no closing bracket\nM30\n";
        let err = Control::new().run(main, &|_: &str| None).unwrap_err();
        assert_eq!(err.to_string(), "T line 3: column 13: expected `,` or `)`");
        assert!(!err.fault.is_alarm());
    }
}
