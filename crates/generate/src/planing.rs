//! Ratio-coupled planing of a cam rotor's end face (X–A–Z): over the cutting stroke the
//! rotary axis follows the ram, `A = A_k + K·(X − X_start)`, and Z follows the face's height
//! at the rotor angle under the tool, through many control points per arc
//! ([`face::RotorFace`]). Front and rear over-travel let A reverse outside the part; the
//! return runs lifted.
//!
//! Resume lives on the control: after each arc's stroke the program writes the arcs done
//! to a persistent variable (`R50` on SINUMERIK, a numbered parameter kept in LinuxCNC's
//! var file on ISO), and every arc is guarded by that variable, so a program started again
//! after an interruption skips to the start of the first unfinished arc. The last block
//! clears the variable, so the next run starts a new rotor.

pub mod coupled;
pub mod face;

use thiserror::Error;

use super::ir::{Axis, Cond, Expr, MachineStmt, Motion, Plane, Program, Stmt, Var};
use super::safety::{Clear, Rotary, Rules};
use super::setup::{Coolant, FeedMode, ToolCall};
use camloop_core::program::{ProgramNameError, validate_program_name};
pub use face::RotorFace;

/// An M function of the planer: `M<code>`, and on LinuxCNC a `P<n>` where the code takes
/// one (M64/M65 switch digital output n).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MCode {
    pub code: u16,
    pub p: Option<u16>,
}

/// The planer's own M codes; `None` writes no block. They differ from machine to machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PlaningMCodes {
    /// Hydraulics on before the first stroke, off after the last.
    pub hydraulics_on: Option<MCode>,
    pub hydraulics_off: Option<MCode>,
    /// A's sense for the cutting stroke, and reversed for the return.
    pub a_forward: Option<MCode>,
    pub a_reverse: Option<MCode>,
    /// Tool lifter: lifted for the return stroke, lowered for the cut.
    pub lift_on: Option<MCode>,
    pub lift_off: Option<MCode>,
}

impl PlaningMCodes {
    /// True when any code carries a P word (LinuxCNC only).
    pub fn any_p(&self) -> bool {
        [
            self.hydraulics_on,
            self.hydraulics_off,
            self.a_forward,
            self.a_reverse,
            self.lift_on,
            self.lift_off,
        ]
        .iter()
        .flatten()
        .any(|m| m.p.is_some())
    }
}

/// A planing job: the rotor, the stroke and the machine.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaningJob {
    pub name: String,
    /// 1 … 6 for G54 … G59.
    pub work_offset: u8,
    pub tool: ToolCall,
    pub coolant: Coolant,
    pub face: RotorFace,
    /// Coupling ratio K, degrees of A per mm of X; one stroke spans one arc.
    pub ratio_deg_per_mm: f64,
    /// The part's extent along the stroke, mm.
    pub x_start_mm: f64,
    pub x_end_mm: f64,
    /// Over-travel before and after the part, for A to reverse outside it, mm.
    pub over_travel_front_mm: f64,
    pub over_travel_rear_mm: f64,
    /// Z of the lifted tool for the return stroke and the index, mm; above every peak.
    pub z_clear_mm: f64,
    pub feed_mm_min: f64,
    /// Largest height error of a straight move against the face, µm.
    pub tolerance_um: f64,
    pub min_points_per_arc: u32,
    pub m_codes: PlaningMCodes,
    /// The ISO parameter that keeps the arcs done between runs (listed in LinuxCNC's var
    /// file); SINUMERIK uses `R50`, which the control keeps over power-off.
    pub mark_parameter_iso: u16,
}

/// Why a planing job is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PlaningError {
    #[error(transparent)]
    Name(#[from] ProgramNameError),
    #[error("{field} is {value}: {rule}")]
    Value {
        field: &'static str,
        value: f64,
        rule: &'static str,
    },
    #[error(
        "the stroke turns A through {stroke_deg} deg (ratio x stroke length), the face's arc spans {arc_deg} deg: one stroke must cut one arc"
    )]
    StrokeNotOneArc { stroke_deg: f64, arc_deg: f64 },
    #[error("the tolerance needs {needed} control points per arc, more than {max}")]
    TooManyPoints { needed: f64, max: usize },
}

/// SINUMERIK's R parameter for the arcs done.
pub const MARK_R: &str = "R50";

/// The mark variable: ISO `#<mark_parameter_iso>` (a program variable is rendered as
/// `#(100 + index)`), SINUMERIK `R50`.
pub fn mark_var(job: &PlaningJob) -> Var {
    Var {
        index: job.mark_parameter_iso.saturating_sub(100),
        name: MARK_R,
    }
}

fn check(job: &PlaningJob) -> Result<(), PlaningError> {
    let bad = |field, value, rule| Err(PlaningError::Value { field, value, rule });
    job.face.check()?;
    if !(1..=6).contains(&job.work_offset) {
        return bad(
            "work offset",
            f64::from(job.work_offset),
            "1 to 6 for G54 to G59",
        );
    }
    for (field, v) in [("tool", job.tool.number), ("tool offset", job.tool.offset)] {
        if !(1..=99).contains(&v) {
            return bad(field, f64::from(v), "a whole number from 1 to 99");
        }
    }
    for (field, v) in [
        ("ratio", job.ratio_deg_per_mm),
        ("x start", job.x_start_mm),
        ("x end", job.x_end_mm),
        ("z clear", job.z_clear_mm),
    ] {
        if !v.is_finite() {
            return bad(field, v, "it must be a finite number");
        }
    }
    if job.x_end_mm <= job.x_start_mm {
        return bad(
            "x end",
            job.x_end_mm,
            "the stroke runs +X: it must exceed x start",
        );
    }
    for (field, v) in [
        ("over-travel front", job.over_travel_front_mm),
        ("over-travel rear", job.over_travel_rear_mm),
        ("feed", job.feed_mm_min),
        ("tolerance (um)", job.tolerance_um),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return bad(field, v, "it must be > 0");
        }
    }
    if job.z_clear_mm <= job.face.z_peak_mm {
        return bad(
            "z clear",
            job.z_clear_mm,
            "the lifted tool must be above the lobe peaks",
        );
    }
    if !(100..=5000).contains(&job.mark_parameter_iso) {
        return bad(
            "mark parameter (ISO)",
            f64::from(job.mark_parameter_iso),
            "it must be a user parameter from 100 to 5000",
        );
    }
    let stroke_deg = job.ratio_deg_per_mm * (job.x_end_mm - job.x_start_mm);
    let arc_deg = job.face.period_deg();
    // 1e-6 deg: far below A's 0.0001 deg resolution, far above rounding of the product.
    if (stroke_deg - arc_deg).abs() > 1e-6 {
        return Err(PlaningError::StrokeNotOneArc {
            stroke_deg,
            arc_deg,
        });
    }
    Ok(())
}

/// A of arc k (0-based) at X.
pub fn a_at(job: &PlaningJob, k: usize, x_mm: f64) -> f64 {
    job.face.period_deg() * k as f64 + job.ratio_deg_per_mm * (x_mm - job.x_start_mm)
}

/// Z of the face under the tool at X on arc k; held at the part's edge over the over-travel.
pub fn z_at(job: &PlaningJob, k: usize, x_mm: f64) -> f64 {
    let x = x_mm.clamp(job.x_start_mm, job.x_end_mm);
    job.face.z_at(a_at(job, k, x))
}

/// The control points of every stroke, X in mm (the same for every arc).
pub fn stroke_x_mm(job: &PlaningJob) -> Result<Vec<f64>, PlaningError> {
    check(job)?;
    face::stroke_points(
        &job.face,
        job.ratio_deg_per_mm,
        job.x_start_mm,
        job.x_end_mm,
        job.tolerance_um / 1000.0,
        job.min_points_per_arc,
    )
}

fn mv(motion: Motion, words: &[(Axis, f64)], feed: Option<f64>) -> Stmt {
    Stmt::Move {
        motion,
        words: words.iter().map(|&(a, v)| (a, Expr::num(v))).collect(),
        feed,
    }
}

/// An M code of the planer, if the machine has one for `what`.
fn m_code(code: Option<MCode>, what: &'static str) -> Option<Stmt> {
    code.map(|m| {
        Stmt::Machine(MachineStmt::MFunction {
            code: m.code,
            p: m.p,
            what,
        })
    })
}

/// The safety check's facts for a planer: no spindle, A turned with the tool lifted to
/// `z_clear_mm` or in the cut it is coupled to.
pub fn safety_rules(job: &PlaningJob) -> Rules {
    Rules {
        min_x_mm: None,
        rotary: vec![Rotary {
            axis: Axis::A,
            coupled_cut: true,
        }],
        clear: vec![Clear::AtLeast {
            axis: Axis::Z,
            mm: job.z_clear_mm,
        }],
        no_spindle: true,
    }
}

/// The whole job: every arc, each guarded by the mark so a run skips the arcs done.
pub fn generate(job: &PlaningJob) -> Result<Program, PlaningError> {
    let name = validate_program_name(&job.name)?;
    let xs = stroke_x_mm(job)?;
    let mark = mark_var(job);
    let m = &job.m_codes;
    // A planer has no spindle: offset, tool, the feed mode before any F, coolant.
    let mut body = vec![
        Stmt::Machine(MachineStmt::WorkOffset(job.work_offset)),
        Stmt::Machine(MachineStmt::Tool(job.tool)),
        Stmt::Machine(MachineStmt::FeedMode(FeedMode::PerMinute)),
    ];
    if job.coolant != Coolant::Off {
        body.push(Stmt::Machine(MachineStmt::Coolant(job.coolant)));
    }
    body.extend(m_code(m.hydraulics_on, "hydraulics on"));
    body.push(mv(Motion::Rapid, &[(Axis::Z, job.z_clear_mm)], None));
    for k in 0..job.face.segments as usize {
        body.push(Stmt::If {
            label: k as u16,
            cond: Cond {
                left: Expr::var(mark),
                less: true,
                right: Expr::num((k + 1) as f64),
            },
            body: arc_stmts(job, k, &xs, mark),
        });
    }
    body.push(Stmt::Mark {
        var: mark,
        value: 0.0,
        text: "job complete: the next run starts a new rotor".to_owned(),
    });
    body.push(mv(
        Motion::Rapid,
        &[(Axis::X, job.x_start_mm - job.over_travel_front_mm)],
        None,
    ));
    body.extend(m_code(m.hydraulics_off, "hydraulics off"));
    body.push(Stmt::Machine(MachineStmt::Coolant(Coolant::Off)));
    Ok(Program {
        name,
        plane: Plane::Xy,
        vars: Vec::new(),
        comments: header(job, xs.len()),
        body,
    })
}

fn header(job: &PlaningJob, points: usize) -> Vec<String> {
    let f = &job.face;
    vec![
        format!(
            "planing: A = A_k + {} deg/mm * (X - {}), {} arcs of {} deg",
            job.ratio_deg_per_mm,
            job.x_start_mm,
            f.segments,
            f.period_deg()
        ),
        format!(
            "face: peaks at Z {} mm, valleys at Z {} mm, arcs at pitch radius {} mm; {} points per stroke within {} um",
            f.z_peak_mm, f.z_valley_mm, f.pitch_radius_mm, points, job.tolerance_um
        ),
        format!(
            "resume: {MARK_R} (ISO #{}) holds the arcs done; a run skips them, the last block clears it",
            job.mark_parameter_iso
        ),
    ]
}

/// One arc: index at the front over-travel, plunge outside the part, the coupled stroke
/// with Z on the face, the rear over-travel, the mark, the lift and A reversed.
fn arc_stmts(job: &PlaningJob, k: usize, xs: &[f64], mark: Var) -> Vec<Stmt> {
    let m = &job.m_codes;
    let x_front = job.x_start_mm - job.over_travel_front_mm;
    let x_rear = job.x_end_mm + job.over_travel_rear_mm;
    let point = |x: f64| {
        [
            (Axis::X, x),
            (Axis::A, a_at(job, k, x)),
            (Axis::Z, z_at(job, k, x)),
        ]
    };
    let mut s = vec![
        Stmt::Comment(format!("arc {} of {}", k + 1, job.face.segments)),
        mv(
            Motion::Rapid,
            &[(Axis::X, x_front), (Axis::A, a_at(job, k, x_front))],
            None,
        ),
    ];
    s.extend(m_code(m.a_forward, "A forward"));
    s.extend(m_code(m.lift_off, "tool lowered"));
    s.push(mv(
        Motion::Linear,
        &[(Axis::Z, z_at(job, k, x_front))],
        Some(job.feed_mm_min),
    ));
    for &x in xs {
        s.push(mv(Motion::Linear, &point(x), None));
    }
    s.push(mv(Motion::Linear, &point(x_rear), None));
    s.push(Stmt::Mark {
        var: mark,
        value: (k + 1) as f64,
        text: format!("arcs done: {}", k + 1),
    });
    s.extend(m_code(m.lift_on, "tool lifted"));
    s.push(mv(Motion::Rapid, &[(Axis::Z, job.z_clear_mm)], None));
    s.extend(m_code(m.a_reverse, "A reversed"));
    s
}
