//! Distributions fitted to a characteristic bounded at zero (max |error|, roundness) by
//! maximum likelihood: folded normal, log-normal and two-parameter Weibull (location 0),
//! and the rule that picks one: the largest log-likelihood. All three have two parameters,
//! so this is also the smallest AIC.

use statrs::distribution::{Continuous, ContinuousCDF, LogNormal, Normal, Weibull};

/// A fitted distribution of a characteristic that cannot be negative.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Fitted {
    /// |X| for X ~ N(mu, sigma²), mu ≥ 0.
    FoldedNormal { mu: f64, sigma: f64 },
    /// ln X ~ N(mu, sigma²).
    LogNormal { mu: f64, sigma: f64 },
    /// F(x) = 1 − exp(−(x/scale)^shape).
    Weibull { shape: f64, scale: f64 },
}

/// One candidate's fit, kept so the reply shows why the chosen one won.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Candidate {
    pub fitted: Fitted,
    pub log_likelihood: f64,
}

impl Fitted {
    /// The distribution's name as shown and in the Q-DAS export.
    pub fn name(&self) -> &'static str {
        match self {
            Fitted::FoldedNormal { .. } => "folded normal",
            Fitted::LogNormal { .. } => "log-normal",
            Fitted::Weibull { .. } => "Weibull",
        }
    }

    /// P(X ≤ x).
    pub(crate) fn cdf(&self, x: f64) -> f64 {
        if x <= 0.0 {
            return 0.0;
        }
        match *self {
            Fitted::FoldedNormal { mu, sigma } => {
                let z = |v: f64| std_normal().cdf((v - mu) / sigma);
                z(x) - z(-x)
            }
            Fitted::LogNormal { mu, sigma } => std_normal().cdf((x.ln() - mu) / sigma),
            Fitted::Weibull { shape, scale } => 1.0 - (-(x / scale).powf(shape)).exp(),
        }
    }

    /// The `p` quantile, 0 < p < 1.
    pub(crate) fn quantile(&self, p: f64) -> f64 {
        match *self {
            Fitted::FoldedNormal { .. } => self.bisect_quantile(p),
            Fitted::LogNormal { mu, sigma } => (mu + sigma * std_normal().inverse_cdf(p)).exp(),
            Fitted::Weibull { shape, scale } => scale * (-(1.0 - p).ln()).powf(1.0 / shape),
        }
    }

    /// The folded normal has no closed-form quantile: bisection on the CDF, which is
    /// increasing, to a relative 1e-12.
    fn bisect_quantile(&self, p: f64) -> f64 {
        let mut hi = 1.0f64;
        while self.cdf(hi) < p && hi < 1e300 {
            hi *= 2.0;
        }
        let mut lo = 0.0f64;
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if self.cdf(mid) < p {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-12 * hi {
                break;
            }
        }
        0.5 * (lo + hi)
    }

    fn log_likelihood(&self, values: &[f64]) -> f64 {
        values.iter().map(|&x| self.ln_pdf(x)).sum()
    }

    fn ln_pdf(&self, x: f64) -> f64 {
        match *self {
            Fitted::FoldedNormal { mu, sigma } => {
                let n = std_normal();
                ((n.pdf((x - mu) / sigma) + n.pdf((x + mu) / sigma)) / sigma).ln()
            }
            Fitted::LogNormal { mu, sigma } => LogNormal::new(mu, sigma)
                .map(|d| d.ln_pdf(x))
                .unwrap_or(f64::NEG_INFINITY),
            Fitted::Weibull { shape, scale } => Weibull::new(shape, scale)
                .map(|d| d.ln_pdf(x))
                .unwrap_or(f64::NEG_INFINITY),
        }
    }
}

pub(crate) fn std_normal() -> Normal {
    Normal::standard()
}

/// Fits every candidate the values allow (log-normal and Weibull need every value > 0) and
/// returns them best first. `values` are ≥ 0, at least two of them different.
pub(crate) fn fit_candidates(values: &[f64]) -> Vec<Candidate> {
    let mut out = vec![folded_normal(values)];
    if values.iter().all(|&x| x > 0.0) {
        out.push(log_normal(values));
        if let Some(w) = weibull(values) {
            out.push(w);
        }
    }
    let mut out: Vec<Candidate> = out
        .into_iter()
        .map(|fitted| Candidate {
            fitted,
            log_likelihood: fitted.log_likelihood(values),
        })
        .filter(|c| c.log_likelihood.is_finite())
        .collect();
    out.sort_by(|a, b| b.log_likelihood.total_cmp(&a.log_likelihood));
    out
}

/// Log-normal maximum likelihood: the mean and the (n-divisor) standard deviation of ln x.
fn log_normal(values: &[f64]) -> Fitted {
    let logs: Vec<f64> = values.iter().map(|x| x.ln()).collect();
    let n = logs.len() as f64;
    let mu = logs.iter().sum::<f64>() / n;
    let sigma = (logs.iter().map(|l| (l - mu).powi(2)).sum::<f64>() / n).sqrt();
    Fitted::LogNormal { mu, sigma }
}

/// Weibull maximum likelihood: the shape k solves
/// Σ xᵏ ln x / Σ xᵏ − 1/k − mean(ln x) = 0 (increasing in k), found by bisection; then
/// scale = (mean xᵏ)^(1/k). Values are scaled by their maximum first so xᵏ cannot overflow.
fn weibull(values: &[f64]) -> Option<Fitted> {
    let top = values.iter().copied().fold(0.0f64, f64::max);
    let y: Vec<f64> = values.iter().map(|x| x / top).collect();
    let mean_ln = y.iter().map(|v| v.ln()).sum::<f64>() / y.len() as f64;
    let g = |k: f64| {
        let (mut s, mut sl) = (0.0, 0.0);
        for &v in &y {
            let p = v.powf(k);
            s += p;
            sl += p * v.ln();
        }
        sl / s - 1.0 / k - mean_ln
    };
    let (mut lo, mut hi) = (1e-3, 1.0);
    while g(hi) < 0.0 {
        hi *= 2.0;
        if hi > 1e6 {
            return None;
        }
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if g(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-13 * hi {
            break;
        }
    }
    let shape = 0.5 * (lo + hi);
    let mean_pow = y.iter().map(|v| v.powf(shape)).sum::<f64>() / y.len() as f64;
    Some(Fitted::Weibull {
        shape,
        scale: top * mean_pow.powf(1.0 / shape),
    })
}

/// Folded-normal maximum likelihood by expectation–maximisation: each value is +x or −x of a
/// normal with probabilities w and 1 − w (w = 1 / (1 + exp(−2μx/σ²))), so each step is
/// μ = mean((2w − 1)·x), σ² = mean(x²) − μ². The likelihood never decreases; it stops when
/// μ and σ move by less than 1e-12 relative, or after 100 000 steps.
fn folded_normal(values: &[f64]) -> Fitted {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let mean_sq = values.iter().map(|x| x * x).sum::<f64>() / n;
    let mut mu = mean;
    let mut sigma = (mean_sq - mean * mean).max(1e-300).sqrt();
    for _ in 0..100_000 {
        let next_mu = (values
            .iter()
            .map(|&x| {
                let w = 1.0 / (1.0 + (-2.0 * mu * x / (sigma * sigma)).exp());
                (2.0 * w - 1.0) * x
            })
            .sum::<f64>()
            / n)
            .max(0.0);
        let next_sigma = (mean_sq - next_mu * next_mu).max(1e-300).sqrt();
        let settled = (next_mu - mu).abs() <= 1e-12 * next_sigma.max(next_mu)
            && (next_sigma - sigma).abs() <= 1e-12 * next_sigma;
        mu = next_mu;
        sigma = next_sigma;
        if settled {
            break;
        }
    }
    Fitted::FoldedNormal { mu, sigma }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_invert_the_cdf() {
        let cases = [
            Fitted::FoldedNormal {
                mu: 0.4,
                sigma: 1.0,
            },
            Fitted::LogNormal {
                mu: 0.1,
                sigma: 0.3,
            },
            Fitted::Weibull {
                shape: 2.5,
                scale: 1.7,
            },
        ];
        for d in cases {
            for p in [0.00135, 0.5, 0.99865] {
                let x = d.quantile(p);
                assert!((d.cdf(x) - p).abs() < 1e-9, "{d:?} p {p}: x {x}");
            }
        }
    }

    #[test]
    fn a_folded_normal_far_from_zero_is_the_normal() {
        // μ = 50σ: the fold carries nothing, so the MLE is the sample's mean and (n-divisor) σ.
        let values: Vec<f64> = (0..40)
            .map(|i| 50.0 + ((i * 7) % 11) as f64 * 0.2)
            .collect();
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let sd = (values.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
        let Fitted::FoldedNormal { mu, sigma } = folded_normal(&values) else {
            panic!("a folded normal");
        };
        assert!((mu - mean).abs() < 1e-9 && (sigma - sd).abs() < 1e-9);
    }
}
