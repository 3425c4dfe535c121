//! Hand-computed and published values; the cross-check against an independent
//! implementation (scipy) is `tests/capability_reference.rs`.

use super::*;

/// Ten values whose moments are easy by hand: 1..=10.
/// x̄ = 5.5, s = √(82.5/9) = 3.02765, moving ranges all 1 → σw = 1/d₂ = 0.886227.
#[test]
fn normal_indices_by_hand() {
    let values: Vec<f64> = (1..=10).map(f64::from).collect();
    let limits = Limits {
        lower: Some(-4.0),
        upper: Some(16.0),
    };
    let c = assess(&values, limits, false).unwrap();
    assert!((c.sigma_overall - 3.027_650_4).abs() < 1e-6);
    assert!((c.sigma_within - 0.886_226_9).abs() < 1e-6);
    let ix = c.indices.unwrap();
    // Cp = 20/(6·0.886227) = 3.76126; Cpk = min(10.5, 9.5)/(3·0.886227) = 3.57320.
    assert!((ix.cp.unwrap().value - 3.761_263).abs() < 1e-5);
    assert!((ix.cpk.value - 3.573_200).abs() < 1e-5);
    // Pp = 20/(6·3.02765) = 1.10097; Ppk = 9.5/(3·3.02765) = 1.04592.
    assert!((ix.pp.unwrap().value - 1.100_967).abs() < 1e-5);
    assert!((ix.ppk.value - 1.045_919).abs() < 1e-5);
    assert_eq!(ix.observed_share_out, 0.0);
    assert_eq!(ix.sides, Sides::Both);
}

/// The chi-square bound with the published table value χ²₀.₀₅;₁₉ = 10.117 (e.g. Montgomery,
/// Introduction to Statistical Quality Control, appendix table III): Cp = 1.33 from 20 parts
/// is at least 1.33·√(10.117/19) = 0.9705 with 95 % confidence.
#[test]
fn chi_square_bound_matches_the_table() {
    let ix = chi_square_bound(1.33, 20);
    assert!((ix.lower_95 - 0.9705).abs() < 5e-4, "{}", ix.lower_95);
}

/// Bissell by hand: Ĉpk = 1.5, n = 50: 1.5 − 1.644854·√(1/450 + 2.25/98) = 1.5 − 1.644854·0.15870
/// = 1.2390.
#[test]
fn bissell_bound_by_hand() {
    let ix = bissell_bound(1.5, 50);
    assert!((ix.lower_95 - 1.239_0).abs() < 1e-4, "{}", ix.lower_95);
}

#[test]
fn no_limit_gives_no_index_and_says_so() {
    let c = assess(&[1.0, 2.0, 4.0, 3.0], Limits::default(), false).unwrap();
    assert_eq!(c.indices, None);
    assert_eq!(c.no_index, Some(NoIndex::NoTolerance));
    let flat = assess(
        &[2.0; 5],
        Limits {
            lower: None,
            upper: Some(3.0),
        },
        true,
    )
    .unwrap();
    assert_eq!(flat.no_index, Some(NoIndex::NoSpread));
}

#[test]
fn bad_windows_are_refused_with_the_part_named() {
    assert_eq!(
        assess(&[1.0, 2.0], Limits::default(), false),
        Err(CapabilityError::TooFewParts { n: 2 })
    );
    assert!(matches!(
        assess(&[1.0, f64::NAN, 2.0], Limits::default(), false),
        Err(CapabilityError::NotFinite { index: 1, .. })
    ));
    assert!(matches!(
        assess(&[1.0, -0.5, 2.0], Limits::default(), true),
        Err(CapabilityError::Negative { index: 1, .. })
    ));
}

/// A one-sided characteristic gets the fitted model, the likeliest candidate first, and the
/// percentile index Ppu = (U − X₅₀)/(X₉₉.₈₆₅ − X₅₀) on it.
#[test]
fn one_sided_uses_the_likeliest_fit_and_the_percentile_method() {
    // Log-normal quantiles exp(z_p·0.3) at 30 evenly spread p: the log-normal must win.
    let normal = fit::std_normal();
    let values: Vec<f64> = (0..30)
        .map(|i| (0.3 * normal.inverse_cdf((i as f64 + 0.5) / 30.0)).exp())
        .collect();
    let limits = Limits {
        lower: None,
        upper: Some(3.0),
    };
    let c = assess(&values, limits, true).unwrap();
    let Model::Fitted { candidates } = &c.model else {
        panic!("a fitted model");
    };
    assert!(matches!(candidates[0].fitted, Fitted::LogNormal { .. }));
    assert!(
        candidates
            .windows(2)
            .all(|w| w[0].log_likelihood >= w[1].log_likelihood)
    );
    let f = candidates[0].fitted;
    let ix = c.indices.unwrap();
    let ppu = (3.0 - f.quantile(0.5)) / (f.quantile(0.998_65) - f.quantile(0.5));
    assert!((ix.ppk.value - ppu).abs() < 1e-12);
    assert_eq!((ix.sides, ix.cp, ix.pp), (Sides::Upper, None, None));
    assert!((ix.expected_share_out - (1.0 - f.cdf(3.0))).abs() < 1e-15);
}
