//! The type-1 gauge study (VDA 5 / Bosch booklet 10, AIAG MSA "bias and repeatability"):
//! repeated measurements of a master part whose reference value is known.
//!
//! Convention: 20 % of the tolerance over a 6σ spread,
//! Cg = 0.2·T / 6s and Cgk = (0.1·T − |x̄ − x_ref|) / 3s, s the sample standard deviation
//! (n − 1). The gauge is capable when both reach 1.33. The bias is x̄ − x_ref, tested against
//! zero with Student's t at 5 % (two-sided). VDA 5 asks for 50 runs (25 at the least); fewer
//! than [`MIN_RUNS`] give no study.

use statrs::distribution::{ContinuousCDF, StudentsT};

/// Fewest master runs that give a study.
pub(crate) const MIN_RUNS: usize = 10;
/// Runs VDA 5 asks for.
pub(crate) const RECOMMENDED_RUNS: usize = 50;
/// Cg and Cgk a capable gauge reaches.
pub(crate) const CAPABLE: f64 = 1.33;

/// A type-1 study of one characteristic.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GaugeStudy {
    pub n: usize,
    pub reference: f64,
    /// Tolerance width T = upper − lower limit.
    pub tolerance: f64,
    pub mean: f64,
    pub sigma: f64,
    /// x̄ − reference.
    pub bias: f64,
    /// |bias| / (s/√n).
    pub bias_t: f64,
    /// The bias differs from zero at the 5 % level.
    pub bias_significant: bool,
    pub cg: f64,
    pub cgk: f64,
    /// Cg ≥ 1.33 and Cgk ≥ 1.33.
    pub capable: bool,
}

/// Why no study.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GaugeStudyError {
    #[error(
        "{n} master runs: a type-1 study needs at least {MIN_RUNS} (VDA 5 asks for {RECOMMENDED_RUNS})"
    )]
    TooFewRuns { n: usize },
    #[error("tolerance width {tolerance} is not a positive number")]
    NoTolerance { tolerance: f64 },
    #[error("master run {index} (from 0): value {value} is not a finite number")]
    NotFinite { index: usize, value: f64 },
    #[error(
        "every master run measured the same value: the gauge's resolution is too coarse for a study"
    )]
    NoSpread,
}

/// The study of `values` (the master's measured values) against `reference` and the
/// tolerance width `tolerance`.
pub fn type1(
    values: &[f64],
    reference: f64,
    tolerance: f64,
) -> Result<GaugeStudy, GaugeStudyError> {
    let n = values.len();
    if n < MIN_RUNS {
        return Err(GaugeStudyError::TooFewRuns { n });
    }
    if !(tolerance > 0.0 && tolerance.is_finite()) {
        return Err(GaugeStudyError::NoTolerance { tolerance });
    }
    if let Some((index, &value)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(GaugeStudyError::NotFinite { index, value });
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let sigma = (values.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    if sigma <= 0.0 {
        return Err(GaugeStudyError::NoSpread);
    }
    let bias = mean - reference;
    let bias_t = bias.abs() / (sigma / (n as f64).sqrt());
    let t_crit = StudentsT::new(0.0, 1.0, (n - 1) as f64)
        .map(|t| t.inverse_cdf(0.975))
        .unwrap_or(f64::INFINITY);
    let cg = 0.2 * tolerance / (6.0 * sigma);
    let cgk = (0.1 * tolerance - bias.abs()) / (3.0 * sigma);
    Ok(GaugeStudy {
        n,
        reference,
        tolerance,
        mean,
        sigma,
        bias,
        bias_t,
        bias_significant: bias_t > t_crit,
        cg,
        cgk,
        capable: cg >= CAPABLE && cgk >= CAPABLE,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-computed: values 10.001, 9.999 alternating (n = 10) against 10.000 with T = 0.03:
    /// x̄ = 10.000, s = 0.001·√(10/9) = 0.0010541, Cg = 0.006/0.0063246 = 0.9487,
    /// Cgk = 0.003/0.0031623 = 0.9487; not capable, no bias.
    #[test]
    fn a_hand_computed_study() {
        let values: Vec<f64> = (0..10)
            .map(|i| if i % 2 == 0 { 10.001 } else { 9.999 })
            .collect();
        let s = type1(&values, 10.0, 0.03).unwrap();
        assert!((s.sigma - 0.001_054_1).abs() < 1e-7, "{}", s.sigma);
        assert!((s.cg - 0.9487).abs() < 1e-4, "{}", s.cg);
        assert!((s.cgk - 0.9487).abs() < 1e-4, "{}", s.cgk);
        assert!(!s.capable && !s.bias_significant);
        // Shifted by 2 s: the bias shows in Cgk only, and is significant (t = 2·√10 = 6.3).
        let shifted: Vec<f64> = values.iter().map(|v| v + 0.002_108_2).collect();
        let s = type1(&shifted, 10.0, 0.03).unwrap();
        assert!((s.cg - 0.9487).abs() < 1e-4);
        assert!((s.cgk - (0.003 - 0.002_108_2) / 0.003_162_3).abs() < 1e-3);
        assert!(s.bias_significant);
        assert!(matches!(
            type1(&values[..5], 10.0, 0.03),
            Err(GaugeStudyError::TooFewRuns { n: 5 })
        ));
    }
}
