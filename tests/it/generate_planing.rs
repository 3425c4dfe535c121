//! Planing a cam rotor's end face: rs274 runs the ISO program and every cutting move keeps
//! A = A_k + K·(X − X_start) with Z on the face, checked against the face's arc built here
//! independently (the circle through peak, valley and peak); the resume lives on the
//! control, proven through LinuxCNC's own var file and through our SINUMERIK evaluator with
//! random interruptions.

use crate::rs274_support;
use crate::sinumerik_support;

use camloop::core::generate::dialect::{Decimals, Dialect, Form};
use camloop::core::generate::planing::coupled::render_sinumerik_table;
use camloop::core::generate::planing::{
    MCode, PlaningError, PlaningJob, PlaningMCodes, RotorFace, generate, safety_rules, stroke_x_mm,
};
use camloop::core::generate::safety::{self, Violation};
use camloop::core::generate::setup::{Coolant, ToolCall};
use rs274_support::Canon;

pub(crate) fn job() -> PlaningJob {
    PlaningJob {
        name: "ROTOR_PLANE".to_owned(),
        work_offset: 1,
        tool: ToolCall {
            number: 1,
            offset: 1,
            change: false,
        },
        coolant: Coolant::Flood,
        face: RotorFace {
            segments: 6,
            pitch_radius_mm: 40.0,
            z_peak_mm: 0.0,
            z_valley_mm: -3.0,
        },
        ratio_deg_per_mm: 0.75,
        x_start_mm: 0.0,
        x_end_mm: 80.0,
        over_travel_front_mm: 8.0,
        over_travel_rear_mm: 6.0,
        z_clear_mm: 5.0,
        feed_mm_min: 2000.0,
        tolerance_um: 2.0,
        min_points_per_arc: 24,
        m_codes: PlaningMCodes::default(),
        mark_parameter_iso: 5000,
    }
}

/// The face's height at rotor angle θ, from the circle through the three points of one
/// arc in the developed section (circumcentre by perpendicular bisectors), not from the
/// generator's closed form.
pub(crate) fn face_z(f: &RotorFace, theta_deg: f64) -> f64 {
    let period = 360.0 / f64::from(f.segments);
    let len = f.pitch_radius_mm * period.to_radians();
    let (p1, p2, p3) = (
        (0.0, f.z_peak_mm),
        (len / 2.0, f.z_valley_mm),
        (len, f.z_peak_mm),
    );
    if f.z_peak_mm == f.z_valley_mm {
        return f.z_peak_mm;
    }
    let d = 2.0 * (p1.0 * (p2.1 - p3.1) + p2.0 * (p3.1 - p1.1) + p3.0 * (p1.1 - p2.1));
    let sq = |p: (f64, f64)| p.0 * p.0 + p.1 * p.1;
    let cx = (sq(p1) * (p2.1 - p3.1) + sq(p2) * (p3.1 - p1.1) + sq(p3) * (p1.1 - p2.1)) / d;
    let cz = (sq(p1) * (p3.0 - p2.0) + sq(p2) * (p1.0 - p3.0) + sq(p3) * (p2.0 - p1.0)) / d;
    let rho = (p1.0 - cx).hypot(p1.1 - cz);
    let s = f.pitch_radius_mm * theta_deg.rem_euclid(period).to_radians();
    // The valley is below the centre: the lower half of the circle.
    cz - (rho * rho - (s - cx) * (s - cx)).sqrt()
}

/// Checks the cutting moves of one run (X, A, Z per feed move, in order) and returns the
/// arcs whose stroke reached the rear over-travel, and the worst chord error in µm.
pub(crate) fn check_cuts(j: &PlaningJob, feeds: &[(f64, f64, f64)]) -> (Vec<usize>, f64) {
    let period = 360.0 / f64::from(j.face.segments);
    let x_rear = j.x_end_mm + j.over_travel_rear_mm;
    let mut done = Vec::new();
    let mut worst_um: f64 = 0.0;
    for (i, &(x, a, z)) in feeds.iter().enumerate() {
        assert!(
            z >= j.face.z_valley_mm - 1e-9,
            "move {i}: Z {z} below the valleys"
        );
        let in_stroke = x >= j.x_start_mm - j.over_travel_front_mm - 1e-9;
        let index = a - j.ratio_deg_per_mm * (x - j.x_start_mm);
        let k = (index / period).round();
        // 4 decimals printed on A: 0.5e-4° each side.
        assert!(
            !in_stroke || (index - k * period).abs() < 1.1e-4,
            "move {i}: A = {a} at X = {x} is off the ratio"
        );
        if (x - x_rear).abs() < 1e-9 {
            done.push(k as usize);
        }
        let Some(&(x0, a0, z0)) = i.checked_sub(1).map(|p| &feeds[p]) else {
            continue;
        };
        let (lo, hi) = (x0.max(j.x_start_mm), x.min(j.x_end_mm));
        if hi <= lo || (a - a0).abs() < 1e-12 {
            continue;
        }
        // The chord, sampled: Z interpolated against the face at the rotor angle A gives.
        for s in 0..=40 {
            let t = f64::from(s) / 40.0;
            let xs = x0 + t * (x - x0);
            if xs < lo || xs > hi {
                continue;
            }
            let (as_, zs) = (a0 + t * (a - a0), z0 + t * (z - z0));
            worst_um = worst_um.max((zs - face_z(&j.face, as_)).abs() * 1000.0);
        }
    }
    (done, worst_um)
}

/// The program, after the shared safety check passed on it.
fn checked(j: &PlaningJob) -> camloop::core::generate::ir::Program {
    let p = generate(j).unwrap();
    let report = safety::check(&p, &safety_rules(j)).unwrap();
    assert!(report.rotary_moves > 0 && report.cutting_moves > 0);
    p
}

fn iso(j: &PlaningJob) -> String {
    Dialect::Iso.render(&checked(j), Form::Loop, Decimals::default())
}

/// rs274 with a var file that lists the mark parameter with `mark`; the feed moves and the
/// var file's value after the run.
fn rs274_with_mark(j: &PlaningJob, mark: f64) -> (Vec<Canon>, f64) {
    let Some(rs) = rs274_support::rs274() else {
        panic!("rs274 (Debian linuxcnc-uspace) is not installed: .ci/run installs it");
    };
    let dir = tempfile::tempdir().unwrap();
    let var = dir.path().join("camloop.var");
    std::fs::write(&var, format!("{} {mark:.6}\n", j.mark_parameter_iso)).unwrap();
    let canon = rs274_support::run_rs274_with_var(&rs, &iso(j), 0.0, &var).unwrap();
    let text = std::fs::read_to_string(&var).unwrap();
    let after = text
        .lines()
        .find_map(|l| {
            let mut w = l.split_whitespace();
            (w.next()? == j.mark_parameter_iso.to_string()).then(|| w.next()?.parse().ok())?
        })
        .expect("the var file keeps the mark parameter");
    (canon, after)
}

fn feeds(canon: &[Canon]) -> Vec<(f64, f64, f64)> {
    canon
        .iter()
        .filter_map(|m| match *m {
            Canon::Feed { x, a, z, .. } => Some((x, a, z)),
            _ => None,
        })
        .collect()
}

#[test]
fn rs274_cuts_the_face_within_tolerance_on_the_ratio_and_lifts_to_return() {
    let j = job();
    let (canon, after) = rs274_with_mark(&j, 0.0);
    let (done, worst_um) = check_cuts(&j, &feeds(&canon));
    eprintln!(
        "planing rs274: {} points per stroke, worst chord error {worst_um:.3} um",
        stroke_x_mm(&j).unwrap().len()
    );
    assert_eq!(done, vec![0, 1, 2, 3, 4, 5], "every arc, in order");
    // 2 µm tolerance, plus Z and A each rounded to 4 decimals (0.05 µm; 0.00005° is 0.03 µm
    // of arc at 40 mm, times a slope under 0.3).
    assert!(worst_um < 2.1, "worst chord error {worst_um} um");
    assert!(
        worst_um > 0.5,
        "the chords do use the tolerance ({worst_um} um)"
    );
    assert_eq!(after, 0.0, "a finished job leaves the mark cleared");
    let mut z = f64::NAN;
    let mut x = f64::NAN;
    for (i, m) in canon.iter().enumerate() {
        if let Canon::Rapid { x: x1, z: z1, .. } = *m {
            if (x1 - x).abs() > 1e-9 {
                assert_eq!(z, j.z_clear_mm, "move {i}: X travels in rapid only lifted");
            }
            (x, z) = (x1, z1);
        } else if let Canon::Feed { x: x1, z: z1, .. } = *m {
            (x, z) = (x1, z1);
        }
    }
}

#[test]
fn rs274_resumes_from_the_var_file_and_clears_it_at_the_end() {
    let j = job();
    let (canon, after) = rs274_with_mark(&j, 4.0);
    let (done, _) = check_cuts(&j, &feeds(&canon));
    assert_eq!(
        done,
        vec![4, 5],
        "arcs 5 and 6 only, from the start of arc 5"
    );
    assert_eq!(after, 0.0);
    let (canon, _) = rs274_with_mark(&j, 6.0);
    assert!(
        feeds(&canon).is_empty(),
        "a job marked finished cuts nothing"
    );
}

/// A tiny deterministic generator for the interruption points.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self, n: usize) -> usize {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 33) as usize) % n
    }
}

#[test]
fn interrupted_runs_resume_on_the_control_and_cut_each_arc_once() {
    let j = job();
    let text = Dialect::Sinumerik.render(&checked(&j), Form::Loop, Decimals::default());
    let x_rear = format!("X={:.4}", j.x_end_mm + j.over_travel_rear_mm);
    let mut rng = Lcg(0x5eed);
    for trial in 0..200 {
        let mut r50 = 0.0; // kept by the control over power-off
        let mut cuts = [0u32; 6];
        let mut runs = 0;
        'job: loop {
            runs += 1;
            assert!(runs < 20, "trial {trial} does not finish");
            let blocks = sinumerik_support::run_with(&text, 4, 4, &[("R50", r50)]).unwrap();
            // An interruption stops a move under way; the R50 writes take no time (one
            // falling between a stroke's end and its mark would cut that arc again: an air
            // cut at the same depth).
            let moves: Vec<usize> = (0..blocks.len())
                .filter(|&i| blocks[i].starts_with('G'))
                .collect();
            let stop = if runs < 4 {
                moves
                    .get(rng.next(moves.len() + 1))
                    .copied()
                    .unwrap_or(blocks.len())
            } else {
                blocks.len()
            };
            for b in &blocks[..stop] {
                if let Some(v) = b.strip_prefix("R50=") {
                    r50 = v.parse().unwrap();
                    if r50 == 0.0 {
                        break 'job;
                    }
                } else if b.starts_with("G1") && b.contains(&x_rear) {
                    let a: f64 = b
                        .split("A=")
                        .nth(1)
                        .unwrap()
                        .split(' ')
                        .next()
                        .unwrap()
                        .parse()
                        .unwrap();
                    let period = 360.0 / f64::from(j.face.segments);
                    let k = ((a - j.ratio_deg_per_mm
                        * (j.x_end_mm + j.over_travel_rear_mm - j.x_start_mm))
                        / period)
                        .round();
                    cuts[k as usize] += 1;
                }
            }
        }
        assert_eq!(cuts, [1; 6], "trial {trial}: every arc exactly once");
    }
}

#[test]
fn sinumerik_text_runs_as_the_program_says() {
    let mut j = job();
    let m = |code| Some(MCode { code, p: None });
    j.m_codes = PlaningMCodes {
        hydraulics_on: m(60),
        hydraulics_off: m(61),
        a_forward: m(62),
        a_reverse: m(63),
        lift_on: m(64),
        lift_off: m(65),
    };
    let p = checked(&j);
    let text = Dialect::Sinumerik.render(&p, Form::Loop, Decimals::default());
    let blocks = sinumerik_support::run(&text, 4, 4).unwrap();
    let feeds: Vec<(f64, f64, f64)> = blocks
        .iter()
        .filter(|b| b.starts_with("G1") && b.contains("A="))
        .map(|b| {
            let w = |ax: &str| -> f64 {
                b.split_whitespace()
                    .find_map(|t| t.strip_prefix(ax))
                    .unwrap()
                    .parse()
                    .unwrap()
            };
            (w("X="), w("A="), w("Z="))
        })
        .collect();
    let (done, worst_um) = check_cuts(&j, &feeds);
    assert_eq!(done, vec![0, 1, 2, 3, 4, 5]);
    assert!(worst_um < 2.1, "{worst_um}");
    // The same moves as the expanded form.
    let expanded = Dialect::Sinumerik.render(&p, Form::Expanded, Decimals::default());
    assert_eq!(sinumerik_support::run(&expanded, 4, 4).unwrap(), blocks);
    insta::assert_snapshot!("planing_sinumerik", text);
}

#[test]
fn the_safety_check_knows_a_planer_has_no_spindle_and_lifts_for_the_index() {
    let j = job();
    let p = generate(&j).unwrap();
    let mut rules = safety_rules(&j);
    rules.no_spindle = false;
    let v = safety::check(&p, &rules).unwrap_err();
    assert!(
        v.iter().all(|v| matches!(
            v,
            Violation::CutBeforeSetup {
                missing: "the spindle start",
                ..
            }
        )),
        "{v:?}"
    );
    // The index of A is checked against the lift: with the lift lower than where the
    // index happens, it is accepted; with it higher, every index is refused.
    let mut rules = safety_rules(&j);
    rules.clear = vec![safety::Clear::AtLeast {
        axis: camloop::core::generate::ir::Axis::Z,
        mm: 6.0,
    }];
    let v = safety::check(&p, &rules).unwrap_err();
    assert!(
        v.iter()
            .any(|v| matches!(v, Violation::RotaryEngaged { axis: 'A', .. })),
        "{v:?}"
    );
}

#[test]
fn iso_m_codes_with_a_p_word_run_in_rs274() {
    let mut j = job();
    j.m_codes.hydraulics_on = Some(MCode {
        code: 64,
        p: Some(0),
    });
    j.m_codes.hydraulics_off = Some(MCode {
        code: 65,
        p: Some(0),
    });
    let text = iso(&j);
    assert!(text.contains("M64 P0 (hydraulics on)"), "{text}");
    let (canon, _) = rs274_with_mark(&j, 0.0);
    assert_eq!(check_cuts(&j, &feeds(&canon)).0.len(), 6);
}

#[test]
fn golden_programs_and_refusals() {
    let j = job();
    insta::assert_snapshot!("planing_iso", iso(&j));
    insta::assert_snapshot!(
        "planing_sinumerik_table",
        render_sinumerik_table(&j, 3).unwrap()
    );
    let mut bad = job();
    bad.z_clear_mm = -1.0;
    assert!(matches!(
        generate(&bad),
        Err(PlaningError::Value {
            field: "z clear",
            ..
        })
    ));
    let mut bad = job();
    bad.x_end_mm = 70.0;
    let e = generate(&bad).unwrap_err();
    assert!(matches!(e, PlaningError::StrokeNotOneArc { .. }), "{e}");
    let mut bad = job();
    bad.face.z_valley_mm = -30.0;
    assert!(matches!(
        generate(&bad),
        Err(PlaningError::Value {
            field: "z peak - z valley",
            ..
        })
    ));
    let mut bad = job();
    bad.tolerance_um = 1e-6;
    assert!(matches!(
        generate(&bad),
        Err(PlaningError::TooManyPoints { .. })
    ));
}
