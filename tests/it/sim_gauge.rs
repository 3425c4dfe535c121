//! The simulated gauge: what it sends is the true lift plus the configured noise, in the
//! shape a real gauge adapter produces, and injected faults land where they were put.

use crate::sim_support;

use camloop::core::fit::TableForm;
use camloop::core::geometry::Follower;
use camloop::core::measure::RawMeasurement;
use camloop::sim::{GaugeConfig, GaugeFault, GrinderConfig, GroundPart, PartLabels, SimGrinder};
use sim_support::*;

fn labels() -> PartLabels {
    PartLabels {
        machine: "grinder-1".to_string(),
        part: "P0001".to_string(),
        lobe: "intake-1".to_string(),
    }
}

fn ground_and_sim(config: GrinderConfig, seed: u64) -> (SimGrinder, GroundPart) {
    let sim = demo_sim(config, Follower::Flat, seed);
    let ground = sim
        .grind(&demo_table(Follower::Flat, 360, TableForm::Poly))
        .unwrap();
    (sim, ground)
}

/// Readings as [revolution][angle index], checking every (revolution, index) pair
/// arrives exactly once.
fn by_revolution(raw: &RawMeasurement) -> Vec<Vec<f64>> {
    let (revs, points) = (
        raw.header.revolutions as usize,
        raw.header.points_per_rev as usize,
    );
    let mut out = vec![vec![f64::NAN; points]; revs];
    for s in &raw.samples {
        let slot = &mut out[s.revolution as usize][s.angle_index as usize];
        assert!(slot.is_nan(), "duplicate sample {s:?}");
        *slot = s.lift_mm;
    }
    assert!(
        out.iter().flatten().all(|v| v.is_finite()),
        "missing samples"
    );
    out
}

#[test]
fn header_and_sample_layout_follow_the_settings() {
    let config = GrinderConfig {
        gauge: GaugeConfig {
            revolutions: 3,
            points_per_rev: 720,
            ..GaugeConfig::default()
        },
        ..GrinderConfig::default()
    };
    let (mut sim, ground) = ground_and_sim(config, 3);
    let raw = sim.measure(&ground, &labels());
    assert_eq!(raw.header.machine, "grinder-1");
    assert_eq!(raw.header.part, "P0001");
    assert_eq!(raw.header.lobe, "intake-1");
    assert_eq!(raw.header.revolutions, 3);
    assert_eq!(raw.header.points_per_rev, 720);
    assert_eq!(raw.origin, "sim");
    assert_eq!(raw.samples.len(), 3 * 720);
    // Arrival order: revolution by revolution, angle ascending.
    let order: Vec<(u32, u32)> = raw
        .samples
        .iter()
        .map(|s| (s.revolution, s.angle_index))
        .collect();
    let mut sorted = order.clone();
    sorted.sort_unstable();
    assert_eq!(order, sorted);
    by_revolution(&raw);
}

/// Default gauge (4 revolutions, σ = 0.3 µm) on the default machine. Per point the mean of
/// 4 readings is within 4σ/√4 = 0.6 µm of the true lift: each such deviation has
/// probability 6e-5, all 360 pass with probability 98 %, and the seed is fixed. The noise
/// is really there and really σ: the standard deviation of (mean − truth) over 360 points
/// estimates σ/√4 = 0.15 µm with a relative standard error of 1/√720 ≈ 3.7 %, so ±15 % is
/// four standard errors; the same for single readings (1440 values, ±10 %).
#[test]
fn mean_of_revolutions_is_the_true_lift_within_the_noise() {
    let (mut sim, ground) = ground_and_sim(GrinderConfig::default(), 11);
    let raw = sim.measure(&ground, &labels());
    let readings = by_revolution(&raw);
    let truth = ground.lift_on_grid(360);
    let revs = readings.len() as f64;
    let sigma_mm = 0.3e-3;
    let mut mean_deviations = Vec::new();
    let mut single_deviations = Vec::new();
    for (j, &t) in truth.iter().enumerate() {
        let mean = readings.iter().map(|r| r[j]).sum::<f64>() / revs;
        assert!(
            (mean - t).abs() < 4.0 * sigma_mm / revs.sqrt(),
            "at {j}°: mean {mean} mm, true {t} mm"
        );
        mean_deviations.push(mean - t);
        single_deviations.extend(readings.iter().map(|r| r[j] - t));
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let mean_rms = rms(&mean_deviations) / (sigma_mm / revs.sqrt());
    let single_rms = rms(&single_deviations) / sigma_mm;
    assert!(
        (0.85..1.15).contains(&mean_rms),
        "mean rms {mean_rms} σ/√revs"
    );
    assert!(
        (0.9..1.1).contains(&single_rms),
        "single rms {single_rms} σ"
    );
}

/// A spike lands on one reading, an offset on one whole revolution, nothing else moves.
#[test]
fn injected_faults_land_where_they_were_put() {
    let faults = vec![
        GaugeFault::Spike {
            revolution: 2,
            angle_index: 123,
            size_um: 40.0,
        },
        GaugeFault::Offset {
            revolution: 1,
            offset_um: -8.0,
        },
    ];
    let noiseless = GaugeConfig {
        noise_sigma_um: 0.0,
        ..GaugeConfig::default()
    };
    let config = GrinderConfig {
        gauge: GaugeConfig {
            faults,
            ..noiseless.clone()
        },
        ..GrinderConfig::default()
    };
    let (mut sim, ground) = ground_and_sim(config, 5);
    let readings = by_revolution(&sim.measure(&ground, &labels()));
    let truth = ground.lift_on_grid(360);
    for (rev, reading) in readings.iter().enumerate() {
        for (j, (&r, &t)) in reading.iter().zip(&truth).enumerate() {
            let expected_um = match (rev, j) {
                (2, 123) => 40.0,
                (1, _) => -8.0,
                _ => 0.0,
            };
            assert!(
                ((r - t) * 1000.0 - expected_um).abs() < 1e-9,
                "revolution {rev}, index {j}: {} µm off, expected {expected_um}",
                (r - t) * 1000.0
            );
        }
    }
}

/// The seed fixes the noise: the same seed gives the same readings, another seed others.
#[test]
fn seed_fixes_the_noise() {
    let read = |seed| {
        let (mut sim, ground) = ground_and_sim(GrinderConfig::default(), seed);
        sim.measure(&ground, &labels())
    };
    assert_eq!(read(1), read(1));
    assert_ne!(read(1), read(2));
}

/// A roller gauge reports lift from the base circle: zero on the base circle of a part
/// ground by a perfect machine, 8 mm at the nose (the lobe's lift), within 0.05 µm.
#[test]
fn roller_gauge_reads_from_the_base_circle() {
    let roller = Follower::Roller { radius_mm: 10.0 };
    let mut sim = demo_sim(GrinderConfig::perfect(), roller, 1);
    let ground = sim
        .grind(&demo_table(roller, 360, TableForm::Poly))
        .unwrap();
    let readings = by_revolution(&sim.measure(&ground, &labels()));
    assert!(readings[0][0].abs() < 5e-5, "{}", readings[0][0]);
    assert!(
        (readings[0][180] - 8.0).abs() < 5e-5,
        "{}",
        readings[0][180]
    );
    // A perfect machine grinds the nominal roller lift everywhere.
    let nominal = nominal_on_grid(360);
    let (worst, at) = max_abs(&error_um(&readings[3], &nominal));
    assert!(worst < 0.05, "{worst} µm at {at}°");
}

/// The simulated gauge feeds the core's real checks: a clean measurement is accepted whole,
/// a probe slip of 8 µm on one revolution is caught by the 5 µm revolution limit (good
/// revolutions deviate from the median by at most ~4σ ≈ 1.2 µm over 360 angles), and a
/// gauge set to 2 revolutions is refused.
#[test]
fn measurements_pass_through_the_core_checks() {
    use camloop::core::measure::{AssemblyLimits, MeasurementError, check_and_average};
    let limits = AssemblyLimits::default();

    let (mut sim, ground) = ground_and_sim(GrinderConfig::default(), 21);
    let averaged = check_and_average(&sim.measure(&ground, &labels()), &limits).unwrap();
    assert_eq!(averaged.revolutions_used, [0, 1, 2, 3]);
    let truth = ground.lift_on_grid(360);
    let (worst, _) = max_abs(&error_um(&averaged.mean_lift_mm, &truth));
    assert!(worst < 0.6, "mean off by {worst} µm (4σ/√4 = 0.6)");

    let slipped = GrinderConfig {
        gauge: GaugeConfig {
            faults: vec![GaugeFault::Offset {
                revolution: 1,
                offset_um: 8.0,
            }],
            ..GaugeConfig::default()
        },
        ..GrinderConfig::default()
    };
    let (mut sim, ground) = ground_and_sim(slipped, 21);
    let averaged = check_and_average(&sim.measure(&ground, &labels()), &limits).unwrap();
    assert_eq!(averaged.revolutions_used, [0, 2, 3]);
    assert_eq!(averaged.dropped_revolutions.len(), 1);
    assert_eq!(averaged.dropped_revolutions[0].revolution, 1);

    let short = GrinderConfig {
        gauge: GaugeConfig {
            revolutions: 2,
            ..GaugeConfig::default()
        },
        ..GrinderConfig::default()
    };
    let (mut sim, ground) = ground_and_sim(short, 21);
    let refused = check_and_average(&sim.measure(&ground, &labels()), &limits).unwrap_err();
    assert!(matches!(
        refused,
        MeasurementError::TooFewRevolutions { announced: 2, .. }
    ));
}
