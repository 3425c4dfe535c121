//! Control charts of one characteristic: individuals and moving range (I-MR) and an EWMA,
//! with limits from a baseline window, and the run rules evaluated at every point.
//!
//! - Baseline: the centre line is the baseline's mean, σ its mean moving range / d₂, but
//!   never less than the chart's resolution; the caller states which parts form it (the
//!   service: the first [`BASELINE_PARTS`] parts of the chart's window).
//! - Resolution: [`RESOLUTION_SHARE`] of the tolerance width (of the upper limit for a
//!   characteristic bounded at zero). A closed loop holds its characteristics to
//!   nanometres, and moves by nanometres from part to part as it learns: a chart whose σ
//!   came from that would flag every learning step. So σ is at least the resolution, a point
//!   within the resolution of the centre is on neither side of it, and a step within the
//!   resolution is neither rising nor falling. Without a tolerance the resolution is 0 and
//!   the rules are the textbook's.
//! - I chart: centre ± 3σ; MR chart: upper limit D₄·MR̄ = 3.267·MR̄. A characteristic that
//!   is the largest of many readings takes the Gumbel quantiles instead ([`Shape`]).
//! - EWMA: zᵢ = λ·xᵢ + (1 − λ)·zᵢ₋₁, z₀ the centre, λ = 0.2, limits centre ± L·σ·
//!   √(λ/(2 − λ)·(1 − (1 − λ)²ⁱ)), L = 3 (in-control average run length about 560 parts).
//! - Rules (Western Electric / Nelson), each fired once when its condition first holds:
//!   1 point beyond 3σ (Nelson 1), 7 in a row on one side of the centre (Western Electric's
//!   run of 7, AIAG), 6 in a row steadily rising or falling (Nelson 3), the EWMA beyond its
//!   limits. A run rule fires again only after its run is broken.

use super::{D2_SPAN_2, moving_range_sigma};

/// The chart's resolution as a share of the tolerance width.
pub(crate) const RESOLUTION_SHARE: f64 = 0.01;

/// The resolution of a characteristic with `limits`: [`RESOLUTION_SHARE`] of U − L (of U
/// when only an upper limit is given, a characteristic bounded at zero); 0 without limits.
pub fn resolution(limits: &super::Limits) -> f64 {
    match (limits.lower, limits.upper) {
        (Some(l), Some(u)) => RESOLUTION_SHARE * (u - l),
        (None, Some(u)) => RESOLUTION_SHARE * u,
        _ => 0.0,
    }
}

/// Parts of the baseline window the service takes for the limits.
pub const BASELINE_PARTS: usize = 25;
/// EWMA weight of the newest point.
pub(crate) const EWMA_LAMBDA: f64 = 0.2;
/// EWMA limit width in σ of the EWMA statistic.
pub(crate) const EWMA_L: f64 = 3.0;
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

/// What the chart's limits assume of a characteristic's distribution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// Normal: centre ± 3σ.
    Normal,
    /// The largest of many readings (a magnitude bounded at zero: max |error| or profile
    /// error over hundreds of angles, a pin's roundness): the Gumbel distribution of a
    /// maximum, skewed to the high side. Its mean + 3σ holds 98.81 % of the parts, not
    /// 99.865 %, so the limits are its own 0.135 % and 99.865 % quantiles instead: mean
    /// + 4.70σ and mean − 1.92σ, the same false-alarm rate as a normal chart's ± 3σ.
    LargestOfMany,
}

/// Euler–Mascheroni constant γ: the Gumbel's mean is its location + γ·scale.
const EULER_GAMMA: f64 = 0.577_215_664_901_532_9;
/// Φ(3): the share of a normal chart's parts below its upper limit.
const PHI_3: f64 = 0.998_650_101_968_369_9;

/// Gumbel limits as offsets from the mean, in units of the scale β: the quantile q lies at
/// location − β·ln(−ln q), the mean at location + γβ.
fn gumbel_offset(q: f64) -> f64 {
    -(-q.ln()).ln() - EULER_GAMMA
}

/// Limits of the I-MR chart from a baseline.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ChartLimits {
    pub baseline_parts: usize,
    /// Differences this small are no difference (see the module's notes).
    pub resolution: f64,
    pub center: f64,
    pub sigma: f64,
    pub lower: f64,
    pub upper: f64,
    pub moving_range_upper: f64,
}

impl ChartLimits {
    /// Limits from `baseline` (part order) at `resolution`; `None` with fewer than 2 parts
    /// or no spread. The service always names the shape; the tests use the normal one.
    #[cfg(test)]
    pub(crate) fn from_baseline(baseline: &[f64], resolution: f64) -> Option<Self> {
        Self::from_baseline_shaped(baseline, resolution, Shape::Normal)
    }

    /// Limits from `baseline` for a characteristic of `shape`. For
    /// [`Shape::LargestOfMany`] the moving ranges estimate the Gumbel's scale: the
    /// difference of two independent Gumbels is logistic, whose mean |value| is 2 ln 2·β, so
    /// β = MR̄/(2 ln 2) and σ = πβ/√6 (MR̄/d₂ would read σ 4 % low).
    pub fn from_baseline_shaped(baseline: &[f64], resolution: f64, shape: Shape) -> Option<Self> {
        let resolution = if resolution.is_finite() {
            resolution.max(0.0)
        } else {
            0.0
        };
        let gumbel_sigma_per_mr_sigma =
            D2_SPAN_2 * std::f64::consts::PI / (6f64.sqrt() * 2.0 * std::f64::consts::LN_2);
        let mr_sigma = moving_range_sigma(baseline);
        let sigma = match shape {
            Shape::Normal => mr_sigma,
            Shape::LargestOfMany => mr_sigma * gumbel_sigma_per_mr_sigma,
        }
        .max(resolution);
        if baseline.len() < 2 || !(sigma > 0.0 && sigma.is_finite()) {
            return None;
        }
        let center = baseline.iter().sum::<f64>() / baseline.len() as f64;
        let (below, above) = match shape {
            Shape::Normal => (3.0, 3.0),
            Shape::LargestOfMany => {
                let beta_per_sigma = 6f64.sqrt() / std::f64::consts::PI;
                (
                    -gumbel_offset(1.0 - PHI_3) * beta_per_sigma,
                    gumbel_offset(PHI_3) * beta_per_sigma,
                )
            }
        };
        Some(Self {
            baseline_parts: baseline.len(),
            resolution,
            center,
            sigma,
            lower: center - below * sigma,
            upper: center + above * sigma,
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
    let mut monitor = Monitor::new(*limits);
    values.iter().map(|&x| monitor.push(x)).collect()
}

/// The charts point by point, for a loop that sees one part at a time.
#[derive(Debug, Clone)]
pub struct Monitor {
    limits: ChartLimits,
    runs: RunState,
    ewma: f64,
    ewma_out: bool,
    points: u32,
}

impl Monitor {
    pub fn new(limits: ChartLimits) -> Self {
        Self {
            limits,
            runs: RunState::default(),
            ewma: limits.center,
            ewma_out: false,
            points: 0,
        }
    }

    pub fn limits(&self) -> &ChartLimits {
        &self.limits
    }

    /// The next part's point, with the rules that fired at it.
    pub fn push(&mut self, x: f64) -> ChartPoint {
        let l = self.limits;
        let moving_range = self.runs.previous.map(|p| (x - p).abs());
        self.points = self.points.saturating_add(1);
        self.ewma = EWMA_LAMBDA * x + (1.0 - EWMA_LAMBDA) * self.ewma;
        let decay = (1.0 - EWMA_LAMBDA).powi(2 * self.points.min(10_000) as i32);
        let half = EWMA_L * l.sigma * (EWMA_LAMBDA / (2.0 - EWMA_LAMBDA) * (1.0 - decay)).sqrt();
        let mut fired = self.runs.push(x, &l);
        let now_out = (self.ewma - l.center).abs() > half;
        if now_out && !self.ewma_out {
            fired.push(Rule::EwmaBeyond);
        }
        self.ewma_out = now_out;
        ChartPoint {
            value: x,
            moving_range,
            ewma: self.ewma,
            ewma_lower: l.center - half,
            ewma_upper: l.center + half,
            fired,
        }
    }
}

/// The runs the rules count, carried from point to point.
#[derive(Debug, Clone, Default)]
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
        let off = x - limits.center;
        let side = if off.abs() <= limits.resolution {
            0
        } else {
            off.partial_cmp(&0.0).map_or(0, |o| o as i64)
        };
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
            .map(|p| x - p)
            .filter(|d| d.abs() > limits.resolution)
            .and_then(|d| d.partial_cmp(&0.0))
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
            resolution: 0.0,
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

    /// A loop's nanometre wander inside the resolution raises nothing; the same pattern
    /// scaled beyond it does.
    #[test]
    fn differences_within_the_resolution_are_no_difference() {
        // 10 nm above, then below, ten parts each, with a rising nanometre inside each run.
        let wander: Vec<f64> = (0..40)
            .map(|i| if (i / 10) % 2 == 0 { 0.01 } else { -0.01 } + 0.0001 * f64::from(i % 10))
            .collect();
        let coarse = ChartLimits::from_baseline(&wander, 0.1).unwrap();
        assert_eq!(coarse.sigma, 0.1);
        let fired = |l: &ChartLimits, v: &[f64]| {
            evaluate(v, l).iter().map(|p| p.fired.len()).sum::<usize>()
        };
        assert_eq!(fired(&coarse, &wander), 0);
        let fine = ChartLimits::from_baseline(&wander, 0.0).unwrap();
        assert!(fired(&fine, &wander) > 0, "runs of 10 on one side, rising");
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

    /// The Gumbel limits against scipy 1.17 (`gumbel_r`: mean 0.5772156649, std
    /// 1.2825498302, ppf(Φ(3)) = 6.6070508926, ppf(1 − Φ(3)) = −1.8882396040): mean +
    /// 4.7014432390σ and mean − 1.9223075867σ; and the normal chart's mean + 3σ, which holds
    /// only 98.81 % of a Gumbel (scipy: sf = 0.0119044013).
    #[test]
    fn a_largest_of_many_chart_has_the_gumbel_quantiles_as_limits() {
        // Moving ranges all 1: MR̄/d₂ = 0.8862; the Gumbel's σ = π/(√6·2 ln 2) = 0.9251.
        let baseline = [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0];
        let l = ChartLimits::from_baseline_shaped(&baseline, 0.0, Shape::LargestOfMany).unwrap();
        let sigma = std::f64::consts::PI / (6f64.sqrt() * 2.0 * std::f64::consts::LN_2);
        assert!((l.sigma - sigma).abs() < 1e-12, "{}", l.sigma);
        assert!((l.center - 0.5).abs() < 1e-12);
        assert!(((l.upper - 0.5) / l.sigma - 4.701_443_238_968_804).abs() < 1e-9);
        assert!(((0.5 - l.lower) / l.sigma - 1.922_307_586_740_123_1).abs() < 1e-9);
        let normal = ChartLimits::from_baseline(&baseline, 0.0).unwrap();
        assert!(((normal.upper - 0.5) / normal.sigma - 3.0).abs() < 1e-12);
        // The resolution still floors σ.
        let floored =
            ChartLimits::from_baseline_shaped(&[0.5; 8], 0.1, Shape::LargestOfMany).unwrap();
        assert_eq!(floored.sigma, 0.1);
    }
}
