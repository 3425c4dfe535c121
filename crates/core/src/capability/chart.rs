//! Control charts of one characteristic: individuals and moving range (I-MR) and an EWMA,
//! with limits from a baseline window, and the run rules evaluated at every point.
//!
//! - Baseline: the centre line is the baseline's mean, σ its mean moving range / d₂; the
//!   caller states which parts form it (the service: the first [`BASELINE_PARTS`] parts of
//!   the chart's window).
//! - I chart: centre ± 3σ; MR chart: upper limit D₄·MR̄ = 3.267·MR̄.
//! - EWMA: zᵢ = λ·xᵢ + (1 − λ)·zᵢ₋₁, z₀ the centre, λ = 0.2, limits centre ± L·σ·
//!   √(λ/(2 − λ)·(1 − (1 − λ)²ⁱ)), L = 3 (in-control average run length about 560 parts).
//! - Rules (Western Electric / Nelson), each fired once when its condition first holds:
//!   1 point beyond 3σ (Nelson 1), 7 in a row on one side of the centre (Western Electric's
//!   run of 7, AIAG), 6 in a row steadily rising or falling (Nelson 3), the EWMA beyond its
//!   limits. A run rule fires again only after its run is broken.

use super::{D2_SPAN_2, moving_range_sigma};

/// Parts of the baseline window the service takes for the limits.
pub const BASELINE_PARTS: usize = 25;
/// EWMA weight of the newest point.
pub const EWMA_LAMBDA: f64 = 0.2;
/// EWMA limit width in σ of the EWMA statistic.
pub const EWMA_L: f64 = 3.0;
/// D₄ of moving ranges of span 2.
const D4_SPAN_2: f64 = 3.267;
const RUN_ONE_SIDE: usize = 7;
const RUN_TREND: usize = 6;

/// A run rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Rule {
    /// Nelson 1: a point beyond centre ± 3σ.
    BeyondThreeSigma,
    /// Seven points in a row on one side of the centre.
    SevenOneSide,
    /// Nelson 3: six points in a row steadily rising or falling.
    SixTrend,
    /// The EWMA left its limits.
    EwmaBeyond,
}

impl Rule {
    pub fn as_str(self) -> &'static str {
        match self {
            Rule::BeyondThreeSigma => "beyond_3_sigma",
            Rule::SevenOneSide => "seven_one_side",
            Rule::SixTrend => "six_trend",
            Rule::EwmaBeyond => "ewma_beyond",
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            Rule::BeyondThreeSigma => "1 point beyond 3σ",
            Rule::SevenOneSide => "7 in a row on one side of the centre",
            Rule::SixTrend => "6 in a row steadily rising or falling",
            Rule::EwmaBeyond => "EWMA beyond its limits",
        }
    }
}

/// Limits of the I-MR chart from a baseline.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ChartLimits {
    pub baseline_parts: usize,
    pub center: f64,
    pub sigma: f64,
    pub lower: f64,
    pub upper: f64,
    pub moving_range_upper: f64,
}

impl ChartLimits {
    /// Limits from `baseline` (part order); `None` with fewer than 2 parts or no spread.
    pub fn from_baseline(baseline: &[f64]) -> Option<Self> {
        let sigma = moving_range_sigma(baseline);
        if baseline.len() < 2 || !(sigma > 0.0 && sigma.is_finite()) {
            return None;
        }
        let center = baseline.iter().sum::<f64>() / baseline.len() as f64;
        Some(Self {
            baseline_parts: baseline.len(),
            center,
            sigma,
            lower: center - 3.0 * sigma,
            upper: center + 3.0 * sigma,
            moving_range_upper: D4_SPAN_2 * sigma * D2_SPAN_2,
        })
    }
}

/// One point of the charts.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ChartPoint {
    pub value: f64,
    /// |xᵢ − xᵢ₋₁|; `None` for the first point.
    pub moving_range: Option<f64>,
    pub ewma: f64,
    pub ewma_lower: f64,
    pub ewma_upper: f64,
    /// Rules that fired at this point.
    pub fired: Vec<Rule>,
}

/// Evaluates every point of `values` (part order) against `limits`.
pub fn evaluate(values: &[f64], limits: &ChartLimits) -> Vec<ChartPoint> {
    let mut out = Vec::with_capacity(values.len());
    let mut state = RunState::default();
    let mut ewma = limits.center;
    let mut ewma_out = false;
    for (i, &x) in values.iter().enumerate() {
        ewma = EWMA_LAMBDA * x + (1.0 - EWMA_LAMBDA) * ewma;
        let decay = (1.0 - EWMA_LAMBDA).powi(2 * (i as i32 + 1));
        let half =
            EWMA_L * limits.sigma * (EWMA_LAMBDA / (2.0 - EWMA_LAMBDA) * (1.0 - decay)).sqrt();
        let mut fired = state.push(x, limits);
        let now_out = (ewma - limits.center).abs() > half;
        if now_out && !ewma_out {
            fired.push(Rule::EwmaBeyond);
        }
        ewma_out = now_out;
        out.push(ChartPoint {
            value: x,
            moving_range: (i > 0).then(|| (x - values[i - 1]).abs()),
            ewma,
            ewma_lower: limits.center - half,
            ewma_upper: limits.center + half,
            fired,
        });
    }
    out
}

/// The runs the rules count, carried from point to point.
#[derive(Debug, Default)]
struct RunState {
    previous: Option<f64>,
    /// Signed run length on one side: +n above, −n below, 0 on the centre.
    side_run: i64,
    /// Signed run of points steadily rising (+) or falling (−), counting the first point.
    trend_run: i64,
}

impl RunState {
    fn push(&mut self, x: f64, limits: &ChartLimits) -> Vec<Rule> {
        let mut fired = Vec::new();
        if x > limits.upper || x < limits.lower {
            fired.push(Rule::BeyondThreeSigma);
        }
        let side = (x - limits.center)
            .partial_cmp(&0.0)
            .map_or(0, |o| o as i64);
        self.side_run = match side {
            0 => 0,
            s if self.side_run.signum() == s => self.side_run + s,
            s => s,
        };
        if self.side_run.unsigned_abs() as usize == RUN_ONE_SIDE {
            fired.push(Rule::SevenOneSide);
        }
        let step = self
            .previous
            .and_then(|p| (x - p).partial_cmp(&0.0))
            .map_or(0, |o| o as i64);
        self.trend_run = match step {
            0 => 1,
            s if self.trend_run.signum() == s => self.trend_run + s,
            s => 2 * s,
        };
        if self.trend_run.unsigned_abs() as usize == RUN_TREND {
            fired.push(Rule::SixTrend);
        }
        self.previous = Some(x);
        fired
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> ChartLimits {
        ChartLimits {
            baseline_parts: 25,
            center: 0.0,
            sigma: 1.0,
            lower: -3.0,
            upper: 3.0,
            moving_range_upper: 3.686,
        }
    }

    fn fired(values: &[f64]) -> Vec<(usize, Rule)> {
        evaluate(values, &limits())
            .iter()
            .enumerate()
            .flat_map(|(i, p)| p.fired.iter().map(move |r| (i, *r)))
            .collect()
    }

    #[test]
    fn each_rule_fires_once_where_its_condition_first_holds() {
        // Alternating small values: nothing.
        let quiet: Vec<f64> = (0..40)
            .map(|i| if i % 2 == 0 { 0.5 } else { -0.5 })
            .collect();
        assert_eq!(fired(&quiet), vec![]);
        // One point at 3.5σ, back at once: rule 1 at that point (the EWMA moves 0.7σ, inside).
        assert_eq!(
            fired(&[0.5, -0.5, 3.5, -0.5]),
            vec![(2, Rule::BeyondThreeSigma)]
        );
        // Seven points at +0.5σ after one below: the run of 7 completes at index 7.
        let mut side = vec![-0.5];
        side.extend([0.5; 8]);
        assert_eq!(fired(&side), vec![(7, Rule::SevenOneSide)]);
        // Six rising from below the centre to above (3 below, 3 above): trend at index 5.
        let rising = [-0.6, -0.4, -0.2, 0.2, 0.4, 0.6, -0.1];
        assert_eq!(fired(&rising), vec![(5, Rule::SixTrend)]);
    }

    #[test]
    fn a_sustained_shift_trips_the_ewma() {
        // +1.5σ from the start: the EWMA's limit (3σ·√(0.2/1.8) = 1σ at steady state)
        // is crossed once z = 1.5·(1 − 0.8ⁱ) passes it: z₅ = 1.008 > its limit 0.945 (z₄ = 0.886
        // < 0.912).
        let values = [1.5; 12];
        let points = evaluate(&values, &limits());
        let first = points
            .iter()
            .position(|p| p.fired.contains(&Rule::EwmaBeyond));
        assert_eq!(first, Some(4));
        assert!(points[6].fired.contains(&Rule::SevenOneSide));
    }
}
