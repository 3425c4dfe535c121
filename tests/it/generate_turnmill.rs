//! Turn-mill: the programmed path transformed back into the part frame gives the drawing
//! (from LinuxCNC's `rs274` running the ISO text, with its own cutter compensation where
//! the program asks for it, and from our evaluation of the SINUMERIK text); C turns only at
//! the park point; every program passes the shared safety check; the source's cut-in point
//! is reproduced.

use crate::rs274_support::{self, Canon, run_rs274};
use crate::sinumerik_support;

use camloop::core::generate::dialect::{Dialect, Form};
use camloop::core::generate::ir::Program;
use camloop::core::generate::safety;
use camloop::core::generate::setup::Setup;
use camloop::core::generate::turnmill::path::Side;
use camloop::core::generate::turnmill::{
    Contour, ContourSeg, EccentricCircle, Feature, RadiusMode, Shape, TurnMillError, TurnMillJob,
    generate, park_x_mm, passes, render, safety_rules,
};

const TOOL_R: f64 = 6.0;

fn circle(e: f64, phase: f64, r: f64, span: (f64, f64), concave: bool) -> EccentricCircle {
    EccentricCircle {
        eccentricity_mm: e,
        phase_deg: phase,
        radius_mm: r,
        start_deg: span.0,
        end_deg: span.1,
        safety_deg: 5.0,
        concave,
        clockwise: false,
        c_deg: None,
    }
}

fn feature(label: &str, shape: Shape, z: &[f64], stock: f64) -> Feature {
    Feature {
        label: label.to_owned(),
        shape,
        z_mm: z.to_vec(),
        stock_mm: stock,
        step_mm: 0.6,
    }
}

/// The arm contour of `config/turnmill-crank.toml`: a line, a tangent arc, a line.
fn arm() -> Contour {
    Contour {
        start: (70.0, -30.0),
        segments: vec![
            ContourSeg::Line { to: (70.0, 30.0) },
            ContourSeg::Arc {
                to: (40.0, 60.0),
                centre: (40.0, 30.0),
                clockwise: false,
            },
            ContourSeg::Line { to: (0.0, 60.0) },
        ],
        tool_side: Side::Right,
        c_deg: 0.0,
    }
}

fn job(mode: RadiusMode) -> TurnMillJob {
    let mut pin = circle(45.0, 30.0, 25.0, (0.0, 360.0), false);
    pin.c_deg = Some(12.345);
    let mut cheek = circle(0.0, 0.0, 60.0, (120.0, 240.0), false);
    cheek.clockwise = true;
    let mut features = vec![
        feature("pin 1", Shape::Circle(pin), &[-20.0, -32.0], 1.0),
        feature("cheek", Shape::Circle(cheek), &[-45.0], 0.0),
        feature("arm", Shape::Contour(arm()), &[-45.0], 0.5),
    ];
    if mode == RadiusMode::Baked {
        let fillet = circle(70.0, 200.0, 9.0, (0.0, 90.0), true);
        features.insert(
            2,
            feature("arm fillet", Shape::Circle(fillet), &[-45.0], 0.0),
        );
    }
    TurnMillJob {
        name: "CRANK_TURNMILL".to_owned(),
        setup: Setup::milling(),
        tool_radius_mm: TOOL_R,
        radius_mode: mode,
        clearance_mm: 2.0,
        lead_mm: 10.0,
        z_clear_mm: 20.0,
        feed_mm_min: 300.0,
        c_axis: "C".to_owned(),
        features,
    }
}

/// The program, after the shared safety check passed on it.
fn checked(j: &TurnMillJob) -> Program {
    let p = generate(j).unwrap();
    let report = safety::check(&p, &safety_rules(j).unwrap()).unwrap();
    assert!(report.rotary_moves > 0 && report.cutting_moves > 0);
    p
}

/// A move of the tool centre (or of the programmed path), end point and, for arcs, the
/// centre and sense, with C and Z.
#[derive(Debug, Clone, Copy)]
struct Mv {
    from: (f64, f64),
    to: (f64, f64),
    arc: Option<((f64, f64), bool)>,
    z: f64,
    c: f64,
    feed: bool,
}

fn rs274_moves(text: &str, tool_r: f64) -> Vec<Mv> {
    let Some(rs) = rs274_support::rs274() else {
        panic!("rs274 (Debian linuxcnc-uspace) is not installed: .ci/run installs it");
    };
    let mut out = Vec::new();
    let mut at = (f64::NAN, f64::NAN);
    for m in run_rs274(&rs, text, tool_r).unwrap() {
        let mv = match m {
            Canon::Rapid { x, y, z, c, .. } | Canon::Feed { x, y, z, c, .. } => Mv {
                from: at,
                to: (x, y),
                arc: None,
                z,
                c,
                feed: matches!(m, Canon::Feed { .. }),
            },
            Canon::Arc {
                e1,
                e2,
                c1,
                c2,
                turns,
                c,
                ..
            } => Mv {
                from: at,
                to: (e1, e2),
                arc: Some(((c1, c2), turns > 0)),
                z: f64::NAN,
                c,
                feed: true,
            },
        };
        at = mv.to;
        out.push(mv);
    }
    out
}

/// Machine → part frame with C: the inverse of `X = cos C·a + sin C·b`, `Y = −sin C·a + cos C·b`.
fn to_part((x, y): (f64, f64), c_deg: f64) -> (f64, f64) {
    let (s, c) = c_deg.to_radians().sin_cos();
    (c * x - s * y, s * x + c * y)
}

/// Points along a move, part frame.
fn samples(m: &Mv) -> Vec<(f64, f64)> {
    (0..=20)
        .map(|i| {
            let t = f64::from(i) / 20.0;
            let p = match m.arc {
                None => (
                    m.from.0 + t * (m.to.0 - m.from.0),
                    m.from.1 + t * (m.to.1 - m.from.1),
                ),
                Some((c, ccw)) => {
                    let r = (m.from.0 - c.0).hypot(m.from.1 - c.1);
                    let a0 = (m.from.1 - c.1).atan2(m.from.0 - c.0);
                    let a1 = (m.to.1 - c.1).atan2(m.to.0 - c.0);
                    let tau = std::f64::consts::TAU;
                    let d = if ccw {
                        (a1 - a0).rem_euclid(tau)
                    } else {
                        -(a0 - a1).rem_euclid(tau)
                    };
                    let a = a0 + t * d;
                    (c.0 + r * a.cos(), c.1 + r * a.sin())
                }
            };
            to_part(p, m.c)
        })
        .collect()
}

/// Distance from `p` to the arm contour, computed here from the drawing.
fn arm_distance(p: (f64, f64)) -> f64 {
    let seg = |a: (f64, f64), b: (f64, f64)| {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let t = (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
        (p.0 - a.0 - t * dx).hypot(p.1 - a.1 - t * dy)
    };
    let ang = (p.1 - 30.0).atan2(p.0 - 40.0).to_degrees();
    // The arc from 0° to 90° about (40, 30), radius 30; outside its angles, its ends.
    let arc = if (0.0..=90.0).contains(&ang) {
        ((p.0 - 40.0).hypot(p.1 - 30.0) - 30.0).abs()
    } else {
        (p.0 - 70.0)
            .hypot(p.1 - 30.0)
            .min((p.0 - 40.0).hypot(p.1 - 60.0))
    };
    seg((70.0, -30.0), (70.0, 30.0))
        .min(arc)
        .min(seg((40.0, 60.0), (0.0, 60.0)))
}

/// The geometry of the tool-centre moves of `job(mode)` as rs274 interprets them.
fn check_tool_path(moves: &[Mv], j: &TurnMillJob) {
    let park = park_x_mm(j).unwrap();
    let mut c_now = f64::NAN;
    let mut z_now = f64::NAN;
    let mut arcs = 0;
    for (i, m) in moves.iter().enumerate() {
        if !m.z.is_nan() {
            z_now = m.z;
        }
        if m.c != c_now && !c_now.is_nan() {
            assert!(
                m.from.0.hypot(m.from.1) >= park - 1e-3,
                "move {i}: C turns off the park point"
            );
        }
        c_now = m.c;
        if !m.feed {
            continue;
        }
        let f = j
            .features
            .iter()
            .find(|f| match &f.shape {
                Shape::Circle(c) => {
                    (camloop::core::generate::turnmill::circle_c_deg(c) - c_now).abs() < 1e-3
                }
                Shape::Contour(k) => (k.c_deg - c_now).abs() < 1e-3,
            })
            .unwrap_or_else(|| panic!("move {i}: C {c_now} is no feature's"));
        assert!(f.z_mm.contains(&z_now), "{}: cut at Z {z_now}", f.label);
        match &f.shape {
            Shape::Circle(c) => {
                let Some((machine_centre, _)) = m.arc else {
                    continue;
                };
                arcs += 1;
                let centre = to_part(machine_centre, c_now);
                let want = (
                    c.eccentricity_mm * c.phase_deg.to_radians().cos(),
                    c.eccentricity_mm * c.phase_deg.to_radians().sin(),
                );
                // 4 decimals on positions and centres: 0.1 µm each, a few roundings.
                assert!(
                    (centre.0 - want.0).hypot(centre.1 - want.1) < 3e-4,
                    "{}: centre {centre:?}",
                    f.label
                );
                let r = (m.to.0 - machine_centre.0).hypot(m.to.1 - machine_centre.1);
                let ok = passes(f.stock_mm, f.step_mm).iter().any(|left| {
                    let want = if c.concave {
                        c.radius_mm - TOOL_R - left
                    } else {
                        c.radius_mm + TOOL_R + left
                    };
                    (r - want).abs() < 3e-4
                });
                assert!(ok, "{}: arc radius {r}", f.label);
            }
            Shape::Contour(_) => {
                // No sample of a cutting move comes nearer the arm than the tool radius.
                for p in samples(m) {
                    assert!(
                        arm_distance(p) > TOOL_R - 3e-4,
                        "{}: move {i} gouges at {p:?}",
                        f.label
                    );
                }
            }
        }
    }
    assert!(arcs > 0);
}

/// Every point of the arm is touched: some sample of the tool path lies at the tool radius
/// from it (within the sampling's 0.05 mm).
fn check_arm_covered(moves: &[Mv]) {
    let cut: Vec<(f64, f64)> = moves
        .iter()
        .filter(|m| m.feed && m.c.abs() < 1e-9)
        .flat_map(|m| {
            let n = ((m.to.0 - m.from.0).hypot(m.to.1 - m.from.1) / 0.02)
                .ceil()
                .max(1.0) as usize;
            (0..=n).map(move |k| {
                let t = k as f64 / n as f64;
                (
                    m.from.0 + t * (m.to.0 - m.from.0),
                    m.from.1 + t * (m.to.1 - m.from.1),
                    m,
                )
            })
        })
        .filter(|(_, _, m)| m.arc.is_none())
        .map(|(x, y, _)| (x, y))
        .collect();
    for k in 0..=60 {
        let p = (70.0, -30.0 + f64::from(k));
        let near = cut
            .iter()
            .map(|q| (q.0 - p.0).hypot(q.1 - p.1))
            .fold(f64::INFINITY, f64::min);
        assert!(
            (near - TOOL_R).abs() < 0.05,
            "arm point {p:?}: nearest tool centre {near}"
        );
    }
}

#[test]
fn rs274_baked_radius_cuts_the_drawing_and_matches_the_sinumerik_text() {
    let j = job(RadiusMode::Baked);
    let p = checked(&j);
    let iso = render(&j, &p, Dialect::Iso, Form::Loop).unwrap();
    let moves = rs274_moves(&iso, 0.0);
    check_tool_path(&moves, &j);
    check_arm_covered(&moves);
    // The SINUMERIK text, evaluated, moves to the same X-Y points in the same order.
    let sin = render(&j, &p, Dialect::Sinumerik, Form::Loop).unwrap();
    let blocks = sinumerik_support::run(&sin, 4, 4).unwrap();
    let mut pos = (f64::NAN, f64::NAN);
    let mut ours = Vec::new();
    for b in &blocks {
        for w in b.split_whitespace() {
            if let Some(v) = w.strip_prefix("X=") {
                pos.0 = v.parse().unwrap();
            } else if let Some(v) = w.strip_prefix("Y=") {
                pos.1 = v.parse().unwrap();
            }
        }
        if !pos.0.is_nan() && !pos.1.is_nan() && ours.last() != Some(&pos) {
            ours.push(pos);
        }
    }
    let mut theirs: Vec<(f64, f64)> = Vec::new();
    for m in &moves {
        if theirs.last() != Some(&m.to) {
            theirs.push(m.to);
        }
    }
    // rs274 starts at the origin: its first move (Z up) is reported there.
    let first = theirs.iter().position(|p| *p == ours[0]).unwrap();
    let theirs = &theirs[first..];
    assert_eq!(theirs.len(), ours.len());
    for (a, b) in theirs.iter().zip(&ours) {
        assert!(
            (a.0 - b.0).abs() < 1e-4 && (a.1 - b.1).abs() < 1e-4,
            "{a:?} vs {b:?}"
        );
    }
    insta::assert_snapshot!("turnmill_sinumerik", sin);
    insta::assert_snapshot!("turnmill_iso", iso);
}

#[test]
fn rs274_compensated_path_is_the_tool_radius_off_the_contour() {
    let j = job(RadiusMode::Compensated);
    let p = checked(&j);
    let iso = render(&j, &p, Dialect::Iso, Form::Loop).unwrap();
    assert!(iso.contains("G42 G1") && iso.contains("G40 G1"), "{iso}");
    // rs274 compensates with the 6 mm tool of its table: its moves are the tool centre's.
    let moves = rs274_moves(&iso, TOOL_R);
    check_tool_path(&moves, &j);
    check_arm_covered(&moves);
    let sin = render(&j, &p, Dialect::Sinumerik, Form::Loop).unwrap();
    sinumerik_support::run(&sin, 4, 4).unwrap();
    assert!(sin.contains("G41 G1") || sin.contains("G42 G1"), "{sin}");
}

/// The turn-mill study's crank eccentric: e = 50 mm at 30°, C at 60°, r = 20 mm: the cut
/// starts at X 63.3013, Y −25.0 (its centre lands at 43.3013, −25.0).
#[test]
fn the_sources_cut_in_point_is_reproduced() {
    let mut c = circle(50.0, 30.0, 20.0, (0.0, 360.0), false);
    c.c_deg = Some(60.0);
    let mut j = job(RadiusMode::Compensated);
    j.features = vec![feature(
        "crank eccentric",
        Shape::Circle(c.clone()),
        &[-10.0],
        0.0,
    )];
    let p = checked(&j);
    let sin = render(&j, &p, Dialect::Sinumerik, Form::Loop).unwrap();
    let iso = render(&j, &p, Dialect::Iso, Form::Loop).unwrap();
    // Tangential along Y onto the cut-in point, at feed: after the move in along X.
    let lines: Vec<&str> = sin.lines().collect();
    let at = lines
        .iter()
        .position(|l| *l == "G1 X=63.3013 Y=-25.0000")
        .expect(&sin);
    assert!(
        lines[at - 1].starts_with("G42 G1 X=63.3013 Y=-35.0000 F"),
        "{}",
        lines[at - 1]
    );
    assert!(iso.contains("\nG1 X63.3013 Y-25.0000\n"), "{iso}");
    // rs274 compensates: the tool centre arrives 6 mm further out on X.
    let moves = rs274_moves(&iso, TOOL_R);
    assert!(
        moves
            .iter()
            .any(|m| m.feed && (m.to.0 - 69.3013).abs() < 1e-3 && (m.to.1 + 25.0).abs() < 1e-3),
        "no tool-centre move to (69.3013, -25)"
    );
    // Baked: a 14 mm pin with the 6 mm tool in the path gives the same point.
    c.radius_mm = 14.0;
    let mut b = job(RadiusMode::Baked);
    b.features = vec![feature("crank eccentric", Shape::Circle(c), &[-10.0], 0.0)];
    let text = render(&b, &checked(&b), Dialect::Sinumerik, Form::Loop).unwrap();
    assert!(text.contains("\nG1 X=63.3013 Y=-25.0000\n"), "{text}");
}

#[test]
fn axis_names_g2_and_g3_and_refusals() {
    let mut j = job(RadiusMode::Baked);
    j.c_axis = "C1".to_owned();
    let p = checked(&j);
    let sin = render(&j, &p, Dialect::Sinumerik, Form::Loop).unwrap();
    assert!(
        sin.contains("G0 C1=12.3450") && !sin.contains(" C="),
        "{sin}"
    );
    assert!(
        sin.contains("\nG2 ") && sin.contains("\nG3 "),
        "both senses of arc"
    );
    assert!(
        sin.contains("G94") && sin.contains("M3") && sin.contains("M5"),
        "{sin}"
    );
    assert!(matches!(
        render(&j, &p, Dialect::Iso, Form::Loop),
        Err(TurnMillError::AxisName(..))
    ));
    // A corner the tool would have to cut into.
    let mut bad = job(RadiusMode::Baked);
    let Shape::Contour(k) = &mut bad.features[3].shape else {
        panic!()
    };
    k.segments.push(ContourSeg::Line { to: (0.0, 100.0) });
    let e = generate(&bad).unwrap_err();
    assert!(e.to_string().contains("arm: segment 3"), "{e}");
    let mut bad = job(RadiusMode::Compensated);
    bad.features.push(feature(
        "bore",
        Shape::Circle(circle(0.0, 0.0, 10.0, (0.0, 90.0), true)),
        &[-5.0],
        0.0,
    ));
    assert!(matches!(
        generate(&bad),
        Err(TurnMillError::Approach { .. })
    ));
    let mut bad = job(RadiusMode::Baked);
    bad.features[2].shape = Shape::Circle(circle(70.0, 200.0, 5.0, (0.0, 90.0), true));
    assert!(generate(&bad).is_err());
}

mod props {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

        /// Random pins, cheeks and settings: the program passes the safety check, rs274
        /// runs it (both radius modes) and our evaluator runs the SINUMERIK text.
        #[test]
        fn random_parts_pass_the_checks(
            e in 0.0f64..80.0, phase in -180.0f64..180.0, r in 8.0f64..40.0,
            start in 0.0f64..300.0, span in 20.0f64..360.0, full in any::<bool>(),
            clockwise in any::<bool>(), c in proptest::option::of(-180.0f64..180.0),
            stock in 0.0f64..2.0, compensated in any::<bool>(), z in -50.0f64..-1.0,
        ) {
            let mut circ = circle(e, phase, r, if full { (0.0, 360.0) } else { (start, start + span.min(300.0)) }, false);
            circ.clockwise = clockwise;
            circ.c_deg = if full { c } else { None };
            let mut j = job(if compensated { RadiusMode::Compensated } else { RadiusMode::Baked });
            // Z as a drawing gives it (the program writes 4 decimals).
            let z = (z * 1000.0).round() / 1000.0;
            j.features = vec![feature("pin", Shape::Circle(circ), &[z], stock)];
            let p = checked(&j);
            let iso = render(&j, &p, Dialect::Iso, Form::Loop).unwrap();
            let moves = rs274_moves(&iso, if compensated { TOOL_R } else { 0.0 });
            check_tool_path(&moves, &j);
            let sin = render(&j, &p, Dialect::Sinumerik, Form::Loop).unwrap();
            sinumerik_support::run(&sin, 4, 4).unwrap();
        }
    }
}
