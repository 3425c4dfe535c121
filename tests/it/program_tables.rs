//! Curve-table programs: golden files, round trips through a small test-only parser, and the
//! rendering checks (C monotonic after rounding, finite values, joined segments).

use camloop::core::program::{
    CDirection, ProgramSettings, TableError, TableMemory, render_g1_table, render_poly_table,
};
use camloop::core::table::{PolySegment, TablePoint};

/// Analytic test profile, mm: smooth, periodic, with a 2nd harmonic so it is not symmetric.
fn x_of(c_deg: f64) -> f64 {
    let c = c_deg.to_radians();
    3.0 + 2.5 * c.cos() + 0.4 * (2.0 * c).sin()
}

/// dX/dc of [`x_of`], mm per degree.
fn dx_of(c_deg: f64) -> f64 {
    let c = c_deg.to_radians();
    (-2.5 * c.sin() + 0.8 * (2.0 * c).cos()) * std::f64::consts::PI / 180.0
}

fn points(step_deg: f64, n: usize) -> Vec<TablePoint> {
    (0..n)
        .map(|i| {
            let c_deg = step_deg * i as f64;
            TablePoint {
                c_deg,
                d_mm: 250.0 + x_of(c_deg),
                x_mm: x_of(c_deg),
            }
        })
        .collect()
}

/// Cubic Hermite segments through knots every `step_deg`, with the analytic slope at the
/// knots; `round_knots` rounds the knot values to 4 decimals so that the written knots are
/// exact and only the coefficient rounding remains.
fn hermite_segments(step_deg: f64, round_knots: bool) -> Vec<PolySegment> {
    let n = (360.0 / step_deg).round() as usize;
    let knot = |c: f64| {
        let x = x_of(c);
        if round_knots {
            (x * 1e4).round() / 1e4
        } else {
            x
        }
    };
    (0..n)
        .map(|i| {
            let (c0, c1) = (step_deg * i as f64, step_deg * (i + 1) as f64);
            let (y0, y1) = (knot(c0), knot(c1));
            // Slopes in mm per unit of u.
            let (m0, m1) = (dx_of(c0) * step_deg, dx_of(c1) * step_deg);
            PolySegment {
                c_start_deg: c0,
                c_end_deg: c1,
                x0_mm: y0,
                a1_mm: m0,
                a2_mm: 3.0 * (y1 - y0) - 2.0 * m0 - m1,
                a3_mm: 2.0 * (y0 - y1) + m0 + m1,
            }
        })
        .collect()
}

fn eval_segment(s: &PolySegment, c_deg: f64) -> f64 {
    let u = (c_deg - s.c_start_deg) / (s.c_end_deg - s.c_start_deg);
    s.x0_mm + u * (s.a1_mm + u * (s.a2_mm + u * s.a3_mm))
}

/// Test-only reader of the blocks between `CTABDEF` and `CTABEND`: the value of each
/// `NAME=value` word per block, keyed by axis name. Comments and other words are skipped.
fn table_blocks(program: &str) -> Vec<Vec<(String, String)>> {
    let mut inside = false;
    let mut blocks = Vec::new();
    for line in program.lines() {
        let code = line.split(';').next().unwrap().trim();
        if code.starts_with("CTABDEF(") {
            inside = true;
            continue;
        }
        if code == "CTABEND" {
            break;
        }
        if inside {
            let words = code
                .split_whitespace()
                .filter_map(|w| w.split_once('='))
                .map(|(a, v)| (a.to_owned(), v.to_owned()))
                .collect();
            blocks.push(words);
        }
    }
    blocks
}

/// (C, X) of every block of a G1 table.
fn parse_g1(program: &str, c_axis: &str, x_axis: &str) -> Vec<(f64, f64)> {
    table_blocks(program)
        .into_iter()
        .map(|words| {
            let get = |axis: &str| -> f64 {
                words
                    .iter()
                    .find(|(a, _)| a == axis)
                    .unwrap()
                    .1
                    .parse()
                    .unwrap()
            };
            (get(c_axis), get(x_axis))
        })
        .collect()
}

/// One POLY piece as the control reads it: a1 derived from the end point.
#[derive(Debug)]
struct Piece {
    c0: f64,
    c1: f64,
    x: [f64; 4],
}

impl Piece {
    fn eval(&self, c: f64) -> f64 {
        let u = (c - self.c0) / (self.c1 - self.c0);
        self.x[0] + u * (self.x[1] + u * (self.x[2] + u * self.x[3]))
    }
}

fn parse_poly(program: &str, c_axis: &str, x_axis: &str) -> Vec<Piece> {
    let blocks = table_blocks(program);
    let start = &blocks[0];
    let get =
        |w: &Vec<(String, String)>, a: &str| w.iter().find(|(n, _)| n == a).unwrap().1.clone();
    let (mut c, mut x): (f64, f64) = (
        get(start, c_axis).parse().unwrap(),
        get(start, x_axis).parse().unwrap(),
    );
    assert!(
        blocks[1].is_empty(),
        "POLY line expected after the start block"
    );
    let tuple = |s: String| -> Vec<f64> {
        s.trim_start_matches('(')
            .trim_end_matches(')')
            .split(',')
            .map(|v| v.parse().unwrap())
            .collect()
    };
    let mut pieces = Vec::new();
    for w in &blocks[2..] {
        let cv = tuple(get(w, &format!("PO[{c_axis}]")));
        let xv = tuple(get(w, &format!("PO[{x_axis}]")));
        assert_eq!(cv.len(), 1, "leading axis is linear in the parameter");
        let (xe, a2, a3) = (xv[0], xv[1], xv[2]);
        pieces.push(Piece {
            c0: c,
            c1: cv[0],
            x: [x, xe - x - a2 - a3, a2, a3],
        });
        (c, x) = (cv[0], xe);
    }
    pieces
}

fn with_comments(mut s: ProgramSettings) -> ProgramSettings {
    s.comment_lines = vec![
        "part: TEST-CAM lobe 1".to_owned(),
        "source: analytic test profile".to_owned(),
    ];
    s
}

#[test]
fn g1_table_golden() {
    let program = render_g1_table(
        &points(10.0, 36),
        &with_comments(ProgramSettings::default()),
    )
    .unwrap();
    insta::assert_snapshot!(program);
}

#[test]
fn poly_table_golden() {
    let program = render_poly_table(
        &hermite_segments(30.0, false),
        &with_comments(ProgramSettings::default()),
    )
    .unwrap();
    insta::assert_snapshot!(program);
}

fn reversed_offset() -> ProgramSettings {
    ProgramSettings {
        name: "cam_rev".to_owned(),
        c_direction: CDirection::Reversed,
        c_offset_deg: 37.5,
        x_offset_mm: 0.25,
        ..ProgramSettings::default()
    }
}

#[test]
fn reversed_c_with_offset_golden() {
    let s = reversed_offset();
    let g1 = render_g1_table(&points(30.0, 12), &s).unwrap();
    let poly = render_poly_table(&hermite_segments(60.0, false), &s).unwrap();
    insta::assert_snapshot!("reversed_offset_g1", g1);
    insta::assert_snapshot!("reversed_offset_poly", poly);
}

#[test]
fn memory_decimals_and_long_axis_names_golden() {
    let s = ProgramSettings {
        name: "Lobe3_v2".to_owned(),
        following_axis: "x1".to_owned(),
        leading_axis: "C1".to_owned(),
        table_number: 12,
        memory: Some(TableMemory::Sram),
        x_decimals: 6,
        x_increments_per_mm: 1_000_000,
        c_decimals: 2,
        ..ProgramSettings::default()
    };
    let program = render_g1_table(&points(30.0, 12), &s).unwrap();
    insta::assert_snapshot!(program);
    let dram = ProgramSettings {
        memory: Some(TableMemory::Dram),
        ..s
    };
    let program = render_g1_table(&points(30.0, 12), &dram).unwrap();
    assert!(
        program.contains("\nCTABDEF(X1,C1,12,1,\"DRAM\")\n"),
        "{program}"
    );
}

/// Map a part-frame point to program axes independently of the library.
fn to_program(s: &ProgramSettings, c_deg: f64, x_mm: f64) -> (f64, f64) {
    let sign = if s.c_direction == CDirection::Reversed {
        -1.0
    } else {
        1.0
    };
    (
        (s.c_offset_deg + sign * c_deg).rem_euclid(360.0),
        x_mm + s.x_offset_mm,
    )
}

#[test]
fn g1_round_trip_reproduces_x_within_half_a_unit() {
    let input = points(1.0, 360);
    let cases = [
        ProgramSettings::default(),
        reversed_offset(),
        ProgramSettings {
            x_decimals: 3,
            c_decimals: 1,
            c_offset_deg: -90.25,
            ..ProgramSettings::default()
        },
    ];
    for s in cases {
        let parsed = parse_g1(&render_g1_table(&input, &s).unwrap(), "C", "X");
        assert_eq!(
            parsed.len(),
            input.len() + 1,
            "one block per point plus the closing block"
        );
        // Half a unit of the last decimal, plus a margin for the binary representation.
        let x_tol = 0.5 * 10f64.powi(-i32::from(s.x_decimals)) + 1e-12;
        let c_tol = 0.5 * 10f64.powi(-i32::from(s.c_decimals)) + 1e-12;
        for p in &input {
            let (c, x) = to_program(&s, p.c_deg, p.x_mm);
            let (_, x_read) = parsed
                .iter()
                .find(|(cr, _)| (cr - c).abs() <= c_tol)
                .unwrap_or_else(|| panic!("no block at C={c} for c = {}", p.c_deg));
            assert!(
                (x_read - x).abs() <= x_tol,
                "c = {}: {x_read} vs {x}",
                p.c_deg
            );
        }
        for w in parsed.windows(2) {
            assert!(w[1].0 > w[0].0, "C must increase: {w:?}");
        }
        let (first, last) = (parsed[0], parsed[parsed.len() - 1]);
        assert_eq!(
            last.0,
            first.0 + 360.0,
            "closing block one period after the first"
        );
        assert_eq!(last.1, first.1, "closing block repeats the first X");
    }
}

#[test]
fn default_mapping_keeps_c_exactly() {
    let s = ProgramSettings::default();
    for i in 0..3600 {
        let c = f64::from(i) * 0.1;
        assert_eq!(s.c_prog_deg(c), c);
        assert_eq!(s.x_prog_mm(c), c);
    }
    assert_eq!(s.c_prog_deg(360.0), 0.0);
    assert_eq!(s.c_prog_deg(-10.0), 350.0);
}

/// The POLY program, read the way the control reads it, matches the fitted cubics.
fn assert_poly_matches(segments: &[PolySegment], s: &ProgramSettings, tol_mm: f64) {
    let pieces = parse_poly(&render_poly_table(segments, s).unwrap(), "C", "X");
    assert_eq!(pieces.len(), segments.len());
    assert_eq!(pieces.last().unwrap().c1, pieces[0].c0 + 360.0);
    let mut worst = 0.0f64;
    for seg in segments {
        for k in 0..=40 {
            let c_deg = seg.c_start_deg + (seg.c_end_deg - seg.c_start_deg) * f64::from(k) / 40.0;
            let (c, x) = to_program(s, c_deg, eval_segment(seg, c_deg));
            // The period end belongs to the first piece shifted by 360.
            let piece = pieces
                .iter()
                .find(|p| p.c0 <= c && c <= p.c1)
                .or_else(|| {
                    pieces
                        .iter()
                        .find(|p| p.c0 <= c + 360.0 && c + 360.0 <= p.c1)
                })
                .unwrap();
            let c_in = if c < piece.c0 { c + 360.0 } else { c };
            worst = worst.max((piece.eval(c_in) - x).abs());
        }
    }
    assert!(worst <= tol_mm, "worst deviation {worst} mm > {tol_mm} mm");
}

#[test]
fn poly_programs_evaluate_to_the_fitted_cubics() {
    // Knots exact at 4 decimals: only the a2/a3 rounding at 6 decimals remains, bounded by
    // 0.5e-6·(1/4 + 2/(3·sqrt 3)) < 0.32e-6 mm; 1e-9 covers the floating-point arithmetic.
    let exact_knots = hermite_segments(30.0, true);
    let coeff_bound = 0.5e-6 * (0.25 + 2.0 / (3.0 * 3f64.sqrt())) + 1e-9;
    assert_poly_matches(&exact_knots, &ProgramSettings::default(), coeff_bound);
    // Reversed C with offset: segment order and parameter direction flip. Offsets 37.5° and
    // 0.25 mm are exact at 4 decimals, so the same bound holds.
    assert_poly_matches(&exact_knots, &reversed_offset(), coeff_bound);
    // Knots not on the grid: add the half unit of the knot rounding.
    let raw = hermite_segments(15.0, false);
    assert_poly_matches(&raw, &reversed_offset(), 0.5e-4 + coeff_bound);
}

#[test]
fn c_equal_after_rounding_is_refused_naming_the_points() {
    let mut pts = points(10.0, 36);
    pts[1].c_deg = 10.00001;
    pts.insert(
        2,
        TablePoint {
            c_deg: 10.00004,
            d_mm: 0.0,
            x_mm: 1.0,
        },
    );
    let err = render_g1_table(&pts, &ProgramSettings::default()).unwrap_err();
    match &err {
        TableError::CNotIncreasing {
            first,
            second,
            c_first_prog,
            c_second_prog,
            ..
        } => {
            assert_eq!((first.as_str(), second.as_str()), ("point 1", "point 2"));
            assert_eq!(
                (c_first_prog.as_str(), c_second_prog.as_str()),
                ("10.0000", "10.0000")
            );
        }
        other => panic!("unexpected {other:?}"),
    }
    assert!(err.to_string().contains("alarm 10949"), "{err}");

    // With 0 decimals, half-degree steps collide.
    let s = ProgramSettings {
        c_decimals: 0,
        ..ProgramSettings::default()
    };
    assert!(matches!(
        render_g1_table(&points(0.5, 720), &s),
        Err(TableError::CNotIncreasing { .. })
    ));
    assert!(render_g1_table(&points(1.0, 360), &s).is_ok());
}

#[test]
fn last_point_rounding_onto_the_period_end_is_refused() {
    let mut pts = points(10.0, 36);
    pts.push(TablePoint {
        c_deg: 359.99996,
        d_mm: 0.0,
        x_mm: 1.0,
    });
    match render_g1_table(&pts, &ProgramSettings::default()).unwrap_err() {
        TableError::CNotIncreasing {
            first,
            second,
            c_first_prog,
            c_second_prog,
            ..
        } => {
            assert_eq!(first, "point 36");
            assert!(second.starts_with("period end"), "{second}");
            assert_eq!(
                (c_first_prog.as_str(), c_second_prog.as_str()),
                ("360.0000", "360.0000")
            );
        }
        other => panic!("unexpected {other:?}"),
    }
    // The same angle given as 360 wraps onto point 0.
    let mut pts = points(10.0, 36);
    pts.push(TablePoint {
        c_deg: 360.0,
        d_mm: 0.0,
        x_mm: 1.0,
    });
    assert!(matches!(
        render_g1_table(&pts, &ProgramSettings::default()),
        Err(TableError::CNotIncreasing { .. })
    ));
}

#[test]
fn bad_points_and_segments_are_refused() {
    let s = ProgramSettings::default();
    let mut pts = points(10.0, 36);
    pts[5].x_mm = f64::NAN;
    assert!(matches!(
        render_g1_table(&pts, &s),
        Err(TableError::NonFinitePoint { index: 5, .. })
    ));
    assert_eq!(
        render_g1_table(&points(10.0, 1), &s),
        Err(TableError::TooFewPoints { count: 1 })
    );
    assert_eq!(render_poly_table(&[], &s), Err(TableError::NoSegments));

    let mut segs = hermite_segments(30.0, false);
    segs[3].a3_mm = f64::INFINITY;
    assert_eq!(
        render_poly_table(&segs, &s),
        Err(TableError::NonFiniteSegment { index: 3 })
    );

    let mut segs = hermite_segments(30.0, false);
    segs[4].x0_mm += 0.001;
    assert!(matches!(
        render_poly_table(&segs, &s),
        Err(TableError::XGap {
            index: 3,
            next_index: 4,
            ..
        })
    ));

    let mut segs = hermite_segments(30.0, false);
    segs.remove(6);
    assert!(matches!(
        render_poly_table(&segs, &s),
        Err(TableError::CGap {
            index: 5,
            next_index: 6,
            ..
        })
    ));

    // A small C gap is refused even when it is below the written resolution.
    let mut segs = hermite_segments(30.0, false);
    segs[8].c_start_deg += 0.3;
    let whole_degrees = ProgramSettings {
        c_decimals: 0,
        ..ProgramSettings::default()
    };
    assert!(matches!(
        render_poly_table(&segs, &whole_degrees),
        Err(TableError::CGap {
            index: 7,
            next_index: 8,
            ..
        })
    ));

    let mut segs = hermite_segments(30.0, false);
    segs[2].c_end_deg = segs[2].c_start_deg;
    assert!(matches!(
        render_poly_table(&segs, &s),
        Err(TableError::EmptySegment { index: 2, .. })
    ));
}

#[test]
fn invalid_settings_are_all_reported() {
    let s = ProgramSettings {
        name: "S_TABLE".to_owned(),
        leading_axis: "x".to_owned(),
        x_decimals: 2,
        ..ProgramSettings::default()
    };
    let err = render_g1_table(&points(10.0, 36), &s).unwrap_err();
    let TableError::Settings(list) = &err else {
        panic!("unexpected {err:?}")
    };
    assert_eq!(list.0.len(), 3, "{err}");
    assert_eq!(
        err.to_string(),
        "program settings: program name `S_TABLE` starts with `S_`, a prefix reserved by Siemens; \
         following and leading axis are both `X`; x_decimals is 2: allowed 3 to 9"
    );
}

/// The geometry core's tables and POLY fit render in both forms, and the POLY program read
/// back matches the crankpin formula d(α) = b·cos α + sqrt((R + r_p)² − (b·sin α)²) within the
/// fit error plus the written resolution.
#[test]
fn crankpin_tables_from_the_geometry_core_render() {
    use camloop::core::fit::fit_poly;
    use camloop::core::geometry::{CrankpinGeometry, Part};
    let (b, r_p, r) = (45.0, 30.0, 300.0);
    let part = Part::crankpin(CrankpinGeometry {
        throw_mm: b,
        pin_radius_mm: r_p,
        wheel_radius_mm: r,
    })
    .unwrap();
    let table = part.wheel_table(360).unwrap();
    let segments = fit_poly(&table);
    for s in [ProgramSettings::default(), reversed_offset()] {
        let g1 = render_g1_table(&table, &s).unwrap();
        assert_eq!(parse_g1(&g1, "C", "X").len(), 361);
        let pieces = parse_poly(&render_poly_table(&segments, &s).unwrap(), "C", "X");
        assert_eq!(pieces.len(), 360);
        let sign = if s.c_direction == CDirection::Reversed {
            -1.0
        } else {
            1.0
        };
        let mut worst = 0.0f64;
        for p in &pieces {
            let c_prog = 0.5 * (p.c0 + p.c1);
            let alpha = (sign * (c_prog - s.c_offset_deg)).to_radians();
            let d = b * alpha.cos() + ((r + r_p).powi(2) - (b * alpha.sin()).powi(2)).sqrt();
            worst = worst.max((p.eval(c_prog) - (d - r - r_p + s.x_offset_mm)).abs());
        }
        // Written knots are within 0.5e-4 mm; a 1° C2 spline of this smooth d(α) errs by
        // about h⁴·max|d⁗|/384 ≈ 1e-8 mm and the a2/a3 rounding by < 0.32e-6 mm, so 1e-6 mm
        // covers both. A sign or offset error in the mapping would show as millimetres.
        assert!(worst <= 0.5e-4 + 1e-6, "worst {worst} mm");
    }
}
