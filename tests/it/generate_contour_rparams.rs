//! The 802D study's R-parameter form: the constants at the top, a fixed-step loop that reads
//! them. Run as text by the SINUMERIK evaluator and by LinuxCNC's `rs274`, checked against
//! the exact curves, and edited at the top as a machinist would.

use crate::generate_contour_sources::job;
use crate::rs274_support::{self, Canon, run_rs274};
use crate::sinumerik_support;

use camloop::core::generate::contour::{ContourError, Roughing, generate_rparams};
use camloop::core::generate::curve::{Curve, Ellipse, Parabola, Sine, Tangent};
use camloop::core::generate::dialect::{Decimals, Dialect, Form};
use camloop::core::generate::safety::{Rules, check};

/// The sources' curves the form can carry: the AA5 ellipse (10 × 20 to z = −14.359), the
/// parabola, a sine and a tangent curve.
fn curves() -> Vec<(&'static str, Curve)> {
    vec![
        (
            "AA5 ellipse",
            Curve::Ellipse(Ellipse {
                centre_z_mm: -10.0,
                centre_x_mm: 0.0,
                a_mm: 10.0,
                b_mm: 20.0,
                start_deg: 0.0,
                end_deg: 180.0 - 0.9f64.asin().to_degrees(),
            }),
        ),
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
        (
            "sine",
            Curve::Sine(Sine {
                mean_x_mm: 20.0,
                amplitude_mm: 2.0,
                wavelength_mm: 25.0,
                phase_deg: 30.0,
                z_start_mm: 0.0,
                z_end_mm: -40.0,
            }),
        ),
        (
            "tangent",
            Curve::Tangent(Tangent {
                mean_x_mm: 30.0,
                amplitude_mm: 3.0,
                rate_deg_per_mm: 4.0,
                centre_z_mm: -20.0,
                z_start_mm: -5.0,
                z_end_mm: -35.0,
            }),
        ),
    ]
}

/// `(z, x)` of every motion block with both words, in order (the evaluator's R writes and the
/// single-axis retracts left out).
fn xz(blocks: &[String]) -> Vec<(f64, f64)> {
    blocks
        .iter()
        .filter_map(|b| {
            let word = |axis: &str| {
                b.split_whitespace()
                    .find_map(|w| w.strip_prefix(axis))
                    .and_then(|v| v.parse::<f64>().ok())
            };
            Some((word("Z=")?, word("X=")?))
        })
        .collect()
}

/// Worst distance of the exact curve from the written chords (rounded ends, as the control
/// cuts them), by 400 plain samples of the curve per chord: independent of the generator's
/// own measure.
fn worst_written(curve: &Curve, params: &[f64], points: &[(f64, f64)]) -> f64 {
    let mut worst: f64 = 0.0;
    for (w, u) in points.windows(2).zip(params.windows(2)) {
        let (a, b) = (w[0], w[1]);
        let (dz, dx) = (b.0 - a.0, b.1 - a.1);
        for k in 0..=400 {
            let j = curve.jet(u[0] + (u[1] - u[0]) * f64::from(k) / 400.0);
            let t = (((j.z - a.0) * dz + (j.x - a.1) * dx) / (dz * dz + dx * dx)).clamp(0.0, 1.0);
            worst = worst.max((j.z - a.0 - t * dz).hypot(j.x - a.1 - t * dx));
        }
    }
    worst
}

#[test]
fn the_control_runs_the_constants_at_a_fixed_step_within_the_tolerance() {
    let d = Decimals::default();
    for (name, curve) in curves() {
        let mut j = job("RFORM", curve.clone());
        j.roughing = Some(Roughing {
            stock_mm: 2.0,
            depth_mm: 1.0,
            allowance_mm: 0.2,
        });
        let c = generate_rparams(&j).unwrap();
        check(&c.program, &Rules::lathe()).unwrap();
        let text = Dialect::Sinumerik.render(&c.program, Form::Loop, d);
        // What an 802D reads: no DEF, R parameters within R0–R249, blocks under 200
        // characters, and the constants before the first motion.
        assert!(!text.contains("DEF "), "{name}: {text}");
        assert!(text.lines().all(|l| l.len() <= 200), "{name}");
        for w in text.split(|c: char| !c.is_ascii_alphanumeric()) {
            if let Some(n) = w.strip_prefix('R').and_then(|n| n.parse::<u32>().ok()) {
                assert!(n <= 249, "{name}: R{n}");
            }
        }
        let first_motion = text.find("\nG0 ").unwrap();
        for r in ["R10=", "R11=", "R12=", "R13=", "R15="] {
            assert!(
                text.find(&format!("\n{r}")).unwrap() < first_motion,
                "{name}: {r}"
            );
        }
        // The loop as the control runs it moves exactly as the expanded program.
        let looped = sinumerik_support::run(&text, d.linear, d.angle).unwrap();
        let expanded = Dialect::Sinumerik.render(&c.program, Form::Expanded, d);
        let moves = |b: Vec<String>| {
            b.into_iter()
                .filter(|l| !l.starts_with('R'))
                .collect::<Vec<_>>()
        };
        assert_eq!(
            moves(looped.clone()),
            moves(sinumerik_support::run(&expanded, d.linear, d.angle).unwrap()),
            "{name}"
        );
        // The finish pass (the last chords + 1 two-word moves before the lead-out) lands
        // on the points the report names, and they are within the tolerance of the exact
        // curve by 400 samples per chord, independent of the generator's search.
        let pts = xz(&looped);
        let finish = &pts[pts.len() - c.points.len() - 1..pts.len() - 1];
        for (got, want) in finish.iter().zip(&c.points) {
            assert!(
                (got.0 - want.0).abs() < 1.5e-4 && (got.1 - want.1).abs() < 1.5e-4,
                "{name}: {got:?} vs {want:?}"
            );
        }
        assert_eq!(c.points.len(), c.report.chords + 1, "{name}");
        let worst = worst_written(&curve, &c.params, &c.points);
        assert!(worst <= j.tolerance_mm, "{name}: {worst}");
        eprintln!(
            "{name}: {} chords at a fixed step, worst {:.3} um by sampling, {:.3} um reported",
            c.report.chords,
            worst * 1e3,
            c.report.worst_deviation_mm * 1e3
        );
    }
}

#[test]
fn a_machinist_edits_the_ellipse_at_the_top_and_the_loop_follows() {
    let d = Decimals::default();
    let (_, curve) = curves().remove(0);
    let c = generate_rparams(&job("AA5", curve)).unwrap();
    let text = Dialect::Sinumerik.render(&c.program, Form::Loop, d);
    // b from 20 to 22 mm and the end angle to 90°: the semi-axes are R15, R16.
    assert!(
        text.contains("\nR16=20\n") && text.contains("\nR11="),
        "{text}"
    );
    let end_line = text
        .lines()
        .find(|l| l.starts_with("R11="))
        .unwrap()
        .to_owned();
    let edited = text
        .replace("\nR16=20\n", "\nR16=22\n")
        .replace(&end_line, "R11=90");
    let pts = xz(&sinumerik_support::run(&edited, d.linear, d.angle).unwrap());
    let finish = &pts[pts.len() - c.points.len() - 1..pts.len() - 1];
    // Every written point on the edited ellipse ((z + 10)/10)² + (x/22)² = 1, to the
    // written rounding (0.05 µm per coordinate gives at most 1.1e-5 in the form).
    for &(z, x) in finish {
        let form = ((z + 10.0) / 10.0).powi(2) + (x / 22.0).powi(2);
        assert!((form - 1.0).abs() < 2e-5, "({z}, {x}): {form}");
    }
    assert_eq!(*finish.last().unwrap(), (-10.0, 22.0));
}

#[test]
fn linuxcnc_runs_the_iso_form_to_the_same_points() {
    let Some(rs) = rs274_support::rs274() else {
        panic!("rs274 (Debian linuxcnc-uspace) is not installed: .ci/run installs it");
    };
    let d = Decimals::default();
    for (name, curve) in curves() {
        let c = generate_rparams(&job("RFORM", curve)).unwrap();
        let text = Dialect::Iso.render(&c.program, Form::Loop, d);
        let canon = run_rs274(&rs, &text, 0.0).unwrap();
        let feeds: Vec<(f64, f64)> = canon
            .iter()
            .filter_map(|m| match *m {
                Canon::Feed { x, z, .. } => Some((z, x)),
                _ => None,
            })
            .collect();
        let finish = &feeds[..feeds.len() - 1];
        assert_eq!(finish.len(), c.points.len(), "{name}");
        for (got, want) in finish.iter().zip(&c.points) {
            assert!(
                (got.0 - want.0).abs() < 1.5e-4 && (got.1 - want.1).abs() < 1.5e-4,
                "{name}: {got:?} vs {want:?}"
            );
        }
    }
}

#[test]
fn a_curve_the_control_cannot_evaluate_is_refused_by_name() {
    let (_, curve) = curves().remove(0);
    let spline = camloop::core::generate::param_curve::ParamCurve::parametric(
        "-10*t + 87.781",
        "3*tan(t) - 20",
        0.5,
        -0.5,
    )
    .unwrap();
    let e = generate_rparams(&job("P", Curve::Param(Box::new(spline)))).unwrap_err();
    assert!(matches!(e, ContourError::RParamsNeedFormula { .. }));
    assert!(e.to_string().contains("parametric curve"), "{e}");
    // The loop form's checks hold here too: a tolerance below the resolution is named.
    let mut j = job("ELL", curve);
    j.tolerance_mm = 1e-5;
    let e = generate_rparams(&j).unwrap_err().to_string();
    assert!(e.contains("tolerance"), "{e}");
}
