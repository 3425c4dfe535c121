//! The wheel's life (wear, dressing, what the control is told), the control's X zero, the
//! settings file and the refusal of bad settings and tables.

use crate::sim_support;

use camloop::core::fit::TableForm;
use camloop::core::geometry::Follower;
use camloop::core::table::{PolySegment, TablePoint};
use camloop::sim::{
    CommandedTable, GaugeConfig, GrinderConfig, SimError, SimGrinder, TableShape, Workpiece,
};
use sim_support::*;

/// Radii compared to 1e-9 mm: they are sums of a few µm-sized steps on 250 mm.
const RADIUS_TOLERANCE_MM: f64 = 1e-9;

#[test]
fn wheel_wears_per_part_and_dresses_on_schedule() {
    let config = GrinderConfig {
        wheel_size_error_um: 3.0,
        wear_um_per_part: 0.5,
        dress_every_parts: 4,
        dress_at_parts: vec![6],
        dress_depth_um: 20.0,
        dressing_error_um: 2.0,
        dressing_error_sigma_um: 0.0,
        ..GrinderConfig::perfect()
    };
    let mut sim = demo_sim(config, Follower::Flat, 1);
    assert_eq!(sim.believed_wheel_radius_mm(), WHEEL_RADIUS_MM);
    let mut truth = WHEEL_RADIUS_MM + 0.003;
    assert!((sim.wheel_radius_mm() - truth).abs() < RADIUS_TOLERANCE_MM);
    let mut believed = WHEEL_RADIUS_MM;
    let mut dressed_after = Vec::new();
    for part in 1..=9u32 {
        let event = sim.after_part();
        truth -= 0.0005;
        if [4, 6, 8].contains(&part) {
            truth -= 0.020;
            believed = truth + 0.002;
            let event = event.expect("dressing due");
            assert_eq!(event.after_part, part);
            assert!((event.depth_mm - 0.020).abs() < 1e-15);
            assert!((event.wheel_radius_mm - truth).abs() < RADIUS_TOLERANCE_MM);
            assert!((event.believed_wheel_radius_mm - believed).abs() < RADIUS_TOLERANCE_MM);
            dressed_after.push(part);
        } else {
            assert!(event.is_none(), "no dressing after part {part}");
        }
        assert_eq!(sim.parts_ground(), part);
        assert!((sim.wheel_radius_mm() - truth).abs() < RADIUS_TOLERANCE_MM);
        assert!((sim.believed_wheel_radius_mm() - believed).abs() < RADIUS_TOLERANCE_MM);
    }
    assert_eq!(dressed_after, [4, 6, 8]);
}

/// Random dressing errors: 400 dressings with 2 µm bias and σ = 1 µm. The mean error has a
/// standard error of 0.05 µm (bound 0.2 µm = 4 s.e.), the spread 0.035 µm (bound 0.15 µm).
#[test]
fn dressing_error_has_the_configured_bias_and_spread() {
    let config = GrinderConfig {
        dress_every_parts: 1,
        dress_depth_um: 10.0,
        dressing_error_um: 2.0,
        dressing_error_sigma_um: 1.0,
        ..GrinderConfig::perfect()
    };
    let mut sim = demo_sim(config, Follower::Flat, 99);
    let errors_um: Vec<f64> = (0..400)
        .map(|_| {
            let e = sim.after_part().expect("dressing every part");
            (e.believed_wheel_radius_mm - e.wheel_radius_mm) * 1000.0
        })
        .collect();
    let mean = errors_um.iter().sum::<f64>() / 400.0;
    let sd = (errors_um.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / 399.0).sqrt();
    assert!((mean - 2.0).abs() < 0.2, "mean {mean} µm");
    assert!((sd - 1.0).abs() < 0.15, "sd {sd} µm");
}

/// The dresser's infeed reading: 400 dressings of 10 µm read with σ = 0.2 µm. The mean error
/// has a standard error of 0.01 µm (bound 0.04 µm = 4 s.e.), the spread about 0.007 µm
/// (bound 0.03 µm). Turned off, the report is absent and every other draw of the seed is
/// the same: the radius the control is told after each dressing does not move.
#[test]
fn the_dresser_reads_its_infeed_to_the_configured_spread() {
    let config = |report: bool| GrinderConfig {
        dress_every_parts: 1,
        dress_depth_um: 10.0,
        dressing_error_um: 2.0,
        dressing_error_sigma_um: 1.0,
        dresser_reports_infeed: report,
        dresser_infeed_sigma_um: 0.2,
        ..GrinderConfig::perfect()
    };
    let (mut with, mut without) = (
        demo_sim(config(true), Follower::Flat, 5),
        demo_sim(config(false), Follower::Flat, 5),
    );
    let mut errors_um = Vec::new();
    for _ in 0..400 {
        let (a, b) = (with.after_part().unwrap(), without.after_part().unwrap());
        assert_eq!(b.measured_infeed_um, None);
        assert_eq!(a.believed_wheel_radius_mm, b.believed_wheel_radius_mm);
        errors_um.push(a.measured_infeed_um.unwrap() - a.depth_mm * 1000.0);
    }
    let mean = errors_um.iter().sum::<f64>() / 400.0;
    let sd = (errors_um.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / 399.0).sqrt();
    assert!(mean.abs() < 0.04, "mean {mean} µm");
    assert!((sd - 0.2).abs() < 0.03, "sd {sd} µm");
}

/// After a dressing the control believes R_true + 2 µm. A table regenerated for that
/// radius grinds every angle 2 µm high (the wheel is smaller than believed). A table left
/// from before the dressing is shifted by the control's X zero (tool offset), so after a
/// 20 µm dressing it is off only by the flank geometry (< 0.02 µm); after a 5 mm dressing
/// that geometry costs micrometres on the flanks, which is why tables are regenerated.
#[test]
fn control_x_zero_follows_the_believed_wheel() {
    let nominal = nominal_on_grid(3600);
    let old_table = demo_table(Follower::Flat, 360, TableForm::Poly);
    let dressed = |depth_um: f64| {
        let config = GrinderConfig {
            dress_at_parts: vec![1],
            dress_depth_um: depth_um,
            dressing_error_um: 2.0,
            ..GrinderConfig::perfect()
        };
        let mut sim = demo_sim(config, Follower::Flat, 1);
        sim.after_part().expect("dressing after part 1");
        sim
    };
    let sim = dressed(20.0);
    let part = demo_part(Follower::Flat)
        .with_wheel_radius(sim.believed_wheel_radius_mm())
        .unwrap();
    let fresh = CommandedTable::nominal(&part, 360, TableForm::Poly).unwrap();
    assert!((sim.x_zero_mm(&fresh) - fresh.x_zero_mm).abs() < 1e-12);
    let fresh_error = error_um(&sim.grind(&fresh).unwrap().lift_on_grid(3600), &nominal);
    assert!(fresh_error.iter().all(|e| (e - 2.0).abs() < 0.01));
    let stale_error = error_um(&sim.grind(&old_table).unwrap().lift_on_grid(3600), &nominal);
    assert!(stale_error.iter().all(|e| (e - 2.0).abs() < 0.02));

    let sim = dressed(5000.0);
    let stale_error = error_um(&sim.grind(&old_table).unwrap().lift_on_grid(3600), &nominal);
    let (worst, _) = max_abs(&stale_error.iter().map(|e| e - 2.0).collect::<Vec<_>>());
    assert!(
        (1.0..10.0).contains(&worst),
        "stale-table flank error {worst} µm"
    );
    assert!(
        (stale_error[0] - 2.0).abs() < 0.01,
        "base circle {}",
        stale_error[0]
    );
}

#[test]
fn settings_parse_from_toml_with_defaults_for_missing_keys() {
    let text = r#"
        c_speed_rpm = 20.0
        servo_lag_ms = 0.3
        harmonics = [{ order = 2, amplitude_um = 1.5, phase_deg = 10.0 }]
        wheel_size_error_um = -1.0
        dress_at_parts = [10, 30]

        [gauge]
        revolutions = 5
        faults = [
            { kind = "spike", revolution = 1, angle_index = 7, size_um = 25.0 },
            { kind = "offset", revolution = 0, offset_um = 3.0 },
        ]
    "#;
    let config: GrinderConfig = toml::from_str(text).unwrap();
    assert_eq!(config.c_speed_rpm, 20.0);
    assert_eq!(config.harmonics.len(), 1);
    assert_eq!(config.dress_at_parts, [10, 30]);
    assert_eq!(config.gauge.revolutions, 5);
    assert_eq!(config.gauge.faults.len(), 2);
    let defaults = GrinderConfig::default();
    assert_eq!(config.dress_every_parts, defaults.dress_every_parts);
    assert_eq!(config.gauge.points_per_rev, defaults.gauge.points_per_rev);
    assert!(config.problems().is_empty());

    let unknown = toml::from_str::<GrinderConfig>("servo_lag = 1.0").unwrap_err();
    assert!(unknown.to_string().contains("servo_lag"), "{unknown}");
}

/// Every problem is reported at once, each naming its field.
#[test]
fn bad_settings_are_all_reported() {
    let config = GrinderConfig {
        c_speed_rpm: 0.0,
        servo_lag_ms: -1.0,
        samples_per_segment: 1,
        gauge: GaugeConfig {
            points_per_rev: 10,
            revolutions: 0,
            ..GaugeConfig::default()
        },
        ..GrinderConfig::default()
    };
    let Err(SimError::Config { problems }) =
        SimGrinder::new(config, Workpiece::Cam(demo_geometry(Follower::Flat)), 1)
    else {
        panic!("bad settings accepted")
    };
    let text = problems.join("\n");
    for field in [
        "c_speed_rpm = 0",
        "servo_lag_ms = -1",
        "samples_per_segment = 1",
        "gauge.points_per_rev = 10",
        "gauge.revolutions = 0",
    ] {
        assert!(text.contains(field), "`{field}` missing from:\n{text}");
    }
    assert_eq!(problems.len(), 5, "only these five: {text}");
}

#[test]
fn bad_tables_are_refused_naming_the_entry() {
    let sim = demo_sim(GrinderConfig::perfect(), Follower::Flat, 1);
    let good = demo_table(Follower::Flat, 36, TableForm::G1);
    let TableShape::G1(points) = good.shape.clone() else {
        unreachable!("G1 table")
    };
    let with_points = |points: Vec<TablePoint>| CommandedTable {
        shape: TableShape::G1(points),
        ..good.clone()
    };
    let mut unsorted = points.clone();
    unsorted.swap(3, 4);
    let mut nan = points.clone();
    nan[5].x_mm = f64::NAN;
    let cases = vec![
        (with_points(points[..2].to_vec()), "table has 2 entries"),
        (with_points(unsorted), "table entry 4 at c = 30°"),
        (with_points(nan), "table entry 5 at c = 50°"),
    ];
    for (table, expected) in cases {
        let message = sim.grind(&table).unwrap_err().to_string();
        assert!(message.starts_with(expected), "`{message}`");
    }

    let poly = demo_table(Follower::Flat, 36, TableForm::Poly);
    let TableShape::Poly(segments) = poly.shape.clone() else {
        unreachable!("POLY table")
    };
    let with_segments = |segments: Vec<PolySegment>| CommandedTable {
        shape: TableShape::Poly(segments),
        ..poly.clone()
    };
    let mut gap = segments.clone();
    gap[7].c_end_deg -= 0.01;
    let mut jump = segments.clone();
    jump[7].x0_mm += 0.001;
    for (table, expected) in [
        (with_segments(gap), "poly segment 7 ends at c = 79.99°"),
        (with_segments(jump), "poly segment 6 ends at x ="),
    ] {
        let message = sim.grind(&table).unwrap_err().to_string();
        assert!(message.starts_with(expected), "`{message}`");
    }
}

#[test]
fn bad_workpieces_are_refused_naming_the_parameter() {
    let mut geometry = demo_geometry(Follower::Flat);
    geometry.base_radius_mm = -1.0;
    let message = SimGrinder::new(GrinderConfig::default(), Workpiece::Cam(geometry), 1)
        .unwrap_err()
        .to_string();
    assert_eq!(
        message,
        "base radius = -1 is invalid: must be a finite number > 0"
    );
    // A wheel-size error that leaves no wheel.
    let config = GrinderConfig {
        wheel_size_error_um: -300_000.0,
        ..GrinderConfig::default()
    };
    let message = SimGrinder::new(config, Workpiece::Cam(demo_geometry(Follower::Flat)), 1)
        .unwrap_err()
        .to_string();
    assert!(message.starts_with("true wheel radius = -50"), "{message}");
}
