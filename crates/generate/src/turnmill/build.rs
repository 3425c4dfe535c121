//! The turn-mill program: set-up, then per feature, Z station and radial pass, C at the park
//! point, the approach, the path and the retract back to the park point; the end.

use super::path::{self, P, Seg, Side};
use super::{
    Compensation, Feature, RadiusMode, Shape, TurnMillError, TurnMillJob, circle_c_deg,
    circle_side, comp_for, move_1, move_xy, offset_error, part_path, program,
};
use crate::dialect::{Decimals, Dialect, Form};
use crate::ir::{Axis, Expr, Motion, Program, Stmt};
use crate::safety::{Clear, Rotary, Rules};
use crate::setup::FeedMode;
use camloop_core::program::{validate_axis_name, validate_program_name};

/// The angles a circle's arc runs through, drawing angles, `from < to`: the drawing span
/// widened by the safety angle at both ends; a full turn from the angle C puts on +X, once
/// round and on by the safety angle.
pub fn cut_span_deg(c: &super::EccentricCircle) -> (f64, f64) {
    if c.end_deg - c.start_deg >= 360.0 {
        let phi = circle_c_deg(c);
        if c.clockwise {
            (phi - 360.0 - c.safety_deg, phi)
        } else {
            (phi, phi + 360.0 + c.safety_deg)
        }
    } else {
        (c.start_deg - c.safety_deg, c.end_deg + c.safety_deg)
    }
}

fn check(job: &TurnMillJob) -> Result<(), TurnMillError> {
    let bad = |label: &str, field, value: f64, rule| TurnMillError::Value {
        label: label.to_owned(),
        field,
        value,
        rule,
    };
    for (field, v) in [
        ("tool radius", job.tool_radius_mm),
        ("clearance", job.clearance_mm),
        ("lead", job.lead_mm),
        ("feed", job.feed_mm_min),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(bad("job", field, v, "it must be > 0"));
        }
    }
    if !job.z_clear_mm.is_finite() {
        return Err(bad(
            "job",
            "z clear",
            job.z_clear_mm,
            "it must be a finite number",
        ));
    }
    for f in &job.features {
        let l = f.label.as_str();
        if f.z_mm.is_empty() {
            return Err(bad(l, "z stations", 0.0, "at least one"));
        }
        for &z in &f.z_mm {
            if !(z.is_finite() && z < job.z_clear_mm) {
                return Err(bad(l, "z station", z, "it must be below z clear"));
            }
        }
        if !(f.stock_mm.is_finite() && f.stock_mm >= 0.0) {
            return Err(bad(l, "stock", f.stock_mm, "it must be >= 0"));
        }
        if !(f.step_mm.is_finite() && f.step_mm > 0.0) {
            return Err(bad(l, "step", f.step_mm, "it must be > 0"));
        }
        if let Shape::Circle(c) = &f.shape {
            check_circle(job, l, c)?;
        }
    }
    Ok(())
}

fn check_circle(
    job: &TurnMillJob,
    l: &str,
    c: &super::EccentricCircle,
) -> Result<(), TurnMillError> {
    let bad = |field, value: f64, rule| TurnMillError::Value {
        label: l.to_owned(),
        field,
        value,
        rule,
    };
    for (field, v) in [
        ("eccentricity", c.eccentricity_mm),
        ("phase", c.phase_deg),
        ("start angle", c.start_deg),
        ("end angle", c.end_deg),
        ("C", c.c_deg.unwrap_or(0.0)),
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
    if !(c.safety_deg.is_finite() && (0.0..=45.0).contains(&c.safety_deg)) {
        return Err(bad(
            "safety angle",
            c.safety_deg,
            "it must be in [0, 45] deg",
        ));
    }
    if c.concave && job.radius_mode == RadiusMode::Compensated {
        return Err(TurnMillError::Approach {
            label: l.to_owned(),
            what: "a concave circle is entered radially from inside, which G41/G42 cannot start on: bake the tool radius in",
        });
    }
    Ok(())
}

/// The program for every feature, in order.
pub fn generate(job: &TurnMillJob) -> Result<Program, TurnMillError> {
    let name = validate_program_name(&job.name)?;
    job.setup.check()?;
    if job.setup.feed_mode != FeedMode::PerMinute {
        return Err(TurnMillError::Value {
            label: "job".to_owned(),
            field: "feed mode",
            value: 95.0,
            rule: "a milling feed is per minute (G94)",
        });
    }
    if job.features.is_empty() {
        return Err(TurnMillError::Empty);
    }
    check(job)?;
    let paths = job
        .features
        .iter()
        .map(part_path)
        .collect::<Result<Vec<_>, _>>()?;
    let park = (park_x_mm(job)?, 0.0);
    let mut body = job.setup.start();
    body.push(move_1(Motion::Rapid, Axis::Z, job.z_clear_mm));
    body.push(move_xy(Motion::Rapid, park, None));
    let mut c_now = None;
    for (f, p) in job.features.iter().zip(&paths) {
        body.push(Stmt::Comment(describe(f)));
        for &z in &f.z_mm {
            for remaining in passes(f.stock_mm, f.step_mm) {
                let pass = Pass {
                    job,
                    f,
                    park,
                    z,
                    remaining,
                };
                body.extend(pass.stmts(p, &mut c_now)?);
            }
        }
    }
    body.push(move_1(Motion::Rapid, Axis::Z, job.z_clear_mm));
    body.extend(job.setup.end());
    Ok(program(name, header(job, park), body))
}

fn header(job: &TurnMillJob, park: P) -> Vec<String> {
    let radius = match job.radius_mode {
        RadiusMode::Baked => format!("tool radius {} mm baked into the path", job.tool_radius_mm),
        RadiusMode::Compensated => format!(
            "path on the part contour, G41/G42: the control adds the tool radius ({} mm)",
            job.tool_radius_mm
        ),
    };
    vec![
        format!("turn-mill: {} features, {radius}", job.features.len()),
        job.setup.describe(),
        "centre with C at phi: X = COS(phi)*a + SIN(phi)*b, Y = -SIN(phi)*a + COS(phi)*b"
            .to_owned(),
        format!(
            "{} turns only at the park point X {:.3} Y 0, outside the part's swing",
            job.c_axis, park.0
        ),
    ]
}

fn describe(f: &Feature) -> String {
    let what = match &f.shape {
        Shape::Circle(c) => format!(
            "radius {} mm at e = {} mm, phase {} deg, C {} deg",
            c.radius_mm,
            c.eccentricity_mm,
            c.phase_deg,
            circle_c_deg(c)
        ),
        Shape::Contour(k) => format!(
            "contour of {} segments, C {} deg",
            k.segments.len(),
            k.c_deg
        ),
    };
    format!(
        "{}: {what}; Z stations {:?}; stock {} mm in passes of at most {} mm",
        f.label, f.z_mm, f.stock_mm, f.step_mm
    )
}

/// X of the park point (Y 0): outside the swing circle of every feature with its stock,
/// the tool and the clearance. C turns only there.
pub fn park_x_mm(job: &TurnMillJob) -> Result<f64, TurnMillError> {
    let mut reach: f64 = 0.0;
    for f in &job.features {
        reach = reach.max(path::reach(&part_path(f)?) + f.stock_mm);
    }
    Ok(reach + job.tool_radius_mm + job.clearance_mm)
}

/// The safety check's facts for this job: C turns only at the park point's radius or
/// farther out; X may be negative (milling).
pub fn safety_rules(job: &TurnMillJob) -> Result<Rules, TurnMillError> {
    // 1 µm less: the park point as written, rounded to 4 decimals.
    let park = park_x_mm(job)? - 1e-3;
    Ok(Rules {
        min_x_mm: None,
        rotary: vec![Rotary {
            axis: Axis::C,
            coupled_cut: false,
        }],
        clear: vec![Clear::RadiusAtLeast { mm: park }],
        no_spindle: false,
    })
}

/// Stock left after each radial pass, last 0: equal steps no larger than `step`.
pub fn passes(stock: f64, step: f64) -> Vec<f64> {
    let n = (stock / step).ceil().max(1.0) as usize;
    (1..=n)
        .map(|i| (stock - stock * i as f64 / n as f64).max(0.0))
        .collect()
}

struct Pass<'a> {
    job: &'a TurnMillJob,
    f: &'a Feature,
    park: P,
    z: f64,
    remaining: f64,
}

impl Pass<'_> {
    /// The pass's path in the machine frame (offset, arcs split, turned by C), the tool's
    /// side, C and whether the surface is concave.
    fn machine_path(&self, part: &[Seg]) -> Result<(Vec<Seg>, Side, f64, bool), TurnMillError> {
        let job = self.job;
        let (side, c_deg, concave) = match &self.f.shape {
            Shape::Circle(c) => (circle_side(c), circle_c_deg(c), c.concave),
            Shape::Contour(k) => (k.tool_side, k.c_deg, false),
        };
        let baked = job.radius_mode == RadiusMode::Baked;
        let d = self.remaining + if baked { job.tool_radius_mm } else { 0.0 };
        let label = &self.f.label;
        let off = path::offset(part, side, d).map_err(|e| offset_error(label, e))?;
        let m: Vec<Seg> = path::split_arcs(&off)
            .iter()
            .map(|s| s.to_machine(c_deg))
            .collect();
        if !baked && let Some(Seg::Arc { radius, .. }) = m.iter().find(|s| {
            matches!(s, Seg::Arc { radius, sweep_deg, .. } if (*sweep_deg > 0.0) == (side == Side::Left) && *radius <= job.tool_radius_mm)
        }) {
            return Err(TurnMillError::ToolTooLarge {
                label: label.clone(),
                radius_mm: *radius,
            });
        }
        Ok((m, side, c_deg, concave))
    }

    fn stmts(&self, part: &[Seg], c_now: &mut Option<f64>) -> Result<Vec<Stmt>, TurnMillError> {
        let job = self.job;
        let (m, side, c_deg, concave) = self.machine_path(part)?;
        let baked = job.radius_mode == RadiusMode::Baked;
        let label = &self.f.label;
        let (first, last) = (m[0], m[m.len() - 1]);
        let mut s = vec![Stmt::Comment(format!(
            "{label}: Z {}, {} mm stock left after this pass",
            self.z, self.remaining
        ))];
        if *c_now != Some(c_deg) {
            s.push(move_1(Motion::Rapid, Axis::C, c_deg));
            *c_now = Some(c_deg);
        }
        let (p0, t0) = (first.start(), first.tangent(false));
        let (p1, t1) = (last.end(), last.tangent(true));
        let (n0, n1) = (path::normal(t0, side), path::normal(t1, side));
        let at =
            |p: P, t: P, k: f64, n: P, j: f64| (p.0 + k * t.0 + j * n.0, p.1 + k * t.1 + j * n.1);
        // Off the surface: the clearance; compensated, the programmed path is the contour and
        // the tool a radius farther out. A concave surface is entered radially from inside.
        let (lead, out) = if concave {
            let radius = match first {
                Seg::Arc { radius, .. } => radius,
                Seg::Line { .. } => f64::INFINITY,
            };
            (0.0, job.clearance_mm.min(radius / 2.0))
        } else {
            (
                job.lead_mm,
                job.clearance_mm + if baked { 0.0 } else { job.tool_radius_mm },
            )
        };
        let q1 = at(p0, t0, -lead, n0, 0.0);
        let q0 = at(p0, t0, -lead, n0, out);
        self.check_entry(&m, q0)?;
        // From the park point at Z clear: along Y, then X, down to the station beside the
        // surface, then in (X) and onto it (Y) at feed.
        s.push(move_1(Motion::Rapid, Axis::Y, q0.1));
        s.push(move_1(Motion::Rapid, Axis::X, q0.0));
        s.push(move_1(Motion::Rapid, Axis::Z, self.z));
        if !baked {
            s.push(Stmt::Comp(comp_for(side)));
        }
        s.push(move_xy(Motion::Linear, q1, Some(job.feed_mm_min)));
        if lead > 0.0 {
            s.push(move_xy(Motion::Linear, p0, None));
        }
        s.extend(m.iter().map(seg_move));
        let e1 = at(p1, t1, lead, n1, 0.0);
        if lead > 0.0 {
            s.push(move_xy(Motion::Linear, e1, None));
        }
        if !baked {
            s.push(Stmt::Comp(Compensation::Off));
        }
        s.push(move_xy(Motion::Linear, at(p1, t1, lead, n1, out), None));
        // Back to the park point over the part.
        s.push(move_1(Motion::Rapid, Axis::Z, job.z_clear_mm));
        s.push(move_1(Motion::Rapid, Axis::X, self.park.0));
        s.push(move_1(Motion::Rapid, Axis::Y, self.park.1));
        Ok(s)
    }

    /// Where the tool comes down beside the surface it keeps half the clearance from the
    /// path (every element of it): a start that would sit on the part is refused.
    fn check_entry(&self, m: &[Seg], q0: P) -> Result<(), TurnMillError> {
        let margin = match self.job.radius_mode {
            RadiusMode::Baked => 0.0,
            RadiusMode::Compensated => self.job.tool_radius_mm,
        };
        if m.iter()
            .any(|s| path::distance(s, q0) < margin + self.job.clearance_mm / 2.0 - 1e-9)
        {
            return Err(TurnMillError::Approach {
                label: self.f.label.clone(),
                what: "the tool would come down on the path: the entry point beside the surface is too close to it",
            });
        }
        Ok(())
    }
}

fn seg_move(s: &Seg) -> Stmt {
    match *s {
        Seg::Line { to, .. } => move_xy(Motion::Linear, to, None),
        Seg::Arc {
            centre, sweep_deg, ..
        } => {
            let (a, b) = (s.start(), s.end());
            Stmt::Move {
                motion: if sweep_deg > 0.0 {
                    Motion::ArcCcw
                } else {
                    Motion::ArcCw
                },
                words: vec![
                    (Axis::X, Expr::num(b.0)),
                    (Axis::Y, Expr::num(b.1)),
                    (Axis::I, Expr::num(centre.0 - a.0)),
                    (Axis::J, Expr::num(centre.1 - a.1)),
                ],
                feed: None,
            }
        }
    }
}

/// The program as text, the C axis under its configured name.
pub fn render(
    job: &TurnMillJob,
    program: &Program,
    dialect: Dialect,
    form: Form,
) -> Result<String, TurnMillError> {
    let text = dialect.render(program, form, Decimals::default());
    let name = validate_axis_name("C", &job.c_axis).map_err(|_| {
        TurnMillError::AxisName(job.c_axis.clone(), "not an axis name the control accepts")
    })?;
    if name == "C" {
        return Ok(text);
    }
    if dialect == Dialect::Iso {
        return Err(TurnMillError::AxisName(
            name,
            "ISO (LinuxCNC) names its rotary axes by one letter: A, B or C",
        ));
    }
    // Only motion words: ` C=` before any comment of a block.
    Ok(text
        .lines()
        .map(|l| {
            let (code, comment) = l.split_once(';').map_or((l, None), |(c, k)| (c, Some(k)));
            let code = code.replace(" C=", &format!(" {name}="));
            match comment {
                Some(k) => format!("{code};{k}\n"),
                None => format!("{code}\n"),
            }
        })
        .collect())
}
