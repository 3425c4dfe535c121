//! Chained contours from the contour file: the shipped AA5 part roughed and finished
//! through LinuxCNC's `rs274` and the SINUMERIK evaluator, checked against the exact part
//! outline (independent of the generator), in radius and in diameter; the safety check on
//! every program; refusals that name the segment.

use crate::rs274_support::{self, Canon, run_rs274};
use crate::sinumerik_support::{self, inline_sub};

use camloop::core::generate::contour_chain::program::{ChainPrograms, generate};
use camloop::core::generate::contour_chain::{ChainError, ChainJob};
use camloop::core::generate::contour_file::parse_contour_file;
use camloop::core::generate::dialect::{Decimals, Dialect, Form};
use camloop::core::generate::ir::inline;
use camloop::core::generate::safety::{Rules, check};
use camloop::core::generate::setup::{Setup, XMode};

const AA5: &str = include_str!("../../config/contour-802d-aa5.toml");

fn aa5(setup: Setup) -> ChainJob {
    parse_contour_file(AA5, "contour-802d-aa5.toml", setup).unwrap()
}

/// The finished AA5 part's radius at z, from the drawing (not from the generator): the
/// ellipse (z + 10)²/10² + x²/20² = 1 from the tip to x = 18, the 36 mm diameter to z = −20,
/// the 46 mm diameter with its 1 mm chamfer to z = −30. `None` outside the part.
fn part_radius(z: f64) -> Option<f64> {
    let ze = -10.0 - 10.0 * (1.0f64 - 0.81).sqrt();
    match z {
        z if !(-30.0..=0.0).contains(&z) => None,
        z if z >= ze => Some(20.0 * (1.0 - ((z + 10.0) / 10.0).powi(2)).max(0.0).sqrt()),
        z if z >= -20.0 => Some(18.0),
        z if z >= -21.0 => Some(22.0 + (-20.0 - z)),
        _ => Some(23.0),
    }
}

/// Closest distance from (z, x) to the part's outline, from the drawing: the ellipse
/// sampled by its angle (100 000 points, 0.4 µm apart), the lines and faces exactly.
fn outline_distance(z: f64, x: f64) -> f64 {
    let end = std::f64::consts::PI - 0.9f64.asin();
    let n = 100_000;
    let mut best = (0..=n)
        .map(|i| end * f64::from(i) / f64::from(n))
        .map(|t| (z + 10.0 - 10.0 * t.cos()).hypot(x - 20.0 * t.sin()))
        .fold(f64::MAX, f64::min);
    let ze = -10.0 - 10.0 * (1.0f64 - 0.81).sqrt();
    let corners = [
        (ze, 18.0),
        (-20.0, 18.0),
        (-20.0, 22.0),
        (-21.0, 23.0),
        (-30.0, 23.0),
        (-30.0, 25.0),
    ];
    for w in corners.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (dz, dx) = (b.0 - a.0, b.1 - a.1);
        let t = (((z - a.0) * dz + (x - a.1) * dx) / (dz * dz + dx * dx)).clamp(0.0, 1.0);
        best = best.min((z - a.0 - t * dz).hypot(x - a.1 - t * dx));
    }
    best
}

/// Feed moves of an rs274 run as (from, to) pairs in (z, x), with the index of each.
fn feeds(canon: &[Canon]) -> Vec<((f64, f64), (f64, f64))> {
    let mut at = None;
    let mut out = Vec::new();
    for m in canon {
        match *m {
            Canon::Rapid { x, z, .. } => at = Some((z, x)),
            Canon::Feed { x, z, .. } => {
                if let Some(a) = at {
                    out.push((a, (z, x)));
                }
                at = Some((z, x));
            }
            Canon::Arc { .. } => panic!("the AA5 part has no arcs"),
        }
    }
    out
}

fn render_iso(p: &ChainPrograms, diameter: bool) -> String {
    let files = Dialect::Iso.render_set(
        &p.main,
        std::slice::from_ref(&p.contour),
        Form::Expanded,
        Decimals::default(),
        diameter,
    );
    assert_eq!(files.len(), 1, "one ISO file, the subprogram inside");
    files[0].text.clone()
}

#[test]
fn aa5_from_the_file_is_roughed_from_the_bar_and_finished_without_touching_the_part() {
    let rs = rs274_support::rs274().expect("rs274 installed (.ci/run installs it)");
    let p = generate(&aa5(Setup::turning())).unwrap();
    let text = render_iso(&p, false);
    let canon = run_rs274(&rs, &text, 0.0).unwrap();
    let moves = feeds(&canon);
    // The finish pass is the last run of feeds: lead-in, the contour, lead-out.
    let sub_points = p.contour.body.len();
    // lead-in + the subprogram's moves + lead-out
    let finish_start = moves.len() - sub_points - 2;
    let (rough, finish) = moves.split_at(finish_start);
    // Roughing: no sample of any cut comes closer to the finished part than the allowance
    // (0.2 mm), less 1 µm for printing and sampling, and none enters the part.
    let mut closest = f64::MAX;
    for &(a, b) in rough {
        for k in 0..=20 {
            let t = f64::from(k) / 20.0;
            let (z, x) = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
            assert!(
                part_radius(z).is_none_or(|r| x >= r),
                "a roughing cut enters the part at z = {z}, x = {x}"
            );
            closest = closest.min(outline_distance(z, x));
        }
    }
    eprintln!(
        "AA5 roughing: {} cuts in {} feed moves, closest approach to the part {:.4} mm",
        p.levels_mm.len(),
        rough.len(),
        closest
    );
    // The pass along the contour is the offset curve in chords: each within the chord
    // tolerance (2 µm) times (ρ + 0.2)/ρ ≤ 1.04 (ρ ≥ 5 mm, the tip), plus 0.1 µm printed.
    assert!(closest >= 0.2 - 2.2e-3, "{closest}");
    // The first cut from the 50 mm bar is 2 mm deep at most, not the 20 mm a contour-
    // parallel first pass cuts on bar stock.
    assert!(25.0 - p.levels_mm[0] <= 2.0 + 1e-9, "{:?}", p.levels_mm);
    // Finish: every contour point on the drawing within the chord tolerance (2 µm) plus
    // the printed 0.05 µm; nothing behind the axis anywhere.
    let mut worst: f64 = 0.0;
    for &(_, (z, x)) in &finish[1..finish.len() - 1] {
        worst = worst.max(outline_distance(z, x));
    }
    eprintln!(
        "AA5 finish: {} moves, worst distance of a written point from the drawing {:.4} um; chords' worst {:.3} um",
        finish.len(),
        worst * 1e3,
        p.worst_deviation_mm * 1e3
    );
    assert!(worst <= 2e-3 + 1e-4, "{worst}");
    assert!(p.worst_deviation_mm <= 2e-3);
    let lowest = canon
        .iter()
        .filter_map(|c| match *c {
            Canon::Feed { x, .. } | Canon::Rapid { x, .. } => Some(x),
            Canon::Arc { .. } => None,
        })
        .fold(f64::MAX, f64::min);
    assert!(lowest >= 0.0, "behind the axis: x = {lowest}");
    // The safety check on the program as run (subprogram inlined) agrees.
    let r = check(
        &inline(&p.main, std::slice::from_ref(&p.contour)),
        &Rules::lathe(),
    )
    .unwrap();
    assert_eq!(r.min_x_mm, Some(0.0));
}

#[test]
fn diameter_programming_moves_the_tool_exactly_as_radius_programming() {
    let rs = rs274_support::rs274().expect("rs274 installed (.ci/run installs it)");
    let radius = generate(&aa5(Setup::turning())).unwrap();
    let mut setup = Setup::turning();
    setup.x_mode = Some(XMode::Diameter);
    let diameter = generate(&aa5(setup)).unwrap();
    let iso_r = render_iso(&radius, false);
    let iso_d = render_iso(&diameter, true);
    assert!(iso_d.contains("G7 (X as a diameter)"), "{iso_d}");
    assert!(iso_d.contains("G0 X52.0000"), "the 52 mm retract diameter");
    let (cr, cd) = (
        run_rs274(&rs, &iso_r, 0.0).unwrap(),
        run_rs274(&rs, &iso_d, 0.0).unwrap(),
    );
    // rs274 reports X as the radius in both modes. Diameters are written with 4 decimals,
    // so each radius may differ by half a unit of the 4th decimal, and rs274 prints 4.
    assert_eq!(cr.len(), cd.len());
    for (a, b) in cr.iter().zip(&cd) {
        match (*a, *b) {
            (Canon::Feed { x, z, .. }, Canon::Feed { x: x2, z: z2, .. })
            | (Canon::Rapid { x, z, .. }, Canon::Rapid { x: x2, z: z2, .. }) => {
                assert!((x - x2).abs() <= 1.01e-4 && z == z2, "{a:?} {b:?}");
            }
            _ => panic!("{a:?} {b:?}"),
        }
    }
    // SINUMERIK: the same two programs, subprogram inlined, evaluated by text; every X
    // word under DIAMON is twice the radius program's (each rounded to 4 decimals).
    let sinumerik = |p: &ChainPrograms, diameter: bool| {
        let files = Dialect::Sinumerik.render_set(
            &p.main,
            std::slice::from_ref(&p.contour),
            Form::Expanded,
            Decimals::default(),
            diameter,
        );
        assert_eq!(files.len(), 2);
        assert!(
            files[1]
                .text
                .starts_with("%_N_AA5_C_SPF\n;$PATH=/_N_SPF_DIR\n")
        );
        assert!(files[1].text.ends_with("RET\n"));
        let text = inline_sub(&files[0].text, "AA5_C", &files[1].text);
        assert_eq!(text.contains("DIAMON ; X as a diameter"), diameter);
        sinumerik_support::run(&text, 4, 4).unwrap()
    };
    let (mr, md) = (sinumerik(&radius, false), sinumerik(&diameter, true));
    assert_eq!(mr.len(), md.len());
    let x_of = |m: &str| {
        m.split_whitespace()
            .find_map(|w| w.strip_prefix("X="))
            .map(|v| v.parse::<f64>().unwrap())
    };
    let mut compared = 0;
    for (a, b) in mr.iter().zip(&md) {
        assert_eq!(x_of(a).is_some(), x_of(b).is_some(), "{a} / {b}");
        if let (Some(r), Some(d)) = (x_of(a), x_of(b)) {
            assert!((d / 2.0 - r).abs() <= 0.76e-4, "{a} / {b}");
            compared += 1;
        }
    }
    assert!(compared > 150, "{compared}");
}

#[test]
fn cycle95_main_program_and_its_contour_subprogram() {
    let mut job = aa5(Setup::turning());
    job.roughing = camloop::core::generate::contour_chain::ChainRoughing::Cycle95 {
        depth_mm: 2.0,
        allowance_mm: 0.2,
    };
    let p = generate(&job).unwrap();
    let files = Dialect::Sinumerik.render_set(
        &p.main,
        std::slice::from_ref(&p.contour),
        Form::Expanded,
        Decimals::default(),
        false,
    );
    let main = &files[0].text;
    let cyc = main.lines().find(|l| l.starts_with("CYCLE95")).unwrap();
    assert!(
        cyc.starts_with("CYCLE95(\"AA5_C\",2,0,0.2,0.2,0.2500,0.2500,0.2500,1,0,0,1)"),
        "{cyc}"
    );
    // The set-up comes before the cycle, the feed mode before its feeds.
    let at = |s: &str| main.find(s).unwrap();
    assert!(at("T1 D1") < at("CYCLE95") && at("G95") < at("CYCLE95"));
    assert!(at("G96 S180 LIMS=3000 M3") < at("CYCLE95"));
    let text = inline_sub(main, "AA5_C", &files[1].text).replace(
        cyc,
        "; (the control's own stock removal: no moves to evaluate here)",
    );
    let moves = sinumerik_support::run(&text, 4, 4).unwrap();
    assert!(moves.iter().any(|m| m.starts_with("G42 G1")), "{moves:?}");
    insta::assert_snapshot!("aa5_cycle95_main", main);
    insta::assert_snapshot!("aa5_cycle95_contour", files[1].text);
}

fn refusal(toml_edit: impl Fn(&str) -> String) -> String {
    let text = toml_edit(AA5);
    match parse_contour_file(&text, "part.toml", Setup::turning()) {
        Err(e) => e.to_string(),
        Ok(job) => generate(&job).map(|_| ()).unwrap_err().to_string(),
    }
}

#[test]
fn refusals_name_the_segment_or_the_key() {
    // An 80° insert (C) cannot follow the ellipse's 44° descent behind its crown.
    let e = refusal(|t| t.replace("included_deg = 35.0", "included_deg = 80.0"));
    assert!(
        e.starts_with("segment 1 (ellipse): the contour descends at ")
            && e.contains("the insert follows at most 5.0 deg"),
        "{e}"
    );
    // A curve that does not start where the chain is.
    let e = refusal(|t| t.replace("centre_z_mm = -10.0", "centre_z_mm = -10.5"));
    assert!(
        e.starts_with("segment 1 (ellipse) starts at z = -0.5 mm"),
        "{e}"
    );
    // A concave radius tighter than the nose: a cw arc of 0.3 mm into the 36 mm diameter.
    let e = refusal(|t| {
        t.replace(
            "[[segment]]\nkind = \"line\"\nz_mm = -20.0",
            "[[segment]]\nkind = \"line\"\nz_mm = -19.7\n\n[[segment]]\nkind = \"arc\"\nz_mm = -20.0\nx_mm = 18.3\nradius_mm = 0.3\ndirection = \"cw\"",
        )
    });
    assert!(
        e.starts_with("segment 3 (arc): the concave radius 0.300 mm"),
        "{e}"
    );
    // Unknown keys and bad expressions name themselves.
    let e = refusal(|t| t.replace("depth_mm = 2.0", "depth = 2.0"));
    assert!(e.starts_with("part.toml: ") && e.contains("depth"), "{e}");
    let graph = "[[segment]]\nkind = \"graph\"\nx = \"25 + sqrt(z + 29)\"\nz_start_mm = -30.0\nz_end_mm = -31.0\n";
    let e = refusal(|t| format!("{t}\n{graph}"));
    assert!(
        e.starts_with("part.toml: segment 6 (graph): x = `25 + sqrt(z + 29)` is NaN at z = -30"),
        "{e}"
    );
    let e = refusal(|t| format!("{t}\n{}", graph.replace("sqrt(z + 29)", "q*z")));
    assert!(e.contains("uses `q`: only `z` is known here"), "{e}");
    // A recess deeper than one cut is left to CYCLE95.
    let e = refusal(|t| t.replace("depth_mm = 2.0", "depth_mm = 1.5"));
    assert!(
        e.starts_with("segment 1 (ellipse): the recess behind the crown is 1.99"),
        "{e}"
    );
}

#[test]
fn chain_error_for_an_empty_chain() {
    let mut job = aa5(Setup::turning());
    job.segments.clear();
    assert!(matches!(generate(&job), Err(ChainError::Empty)));
}
