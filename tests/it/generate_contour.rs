//! Turning contours: chords proven against the exact curve by an independent method, the
//! SINUMERIK loop checked against the expanded form by evaluating its text, the ISO loop run
//! through LinuxCNC's `rs274` interpreter, refusals, and golden programs.

use crate::sinumerik_support;
use sinumerik_support as sinumerik_eval;

use crate::rs274_support;

use camloop::core::generate::contour::{ContourError, ContourJob, Roughing, Side, generate};
use camloop::core::generate::curve::{Curve, Ellipse, Parabola, Sine, Tangent};
use camloop::core::generate::dialect::{Decimals, Dialect, Form};
use camloop::core::generate::ir::Compensation;
use camloop::core::generate::setup::Setup;
use rs274_support::{Canon, run_rs274};

/// The ellipse of the tests: centre z = −30, x = 10; semi-axes 30 (z) and 20 (x); from
/// 10° to 170°, so the tool runs −z over the crown.
const ZC: f64 = -30.0;
const XC: f64 = 10.0;
const A: f64 = 30.0;
const B: f64 = 20.0;

fn ellipse_job(tolerance_mm: f64, roughing: Option<Roughing>) -> ContourJob {
    ContourJob {
        name: "ELLIPSE_TURN".to_owned(),
        curve: Curve::Ellipse(Ellipse {
            centre_z_mm: ZC,
            centre_x_mm: XC,
            a_mm: A,
            b_mm: B,
            start_deg: 10.0,
            end_deg: 170.0,
        }),
        tolerance_mm,
        decimals: 4,
        side: Side::Outside,
        nose_radius_mm: 0.8,
        roughing,
        clearance_mm: 1.0,
        finish_feed: 0.1,
        rough_feed: 0.25,
        setup: Setup::turning(),
    }
}

/// Independent oracle for an ellipse chord: an affine image of a circle, so the point of
/// the arc whose tangent is parallel to the chord is at the mid-angle of its end angles,
/// and that point is the farthest from the chord's line. The end angles come from the
/// written points by inverting the ellipse (atan2), not from the generator.
/// A sine of 2 mm amplitude on a 20 mm wavelength about X = 20 mm, over 40 mm of Z: its
/// concave radius is 5.066 mm.
fn sine() -> Curve {
    Curve::Sine(Sine {
        mean_x_mm: 20.0,
        amplitude_mm: 2.0,
        wavelength_mm: 20.0,
        phase_deg: 0.0,
        z_start_mm: 0.0,
        z_end_mm: -40.0,
    })
}

fn ellipse_chord_deviation(p: (f64, f64), q: (f64, f64)) -> f64 {
    let angle = |(z, x): (f64, f64)| ((x - XC) / B).atan2((z - ZC) / A);
    let (t0, t1) = (angle(p), angle(q));
    let tm = (t0 + t1) / 2.0;
    let m = (ZC + A * tm.cos(), XC + B * tm.sin());
    let (dz, dx) = (q.0 - p.0, q.1 - p.1);
    let line = ((m.0 - p.0) * dx - (m.1 - p.1) * dz).abs() / dz.hypot(dx);
    // The written ends are off the curve by rounding: count that too.
    let off = |(z, x): (f64, f64)| (((z - ZC) / A).hypot((x - XC) / B) - 1.0).abs() * B.min(A);
    line.max(off(p)).max(off(q))
}

#[test]
fn every_chord_is_within_the_tolerance_and_fewer_than_a_fixed_step_needs() {
    for tol_um in [2.0, 1.0, 10.0] {
        let c = generate(&ellipse_job(tol_um * 1e-3, None)).unwrap();
        let worst = c
            .points
            .windows(2)
            .map(|w| ellipse_chord_deviation(w[0], w[1]))
            .fold(0.0, f64::max);
        let r = &c.report;
        eprintln!(
            "ellipse {tol_um} um: {} chords, worst {:.3} um (oracle {:.3} um); fixed step needs {:?} chords (worst {:.3} um)",
            r.chords,
            r.worst_deviation_mm * 1e3,
            worst * 1e3,
            r.fixed_step_chords,
            r.fixed_step_worst_mm.unwrap_or(f64::NAN) * 1e3
        );
        assert!(worst <= tol_um * 1e-3, "{worst} mm at {tol_um} um");
        // The oracle and the generator's own measure agree to 0.01 µm.
        assert!((worst - r.worst_deviation_mm).abs() < 1e-5);
        let fixed = r.fixed_step_chords.unwrap();
        assert!(fixed > r.chords, "fixed {fixed} vs {}", r.chords);
    }
}

/// Largest distance of the exact curve from the written chords, by 400 plain samples per
/// chord: no refinement, no shared code with the generator's measure.
fn dense_worst(c: &camloop::core::generate::contour::Contour, curve: &Curve) -> f64 {
    dense_worst_of(&c.points, &c.params, curve)
}

/// The same for any points (z, x) at the curve parameters `params`.
fn dense_worst_of(points: &[(f64, f64)], params: &[f64], curve: &Curve) -> f64 {
    let mut worst: f64 = 0.0;
    for (w, u) in points.windows(2).zip(params.windows(2)) {
        for k in 0..=400 {
            let j = curve.jet(u[0] + (u[1] - u[0]) * f64::from(k) / 400.0);
            let (a, b) = (w[0], w[1]);
            let (dz, dx) = (b.0 - a.0, b.1 - a.1);
            let t = (((j.z - a.0) * dz + (j.x - a.1) * dx) / (dz * dz + dx * dx)).clamp(0.0, 1.0);
            worst = worst.max((j.z - a.0 - t * dz).hypot(j.x - a.1 - t * dx));
        }
    }
    worst
}

#[test]
fn parabola_sine_tangent_and_a_slender_ellipse_within_the_tolerance() {
    let curves = [
        (
            "parabola",
            Curve::Parabola(Parabola {
                vertex_z_mm: -20.0,
                vertex_x_mm: 5.0,
                p_mm: 4.0,
                x_start_mm: 5.0,
                x_end_mm: 25.0,
            }),
        ),
        ("sine", sine()),
        (
            "tangent",
            Curve::Tangent(Tangent {
                mean_x_mm: 20.0,
                amplitude_mm: 1.0,
                rate_deg_per_mm: 4.0,
                centre_z_mm: -20.0,
                z_start_mm: 0.0,
                z_end_mm: -40.0,
            }),
        ),
        (
            "slender ellipse",
            Curve::Ellipse(Ellipse {
                centre_z_mm: -40.0,
                centre_x_mm: 10.0,
                a_mm: 40.0,
                b_mm: 8.0,
                start_deg: 5.0,
                end_deg: 175.0,
            }),
        ),
    ];
    for (name, curve) in curves {
        let mut job = ellipse_job(2e-3, None);
        job.curve = curve.clone();
        let c = generate(&job).unwrap();
        let worst = dense_worst(&c, &curve);
        eprintln!(
            "{name}: {} chords, worst {:.3} um (dense {:.3} um); fixed step {:?} chords",
            c.report.chords,
            c.report.worst_deviation_mm * 1e3,
            worst * 1e3,
            c.report.fixed_step_chords
        );
        assert!(worst <= 2e-3, "{name}: {worst}");
        // The ISO loop as LinuxCNC interprets it: every move ends where we placed it (to
        // its printed 0.1 µm) and its chords stay within the tolerance of the exact curve.
        // Block length: LinuxCNC refuses lines over 256 characters, the 802D over 200; the
        // 840D sl limit is open, so every form stays within the smaller.
        for dialect in [Dialect::Sinumerik, Dialect::Iso] {
            let text = dialect.render(&c.program, Form::Loop, Decimals::default());
            let longest = text.lines().map(str::len).max().unwrap();
            assert!(longest <= 200, "{name} {dialect:?}: {longest} characters");
        }
        let rs = rs274_support::rs274().expect("rs274 installed (.ci/run installs it)");
        let text = Dialect::Iso.render(&c.program, Form::Loop, Decimals::default());
        let pts = finish_points(&run_rs274(&rs, &text, 0.0).unwrap());
        assert_eq!(pts.len(), c.points.len(), "{name}");
        let rs_worst = dense_worst_of(&pts, &c.params, &curve);
        eprintln!("{name}: rs274 moves worst {:.4} um", rs_worst * 1e3);
        assert!(rs_worst <= 2e-3, "{name}: rs274 {rs_worst}");
        assert!(
            c.report.chords < c.report.fixed_step_chords.unwrap(),
            "{name}"
        );
    }
}

#[test]
fn sinumerik_loop_expands_to_exactly_the_expanded_program() {
    let rough = Some(Roughing {
        stock_mm: 2.0,
        depth_mm: 0.7,
        allowance_mm: 0.2,
    });
    let c = generate(&ellipse_job(2e-3, rough)).unwrap();
    let d = Decimals::default();
    let looped = Dialect::Sinumerik.render(&c.program, Form::Loop, d);
    let expanded = Dialect::Sinumerik.render(&c.program, Form::Expanded, d);
    assert!(looped.contains("GOTOB LOOP_4"), "{looped}");
    let from_loop = sinumerik_eval::run(&looped, d.linear, d.angle).unwrap();
    let from_expanded = sinumerik_eval::run(&expanded, d.linear, d.angle).unwrap();
    let written: Vec<&str> = expanded.lines().filter(|l| is_move_line(l)).collect();
    assert_eq!(
        from_expanded, written,
        "the evaluator reads the expanded form as written"
    );
    assert_eq!(
        from_loop, written,
        "the loop runs exactly the expanded moves"
    );
    // 3 roughing passes and the finish pass, each chord count + entry/exit moves.
    assert_eq!(c.report.pass_offsets_mm.len(), 3);
    assert_eq!(c.report.compensation, Compensation::Right);
    assert!(expanded.contains("G42 G1"), "stated side");
}

/// A motion block of the written text (`G0`…`G3`, after a `G40`…`G42`), not a mode block
/// of the set-up (`G54`, `G95`, `G96 …`).
fn is_move_line(l: &str) -> bool {
    l.split_whitespace()
        .find(|w| !matches!(*w, "G40" | "G41" | "G42"))
        .is_some_and(|w| matches!(w, "G0" | "G1" | "G2" | "G3"))
}

/// The finish pass of the rs274 run: the feed moves between the approach and the exit.
fn finish_points(canon: &[Canon]) -> Vec<(f64, f64)> {
    let feeds: Vec<(f64, f64)> = canon
        .iter()
        .filter_map(|c| match c {
            Canon::Feed { x, z, .. } => Some((*z, *x)),
            _ => None,
        })
        .collect();
    feeds[..feeds.len() - 1].to_vec()
}

#[test]
fn iso_loop_run_by_rs274_stays_within_the_tolerance() {
    let Some(rs) = rs274_support::rs274() else {
        panic!("rs274 (Debian linuxcnc-uspace) is not installed: .ci/run installs it");
    };
    let tol = 2e-3;
    let c = generate(&ellipse_job(tol, None)).unwrap();
    let text = Dialect::Iso.render(&c.program, Form::Loop, Decimals::default());
    let canon = run_rs274(&rs, &text, 0.0).unwrap();
    let pts = finish_points(&canon);
    assert_eq!(
        pts.len(),
        c.points.len(),
        "one interpreted move per chord end"
    );
    let worst = pts
        .windows(2)
        .map(|w| ellipse_chord_deviation(w[0], w[1]))
        .fold(0.0, f64::max);
    eprintln!(
        "rs274 ISO loop: {} moves, worst deviation {:.4} um",
        pts.len(),
        worst * 1e3
    );
    assert!(worst <= tol, "{worst}");
    // rs274 prints 4 decimals, as we write: its points are ours to the last digit.
    for (p, q) in pts.iter().zip(&c.points) {
        assert!(
            (p.0 - q.0).abs() < 1.5e-4 && (p.1 - q.1).abs() < 1.5e-4,
            "{p:?} {q:?}"
        );
    }
    let expanded = Dialect::Iso.render(&c.program, Form::Expanded, Decimals::default());
    let pts_x = finish_points(&run_rs274(&rs, &expanded, 0.0).unwrap());
    assert_eq!(
        pts_x, pts,
        "expanded and loop forms interpret to the same moves"
    );
}

#[test]
fn rs274_roughing_passes_are_the_contour_shifted_by_each_offset() {
    let Some(rs) = rs274_support::rs274() else {
        panic!("rs274 (Debian linuxcnc-uspace) is not installed: .ci/run installs it");
    };
    let tol = 2e-3;
    let rough = Some(Roughing {
        stock_mm: 2.0,
        depth_mm: 0.7,
        allowance_mm: 0.2,
    });
    let c = generate(&ellipse_job(tol, rough)).unwrap();
    let text = Dialect::Iso.render(&c.program, Form::Loop, Decimals::default());
    let canon = run_rs274(&rs, &text, 0.0).unwrap();
    // Runs of feed moves between rapids: one per pass, each ending with its lead-out.
    let mut passes: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut in_run = false;
    for m in &canon {
        match *m {
            Canon::Feed { x, z, .. } => {
                if !in_run {
                    passes.push(Vec::new());
                    in_run = true;
                }
                passes.last_mut().unwrap().push((z, x));
            }
            _ => in_run = false,
        }
    }
    let mut offsets = c.report.pass_offsets_mm.clone();
    offsets.push(0.0);
    assert_eq!(
        passes.len(),
        offsets.len(),
        "3 roughing passes and the finish pass"
    );
    // Equal depths of (2.0 − 0.2) / 3 = 0.6 mm: offsets 1.4, 0.8, 0.2, then the finish.
    for (o, want) in offsets.iter().zip([1.4, 0.8, 0.2, 0.0]) {
        assert!((o - want).abs() < 1e-9, "{offsets:?}");
    }
    let mut worst: f64 = 0.0;
    for (pass, ofs) in passes.iter().zip(&offsets) {
        let contour: Vec<(f64, f64)> = pass[..pass.len() - 1]
            .iter()
            .map(|&(z, x)| (z, x - ofs))
            .collect();
        assert_eq!(contour.len(), c.points.len());
        for w in contour.windows(2) {
            worst = worst.max(ellipse_chord_deviation(w[0], w[1]));
        }
    }
    eprintln!(
        "rs274 roughing + finish: worst deviation {:.4} um",
        worst * 1e3
    );
    // Shifting back by the offset adds one more rounding of X (0.05 µm).
    assert!(worst <= tol + 1e-7, "{worst}");
}

#[test]
fn with_the_nose_radius_rs274_keeps_the_tool_outside_the_material() {
    let Some(rs) = rs274_support::rs274() else {
        panic!("rs274 (Debian linuxcnc-uspace) is not installed: .ci/run installs it");
    };
    let c = generate(&ellipse_job(2e-3, None)).unwrap();
    let text = Dialect::Iso.render(&c.program, Form::Expanded, Decimals::default());
    let canon = run_rs274(&rs, &text, 0.8).unwrap();
    // Distance of a point to the ellipse by dense search on the angle (independent of the
    // generator): the compensated path is 0.8 mm off the contour, outside it.
    let dist = |(z, x): (f64, f64)| {
        (0..=20_000)
            .map(|i| (10.0 + 160.0 * f64::from(i) / 20_000.0).to_radians())
            .map(|t| (z - ZC - A * t.cos()).hypot(x - XC - B * t.sin()))
            .fold(f64::MAX, f64::min)
    };
    let feeds: Vec<(f64, f64)> = canon
        .iter()
        .filter_map(|c| match *c {
            Canon::Feed { x, z, .. } => Some((z, x)),
            _ => None,
        })
        .collect();
    let mut checked = 0;
    // The first feed ends the lead-in and the last is the lead-out: every move between
    // them is on the compensated contour.
    for &(z, x) in &feeds[1..feeds.len() - 1] {
        let inside = ((z - ZC) / A).hypot((x - XC) / B) < 1.0;
        assert!(!inside, "tool in the material at z = {z}, x = {x}");
        let d = dist((z, x));
        // 0.8 mm nose, chord error ≤ 2 µm, dense search step ≤ 0.3 µm, print 0.1 µm.
        assert!((d - 0.8).abs() < 3e-3, "{d} at z = {z}, x = {x}");
        checked += 1;
    }
    assert!(checked > 100, "{checked}");
}

#[test]
fn golden_programs() {
    let rough = Some(Roughing {
        stock_mm: 1.0,
        depth_mm: 0.6,
        allowance_mm: 0.2,
    });
    let mut job = ellipse_job(10e-3, rough);
    job.curve = Curve::Parabola(Parabola {
        vertex_z_mm: -20.0,
        vertex_x_mm: 5.0,
        p_mm: 4.0,
        x_start_mm: 5.0,
        x_end_mm: 15.0,
    });
    job.name = "PARABOLA_TURN".to_owned();
    let c = generate(&job).unwrap();
    let d = Decimals::default();
    insta::assert_snapshot!(
        "parabola_sinumerik_loop",
        Dialect::Sinumerik.render(&c.program, Form::Loop, d)
    );
    insta::assert_snapshot!(
        "parabola_iso_loop",
        Dialect::Iso.render(&c.program, Form::Loop, d)
    );
    insta::assert_snapshot!(
        "parabola_iso_expanded",
        Dialect::Iso.render(&c.program, Form::Expanded, d)
    );
}

#[test]
fn profile_from_csv_is_placed_within_the_tolerance() {
    use camloop::core::generate::profile::parse_profile;
    // A profile sampled from x = 20 + 3·sin(z·18°) every 2 mm: the spline between the
    // points is the curve the chords must follow.
    let text: String = std::iter::once("z_mm,x_mm\n".to_owned())
        .chain((0..=20).map(|i| {
            let z = -2.0 * f64::from(i);
            format!("{z},{}\n", 20.0 + 3.0 * (z * 18.0f64).to_radians().sin())
        }))
        .collect();
    let curve = parse_profile(&text, "p.csv").unwrap();
    let mut job = ellipse_job(2e-3, None);
    job.curve = curve.clone();
    job.name = "PROFILE_TURN".to_owned();
    let c = generate(&job).unwrap();
    // Dense independent sampling: 400 points per chord against the spline itself.
    let worst = dense_worst(&c, &curve);
    eprintln!(
        "profile: {} chords, worst {:.3} um; fixed step {:?}",
        c.report.chords,
        worst * 1e3,
        c.report.fixed_step_chords
    );
    assert!(worst <= 2e-3, "{worst}");
    let bad = "z_mm,x_mm\n0,20\n-2,20.5\n-1,21\n";
    let e = parse_profile(bad, "p.csv").unwrap_err().to_string();
    assert!(e.contains("p.csv line 4"), "{e}");
}

#[test]
fn refusals_name_the_reason() {
    let job = ellipse_job(0.1e-3, None);
    assert!(matches!(
        generate(&job),
        Err(ContourError::ToleranceBelowResolution { .. })
    ));
    let mut job = ellipse_job(2e-3, None);
    job.curve = sine();
    job.nose_radius_mm = 6.0;
    let e = generate(&job).unwrap_err();
    assert!(
        matches!(e, ContourError::NoseTooLarge { radius_mm, .. } if (radius_mm - 5.066).abs() < 0.01),
        "{e}"
    );
    job.nose_radius_mm = 0.8;
    assert!(generate(&job).is_ok());
    job.curve = Curve::Tangent(Tangent {
        mean_x_mm: 20.0,
        amplitude_mm: 1.0,
        rate_deg_per_mm: 5.0,
        centre_z_mm: -20.0,
        z_start_mm: 0.0,
        z_end_mm: -40.0,
    });
    assert!(matches!(
        generate(&job),
        Err(ContourError::TangentAsymptote { .. })
    ));
    let mut job = ellipse_job(2e-3, None);
    job.curve = Curve::Ellipse(Ellipse {
        centre_z_mm: ZC,
        centre_x_mm: XC,
        a_mm: A,
        b_mm: B,
        start_deg: 0.0,
        end_deg: 270.0,
    });
    assert!(matches!(
        generate(&job),
        Err(ContourError::TurnsBack { .. })
    ));
    job.curve = Curve::Parabola(Parabola {
        vertex_z_mm: -20.0,
        vertex_x_mm: 5.0,
        p_mm: 0.0,
        x_start_mm: 5.0,
        x_end_mm: 15.0,
    });
    let e = generate(&job).unwrap_err();
    assert!(e.to_string().starts_with("parabola p is 0"), "{e}");
}

#[test]
fn the_evaluator_refuses_what_it_cannot_read_with_the_line() {
    let text = "DEF REAL CL_U\nCL_U=1\nG1 X=CL_V Z=0\nM30\n";
    let e = sinumerik_eval::run(text, 4, 4).unwrap_err().to_string();
    assert_eq!(e, "line 3: unknown variable `CL_V`");
    let text = "DEF REAL CL_U\nLOOP_1:\nCL_U=CL_U+1\nIF CL_U<3 GOTOB LOOP_9\n";
    let e = sinumerik_eval::run(text, 4, 4).unwrap_err().to_string();
    assert_eq!(e, "line 4: no label `LOOP_9`");
}
