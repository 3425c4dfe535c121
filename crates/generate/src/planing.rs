//! Ratio-coupled planing of twisted-lobe rotors (X–A): over the cutting stroke the rotary
//! axis follows the ram, `A = A_k + K·(X − X_start)`; a lead-in brings A up to speed before
//! the cut, the return stroke runs with the tool lifted, then the rotor indexes to the next
//! segment.
//!
//! The rotor end face has identical segments (six arcs in the common design). Each
//! segment's cutting stroke is followed at once by a job mark (`R50`/`#50` = segments done),
//! so the job state after an interruption is the set of marked segments, and the resume
//! program starts at the first unfinished segment.

use std::fmt::Write as _;

use thiserror::Error;

use super::ir::{Axis, Expr, Motion, Plane, Program, Stmt, Var};
use camloop_core::program::{ProgramNameError, validate_program_name};

/// A planing job.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaningJob {
    pub name: String,
    /// Identical segments of the end face, at least 1.
    pub segments: u32,
    /// Coupling ratio K, degrees of A per mm of X.
    pub ratio_deg_per_mm: f64,
    pub x_start_mm: f64,
    pub x_end_mm: f64,
    /// Length of the lead-in before the cut, mm.
    pub lead_in_mm: f64,
    /// Z while cutting and while returning (lifted), mm.
    pub z_cut_mm: f64,
    pub z_lift_mm: f64,
    pub feed_mm_min: f64,
}

/// Which segments are finished, in segment order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JobState {
    pub finished: Vec<bool>,
}

impl JobState {
    pub fn new(segments: u32) -> Self {
        JobState {
            finished: vec![false; segments as usize],
        }
    }

    /// The job state from the mark the control kept (segments done in order).
    pub fn from_mark(segments: u32, done: u32) -> Self {
        JobState {
            finished: (0..segments).map(|k| k < done).collect(),
        }
    }

    pub(crate) fn first_unfinished(&self) -> Option<usize> {
        self.finished.iter().position(|f| !f)
    }
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
    #[error("the job state has {state} segments, the job {job}")]
    StateMismatch { state: usize, job: u32 },
    #[error("every segment is finished: nothing to cut")]
    Finished,
}

/// The mark variable: segments done, in order.
pub(crate) const MARK: Var = Var {
    index: 50,
    name: "R50",
};

fn check(job: &PlaningJob) -> Result<(), PlaningError> {
    let bad = |field, value, rule| Err(PlaningError::Value { field, value, rule });
    if job.segments == 0 {
        return bad("segments", 0.0, "at least 1");
    }
    for (field, v) in [
        ("ratio", job.ratio_deg_per_mm),
        ("x start", job.x_start_mm),
        ("x end", job.x_end_mm),
        ("z cut", job.z_cut_mm),
        ("z lift", job.z_lift_mm),
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
    if !(job.lead_in_mm.is_finite() && job.lead_in_mm > 0.0) {
        return bad("lead-in", job.lead_in_mm, "it must be > 0");
    }
    if job.z_lift_mm <= job.z_cut_mm {
        return bad(
            "z lift",
            job.z_lift_mm,
            "the lifted tool must be above z cut",
        );
    }
    if !(job.feed_mm_min.is_finite() && job.feed_mm_min > 0.0) {
        return bad("feed", job.feed_mm_min, "it must be > 0");
    }
    Ok(())
}

/// A of segment k at X.
pub fn a_at(job: &PlaningJob, k: usize, x_mm: f64) -> f64 {
    360.0 * k as f64 / f64::from(job.segments) + job.ratio_deg_per_mm * (x_mm - job.x_start_mm)
}

/// The program from the first unfinished segment to the end, skipping finished ones.
pub fn generate(job: &PlaningJob, state: &JobState) -> Result<Program, PlaningError> {
    let name = validate_program_name(&job.name)?;
    check(job)?;
    if state.finished.len() != job.segments as usize {
        return Err(PlaningError::StateMismatch {
            state: state.finished.len(),
            job: job.segments,
        });
    }
    let first = state.first_unfinished().ok_or(PlaningError::Finished)?;
    let n = Expr::num;
    let mv = |motion, words: Vec<(Axis, f64)>, feed| Stmt::Move {
        motion,
        words: words.into_iter().map(|(a, v)| (a, n(v))).collect(),
        feed,
    };
    let x_lead = job.x_start_mm - job.lead_in_mm;
    let mut body = vec![mv(Motion::Rapid, vec![(Axis::Z, job.z_lift_mm)], None)];
    for k in first..job.segments as usize {
        if state.finished[k] {
            continue;
        }
        body.push(Stmt::Comment(format!(
            "segment {} of {}",
            k + 1,
            job.segments
        )));
        body.push(mv(
            Motion::Rapid,
            vec![(Axis::X, x_lead), (Axis::A, a_at(job, k, x_lead))],
            None,
        ));
        body.push(mv(Motion::Rapid, vec![(Axis::Z, job.z_cut_mm)], None));
        // Lead-in: A coupled before the tool meets the rotor, so it is at speed at the cut.
        body.push(mv(
            Motion::Linear,
            vec![
                (Axis::X, job.x_start_mm),
                (Axis::A, a_at(job, k, job.x_start_mm)),
            ],
            Some(job.feed_mm_min),
        ));
        body.push(mv(
            Motion::Linear,
            vec![
                (Axis::X, job.x_end_mm),
                (Axis::A, a_at(job, k, job.x_end_mm)),
            ],
            None,
        ));
        body.push(Stmt::Mark {
            var: MARK,
            value: (k + 1) as f64,
            text: format!("segments done: {}", k + 1),
        });
        body.push(mv(Motion::Rapid, vec![(Axis::Z, job.z_lift_mm)], None));
    }
    body.push(mv(Motion::Rapid, vec![(Axis::X, x_lead)], None));
    Ok(Program {
        name,
        plane: Plane::Xy,
        vars: Vec::new(),
        comments: vec![
            format!(
                "planing: A = A_k + {} deg/mm * (X - {}), {} segments, resuming at segment {}",
                job.ratio_deg_per_mm,
                job.x_start_mm,
                job.segments,
                first + 1
            ),
            "the return stroke and the index run with the tool lifted".to_owned(),
        ],
        body,
    })
}

/// The coupling as a SINUMERIK curve table (A following X over lead-in and stroke) and the
/// strokes with `LEADON`, each segment's index as the coupling's output offset (SD43106,
/// `$SA_LEAD_OFFSET_OUT_POS`) [K]. Same segments and marks as [`generate`].
pub fn render_sinumerik_table(
    job: &PlaningJob,
    state: &JobState,
    table: u32,
) -> Result<String, PlaningError> {
    let p = generate(job, state)?;
    let x_lead = job.x_start_mm - job.lead_in_mm;
    let mut out = String::new();
    let _ = writeln!(out, "%_N_{}_MPF\n;$PATH=/_N_MPF_DIR", p.name);
    for c in &p.comments {
        let _ = writeln!(out, "; {c}");
    }
    out.push_str("G90 G71\n");
    let _ = writeln!(out, "CTABDEF(A,X,{table},0) ; A follows X, not periodic");
    let _ = writeln!(out, "G1 X={x_lead:.4} A={:.4}", a_at(job, 0, x_lead));
    let _ = writeln!(
        out,
        "X={:.4} A={:.4}",
        job.x_end_mm,
        a_at(job, 0, job.x_end_mm)
    );
    out.push_str("CTABEND\n");
    let _ = writeln!(out, "G0 Z={:.4}", job.z_lift_mm);
    let first = state.first_unfinished().unwrap_or(0);
    for k in first..job.segments as usize {
        if state.finished[k] {
            continue;
        }
        let index = 360.0 * k as f64 / f64::from(job.segments);
        let _ = writeln!(out, "; segment {} of {}", k + 1, job.segments);
        let _ = writeln!(out, "G0 X={x_lead:.4} A={:.4}", a_at(job, k, x_lead));
        let _ = writeln!(out, "$SA_LEAD_OFFSET_OUT_POS[A]={index:.4}");
        let _ = writeln!(out, "G0 Z={:.4}", job.z_cut_mm);
        let _ = writeln!(out, "LEADON(A,X,{table})");
        let _ = writeln!(out, "G1 X={:.4} F{:.1}", job.x_end_mm, job.feed_mm_min);
        let _ = writeln!(out, "LEADOF(A,X)");
        out.push_str("STOPRE ; the mark waits for the stroke to end\n");
        let _ = writeln!(out, "R{}={} ; segments done: {}", MARK.index, k + 1, k + 1);
        let _ = writeln!(out, "G0 Z={:.4}", job.z_lift_mm);
    }
    let _ = writeln!(out, "G0 X={x_lead:.4}\nM30");
    Ok(out)
}
