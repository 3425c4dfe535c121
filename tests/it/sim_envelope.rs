//! The ground part is the exact envelope of the real wheel: a perfect machine with a POLY
//! table grinds the nominal lobe, a G1 table leaves its chord error, and the outline and the
//! gauge readings agree with a brute-force disc sweep (tests/sim_support/brute.rs) that
//! shares no code with the simulator.

use crate::sim_support;

use camloop::core::fit::{self, TableForm};
use camloop::core::geometry::{Follower, Part};
use camloop::sim::{CommandedTable, GrinderConfig, Workpiece};
use camloop::sim::{SimGrinder, TableShape};
use sim_support::brute::BrutePath;
use sim_support::*;

/// Gauge grid for judging profile error: 0.1°.
const FINE: usize = 3600;

/// Angles for the brute-force comparison, degrees: base circle, ramps, flanks (both sides
/// of the peak velocity), and several points on the nose between and at G1 corners.
const PROBE_ANGLES_DEG: [f64; 10] = [
    10.0, 100.7, 110.3, 143.2, 170.0, 179.73, 180.5, 185.25, 215.9, 259.4,
];

/// Agreement demanded between the simulator and the brute force: 0.001 µm (the brief asks
/// for 0.01 µm). The simulator's Hermite reading errs by < 1e-9 mm with 1° tables and about
/// 1.5e-7 mm (polar radius) with the 10° facets of a 36-point table; the brute force's own
/// error is below 1e-8 mm (see its docs). Observed: ≤ 1.5e-7 mm, mostly ~1e-11 mm.
const BRUTE_TOLERANCE_MM: f64 = 1e-6;

/// A perfect machine only follows the POLY cubics' departure from the exact path, which the
/// 1° periodic spline keeps far below 0.05 µm for this smooth lobe.
#[test]
fn perfect_machine_with_poly_table_grinds_the_nominal_lift() {
    let sim = demo_sim(GrinderConfig::perfect(), Follower::Flat, 1);
    let ground = sim
        .grind(&demo_table(Follower::Flat, 360, TableForm::Poly))
        .unwrap();
    let error = error_um(&ground.lift_on_grid(FINE), &nominal_on_grid(FINE));
    let (worst, at) = max_abs(&error);
    assert!(
        worst < 0.05,
        "max error {worst} µm at {}°",
        at as f64 / 10.0
    );
}

/// With G1 the wheel centre runs on chords of X(C). At the nose d(c) is concave, the chord
/// lies below it by up to X''·Δc²/8 ≈ 1 µm at mid-segment, the contact normal there is
/// within a fraction of a degree of the wheel direction, so the lift is low by about the
/// chord sag. The core's own chord check (`fit::g1_deviation`, a separate computation on the
/// exact wheel path) measures that sag: the two must agree within 10 %. On the flanks the
/// sag is smaller (~0.5 µm), on the base circle the chords are exact.
#[test]
fn g1_table_leaves_the_chord_error() {
    let sim = demo_sim(GrinderConfig::perfect(), Follower::Flat, 1);
    let part = demo_part(Follower::Flat);
    let table = demo_table(Follower::Flat, 360, TableForm::G1);
    let ground = sim.grind(&table).unwrap();
    let error = error_um(&ground.lift_on_grid(FINE), &nominal_on_grid(FINE));
    let (worst, at) = max_abs(&error);
    assert!(
        (0.3..2.0).contains(&worst),
        "max error {worst} µm at {}°",
        at as f64 / 10.0
    );
    let TableShape::G1(points) = &table.shape else {
        unreachable!("G1 table")
    };
    let sag = fit::g1_deviation(&part, points).unwrap();
    assert!(
        (worst - sag.max_um).abs() < 0.1 * sag.max_um,
        "lift error {worst} µm, chord sag {} µm at {}°",
        sag.max_um,
        sag.at_c_deg
    );
    // The worst place is the nose and the part is ground too small there.
    assert!((170..=190).contains(&(at / 10)), "worst at {}°", at / 10);
    assert!(error[at] < 0.0);
    let flanks = error[1000..1500].iter().chain(&error[2100..2600]);
    let flank = flanks.fold(0.0f64, |m, e| m.max(e.abs()));
    assert!((0.3..0.8).contains(&flank), "flank error {flank} µm");
    let base = error[3000..3600].iter().fold(0.0f64, |m, e| m.max(e.abs()));
    assert!(base < 1e-3, "base circle error {base} µm");
}

/// Outline radius and flat lift against the brute-force disc sweep, for G1 tables (corners
/// and wheel arcs at every point, the trimming at the nose removing most of each piece),
/// the default machine (lag shifts every corner off the table points, harmonics bend the
/// path), a POLY table and a coarse 36-point G1 table (10° facets). Without the corner
/// trimming the flat lift at the nose comes out 0.9 µm too high with 360 points and 86 µm
/// with 36, so this comparison has teeth.
#[test]
fn outline_and_flat_lift_match_brute_force() {
    let cases = [
        (
            "perfect G1 360",
            GrinderConfig::perfect(),
            360,
            TableForm::G1,
        ),
        (
            "default G1 360",
            GrinderConfig::default(),
            360,
            TableForm::G1,
        ),
        (
            "default POLY 360",
            GrinderConfig::default(),
            360,
            TableForm::Poly,
        ),
        ("perfect G1 36", GrinderConfig::perfect(), 36, TableForm::G1),
    ];
    for (name, config, points, form) in cases {
        let sim = demo_sim(config, Follower::Flat, 1);
        let table = demo_table(Follower::Flat, points, form);
        let ground = sim.grind(&table).unwrap();
        let brute = brute_path(&sim, &table);
        for angle_deg in PROBE_ANGLES_DEG {
            let angle = angle_deg.to_radians();
            let radius = ground.radius_mm(angle_deg) - brute.radius_mm(angle);
            let lift = ground.lift_mm(angle_deg) + BASE_RADIUS_MM - brute.support_mm(angle);
            assert!(
                radius.abs() < BRUTE_TOLERANCE_MM && lift.abs() < BRUTE_TOLERANCE_MM,
                "{name} at {angle_deg}°: radius off by {radius:e} mm, flat lift by {lift:e} mm"
            );
        }
    }
}

/// A roller gauge (r = 10 mm) reads the pitch curve; against the brute force, on the
/// default machine with a G1 table.
#[test]
fn roller_lift_matches_brute_force() {
    let roller = Follower::Roller { radius_mm: 10.0 };
    let sim = demo_sim(GrinderConfig::default(), roller, 1);
    let table = demo_table(roller, 360, TableForm::G1);
    let ground = sim.grind(&table).unwrap();
    let brute = brute_path(&sim, &table);
    for angle_deg in [10.0f64, 120.4, 150.0, 179.73, 181.0, 230.6] {
        let centre = brute.roller_centre_mm(angle_deg.to_radians(), 10.0);
        let lift = ground.lift_mm(angle_deg) + BASE_RADIUS_MM + 10.0 - centre;
        assert!(
            lift.abs() < BRUTE_TOLERANCE_MM,
            "roller lift at {angle_deg}° off by {lift:e} mm"
        );
    }
}

/// Grid and single-angle readings are the same computation seen two ways: they must agree
/// to rounding.
#[test]
fn grid_and_single_angle_readings_agree() {
    let sim = demo_sim(GrinderConfig::default(), Follower::Flat, 1);
    let ground = sim
        .grind(&demo_table(Follower::Flat, 360, TableForm::G1))
        .unwrap();
    let grid = ground.lift_on_grid(720);
    for j in (0..720).step_by(37) {
        let single = ground.lift_mm(j as f64 * 0.5);
        assert!((single - grid[j]).abs() < 1e-12, "at {}°", j as f64 * 0.5);
    }
}

/// A crankpin on a perfect machine: the gauge's flat reading is the pin's support function
/// b·cos ψ + r_p, i.e. lift b·(1 + cos ψ), within 0.05 µm (the POLY fit error).
#[test]
fn perfect_machine_grinds_the_crankpin() {
    let geometry = pin_geometry();
    let part = Part::crankpin(geometry).unwrap();
    let table = CommandedTable::nominal(&part, 360, TableForm::Poly).unwrap();
    let sim = SimGrinder::new(GrinderConfig::perfect(), Workpiece::Crankpin(geometry), 1).unwrap();
    let ground = sim.grind(&table).unwrap();
    let support = ground.support_on_grid(FINE);
    let lift = ground.lift_on_grid(FINE);
    let b = geometry.throw_mm;
    let mut worst = 0.0f64;
    for j in 0..FINE {
        let psi = (j as f64 * 0.1).to_radians();
        worst = worst.max((support[j] - (b * psi.cos() + geometry.pin_radius_mm)).abs());
        worst = worst.max((lift[j] - b * (1.0 + psi.cos())).abs());
    }
    assert!(worst * 1000.0 < 0.05, "max error {} µm", worst * 1000.0);
}

/// The same crankpin from a G1 table, on the default machine, against the brute force. On
/// the far side the wheel centre is only R + r_p − b = 285 mm from the axis, so each
/// polar-linear G1 segment turns tighter than the 300 mm wheel: its envelope is covered and
/// the outline is made of the wheel arcs at the table points, crossing at corners.
#[test]
fn crankpin_g1_matches_brute_force() {
    let geometry = pin_geometry();
    let part = Part::crankpin(geometry).unwrap();
    let table = CommandedTable::nominal(&part, 360, TableForm::G1).unwrap();
    let sim = SimGrinder::new(GrinderConfig::default(), Workpiece::Crankpin(geometry), 1).unwrap();
    let ground = sim.grind(&table).unwrap();
    let brute = BrutePath {
        origin: [geometry.throw_mm, 0.0],
        ..brute_path(&sim, &table)
    };
    let zero = geometry.pin_radius_mm - geometry.throw_mm;
    for angle_deg in [0.0f64, 45.3, 90.0, 135.7, 180.0, 270.2] {
        let lift = ground.lift_mm(angle_deg) + zero - brute.support_mm(angle_deg.to_radians());
        assert!(
            lift.abs() < BRUTE_TOLERANCE_MM,
            "pin lift at {angle_deg}° off by {lift:e} mm"
        );
    }
}
