//! Turn-mill eccentric circles: the programmed path transformed back into the part frame
//! must give the drawing's radius and phase, from our own evaluation of the SINUMERIK text
//! and from LinuxCNC's interpreter running the ISO text.

use crate::sinumerik_support;
use sinumerik_support as sinumerik_eval;

use crate::rs274_support;

use camloop::core::generate::dialect::{Decimals, Dialect, Form};
use camloop::core::generate::turnmill::{
    EccentricCircle, TurnMillError, TurnMillJob, cut_span_deg, generate,
};
use rs274_support::{Canon, run_rs274};

const TOOL_R: f64 = 6.0;

fn circle(
    label: &str,
    e: f64,
    phase: f64,
    r: f64,
    span: (f64, f64),
    concave: bool,
) -> EccentricCircle {
    EccentricCircle {
        label: label.to_owned(),
        eccentricity_mm: e,
        phase_deg: phase,
        radius_mm: r,
        start_deg: span.0,
        end_deg: span.1,
        safety_deg: 5.0,
        concave,
        c_deg: None,
    }
}

fn job() -> TurnMillJob {
    let mut cheek = circle("cheek", 0.0, 0.0, 60.0, (120.0, 240.0), false);
    cheek.c_deg = Some(17.5);
    // C away from the phase, so the pins' centres land off the X axis and the phase check
    // sees real rounding.
    let mut pin1 = circle("pin 1", 45.0, 30.0, 25.0, (0.0, 360.0), false);
    pin1.c_deg = Some(12.345);
    let mut pin2 = circle("pin 2", 45.0, 210.0, 25.0, (0.0, 360.0), false);
    pin2.c_deg = Some(-47.0);
    TurnMillJob {
        name: "CRANK_TURNMILL".to_owned(),
        tool_radius_mm: TOOL_R,
        clearance_mm: 2.0,
        feed_mm_min: 300.0,
        circles: vec![
            pin1,
            cheek,
            circle("arm fillet", 70.0, 200.0, 8.0, (0.0, 90.0), true),
            pin2,
        ],
    }
}

/// An arc in machine X/Y with C: start, end, centre.
struct Arc {
    c_deg: f64,
    start: (f64, f64),
    end: (f64, f64),
    centre: (f64, f64),
}

/// Machine → part frame: the inverse of `X = cos φ·a + sin φ·b`, `Y = −sin φ·a + cos φ·b`.
fn to_part((x, y): (f64, f64), c_deg: f64) -> (f64, f64) {
    let (s, c) = c_deg.to_radians().sin_cos();
    (c * x - s * y, s * x + c * y)
}

/// Per circle of the job, in order: the arcs cut.
fn check_arcs(arcs_per_circle: &[Vec<Arc>], job: &TurnMillJob) -> f64 {
    let mut worst_phase_deg: f64 = 0.0;
    assert_eq!(arcs_per_circle.len(), job.circles.len());
    for (arcs, c) in arcs_per_circle.iter().zip(&job.circles) {
        let path_r = if c.concave {
            c.radius_mm - TOOL_R
        } else {
            c.radius_mm + TOOL_R
        };
        let mut swept = 0.0;
        for a in arcs {
            let centre = to_part(a.centre, a.c_deg);
            let e = centre.0.hypot(centre.1);
            // 4-decimal positions: 0.1 µm, and the centre is start + (I, J), two roundings.
            assert!((e - c.eccentricity_mm).abs() < 2e-4, "{}: e = {e}", c.label);
            if c.eccentricity_mm > 0.0 {
                let phase = centre.1.atan2(centre.0).to_degrees();
                let err = ((phase - c.phase_deg + 540.0).rem_euclid(360.0) - 180.0).abs();
                worst_phase_deg = worst_phase_deg.max(err);
            }
            for p in [a.start, a.end] {
                let q = to_part(p, a.c_deg);
                let r = (q.0 - centre.0).hypot(q.1 - centre.1);
                assert!((r - path_r).abs() < 2e-4, "{}: radius {r}", c.label);
            }
            let ang = |p: (f64, f64)| {
                let q = to_part(p, a.c_deg);
                (q.1 - centre.1).atan2(q.0 - centre.0).to_degrees()
            };
            swept += (ang(a.end) - ang(a.start)).rem_euclid(360.0);
        }
        let (from, to) = cut_span_deg(c);
        // The arcs sweep exactly the drawing span plus the safety overlap: no air cutting.
        assert!(
            (swept - (to - from)).abs() < 1e-3,
            "{}: swept {swept} vs {}",
            c.label,
            to - from
        );
        let first = arcs[0].start;
        let q = to_part(first, arcs[0].c_deg);
        let centre = to_part(arcs[0].centre, arcs[0].c_deg);
        let start_ang = (q.1 - centre.1).atan2(q.0 - centre.0).to_degrees();
        let d = ((start_ang - from + 540.0).rem_euclid(360.0) - 180.0).abs();
        assert!(
            d < 1e-3,
            "{}: cut starts at {start_ang} deg, drawing says {from}",
            c.label
        );
    }
    worst_phase_deg
}

fn word(line: &str, axis: &str) -> Option<f64> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(axis).and_then(|v| v.strip_prefix('=')))
        .map(|v| v.parse().unwrap())
}

#[test]
fn sinumerik_path_transformed_back_matches_the_drawing() {
    let job = job();
    let program = generate(&job).unwrap();
    let text = Dialect::Sinumerik.render(&program, Form::Loop, Decimals::default());
    assert!(text.contains("DEF REAL PHI,ECC,PHA,RAD,XC,YC"), "{text}");
    let moves = sinumerik_eval::run(&text, 4, 4).unwrap();
    let mut per_circle: Vec<Vec<Arc>> = Vec::new();
    let (mut c_deg, mut pos) = (0.0, (0.0, 0.0));
    for m in &moves {
        if let Some(c) = word(m, "C") {
            c_deg = c;
            per_circle.push(Vec::new());
            continue;
        }
        let end = (word(m, "X").unwrap(), word(m, "Y").unwrap());
        if m.starts_with("G3") {
            let centre = (pos.0 + word(m, "I").unwrap(), pos.1 + word(m, "J").unwrap());
            per_circle.last_mut().unwrap().push(Arc {
                c_deg,
                start: pos,
                end,
                centre,
            });
        }
        pos = end;
    }
    let worst = check_arcs(&per_circle, &job);
    eprintln!("turn-mill SINUMERIK: worst phase error {worst:.2e} deg");
    assert!(worst < 1e-3);
    insta::assert_snapshot!("turnmill_sinumerik", text);
}

#[test]
fn rs274_path_transformed_back_matches_the_drawing() {
    let Some(rs) = rs274_support::rs274() else {
        panic!("rs274 (Debian linuxcnc-uspace) is not installed: .ci/run installs it");
    };
    let job = job();
    let program = generate(&job).unwrap();
    let text = Dialect::Iso.render(&program, Form::Loop, Decimals::default());
    let canon = run_rs274(&rs, &text, 0.0).unwrap();
    let mut per_circle: Vec<Vec<Arc>> = Vec::new();
    let (mut c_deg, mut pos) = (f64::NAN, (0.0, 0.0));
    for m in canon {
        match m {
            Canon::Rapid { x, y, c, .. } | Canon::Feed { x, y, c, .. } => {
                if c != c_deg {
                    c_deg = c;
                    per_circle.push(Vec::new());
                }
                pos = (x, y);
            }
            Canon::Arc {
                e1,
                e2,
                c1,
                c2,
                turns,
                ..
            } => {
                assert_eq!(turns, 1, "counter-clockwise, less than one turn");
                per_circle.last_mut().unwrap().push(Arc {
                    c_deg,
                    start: pos,
                    end: (e1, e2),
                    centre: (c1, c2),
                });
                pos = (e1, e2);
            }
        }
    }
    per_circle.retain(|arcs| !arcs.is_empty());
    let worst = check_arcs(&per_circle, &job);
    eprintln!("turn-mill rs274: worst phase error {worst:.2e} deg");
    assert!(worst < 1e-3);
}

#[test]
fn refusals() {
    let mut j = job();
    j.circles[2].radius_mm = 5.0;
    let e = generate(&j).unwrap_err();
    assert!(matches!(e, TurnMillError::ToolTooLarge { .. }), "{e}");
    assert!(e.to_string().contains("arm fillet"));
    let mut j = job();
    j.circles[0].end_deg = -10.0;
    assert!(matches!(generate(&j), Err(TurnMillError::Value { .. })));
}
