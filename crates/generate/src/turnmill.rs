//! Turn-mill eccentric surfaces (X/Y/C): crank pins, cheek faces and arm contours given as
//! circles in the part frame, milled with C held at an angle φ and the tool on an X–Y arc.
//!
//! With the circle's centre at `(a, b) = e·(cos phase, sin phase)` in the part frame, C at
//! φ puts it at `X = cos φ·a + sin φ·b`, `Y = −sin φ·a + cos φ·b`; the cut-in point on X is
//! that plus the path radius. The program carries these as `DEF REAL` variables, as
//! machinists write them, and cuts with G2/G3 arcs around the centre. The cut arc runs from
//! `start − safety` to `end + safety` (drawing angles), so entry and exit overlap the
//! surface by the safety angle and no further: no air cutting is programmed.

use thiserror::Error;

use super::ir::{Axis, Expr, Motion, Plane, Program, Stmt, Var};
use camloop_core::program::{ProgramNameError, validate_program_name};

/// One circular surface of the drawing.
#[derive(Debug, Clone, PartialEq)]
pub struct EccentricCircle {
    pub label: String,
    pub eccentricity_mm: f64,
    pub phase_deg: f64,
    pub radius_mm: f64,
    /// Drawing angles about the circle's own centre, part frame; end > start.
    pub start_deg: f64,
    pub end_deg: f64,
    pub safety_deg: f64,
    /// True for a concave surface (bore, arm fillet): the tool runs inside the circle.
    pub concave: bool,
    /// C angle while cutting; `None` puts the centre on +X (φ = phase).
    pub c_deg: Option<f64>,
}

/// A turn-mill job.
#[derive(Debug, Clone, PartialEq)]
pub struct TurnMillJob {
    pub name: String,
    pub tool_radius_mm: f64,
    pub clearance_mm: f64,
    pub feed_mm_min: f64,
    pub circles: Vec<EccentricCircle>,
}

/// Why a turn-mill job is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TurnMillError {
    #[error(transparent)]
    Name(#[from] ProgramNameError),
    #[error("{label}: {field} is {value}: {rule}")]
    Value {
        label: String,
        field: &'static str,
        value: f64,
        rule: &'static str,
    },
    #[error(
        "{label}: the tool radius {tool_radius_mm} mm does not fit the concave radius {radius_mm} mm"
    )]
    ToolTooLarge {
        label: String,
        tool_radius_mm: f64,
        radius_mm: f64,
    },
    #[error("the job has no circles")]
    Empty,
}

const PHI: Var = Var {
    index: 1,
    name: "PHI",
};
const ECC: Var = Var {
    index: 2,
    name: "ECC",
};
const PHA: Var = Var {
    index: 3,
    name: "PHA",
};
const RAD: Var = Var {
    index: 4,
    name: "RAD",
};
const XC: Var = Var {
    index: 5,
    name: "XC",
};
const YC: Var = Var {
    index: 6,
    name: "YC",
};

/// The program for every circle, in order.
pub fn generate(job: &TurnMillJob) -> Result<Program, TurnMillError> {
    let name = validate_program_name(&job.name)?;
    if job.circles.is_empty() {
        return Err(TurnMillError::Empty);
    }
    let mut body = Vec::new();
    for c in &job.circles {
        check(job, c)?;
        body.extend(circle_stmts(job, c));
    }
    Ok(Program {
        name,
        plane: Plane::Xy,
        vars: vec![PHI, ECC, PHA, RAD, XC, YC],
        comments: vec![
            format!(
                "turn-mill: {} circles, tool radius {:.3} mm in the path (no G41/G42)",
                job.circles.len(),
                job.tool_radius_mm
            ),
            "XC = COS(PHI)*a + SIN(PHI)*b, YC = -SIN(PHI)*a + COS(PHI)*b, (a, b) = ECC*(COS(PHA), SIN(PHA))".to_owned(),
        ],
        body,
    })
}

fn check(job: &TurnMillJob, c: &EccentricCircle) -> Result<(), TurnMillError> {
    let bad = |field, value: f64, rule| TurnMillError::Value {
        label: c.label.clone(),
        field,
        value,
        rule,
    };
    for (field, v) in [
        ("eccentricity", c.eccentricity_mm),
        ("phase", c.phase_deg),
        ("start angle", c.start_deg),
        ("end angle", c.end_deg),
    ] {
        if !v.is_finite() {
            return Err(bad(field, v, "it must be a finite number"));
        }
    }
    if !(c.radius_mm.is_finite() && c.radius_mm > 0.0) {
        return Err(bad("radius", c.radius_mm, "it must be > 0"));
    }
    if c.eccentricity_mm < 0.0 {
        return Err(bad("eccentricity", c.eccentricity_mm, "it must be >= 0"));
    }
    let span = c.end_deg - c.start_deg;
    if !(span > 0.0 && span <= 360.0) {
        return Err(bad("end - start angle", span, "it must be in (0, 360] deg"));
    }
    if !(c.safety_deg.is_finite() && c.safety_deg >= 0.0 && c.safety_deg <= 45.0) {
        return Err(bad(
            "safety angle",
            c.safety_deg,
            "it must be in [0, 45] deg",
        ));
    }
    if !(job.tool_radius_mm.is_finite() && job.tool_radius_mm > 0.0) {
        return Err(bad("tool radius", job.tool_radius_mm, "it must be > 0"));
    }
    if c.concave && job.tool_radius_mm >= c.radius_mm {
        return Err(TurnMillError::ToolTooLarge {
            label: c.label.clone(),
            tool_radius_mm: job.tool_radius_mm,
            radius_mm: c.radius_mm,
        });
    }
    Ok(())
}

/// The angles the arc runs through: the drawing span widened by the safety angle at both
/// ends, but never past one full turn (a full pin overlaps by the safety angle once).
pub fn cut_span_deg(c: &EccentricCircle) -> (f64, f64) {
    let from = c.start_deg - c.safety_deg;
    let to = (c.end_deg + c.safety_deg).min(from + 360.0 + c.safety_deg);
    (from, to)
}

fn circle_stmts(job: &TurnMillJob, c: &EccentricCircle) -> Vec<Stmt> {
    let n = Expr::num;
    let v = Expr::var;
    let phi = c.c_deg.unwrap_or(c.phase_deg);
    let path_r = if c.concave {
        c.radius_mm - job.tool_radius_mm
    } else {
        c.radius_mm + job.tool_radius_mm
    };
    // Machine angles are drawing angles less φ (C turns the part by φ).
    let (from, to) = cut_span_deg(c);
    let pieces = ((to - from) / 180.0).ceil().max(1.0) as usize;
    // On the cut the radius is the variable RAD; off it (approach, retract) RAD ± clearance.
    let at = |ang: f64, r: Expr| {
        let a = n(ang - phi);
        vec![
            (Axis::X, v(XC).add(r.clone().mul(a.clone().cos()))),
            (Axis::Y, v(YC).add(r.mul(a.sin()))),
        ]
    };
    let out_r = if c.concave {
        v(RAD).sub(n(job.clearance_mm.min(path_r / 2.0)))
    } else {
        v(RAD).add(n(job.clearance_mm))
    };
    let mut s = centre_stmts(c, phi, path_r);
    s.extend([
        Stmt::Move {
            motion: Motion::Rapid,
            words: vec![(Axis::C, v(PHI))],
            feed: None,
        },
        Stmt::Move {
            motion: Motion::Rapid,
            words: at(from, out_r.clone()),
            feed: None,
        },
        Stmt::Move {
            motion: Motion::Linear,
            words: at(from, v(RAD)),
            feed: Some(job.feed_mm_min),
        },
    ]);
    for k in 0..pieces {
        let a0 = from + (to - from) * k as f64 / pieces as f64;
        let a1 = from + (to - from) * (k + 1) as f64 / pieces as f64;
        let mut words = at(a1, v(RAD));
        // Centre relative to the arc's start point.
        let a0m = n(a0 - phi);
        words.push((Axis::I, n(0.0).sub(v(RAD)).mul(a0m.clone().cos())));
        words.push((Axis::J, n(0.0).sub(v(RAD)).mul(a0m.sin())));
        s.push(Stmt::Move {
            motion: Motion::ArcCcw,
            words,
            feed: None,
        });
    }
    s.push(Stmt::Move {
        motion: Motion::Linear,
        words: at(to, out_r),
        feed: None,
    });
    s
}

/// The circle's header comment and the variables the control works it out from: φ, the
/// eccentricity and phase, the path radius, and the centre (XC, YC) turned by φ.
fn centre_stmts(c: &EccentricCircle, phi: f64, path_r: f64) -> Vec<Stmt> {
    let n = Expr::num;
    let v = Expr::var;
    vec![
        Stmt::Comment(format!(
            "{}: radius {} mm at e = {} mm, phase {} deg, drawing angles {} to {} deg, safety {} deg",
            c.label,
            c.radius_mm,
            c.eccentricity_mm,
            c.phase_deg,
            c.start_deg,
            c.end_deg,
            c.safety_deg
        )),
        Stmt::Assign(PHI, n(phi)),
        Stmt::Assign(ECC, n(c.eccentricity_mm)),
        Stmt::Assign(PHA, n(c.phase_deg)),
        Stmt::Assign(RAD, n(path_r)),
        Stmt::Assign(
            XC,
            v(PHI)
                .cos()
                .mul(v(ECC).mul(v(PHA).cos()))
                .add(v(PHI).sin().mul(v(ECC).mul(v(PHA).sin()))),
        ),
        Stmt::Assign(
            YC,
            v(ECC)
                .mul(v(PHA).cos())
                .mul(v(PHI).sin())
                .mul(n(-1.0))
                .add(v(PHI).cos().mul(v(ECC).mul(v(PHA).sin()))),
        ),
    ]
}
