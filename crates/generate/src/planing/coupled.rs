//! The planing job for a SINUMERIK whose A and Z follow X by the control's own master-value
//! coupling (`CTABDEF` curve tables, `LEADON`): the form the hydraulic-ram planer needs,
//! where X is measured, not commanded, and A and Z must follow the measured position.
//!
//! Two tables over X from the front to the rear over-travel: A (one straight piece, the
//! ratio) and Z (the face's control points). Every stroke uses both; each arc's index is
//! the A coupling's output offset (SD43106, `$SA_LEAD_OFFSET_OUT_POS`) [K]. The arcs are
//! guarded by `R50` as in [`super::generate`], so the control resumes by itself.

use std::fmt::Write as _;

use super::{MARK_R, MCode, PlaningError, PlaningJob, a_at, stroke_x_mm, z_at};
use crate::setup::Coolant;
use camloop_core::program::validate_program_name;

/// The curve-table program; `table` and `table + 1` are the A and Z tables.
pub fn render_sinumerik_table(job: &PlaningJob, table: u32) -> Result<String, PlaningError> {
    let name = validate_program_name(&job.name)?;
    let xs = stroke_x_mm(job)?;
    let x_front = job.x_start_mm - job.over_travel_front_mm;
    let x_rear = job.x_end_mm + job.over_travel_rear_mm;
    let (ta, tz) = (table, table + 1);
    let mut out = String::new();
    let _ = writeln!(out, "%_N_{name}_MPF\n;$PATH=/_N_MPF_DIR");
    for c in super::header(job, xs.len()) {
        let _ = writeln!(out, "; {c}");
    }
    out.push_str("G17 G90 G71 ; X-Y plane, absolute, metric\n");
    // The set-up of [`super::generate`], in SINUMERIK's words: no spindle on a planer.
    let _ = writeln!(out, "G{} ; work offset", 53 + u32::from(job.work_offset));
    let _ = writeln!(out, "T{} D{} ; tool", job.tool.number, job.tool.offset);
    out.push_str("G94 ; F in mm per minute\n");
    let coolant = match job.coolant {
        Coolant::Flood => Some("M8 ; coolant on"),
        Coolant::Mist => Some("M7 ; mist coolant on"),
        Coolant::Off => None,
    };
    if let Some(c) = coolant {
        let _ = writeln!(out, "{c}");
    }
    let m = &job.m_codes;
    m_line(&mut out, m.hydraulics_on, "hydraulics on");
    let _ = writeln!(out, "CTABDEF(A,X,{ta},0) ; A follows X, not periodic");
    let _ = writeln!(out, "G1 X={x_front:.4} A={:.4}", a_at(job, 0, x_front));
    let _ = writeln!(out, "X={x_rear:.4} A={:.4}", a_at(job, 0, x_rear));
    out.push_str("CTABEND\n");
    let _ = writeln!(out, "CTABDEF(Z,X,{tz},0) ; Z follows X over the face");
    let _ = writeln!(out, "G1 X={x_front:.4} Z={:.4}", z_at(job, 0, x_front));
    for &x in &xs {
        let _ = writeln!(out, "X={x:.4} Z={:.4}", z_at(job, 0, x));
    }
    let _ = writeln!(out, "X={x_rear:.4} Z={:.4}", z_at(job, 0, x_rear));
    out.push_str("CTABEND\n");
    let _ = writeln!(out, "G0 Z={:.4}", job.z_clear_mm);
    for k in 0..job.face.segments as usize {
        let index = job.face.period_deg() * k as f64;
        let _ = writeln!(out, "IF {MARK_R}>={} GOTOF SKIP_{k}", k + 1);
        let _ = writeln!(out, "; arc {} of {}", k + 1, job.face.segments);
        let _ = writeln!(out, "G0 X={x_front:.4} A={:.4}", a_at(job, k, x_front));
        let _ = writeln!(out, "$SA_LEAD_OFFSET_OUT_POS[A]={index:.4}");
        m_line(&mut out, m.a_forward, "A forward");
        m_line(&mut out, m.lift_off, "tool lowered");
        let _ = writeln!(
            out,
            "G1 Z={:.4} F{:.1}",
            z_at(job, k, x_front),
            job.feed_mm_min
        );
        let _ = writeln!(out, "LEADON(A,X,{ta})\nLEADON(Z,X,{tz})");
        let _ = writeln!(out, "G1 X={x_rear:.4} F{:.1}", job.feed_mm_min);
        out.push_str("LEADOF(A,X)\nLEADOF(Z,X)\n");
        out.push_str("STOPRE ; the mark waits for the stroke to end\n");
        let _ = writeln!(out, "{MARK_R}={} ; arcs done: {}", k + 1, k + 1);
        m_line(&mut out, m.lift_on, "tool lifted");
        let _ = writeln!(out, "G0 Z={:.4}", job.z_clear_mm);
        m_line(&mut out, m.a_reverse, "A reversed");
        let _ = writeln!(out, "SKIP_{k}:");
    }
    out.push_str("STOPRE\n");
    let _ = writeln!(
        out,
        "{MARK_R}=0 ; job complete: the next run starts a new rotor"
    );
    let _ = writeln!(out, "G0 X={x_front:.4}");
    m_line(&mut out, m.hydraulics_off, "hydraulics off");
    out.push_str("M9 ; coolant off\nM30\n");
    Ok(out)
}

/// An M function line (SINUMERIK: no P word; the card refuses one before this).
fn m_line(out: &mut String, code: Option<MCode>, what: &str) {
    if let Some(m) = code {
        let _ = writeln!(out, "M{} ; {what}", m.code);
    }
}
