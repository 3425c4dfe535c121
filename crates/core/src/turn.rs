//! One turn of the loop, the same for the service, `camloop compensate` and the simulator:
//! a raw measurement and the learning state of the table that ground the part go in; the
//! checks, the analysis, the learning step and the guarded next table come out as one typed
//! [`Turn`]. With a C speed plan the new table is also guarded as it will be delivered, its
//! X table over VA against the X limits, so a plan's refusal is the turn's like any other
//! guard's. Nothing here decides whether the table reaches the control: the caller adopts
//! the returned state only once the table is delivered, so a step never builds on a
//! correction the control has not run.

use super::analysis::{AnalysisError, LobeOptions, LobeReport, ToleranceBand, analyse_lobe};
use super::compensate::{self, CycleError, GuardError, GuardedTable, LobeLoop};
use super::learn::{LearnError, LearningState, PartError, PreviousPart, StepOutcome};
use super::lift::LiftCurve;
use super::measure::{AssemblyLimits, AveragedMeasurement, MeasurementError, RawMeasurement};
use super::speed_plan::TimeLaw;
use super::speed_plan::guard::planned_tables as plan_tables;
use super::speed_plan::tables::VaTables;
use super::spline::PeriodicSpline;

/// What stays fixed between turns of one feature's loop.
#[derive(Debug, Clone, Copy)]
pub struct TurnSetup<'a> {
    pub lobe: LobeLoop<'a>,
    /// Tolerance bands on the profile error (empty: the analysis default).
    pub bands: &'a [ToleranceBand],
    pub assembly: AssemblyLimits,
    /// Where the feature's 0° is on the shaft, degrees: the gauge reads in the shaft's frame
    /// (index 0 at the shaft datum), the nominal and the correction live in the feature's.
    pub phase_deg: f64,
    /// The C speed plan's time law the feature is ground with (made for the nominal part on
    /// the wheel believed), None at constant speed: a new table is then guarded over VA too.
    pub plan: Option<&'a TimeLaw>,
}

/// Why a turn analyses but does not learn.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HoldReason {
    /// The disk is full: what is learned could not be kept, so nothing is.
    #[error("the disk is full: measurements are kept on the journal's reserve, nothing is learned")]
    DiskFull,
    /// The part was ground with another table than the one the learning state belongs to.
    #[error("part was ground with table v{ground_with}, the learning state belongs to v{in_force}")]
    OtherTable { ground_with: u64, in_force: u64 },
    /// A master part's run (a gauge study): evidence about the gauge, never about the table.
    /// `part` is the measurement's raw label: the turn judges a master by its prefix alone, so
    /// a master run is held even when a caller (the simulated cell) never checked its id.
    #[error("part {part} is a master part (gauge study): never learned from")]
    MasterPart { part: String },
}

/// The outcome of the learning half of a turn.
#[derive(Debug, Clone)]
pub enum Decision {
    /// A new table passed every guard; `next` is the state to adopt once it is delivered.
    Table {
        outcome: StepOutcome,
        next: Box<LearningState>,
        table: Box<GuardedTable>,
        /// With a speed plan, the tables over VA the table is delivered as (already checked
        /// against the X limits); None at constant speed.
        planned: Option<Box<VaTables>>,
    },
    /// Learning or a guard refused: the table in force stays, the state is unchanged.
    Refused(CycleError),
    /// Evidence only: analysed and recorded, not learned from.
    Held(HoldReason),
}

/// A measurement that passed the checks and was analysed.
#[derive(Debug, Clone)]
pub struct Measured {
    pub averaged: AveragedMeasurement,
    pub report: LobeReport,
    /// Largest |lift error| with nothing fitted, µm.
    pub max_error_um: f64,
    /// Largest |profile error| after the datum fit, µm.
    pub max_profile_error_um: f64,
    /// Timing (phase) error of the feature against its nominal position on the shaft,
    /// degrees, positive when it lags: a lobe's timing, a pin's index angle.
    pub timing_error_deg: f64,
    /// The part number the gauge gave, when it is a number.
    pub part_number: Option<u64>,
    /// Standard error of the timing estimate, degrees (see [`PartError::timing_sigma_deg`]).
    pub timing_sigma_deg: f64,
}

impl Measured {
    /// What the next learning step needs to know of this part once it is the previous one.
    pub fn as_previous(&self) -> PreviousPart {
        PreviousPart {
            max_error_um: max_abs(&self.report.profile_error_um)
                + self.report.base_radius_error_um.abs(),
            timing_error_deg: self.timing_error_deg,
            part_number: self.part_number,
        }
    }
}

/// A measured part and what the loop decided from it.
#[derive(Debug, Clone)]
pub struct Turn {
    pub measured: Measured,
    pub decision: Decision,
}

/// Why a measurement went no further than the checks.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TurnError {
    #[error("measurement rejected: {0}")]
    Measurement(#[from] MeasurementError),
    #[error("analysis failed: {0}")]
    Analysis(#[from] AnalysisError),
}

/// One turn: checks and averaging, analysis against the nominal, then (unless `hold` says
/// why not) one learning step from `in_force` and the guarded table for it. `previous` is
/// what the feature's previous part measured ([`Measured::as_previous`]): a limit bounds a
/// step only when this part confirms it.
///
/// A measurement on another grid than the state's is learned from a fresh state while
/// nothing was learned yet (the first part sets the grid); afterwards it is refused with
/// [`LearnError::GridMismatch`], the same for every caller.
pub fn turn(
    setup: &TurnSetup<'_>,
    in_force: &LearningState,
    raw: &RawMeasurement,
    hold: Option<HoldReason>,
    previous: Option<PreviousPart>,
) -> Result<Turn, TurnError> {
    let measured = measure(setup, raw)?;
    let hold = if super::measure::is_master_part(&raw.header.part) {
        Some(HoldReason::MasterPart {
            part: raw.header.part.clone(),
        })
    } else {
        hold
    };
    let decision = match hold {
        Some(reason) => Decision::Held(reason),
        None => learn(setup, in_force, &measured, previous),
    };
    Ok(Turn { measured, decision })
}

/// The first half of a turn: checks, averaging and analysis against the nominal.
pub fn measure(setup: &TurnSetup<'_>, raw: &RawMeasurement) -> Result<Measured, TurnError> {
    let averaged = super::measure::check_and_average(raw, &setup.assembly)?;
    let curve = LiftCurve::new(setup.lobe.nominal);
    let report = analyse(setup, &curve, &averaged)?;
    let revolutions = averaged.revolutions_used.len() as u32;
    let timing_sigma_deg = timing_sigma_deg(setup, &curve, &report.repeatability_um, revolutions);
    let max_error_um = max_abs(&report.error_um);
    let max_profile_error_um = report
        .profile_error_max_um
        .abs()
        .max(report.profile_error_min_um.abs());
    Ok(Measured {
        timing_error_deg: report.phase_error_deg,
        timing_sigma_deg,
        part_number: raw.header.part.trim().parse().ok(),
        averaged,
        report,
        max_error_um,
        max_profile_error_um,
    })
}

fn analyse(
    setup: &TurnSetup<'_>,
    curve: &LiftCurve,
    averaged: &AveragedMeasurement,
) -> Result<LobeReport, AnalysisError> {
    let nominal = |psi_deg: f64| {
        let s = curve.eval((psi_deg - setup.phase_deg).to_radians());
        (s.h_mm, s.dh_mm.to_radians())
    };
    let options = LobeOptions {
        bands: setup.bands.to_vec(),
        ..LobeOptions::default()
    };
    analyse_lobe(averaged, &nominal, &options)
}

fn learn(
    setup: &TurnSetup<'_>,
    in_force: &LearningState,
    measured: &Measured,
    previous: Option<PreviousPart>,
) -> Decision {
    let (averaged, report) = (&measured.averaged, &measured.report);
    let mut next = if averaged.points_per_rev != in_force.points_per_rev {
        if in_force.iteration != 0 {
            return Decision::Refused(CycleError::Learn(LearnError::GridMismatch {
                expected: in_force.points_per_rev,
                got: averaged.points_per_rev as usize,
            }));
        }
        LearningState::new(averaged.points_per_rev)
    } else {
        in_force.clone()
    };
    // The timing goes to the C offset, so the lift learns the error with it taken out: the
    // profile error plus the size, carried into the feature's frame.
    let lift_error: Vec<f64> = report
        .profile_error_um
        .iter()
        .map(|e| e + report.base_radius_error_um)
        .collect();
    let error_um = to_feature_frame(&lift_error, setup.phase_deg);
    let repeatability_um = to_feature_frame(&report.repeatability_um, setup.phase_deg);
    let revolutions = averaged.revolutions_used.len() as u32;
    let part = PartError {
        error_um: &error_um,
        repeatability_um: &repeatability_um,
        revolutions,
        timing_error_deg: measured.timing_error_deg,
        timing_sigma_deg: measured.timing_sigma_deg,
        part_number: measured.part_number,
        previous,
    };
    let (outcome, table) = match compensate::learn_and_regenerate(&mut next, &part, &setup.lobe) {
        Ok(done) => done,
        Err(e) => return Decision::Refused(e),
    };
    let planned = match setup.plan {
        None => None,
        // Over an X limit with the plan: refused like any guard, the table in force stays.
        Some(law) => match planned_tables(&setup.lobe, law, &next, &table) {
            Ok(tables) => Some(Box::new(tables)),
            Err(e) => return Decision::Refused(CycleError::Guard(e)),
        },
    };
    Decision::Table {
        outcome,
        next: Box::new(next),
        table: Box::new(table),
        planned,
    }
}

/// The speed plan's guard: the tables over VA that `table` (made from `state`) is delivered
/// as with the time law `law`, made for the commanded part (the nominal plus the correction)
/// and refused when the corrected X table exceeds an X limit of `lobe` anywhere along them.
/// The one check every caller runs: the turn on a new table, the service and the simulated
/// cell on a table made again (a dressing, a rollback, a restart).
pub fn planned_tables(
    lobe: &LobeLoop<'_>,
    law: &TimeLaw,
    state: &LearningState,
    table: &GuardedTable,
) -> Result<VaTables, GuardError> {
    let lift = compensate::commanded_lift(lobe.nominal, &state.correction_um)?;
    let commanded = lobe.feature.part(&lift)?;
    let tolerance_um = lobe.request.poly_tolerance_um;
    plan_tables(table, &commanded, law, tolerance_um, lobe.limits)
}

/// Standard error of the timing estimate, degrees: σ of the per-angle mean (the rms
/// repeatability over √revolutions) over √Σ h′², h′ the nominal slope in mm/° at each gauge
/// angle (a least-squares phase from N points of equal noise).
fn timing_sigma_deg(
    setup: &TurnSetup<'_>,
    curve: &LiftCurve,
    repeatability_um: &[f64],
    revolutions: u32,
) -> f64 {
    let n = repeatability_um.len();
    if n == 0 {
        return 0.0;
    }
    let sigma_mm = (repeatability_um.iter().map(|s| s * s).sum::<f64>() / n as f64).sqrt()
        / f64::from(revolutions.max(1)).sqrt()
        / 1000.0;
    let slope_sq: f64 = (0..n)
        .map(|k| {
            let feature_deg = k as f64 * 360.0 / n as f64 - setup.phase_deg;
            let per_deg = curve.eval(feature_deg.to_radians()).dh_mm.to_radians();
            per_deg * per_deg
        })
        .sum();
    if slope_sq > 0.0 {
        sigma_mm / slope_sq.sqrt()
    } else {
        0.0
    }
}

/// Values on the shaft's uniform grid (index j at j·360°/N from the datum) carried to the
/// feature's frame, whose 0° is at `phase_deg` on the shaft: `v_feature(θ) = v_shaft(θ +
/// phase)`. A phase on the grid is an exact rotation of the indices; any other goes through
/// the periodic spline of the values.
pub(crate) fn to_feature_frame(values: &[f64], phase_deg: f64) -> Vec<f64> {
    let n = values.len();
    if n == 0 {
        return Vec::new();
    }
    let steps = phase_deg.rem_euclid(360.0) * n as f64 / 360.0;
    let whole = steps.round();
    if (steps - whole).abs() < 1e-9 {
        let k = whole as usize % n;
        return (0..n).map(|j| values[(j + k) % n]).collect();
    }
    let grid: Vec<f64> = (0..n).map(|j| j as f64 * 360.0 / n as f64).collect();
    let spline = PeriodicSpline::new(&grid, values, 360.0);
    grid.iter()
        .map(|a| spline.eval(a + phase_deg.rem_euclid(360.0)).value)
        .collect()
}

fn max_abs(values: &[f64]) -> f64 {
    values.iter().fold(0.0f64, |m, v| m.max(v.abs()))
}

/// SHA-256 of what a measurement says, independent of how it arrived: machine, part and
/// lobe (length-prefixed, so no two headers hash alike), then every sample's revolution,
/// index and exact lift bits in order. The origin (a path, a bus) is left out, so the same
/// file dropped twice, or under another name, is recognised as the same measurement.
/// Binary rather than text: formatting 1,000+ floats per part cost more than the rest of
/// the turn's bookkeeping.
pub fn measurement_sha256(raw: &RawMeasurement) -> crate::digest::Sha256 {
    use sha2::Digest as _;
    let h = &raw.header;
    let mut hasher = sha2::Sha256::new();
    for field in [&h.machine, &h.part, &h.lobe] {
        hasher.update((field.len() as u64).to_le_bytes());
        hasher.update(field.as_bytes());
    }
    hasher.update(h.revolutions.to_le_bytes());
    hasher.update(h.points_per_rev.to_le_bytes());
    let mut samples = Vec::with_capacity(raw.samples.len() * 16);
    for s in &raw.samples {
        samples.extend_from_slice(&s.revolution.to_le_bytes());
        samples.extend_from_slice(&s.angle_index.to_le_bytes());
        samples.extend_from_slice(&s.lift_mm.to_bits().to_le_bytes());
    }
    hasher.update((raw.samples.len() as u64).to_le_bytes());
    hasher.update(&samples);
    crate::digest::Sha256::from_hasher(hasher)
}

/// SHA-256 of a correction (µm per gauge angle, exact bits), as written into each table
/// program's provenance so an operator can tell two tables' corrections apart.
pub fn correction_sha256(correction_um: &[f64]) -> crate::digest::Sha256 {
    use sha2::Digest as _;
    let mut hasher = sha2::Sha256::new();
    for u in correction_um {
        hasher.update(u.to_bits().to_le_bytes());
    }
    crate::digest::Sha256::from_hasher(hasher)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::{MeasurementHeader, RawSample};

    fn measurement(machine: &str, part: &str, lifts: &[f64]) -> RawMeasurement {
        RawMeasurement {
            header: MeasurementHeader {
                machine: machine.into(),
                part: part.into(),
                lobe: "IN1".into(),
                revolutions: 1,
                points_per_rev: lifts.len() as u32,
            },
            samples: lifts
                .iter()
                .enumerate()
                .map(|(i, &lift_mm)| RawSample {
                    revolution: 0,
                    angle_index: i as u32,
                    lift_mm,
                })
                .collect(),
            origin: "test".into(),
        }
    }

    /// The identity that makes measurements idempotent: equal for the same reading whatever
    /// its origin, different for any change a gauge could make, including the smallest lift
    /// change a float can carry and a character moved from one header field to the next.
    #[test]
    fn measurement_identity_is_the_content() {
        let base = measurement("M1", "P7", &[0.0, 1.25, 2.5]);
        let sha = measurement_sha256(&base);
        assert_eq!(sha.to_string().len(), 64);
        let mut elsewhere = base.clone();
        elsewhere.origin = "drop/processed/copy.csv".into();
        assert_eq!(sha, measurement_sha256(&elsewhere));
        let nudged = measurement("M1", "P7", &[0.0, 1.25f64.next_up(), 2.5]);
        assert_ne!(sha, measurement_sha256(&nudged));
        let moved = measurement("M1P", "7", &[0.0, 1.25, 2.5]);
        assert_ne!(sha, measurement_sha256(&moved));
    }

    #[test]
    fn correction_identity_tells_apart_the_smallest_change() {
        let a = correction_sha256(&[0.0, -1.5, 2.0]);
        assert_eq!(a, correction_sha256(&[0.0, -1.5, 2.0]));
        assert_ne!(a, correction_sha256(&[0.0, (-1.5f64).next_up(), 2.0]));
    }
}
