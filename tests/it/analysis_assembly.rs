//! Assembling and averaging raw measurements: every rejection reason names the reading,
//! and the average, spread and revolution dropping match hand-computed values.

use camloop::core::measure::{
    AssemblyLimits, MeasurementError, MeasurementHeader, RawMeasurement, RawSample, assemble,
    check_and_average,
};
use proptest::prelude::*;

const N: u32 = 8;

/// A complete measurement of `revs` revolutions of N points; lift = f(rev, index) mm.
fn complete(revs: u32, f: impl Fn(u32, u32) -> f64) -> RawMeasurement {
    let samples = (0..revs)
        .flat_map(|r| (0..N).map(move |k| (r, k)))
        .map(|(r, k)| RawSample {
            revolution: r,
            angle_index: k,
            lift_mm: f(r, k),
        })
        .collect();
    RawMeasurement {
        header: MeasurementHeader {
            machine: "m1".into(),
            part: "p1".into(),
            lobe: "ex2".into(),
            revolutions: revs,
            points_per_rev: N,
        },
        samples,
        origin: "gauge-a".into(),
    }
}

fn smooth(r: u32, k: u32) -> f64 {
    1.0 + 0.1 * f64::from(k) + 1e-4 * f64::from(r)
}

fn position(raw: &RawMeasurement, rev: u32, k: u32) -> usize {
    raw.samples
        .iter()
        .position(|s| s.revolution == rev && s.angle_index == k)
        .expect("sample present")
}

struct Reject {
    name: &'static str,
    raw: RawMeasurement,
    /// Fragments the message must contain (origin, revolution, angle index, angle).
    says: &'static [&'static str],
    check: fn(&MeasurementError) -> bool,
}

fn rejects() -> Vec<Reject> {
    let mut cases = Vec::new();

    let mut raw = complete(3, smooth);
    let i = position(&raw, 1, 5);
    raw.samples[i].angle_index = 4; // (1, 4) twice, (1, 5) missing: duplicate reported first
    cases.push(Reject {
        name: "duplicate replacing a reading",
        raw,
        says: &["gauge-a", "revolution 1 angle index 4 (180°)", "more than once"],
        check: |e| {
            matches!(e, MeasurementError::DuplicateReading { revolution: 1, angle_index: 4, angle_deg, .. } if *angle_deg == 180.0)
        },
    });

    let mut raw = complete(3, smooth);
    let extra = raw.samples[position(&raw, 2, 7)];
    raw.samples.insert(3, extra); // arrives early, the original later is the repeat
    cases.push(Reject {
        name: "extra duplicate",
        raw,
        says: &["revolution 2 angle index 7 (315°)", "more than once"],
        check: |e| {
            matches!(
                e,
                MeasurementError::DuplicateReading {
                    revolution: 2,
                    angle_index: 7,
                    ..
                }
            )
        },
    });

    let mut raw = complete(3, smooth);
    let dup = raw.samples[position(&raw, 0, 2)];
    raw.samples
        .retain(|s| !(s.revolution == 2 && s.angle_index < 3));
    raw.samples.push(dup); // fewer samples than announced and a duplicate: sorted path
    cases.push(Reject {
        name: "duplicate in a short measurement",
        raw,
        says: &["revolution 0 angle index 2 (90°)", "more than once"],
        check: |e| {
            matches!(
                e,
                MeasurementError::DuplicateReading {
                    revolution: 0,
                    angle_index: 2,
                    ..
                }
            )
        },
    });

    let mut raw = complete(3, smooth);
    raw.samples.remove(position(&raw, 2, 3));
    cases.push(Reject {
        name: "gap",
        raw,
        says: &["revolution 2 angle index 3 (135°)", "missing (1 readings"],
        check: |e| {
            matches!(
                e,
                MeasurementError::MissingReading {
                    revolution: 2,
                    angle_index: 3,
                    missing_total: 1,
                    ..
                }
            )
        },
    });

    let mut raw = complete(4, smooth);
    raw.samples.retain(|s| s.revolution != 3);
    cases.push(Reject {
        name: "stream stopped before the announced last revolution",
        raw,
        says: &["revolution 3 angle index 0 (0°)", "8 readings missing"],
        check: |e| {
            matches!(
                e,
                MeasurementError::MissingReading {
                    revolution: 3,
                    angle_index: 0,
                    missing_total: 8,
                    ..
                }
            )
        },
    });

    let mut raw = complete(3, smooth);
    let i = position(&raw, 1, 6);
    raw.samples[i].angle_index = N;
    cases.push(Reject {
        name: "angle index out of range",
        raw,
        says: &["revolution 1 angle index 8", "outside 0..8"],
        check: |e| {
            matches!(
                e,
                MeasurementError::AngleIndexOutOfRange {
                    revolution: 1,
                    angle_index: 8,
                    points_per_rev: 8,
                    ..
                }
            )
        },
    });

    let mut raw = complete(3, smooth);
    let i = position(&raw, 2, 1);
    raw.samples[i].revolution = 3;
    cases.push(Reject {
        name: "revolution out of range",
        raw,
        says: &["revolution 3 angle index 1", "outside the 3 announced"],
        check: |e| {
            matches!(
                e,
                MeasurementError::RevolutionOutOfRange {
                    revolution: 3,
                    angle_index: 1,
                    announced: 3,
                    ..
                }
            )
        },
    });

    cases.push(Reject {
        name: "too few revolutions",
        raw: complete(2, smooth),
        says: &["gauge-a", "2 revolutions announced, at least 3 needed"],
        check: |e| {
            matches!(
                e,
                MeasurementError::TooFewRevolutions {
                    announced: 2,
                    minimum: 3,
                    ..
                }
            )
        },
    });

    let mut raw = complete(3, smooth);
    let i = position(&raw, 1, 2);
    raw.samples[i].lift_mm = f64::NAN;
    cases.push(Reject {
        name: "NaN lift",
        raw,
        says: &["revolution 1 angle index 2 (90°)", "lift NaN mm is not finite"],
        check: |e| {
            matches!(e, MeasurementError::NonFiniteLift { revolution: 1, angle_index: 2, lift_mm, .. } if lift_mm.is_nan())
        },
    });

    let mut raw = complete(3, smooth);
    let i = position(&raw, 0, 7);
    raw.samples[i].lift_mm = f64::INFINITY;
    cases.push(Reject {
        name: "infinite lift",
        raw,
        says: &["revolution 0 angle index 7 (315°)", "not finite"],
        check: |e| {
            matches!(
                e,
                MeasurementError::NonFiniteLift {
                    revolution: 0,
                    angle_index: 7,
                    ..
                }
            )
        },
    });

    let mut raw = complete(3, smooth);
    raw.header.points_per_rev = 0;
    cases.push(Reject {
        name: "zero points per revolution",
        raw,
        says: &["gauge-a", "0 points per revolution"],
        check: |e| matches!(e, MeasurementError::NoPointsPerRevolution { .. }),
    });

    let mut raw = complete(3, smooth);
    raw.header.points_per_rev = u32::MAX;
    raw.header.revolutions = u32::MAX;
    cases.push(Reject {
        name: "absurd header, no huge allocation",
        raw,
        says: &["revolution 0 angle index 8"],
        check: |e| {
            matches!(e, MeasurementError::MissingReading { revolution: 0, angle_index: 8, missing_total, .. }
                if *missing_total == u64::from(u32::MAX) * u64::from(u32::MAX) - 24)
        },
    });

    cases
}

#[test]
fn every_rejection_names_the_reading_and_leaves_the_raw_measurement_intact() {
    for case in rejects() {
        let before = case.raw.clone();
        let err = check_and_average(&case.raw, &AssemblyLimits::default()).expect_err(case.name);
        assert!((case.check)(&err), "{}: unexpected {err:?}", case.name);
        let message = err.to_string();
        for fragment in case.says {
            assert!(
                message.contains(fragment),
                "{}: {message:?} lacks {fragment:?}",
                case.name
            );
        }
        assert!(!message.ends_with('.'), "{}: {message}", case.name);
        // The caller still holds the raw data to keep among the rejects (compared through
        // Debug because NaN != NaN).
        assert_eq!(
            format!("{:?}", case.raw),
            format!("{before:?}"),
            "{}",
            case.name
        );
    }
}

#[test]
fn invalid_limits_are_refused() {
    let raw = complete(3, smooth);
    for (limits, field) in [
        (
            AssemblyLimits {
                min_revolutions: 1,
                ..AssemblyLimits::default()
            },
            "min_revolutions",
        ),
        (
            AssemblyLimits {
                revolution_limit_um: f64::NAN,
                ..AssemblyLimits::default()
            },
            "revolution_limit_um",
        ),
        (
            AssemblyLimits {
                revolution_limit_um: 0.0,
                ..AssemblyLimits::default()
            },
            "revolution_limit_um",
        ),
    ] {
        let err = check_and_average(&raw, &limits).expect_err(field);
        assert!(
            matches!(err, MeasurementError::InvalidLimits { field: f, .. } if f == field),
            "{err:?}"
        );
    }
}

#[test]
fn mean_standard_deviation_and_range_match_hand_values() {
    // Revolutions 0, 1, 2 read base + 0, 1, 3 µm at every angle: mean +4/3 µm,
    // sample σ = sqrt(((−4/3)² + (−1/3)² + (5/3)²) / 2) = sqrt(7/3) µm, range 3 µm.
    let offsets_um = [0.0, 1.0, 3.0];
    let raw = complete(3, |r, k| {
        2.0 + 0.01 * f64::from(k) + offsets_um[r as usize] / 1000.0
    });
    let avg = check_and_average(&raw, &AssemblyLimits::default()).expect("valid");
    assert_eq!(avg.revolutions_used, vec![0, 1, 2]);
    assert!(avg.dropped_revolutions.is_empty());
    assert_eq!(avg.points_per_rev, N);
    for k in 0..N as usize {
        let mean = 2.0 + 0.01 * k as f64 + 4.0 / 3.0 / 1000.0;
        assert!((avg.mean_lift_mm[k] - mean).abs() < 1e-12, "mean at {k}");
        let sd = (7.0_f64 / 3.0).sqrt();
        // 1e-9 µm: the lifts are ~2 mm, so differences of µm carry ~1e-13 mm rounding.
        assert!((avg.repeatability_std_um[k] - sd).abs() < 1e-9, "σ at {k}");
        assert!(
            (avg.repeatability_range_um[k] - 3.0).abs() < 1e-9,
            "range at {k}"
        );
    }
}

#[test]
fn a_disagreeing_revolution_is_dropped_with_its_reason() {
    // Revolution 1 reads 6 µm high at 225° only; the limit is 5 µm.
    let raw = complete(4, |r, k| {
        smooth(0, k) + if r == 1 && k == 5 { 0.006 } else { 0.0 }
    });
    let avg = check_and_average(&raw, &AssemblyLimits::default()).expect("3 remain");
    assert_eq!(avg.revolutions_used, vec![0, 2, 3]);
    assert_eq!(avg.dropped_revolutions.len(), 1);
    let d = &avg.dropped_revolutions[0];
    assert_eq!(d.revolution, 1);
    assert!((d.max_deviation_um - 6.0).abs() < 1e-9, "{d:?}");
    assert_eq!(d.at_angle_deg, 225.0);
    assert!(
        d.reason.contains("225°") && d.reason.contains("limit 5 µm"),
        "{}",
        d.reason
    );
    // The mean is of the three good revolutions only.
    assert!((avg.mean_lift_mm[5] - smooth(0, 5)).abs() < 1e-12);

    // 4.9 µm stays: just inside the limit.
    let raw = complete(4, |r, k| {
        smooth(0, k) + if r == 1 && k == 5 { 0.0049 } else { 0.0 }
    });
    let avg = check_and_average(&raw, &AssemblyLimits::default()).expect("all agree");
    assert_eq!(avg.revolutions_used, vec![0, 1, 2, 3]);
}

#[test]
fn too_few_agreeing_revolutions_reject_and_list_the_dropped() {
    // Three revolutions, one offset by 20 µm: two remain, three are needed.
    let raw = complete(3, |r, k| smooth(0, k) + if r == 2 { 0.02 } else { 0.0 });
    let err = check_and_average(&raw, &AssemblyLimits::default()).expect_err("2 < 3");
    match &err {
        MeasurementError::TooFewAgreeingRevolutions {
            remaining: 2,
            minimum: 3,
            dropped,
            ..
        } => {
            assert_eq!(dropped.len(), 1);
            assert_eq!(dropped[0].revolution, 2);
            assert!((dropped[0].max_deviation_um - 20.0).abs() < 1e-9);
        }
        other => panic!("unexpected {other:?}"),
    }
    assert!(
        err.to_string()
            .contains("only 2 revolutions agree within 5 µm"),
        "{err}"
    );

    // Two revolutions with min 2: the median is their mean, so both go when they disagree.
    let raw = complete(2, |r, k| smooth(0, k) + if r == 1 { 0.012 } else { 0.0 });
    let limits = AssemblyLimits {
        min_revolutions: 2,
        ..AssemblyLimits::default()
    };
    let err = check_and_average(&raw, &limits).expect_err("both 6 µm off their mean");
    assert!(
        matches!(&err, MeasurementError::TooFewAgreeingRevolutions { remaining: 0, dropped, .. } if dropped.len() == 2),
        "{err:?}"
    );
}

#[test]
fn the_grid_keeps_each_revolution() {
    let raw = complete(3, smooth);
    let grid = assemble(&raw, &AssemblyLimits::default()).expect("complete");
    assert_eq!((grid.revolutions(), grid.points_per_rev()), (3, N));
    assert_eq!(grid.origin(), "gauge-a");
    let rev2 = grid.revolution_lift_mm(2).expect("exists");
    assert_eq!(
        rev2,
        (0..N).map(|k| smooth(2, k)).collect::<Vec<_>>().as_slice()
    );
    assert!(grid.revolution_lift_mm(3).is_none());
}

proptest! {
    /// Arrival order carries no meaning: any permutation gives the same average.
    #[test]
    fn arrival_order_does_not_matter(seed in any::<u64>()) {
        let raw = complete(4, |r, k| smooth(r, k) + 1e-3 * f64::from((r * 7 + k * 3) % 5));
        let reference = check_and_average(&raw, &AssemblyLimits::default()).expect("valid");
        let mut shuffled = raw.clone();
        // Fisher–Yates driven by a splitmix-style sequence from the seed.
        let mut state = seed;
        for i in (1..shuffled.samples.len()).rev() {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let j = (state >> 33) as usize % (i + 1);
            shuffled.samples.swap(i, j);
        }
        let got = check_and_average(&shuffled, &AssemblyLimits::default()).expect("valid");
        prop_assert_eq!(got, reference);
    }
}
