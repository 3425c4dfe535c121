//! Process capability of one characteristic over a window of parts: n, mean, σ within and
//! σ overall, Cp/Cpk and Pp/Ppk with their lower 95 % confidence bounds, and the share out
//! of tolerance, expected and observed. Pure: values in part order go in, a typed
//! [`Capability`] comes out.
//!
//! Methods (ISO 22514-2 / AIAG SPC):
//! - σ within: the mean moving range of consecutive parts over d₂ = 2/√π (span 2), so the
//!   window must be in part order; σ overall: the sample standard deviation (n − 1).
//! - Two-sided characteristics (size, timing, stroke, diameter, index angle): ISO 22514-2
//!   distribution model A1 (normal, location and dispersion constant). Cp = (U − L)/6σw,
//!   Cpk = min(U − x̄, x̄ − L)/3σw; Pp and Ppk the same with σ overall. Expected share out
//!   from the normal with x̄ and σ overall.
//! - Characteristics bounded at zero with an upper limit only (max |error|, profile error,
//!   roundness): model A2 (stable, not normal). A folded normal, a log-normal and a Weibull
//!   (location 0) are fitted by maximum likelihood and the largest likelihood wins; the
//!   indices follow the percentile method: Ppu = (U − X₅₀)/(X₉₉.₈₆₅ − X₅₀), and
//!   Cpu the same with the percentile spread scaled by σw/σ overall. Expected share out:
//!   1 − F(U).
//! - Lower 95 % bounds: Cp and Pp by the chi-square bound Ĉ·√(χ²₀.₀₅;ₙ₋₁/(n − 1));
//!   Cpk, Ppk, Cpu and Ppu by Bissell's approximation Ĉ − z₀.₉₅·√(1/9n + Ĉ²/2(n − 1))
//!   (for the percentile indices an approximation: Bissell assumes normality).

mod characteristic;
pub mod chart;
pub mod fit;
pub mod gauge_study;

pub use characteristic::{Characteristic, PartValues};
pub use fit::{Candidate, Fitted};

use statrs::distribution::{ChiSquared, ContinuousCDF};

/// d₂ of moving ranges of span 2: E[|X₁ − X₂|] = (2/√π)·σ for a normal.
pub(crate) const D2_SPAN_2: f64 = std::f64::consts::FRAC_2_SQRT_PI;
/// The tail of the percentile method: X₉₉.₈₆₅ is the normal's +3σ.
const UPPER_PERCENTILE: f64 = 0.998_65;
/// Fewest parts that give a statistic.
pub(crate) const MIN_PARTS: usize = 3;

/// Specification limits, in the characteristic's unit.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Limits {
    pub lower: Option<f64>,
    pub upper: Option<f64>,
}

/// An index and its lower 95 % confidence bound.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Index {
    pub value: f64,
    pub lower_95: f64,
}

/// Which limits the indices use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Sides {
    Both,
    /// Only an upper limit: `cpk` is Cpu and `ppk` is Ppu.
    Upper,
    /// Only a lower limit: `cpk` is Cpl and `ppk` is Ppl.
    Lower,
}

/// The indices of a characteristic that has limits.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Indices {
    pub sides: Sides,
    /// Cp and Pp need both limits.
    pub cp: Option<Index>,
    pub cpk: Index,
    pub pp: Option<Index>,
    pub ppk: Index,
    /// Share of parts expected out of tolerance, from the model (0..1).
    pub expected_share_out: f64,
    /// Share of the window's parts out of tolerance (0..1).
    pub observed_share_out: f64,
}

/// The distribution model the indices rest on.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum Model {
    /// ISO 22514-2 model A1.
    Normal,
    /// ISO 22514-2 model A2: the best of `candidates` (largest log-likelihood, first).
    Fitted { candidates: Vec<Candidate> },
}

impl Model {
    /// The chosen fitted distribution, for a non-normal model.
    pub(crate) fn fitted(&self) -> Option<Fitted> {
        match self {
            Model::Normal => None,
            Model::Fitted { candidates } => candidates.first().map(|c| c.fitted),
        }
    }

    /// "normal" or the fitted distribution's name.
    pub fn name(&self) -> &'static str {
        self.fitted().map_or("normal", |f| f.name())
    }
}

/// Why a characteristic with statistics has no index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, thiserror::Error)]
#[serde(rename_all = "snake_case")]
pub enum NoIndex {
    #[error("no tolerance for this characteristic in the recipe: no index")]
    NoTolerance,
    #[error("every part measured the same: the spread is zero, no index")]
    NoSpread,
}

/// Capability of one characteristic over a window.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Capability {
    pub n: usize,
    pub mean: f64,
    pub min: f64,
    pub max: f64,
    /// Mean moving range / d₂.
    pub sigma_within: f64,
    /// Sample standard deviation (n − 1).
    pub sigma_overall: f64,
    pub limits: Limits,
    pub model: Model,
    pub indices: Option<Indices>,
    /// Set when `indices` is `None`.
    pub no_index: Option<NoIndex>,
}

impl Capability {
    /// P(X ≤ x) under the model the indices rest on: the normal with x̄ and σ overall, or
    /// the fitted distribution (what the dashboard draws over the histogram).
    pub fn model_cdf(&self, x: f64) -> f64 {
        match self.model.fitted() {
            Some(f) => f.cdf(x),
            None if self.sigma_overall > 0.0 => {
                fit::std_normal().cdf((x - self.mean) / self.sigma_overall)
            }
            None => f64::from(u8::from(x >= self.mean)),
        }
    }
}

/// Why no statistics could be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CapabilityError {
    #[error("{n} parts in the window: capability needs at least {MIN_PARTS}")]
    TooFewParts { n: usize },
    #[error("part {index} of the window (from 0): value {value} is not a finite number")]
    NotFinite { index: usize, value: f64 },
    #[error(
        "part {index} of the window (from 0): value {value} is negative, but the characteristic is bounded at zero"
    )]
    Negative { index: usize, value: f64 },
}

/// Capability of `values` (part order, oldest first) against `limits`. `bounded_at_zero`
/// characteristics get the fitted one-sided model; the others the normal.
pub fn assess(
    values: &[f64],
    limits: Limits,
    bounded_at_zero: bool,
) -> Result<Capability, CapabilityError> {
    check_values(values, bounded_at_zero)?;
    let n = values.len();
    let mean = values.iter().sum::<f64>() / n as f64;
    let sigma_overall =
        (values.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    let sigma_within = moving_range_sigma(values);
    let spread = sigma_overall > 0.0 && sigma_within > 0.0;
    let model = if bounded_at_zero && spread {
        Model::Fitted {
            candidates: fit::fit_candidates(values),
        }
    } else {
        Model::Normal
    };
    let stats = Stats {
        n,
        mean,
        sigma_within,
        sigma_overall,
    };
    let (indices, no_index) = if limits.lower.is_none() && limits.upper.is_none() {
        (None, Some(NoIndex::NoTolerance))
    } else if !spread {
        (None, Some(NoIndex::NoSpread))
    } else {
        let mut ix = match model.fitted() {
            Some(f) => percentile_indices(&stats, limits, f),
            None => normal_indices(&stats, limits),
        };
        ix.observed_share_out = observed_out(values, limits);
        (Some(ix), None)
    };
    Ok(Capability {
        n,
        mean,
        min: values.iter().copied().fold(f64::INFINITY, f64::min),
        max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        sigma_within,
        sigma_overall,
        limits,
        model,
        indices,
        no_index,
    })
}

fn check_values(values: &[f64], bounded_at_zero: bool) -> Result<(), CapabilityError> {
    if values.len() < MIN_PARTS {
        return Err(CapabilityError::TooFewParts { n: values.len() });
    }
    for (index, &value) in values.iter().enumerate() {
        if !value.is_finite() {
            return Err(CapabilityError::NotFinite { index, value });
        }
        if bounded_at_zero && value < 0.0 {
            return Err(CapabilityError::Negative { index, value });
        }
    }
    Ok(())
}

/// Mean moving range of consecutive values over d₂.
pub(crate) fn moving_range_sigma(values: &[f64]) -> f64 {
    if values.len() < 2 {
        return 0.0;
    }
    let sum: f64 = values.windows(2).map(|w| (w[1] - w[0]).abs()).sum();
    sum / (values.len() - 1) as f64 / D2_SPAN_2
}

struct Stats {
    n: usize,
    mean: f64,
    sigma_within: f64,
    sigma_overall: f64,
}

fn normal_indices(s: &Stats, limits: Limits) -> Indices {
    let k = |sigma: f64| {
        let upper = limits.upper.map(|u| (u - s.mean) / (3.0 * sigma));
        let lower = limits.lower.map(|l| (s.mean - l) / (3.0 * sigma));
        match (upper, lower) {
            (Some(u), Some(l)) => u.min(l),
            (Some(u), None) => u,
            (None, Some(l)) => l,
            (None, None) => f64::NAN,
        }
    };
    let p = |sigma: f64| match (limits.lower, limits.upper) {
        (Some(l), Some(u)) => Some(chi_square_bound((u - l) / (6.0 * sigma), s.n)),
        _ => None,
    };
    let z = |x: Option<f64>| x.map(|x| (x - s.mean) / s.sigma_overall);
    let normal = fit::std_normal();
    let expected = z(limits.lower).map_or(0.0, |z| normal.cdf(z))
        + z(limits.upper).map_or(0.0, |z| 1.0 - normal.cdf(z));
    Indices {
        sides: sides(limits),
        cp: p(s.sigma_within),
        cpk: bissell_bound(k(s.sigma_within), s.n),
        pp: p(s.sigma_overall),
        ppk: bissell_bound(k(s.sigma_overall), s.n),
        expected_share_out: expected,
        observed_share_out: 0.0,
    }
}

/// The percentile method on the fitted distribution: one-sided (upper) for a characteristic
/// bounded at zero; a lower limit, if any, is judged the same way on the lower tail.
fn percentile_indices(s: &Stats, limits: Limits, f: Fitted) -> Indices {
    let median = f.quantile(0.5);
    let hi = f.quantile(UPPER_PERCENTILE) - median;
    let lo = median - f.quantile(1.0 - UPPER_PERCENTILE);
    let within = s.sigma_within / s.sigma_overall;
    let k = |scale: f64| {
        let upper = limits.upper.map(|u| (u - median) / (hi * scale));
        let lower = limits.lower.map(|l| (median - l) / (lo * scale));
        upper.into_iter().chain(lower).fold(f64::INFINITY, f64::min)
    };
    let p = |scale: f64| match (limits.lower, limits.upper) {
        (Some(l), Some(u)) => Some(chi_square_bound((u - l) / ((hi + lo) * scale), s.n)),
        _ => None,
    };
    let expected =
        limits.lower.map_or(0.0, |l| f.cdf(l)) + limits.upper.map_or(0.0, |u| 1.0 - f.cdf(u));
    Indices {
        sides: sides(limits),
        cp: p(within),
        cpk: bissell_bound(k(within), s.n),
        pp: p(1.0),
        ppk: bissell_bound(k(1.0), s.n),
        expected_share_out: expected,
        observed_share_out: 0.0,
    }
}

fn sides(limits: Limits) -> Sides {
    match (limits.lower, limits.upper) {
        (Some(_), Some(_)) => Sides::Both,
        (None, _) => Sides::Upper,
        (Some(_), None) => Sides::Lower,
    }
}

fn observed_out(values: &[f64], limits: Limits) -> f64 {
    let out = values
        .iter()
        .filter(|&&x| limits.lower.is_some_and(|l| x < l) || limits.upper.is_some_and(|u| x > u))
        .count();
    out as f64 / values.len() as f64
}

/// Lower 95 % bound of Cp or Pp: Ĉ·√(χ²₀.₀₅;ν / ν), ν = n − 1.
fn chi_square_bound(value: f64, n: usize) -> Index {
    let dof = (n - 1) as f64;
    let q = ChiSquared::new(dof)
        .map(|c| c.inverse_cdf(0.05))
        .unwrap_or(f64::NAN);
    Index {
        value,
        lower_95: value * (q / dof).sqrt(),
    }
}

/// Bissell's lower 95 % bound of Cpk-like indices: Ĉ − z₀.₉₅·√(1/9n + Ĉ²/2(n − 1)).
fn bissell_bound(value: f64, n: usize) -> Index {
    let z = fit::std_normal().inverse_cdf(0.95);
    let n = n as f64;
    Index {
        value,
        lower_95: value - z * (1.0 / (9.0 * n) + value * value / (2.0 * (n - 1.0))).sqrt(),
    }
}

#[cfg(test)]
mod tests;
