//! Analysis of an averaged lobe measurement against the nominal lift: datum fit (phase and
//! base-circle offset), profile error, statistics, harmonics, runout and the verdict.
//!
//! # Datum convention
//!
//! The measured (averaged) lift `m(ψ)` is modelled as
//!
//! ```text
//! m(ψ) = h(ψ − φ) + δ + e(ψ)
//! ```
//!
//! - `ψ`: angle in the part frame, degrees; angle index `k` is at `ψ_k = k·360°/N`.
//! - `h`: nominal lift, mm, zero on the nominal base circle, periodic over 360°.
//! - `φ` (`phase_error_deg`): positive when the measured lobe **lags** the nominal, i.e. a
//!   feature of the nominal at `ψ` is measured at `ψ + φ` (the peak appears φ later).
//! - `δ` (`base_radius_error_um`): positive when the measured lift is larger, i.e. the part
//!   is **oversize**. A flat probe reads the support function of the part minus the gauge
//!   zero; growing the outline uniformly by `δ` raises the support function by `δ` at every
//!   angle, so `δ` is the base-circle radius error — provided the gauge zero is the nominal
//!   base radius (gauge mastered on a setting master). A gauge that zeroes itself on the
//!   part's own base circle makes `δ` ≈ 0 by construction and it then says nothing of size.
//! - `e` (`profile_error_um`): what remains, the profile error.
//!
//! `φ` and `δ` minimise `Σ_k (m_k − h(ψ_k − φ) − δ)²` over **all N angles, equally
//! weighted** (base circle, ramps, flanks and nose alike: the gauge noise is the same at
//! every angle, so this is the minimum-variance estimate of the two parameters). `δ` is
//! eliminated in closed form (the mean residual for a given `φ`); `φ` is found by
//! Gauss–Newton with the nominal slope `h'`, starting from the difference of the first
//! harmonic phases of `m` and `h` (exact for a pure rotation; from 0 when that is within
//! 1°), halving a step that does not lower the cost, stopping when a step is below 1e-9°
//! (or when the convergence rate predicts that for the next one: the last step, under 1e-5°,
//! is then applied to first order, neglecting `½·h''·t²` < 1e-11 mm).
//! Consequently `e` has zero mean and no component along `h'(ψ − φ)`: whatever part of a
//! true error looks like a rotation or a size change is reported as phase or size, not as
//! profile error.
//!
//! `error_um` is the raw difference `m − h` with nothing fitted.

mod bands;
mod base_circle;
mod pin;

pub use bands::{ToleranceBand, Verdict, Violation, judge};
pub use pin::{PinNominal, PinReport, analyse_pin};

use crate::harmonics::{DftTable, Harmonic, wrap_deg};
use crate::measure::{AveragedMeasurement, DroppedRevolution};

/// Fewest points per revolution the analysis accepts (harmonics, a 3-parameter base-circle
/// fit and a meaningful phase need a few points per feature).
pub(crate) const MIN_POINTS_PER_REV: u32 = 8;

/// A first-harmonic phase estimate within this of 0 starts the fit from 0, degrees.
const START_FROM_ZERO_WITHIN_DEG: f64 = 1.0;

/// Largest final step taken to first order instead of by a new evaluation, degrees.
const LINEAR_FINISH_MAX_DEG: f64 = 1e-5;

/// Phase steps below this end the Gauss–Newton iteration, degrees.
const PHASE_TOLERANCE_DEG: f64 = 1e-9;

/// Why an analysis could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AnalysisError {
    #[error("{origin}: {field} has {found} values for {points_per_rev} points per revolution")]
    InconsistentMeasurement {
        origin: String,
        field: &'static str,
        found: usize,
        points_per_rev: u32,
    },
    #[error("{origin}: {points_per_rev} points per revolution, at least {minimum} needed")]
    TooFewPoints {
        origin: String,
        points_per_rev: u32,
        minimum: u32,
    },
    #[error(
        "{origin}: angle index {angle_index} ({angle_deg}°): mean lift {lift_mm} mm is not finite"
    )]
    NonFiniteLift {
        origin: String,
        angle_index: u32,
        angle_deg: f64,
        lift_mm: f64,
    },
    #[error(
        "nominal lift at {angle_deg}° is not finite (lift {lift_mm} mm, slope {slope_mm_per_deg} mm/°)"
    )]
    NonFiniteNominal {
        angle_deg: f64,
        lift_mm: f64,
        slope_mm_per_deg: f64,
    },
    #[error("{origin}: phase cannot be fitted, the nominal lift has no slope")]
    PhaseUnobservable { origin: String },
    #[error(
        "{origin}: phase fit did not converge in {iterations} iterations (last step {last_step_deg}°)"
    )]
    FitNotConverged {
        origin: String,
        iterations: u32,
        last_step_deg: f64,
    },
    #[error("tolerance band {index} ({band:?}): {reason}")]
    InvalidBand {
        index: usize,
        band: ToleranceBand,
        reason: &'static str,
    },
    #[error("tolerance bands cover none of the {points} measured angles")]
    BandsCoverNoPoint { points: usize },
    #[error("analysis parameter {field} = {value} is invalid: {reason}")]
    InvalidParameter {
        field: &'static str,
        value: f64,
        reason: &'static str,
    },
}

/// How a lobe is analysed and judged.
#[derive(Debug, Clone, PartialEq)]
pub struct LobeOptions {
    /// Bands on `profile_error_um`; empty means `±default_band_um` over the whole revolution.
    pub bands: Vec<ToleranceBand>,
    /// Half-width of the band used when `bands` is empty, µm (default 5).
    pub default_band_um: f64,
    /// Highest harmonic order reported (default 50; capped at N/2).
    pub max_harmonic_order: u32,
    /// Gauss–Newton iterations allowed for the phase (default 50; 3–5 are typical).
    pub max_fit_iterations: u32,
    /// Angles whose phase-shifted nominal lift is at most this count as base circle for
    /// runout and base-circle roundness, mm (default 0.001).
    pub base_circle_max_lift_mm: f64,
}

impl Default for LobeOptions {
    fn default() -> Self {
        Self {
            bands: Vec::new(),
            default_band_um: 5.0,
            max_harmonic_order: 50,
            max_fit_iterations: 50,
            base_circle_max_lift_mm: 0.001,
        }
    }
}

/// Everything reported about one lobe; serialised as the JSON measurement report, so the
/// field names are part of the interface.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LobeReport {
    pub origin: String,
    /// The angle grid, degrees: `k·360/N`.
    pub angle_deg: Vec<f64>,
    /// Measured − nominal lift per angle, nothing fitted, µm.
    pub error_um: Vec<f64>,
    /// `error_um` after removing the fitted phase and base-circle offset (see the module
    /// docs), µm. Zero mean.
    pub profile_error_um: Vec<f64>,
    /// d(profile error)/dψ by a periodic central difference `(e[k+1] − e[k−1]) / (2·Δψ)`,
    /// µm/°.
    pub velocity_error_um_per_deg: Vec<f64>,
    /// `φ`: positive when the measured lobe lags the nominal, degrees in (−180, 180].
    pub phase_error_deg: f64,
    /// `δ`: positive when the part is oversize, µm.
    pub base_radius_error_um: f64,
    /// Per-angle sample standard deviation (1σ, n − 1) over the revolutions used, µm.
    pub repeatability_um: Vec<f64>,
    /// Per-angle range (max − min) over the revolutions used, µm.
    pub repeatability_range_um: Vec<f64>,
    /// Largest of `repeatability_um`, µm.
    pub repeatability_max_um: f64,
    pub profile_error_max_um: f64,
    pub profile_error_min_um: f64,
    pub profile_error_peak_to_valley_um: f64,
    /// Root mean square of `profile_error_um` (equal to its standard deviation: zero mean), µm.
    pub profile_error_rms_um: f64,
    /// Total indicated runout of the base circle: twice the first-harmonic amplitude of the
    /// profile error fitted on the base-circle angles only, µm. `None` when the base circle
    /// spans less than 90°.
    pub runout_um: Option<f64>,
    /// Direction of the high point of that first harmonic, degrees.
    pub runout_phase_deg: Option<f64>,
    /// Peak-to-valley of the base-circle profile error after removing its mean and first
    /// harmonic, µm.
    pub base_circle_roundness_um: Option<f64>,
    /// Number of angles counted as base circle.
    pub base_circle_points: u32,
    /// Harmonics 1..=50 (capped at N/2) of `profile_error_um`.
    pub harmonics: Vec<Harmonic>,
    /// Revolution numbers averaged.
    pub revolutions_used: Vec<u32>,
    pub dropped_revolutions: Vec<DroppedRevolution>,
    /// `profile_error_um` against the tolerance bands.
    pub verdict: Verdict,
    /// Gauss–Newton iterations the phase fit took.
    pub fit_iterations: u32,
}

/// The nominal lift: angle ψ in degrees (called with ψ in [0, 360]) → (lift mm,
/// d lift/dψ in mm per **degree**). A spline giving mm/rad must be scaled by π/180: the fitted
/// phase does not depend on the slope's scale, but a slope 57× too large makes every
/// Gauss–Newton step 57× too short and the fit ends in [`AnalysisError::FitNotConverged`].
pub(crate) type NominalLift<'a> = &'a dyn Fn(f64) -> (f64, f64);

/// Analyses an averaged lobe measurement against the nominal lift. See the module docs for
/// the datum convention. Pure; fails on malformed input or options, never panics.
pub fn analyse_lobe(
    avg: &AveragedMeasurement,
    nominal: NominalLift<'_>,
    options: &LobeOptions,
) -> Result<LobeReport, AnalysisError> {
    let n = check_measurement(avg)?;
    options.validate()?;
    let default_band = [ToleranceBand::everywhere(options.default_band_um)];
    let bands: &[ToleranceBand] = if options.bands.is_empty() {
        &default_band
    } else {
        &options.bands
    };
    bands::validate(bands)?;

    let angle_deg: Vec<f64> = (0..n).map(|k| avg.angle_deg(k as u32)).collect();
    let lift_mm = &avg.mean_lift_mm;
    let table = DftTable::new(n);
    let unshifted = evaluate(nominal, &angle_deg, lift_mm, 0.0)?;
    let error_um: Vec<f64> = unshifted.residual_mm.iter().map(|r| r * 1000.0).collect();
    let fit = fit_datum(avg, nominal, &angle_deg, &table, unshifted, options)?;
    let offset_mm = fit.at.residual_mm.iter().sum::<f64>() / n as f64;
    let profile_error_um: Vec<f64> = fit
        .at
        .residual_mm
        .iter()
        .map(|r| (r - offset_mm) * 1000.0)
        .collect();

    let velocity_error_um_per_deg = periodic_derivative_per_deg(&profile_error_um);
    let (min, max) = extremes(&profile_error_um);
    let rms = (profile_error_um.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
    let base = base_circle::fit(
        &table,
        &profile_error_um,
        &fit.at.nominal_mm,
        options.base_circle_max_lift_mm,
    );
    let verdict = judge(&angle_deg, &profile_error_um, bands)?;
    Ok(LobeReport {
        origin: avg.origin.clone(),
        harmonics: table.harmonics(&profile_error_um, options.max_harmonic_order),
        error_um,
        velocity_error_um_per_deg,
        phase_error_deg: wrap_deg(fit.phase_deg),
        base_radius_error_um: offset_mm * 1000.0,
        repeatability_um: avg.repeatability_std_um.clone(),
        repeatability_range_um: avg.repeatability_range_um.clone(),
        repeatability_max_um: avg.repeatability_std_um.iter().copied().fold(0.0, f64::max),
        profile_error_max_um: max,
        profile_error_min_um: min,
        profile_error_peak_to_valley_um: max - min,
        profile_error_rms_um: rms,
        runout_um: base.runout_um,
        runout_phase_deg: base.runout_phase_deg,
        base_circle_roundness_um: base.roundness_um,
        base_circle_points: base.points,
        revolutions_used: avg.revolutions_used.clone(),
        dropped_revolutions: avg.dropped_revolutions.clone(),
        verdict,
        fit_iterations: fit.iterations,
        profile_error_um,
        angle_deg,
    })
}

/// Periodic central difference `(v[k+1] − v[k−1]) / (2·Δψ)` on an N-point grid, per degree.
/// For a harmonic of order j it returns the exact derivative times `sin(jΔ)/(jΔ)`.
fn periodic_derivative_per_deg(values: &[f64]) -> Vec<f64> {
    let n = values.len();
    let two_steps_deg = 2.0 * 360.0 / n as f64;
    (0..n)
        .map(|k| {
            let next = values[if k + 1 == n { 0 } else { k + 1 }];
            let prev = values[if k == 0 { n - 1 } else { k - 1 }];
            (next - prev) / two_steps_deg
        })
        .collect()
}

/// (min, max) of finite values.
fn extremes(values: &[f64]) -> (f64, f64) {
    values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        })
}

impl LobeOptions {
    fn validate(&self) -> Result<(), AnalysisError> {
        let bad = |field, value, reason| {
            Err(AnalysisError::InvalidParameter {
                field,
                value,
                reason,
            })
        };
        if !(self.default_band_um.is_finite() && self.default_band_um >= 0.0) {
            return bad(
                "default_band_um",
                self.default_band_um,
                "must be finite and not negative",
            );
        }
        if !(self.base_circle_max_lift_mm.is_finite() && self.base_circle_max_lift_mm >= 0.0) {
            return bad(
                "base_circle_max_lift_mm",
                self.base_circle_max_lift_mm,
                "must be finite and not negative",
            );
        }
        if self.max_fit_iterations == 0 {
            return bad("max_fit_iterations", 0.0, "must be at least 1");
        }
        Ok(())
    }
}

/// Checks the shape and values of an averaged measurement; returns N.
pub(crate) fn check_measurement(avg: &AveragedMeasurement) -> Result<usize, AnalysisError> {
    let points_per_rev = avg.points_per_rev;
    if points_per_rev < MIN_POINTS_PER_REV {
        return Err(AnalysisError::TooFewPoints {
            origin: avg.origin.clone(),
            points_per_rev,
            minimum: MIN_POINTS_PER_REV,
        });
    }
    let n = points_per_rev as usize;
    let fields = [
        ("mean_lift_mm", avg.mean_lift_mm.len()),
        ("repeatability_std_um", avg.repeatability_std_um.len()),
        ("repeatability_range_um", avg.repeatability_range_um.len()),
    ];
    for (field, found) in fields {
        if found != n {
            return Err(AnalysisError::InconsistentMeasurement {
                origin: avg.origin.clone(),
                field,
                found,
                points_per_rev,
            });
        }
    }
    if let Some(k) = avg.mean_lift_mm.iter().position(|v| !v.is_finite()) {
        return Err(AnalysisError::NonFiniteLift {
            origin: avg.origin.clone(),
            angle_index: k as u32,
            angle_deg: avg.angle_deg(k as u32),
            lift_mm: avg.mean_lift_mm[k],
        });
    }
    Ok(n)
}

/// The nominal evaluated at `ψ_k − phase` against the measured lift.
struct Evaluation {
    phase_deg: f64,
    /// `m_k − h(ψ_k − φ)`, mm.
    residual_mm: Vec<f64>,
    /// `h(ψ_k − φ)`, mm.
    nominal_mm: Vec<f64>,
    /// `h'(ψ_k − φ)`, mm/°.
    slope_mm_per_deg: Vec<f64>,
    /// `Σ (r_k − mean r)²`, mm²: the cost with the offset eliminated.
    cost: f64,
}

fn evaluate(
    nominal: NominalLift<'_>,
    angle_deg: &[f64],
    lift_mm: &[f64],
    phase_deg: f64,
) -> Result<Evaluation, AnalysisError> {
    let n = angle_deg.len();
    let mut nominal_mm = vec![0.0; n];
    let mut slope_mm_per_deg = vec![0.0; n];
    let outputs = nominal_mm.iter_mut().zip(slope_mm_per_deg.iter_mut());
    for (&psi, (h, dh)) in angle_deg.iter().zip(outputs) {
        (*h, *dh) = nominal(wrap_360(psi - phase_deg));
    }
    let finite = |k: &usize| nominal_mm[*k].is_finite() && slope_mm_per_deg[*k].is_finite();
    if let Some(k) = (0..n).find(|k| !finite(k)) {
        return Err(AnalysisError::NonFiniteNominal {
            angle_deg: wrap_360(angle_deg[k] - phase_deg),
            lift_mm: nominal_mm[k],
            slope_mm_per_deg: slope_mm_per_deg[k],
        });
    }
    let residual_mm: Vec<f64> = lift_mm
        .iter()
        .zip(&nominal_mm)
        .map(|(m, h)| m - h)
        .collect();
    let mean = residual_mm.iter().sum::<f64>() / n as f64;
    let cost = residual_mm.iter().map(|r| (r - mean) * (r - mean)).sum();
    Ok(Evaluation {
        phase_deg,
        residual_mm,
        nominal_mm,
        slope_mm_per_deg,
        cost,
    })
}

impl Evaluation {
    /// Moves the phase by a small `step_deg` to first order: `h(ψ − φ − t) ≈ h − h'·t`. The
    /// neglected `½·h''·t²` is below 1e-11 mm for `t` < 1e-5° and any lift curvature under
    /// 0.2 mm/°² (a 10 mm lobe rising over 20° has about 0.05 mm/°²).
    fn advance_linearly(&mut self, step_deg: f64) {
        let rows = self.residual_mm.iter_mut().zip(self.nominal_mm.iter_mut());
        for ((r, h), g) in rows.zip(&self.slope_mm_per_deg) {
            *r += g * step_deg;
            *h -= g * step_deg;
        }
        self.phase_deg += step_deg;
    }

    /// Gauss–Newton step for φ with δ eliminated: `r(φ + t) ≈ r + h'·t`, so with centred
    /// `r̃`, `g̃`: `t = −Σ r̃·g̃ / Σ g̃²`. `None` when the nominal has no slope variation.
    fn step_deg(&self) -> Option<f64> {
        let n = self.residual_mm.len() as f64;
        let r_mean = self.residual_mm.iter().sum::<f64>() / n;
        let g_mean = self.slope_mm_per_deg.iter().sum::<f64>() / n;
        let (mut num, mut den) = (0.0, 0.0);
        for (r, g) in self.residual_mm.iter().zip(&self.slope_mm_per_deg) {
            num += (r - r_mean) * (g - g_mean);
            den += (g - g_mean) * (g - g_mean);
        }
        // Below a nanometre per degree of slope variation the phase is not defined.
        (den > n * 1e-18).then(|| -num / den)
    }
}

/// An angle brought into [0, 360) degrees; cheap for the usual case of one turn off.
fn wrap_360(angle_deg: f64) -> f64 {
    let a = if angle_deg < 0.0 {
        angle_deg + 360.0
    } else if angle_deg >= 360.0 {
        angle_deg - 360.0
    } else {
        angle_deg
    };
    // Far-off angles, and −1e-17 + 360 rounding to 360.
    if (0.0..360.0).contains(&a) {
        a
    } else {
        a.rem_euclid(360.0)
    }
}

struct DatumFit {
    phase_deg: f64,
    iterations: u32,
    at: Evaluation,
}

fn fit_datum(
    avg: &AveragedMeasurement,
    nominal: NominalLift<'_>,
    angle_deg: &[f64],
    table: &DftTable,
    unshifted: Evaluation,
    options: &LobeOptions,
) -> Result<DatumFit, AnalysisError> {
    let lift_mm = &avg.mean_lift_mm;
    let first = |values: &[f64]| table.coefficients(values, 1).unwrap_or((0.0, 0.0));
    let (am, bm) = first(lift_mm);
    let (ah, bh) = first(&unshifted.nominal_mm);
    // A rotation by φ shifts the first-harmonic phase by exactly φ.
    let start_deg = if ah.hypot(bh) > 1e-6 && am.hypot(bm) > 1e-6 {
        wrap_deg((bm.atan2(am) - bh.atan2(ah)).to_degrees())
    } else {
        0.0
    };
    // Within a degree, φ = 0 (evaluated anyway for `error_um`) is as good a start for
    // Gauss–Newton and saves one pass over the nominal.
    let mut at = if start_deg.abs() <= START_FROM_ZERO_WITHIN_DEG {
        unshifted
    } else {
        evaluate(nominal, angle_deg, lift_mm, start_deg)?
    };
    let mut last_step_deg = f64::NAN;
    let mut moved_deg = f64::NAN;
    for iteration in 1..=options.max_fit_iterations {
        let step = at
            .step_deg()
            .ok_or_else(|| AnalysisError::PhaseUnobservable {
                origin: avg.origin.clone(),
            })?;
        last_step_deg = step;
        if step.abs() < PHASE_TOLERANCE_DEG {
            return Ok(DatumFit {
                phase_deg: at.phase_deg,
                iterations: iteration,
                at,
            });
        }
        // Converging fast enough that the step after this one would be below tolerance
        // (predicted from the ratio of this step to the last): take this one to first order
        // instead of evaluating the nominal again.
        let ratio = (step / moved_deg).abs();
        if step.abs() < LINEAR_FINISH_MAX_DEG && step.abs() * ratio < PHASE_TOLERANCE_DEG {
            at.advance_linearly(step);
            return Ok(DatumFit {
                phase_deg: at.phase_deg,
                iterations: iteration,
                at,
            });
        }
        let mut t = step;
        let mut accepted = false;
        for _ in 0..60 {
            let trial = evaluate(nominal, angle_deg, lift_mm, at.phase_deg + t)?;
            if trial.cost <= at.cost {
                at = trial;
                accepted = true;
                break;
            }
            t *= 0.5;
        }
        moved_deg = t;
        // No step lowers the cost: at the minimum to rounding.
        if !accepted || t.abs() < PHASE_TOLERANCE_DEG {
            return Ok(DatumFit {
                phase_deg: at.phase_deg,
                iterations: iteration,
                at,
            });
        }
    }
    Err(AnalysisError::FitNotConverged {
        origin: avg.origin.clone(),
        iterations: options.max_fit_iterations,
        last_step_deg,
    })
}
