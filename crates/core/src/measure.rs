//! Gauge measurements: raw samples of several revolutions as they arrive, the completeness
//! checks that accept or reject them, and the per-angle average and spread over revolutions.

/// Who and what a measurement belongs to, as announced by the gauge at the start.
///
/// The three labels are raw text, as the gauge sent them: a CAN gauge numbers machine and
/// lobe (`1`, `3`) where the service names them, and a label is judged only where it is
/// routed (the service's routing makes the part a [`crate::ids::PartId`], the machine and
/// lobe its own names), so the codecs and the simulator hand over what they read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MeasurementHeader {
    pub machine: String,
    pub part: String,
    pub lobe: String,
    /// Revolutions the gauge announced it would measure.
    pub revolutions: u32,
    /// Readings per revolution, equally spaced, index 0 at 0° of the part frame.
    pub points_per_rev: u32,
}

/// Part ids of master runs start with this, in any case (`MASTER-1`, `master-7`): the
/// measurement of a master part for a gauge study.
pub const MASTER_PART_PREFIX: &str = "MASTER";

/// Whether `part` names a master part: never learned from, never a production part.
pub fn is_master_part(part: &str) -> bool {
    part.get(..MASTER_PART_PREFIX.len())
        .is_some_and(|p| p.eq_ignore_ascii_case(MASTER_PART_PREFIX))
}

/// One gauge reading: revolution number (0-based), angle index within the revolution
/// (0-based, angle = index · 360° / points_per_rev) and the lift in mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawSample {
    pub revolution: u32,
    pub angle_index: u32,
    pub lift_mm: f64,
}

/// A measurement as received, in arrival order, not yet checked for completeness.
#[derive(Debug, Clone, PartialEq)]
pub struct RawMeasurement {
    pub header: MeasurementHeader,
    pub samples: Vec<RawSample>,
    /// Where it came from, for error messages and traceability ("can0", a file path, …).
    pub origin: String,
}

/// Limits applied when a raw measurement is assembled and averaged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AssemblyLimits {
    /// Fewest revolutions accepted, both as announced and after dropping disagreeing
    /// revolutions. At least 2, since a spread needs two readings (default 3).
    pub min_revolutions: u32,
    /// A revolution whose largest per-angle deviation from the median of all revolutions
    /// exceeds this is dropped, µm (default 5). Finite and positive.
    pub revolution_limit_um: f64,
}

impl Default for AssemblyLimits {
    fn default() -> Self {
        Self {
            min_revolutions: 3,
            revolution_limit_um: 5.0,
        }
    }
}

/// Why a measurement cannot be used. Every variant names the origin; those about a single
/// reading name the revolution, the angle index and the angle in degrees.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeasurementError {
    #[error("assembly limit {field} = {value} is invalid: {reason}")]
    InvalidLimits {
        field: &'static str,
        value: f64,
        reason: &'static str,
    },
    #[error("{origin}: header announces 0 points per revolution")]
    NoPointsPerRevolution { origin: String },
    #[error("{origin}: {announced} revolutions announced, at least {minimum} needed")]
    TooFewRevolutions {
        origin: String,
        announced: u32,
        minimum: u32,
    },
    #[error(
        "{origin}: revolution {revolution} angle index {angle_index}: revolution outside the {announced} announced"
    )]
    RevolutionOutOfRange {
        origin: String,
        revolution: u32,
        angle_index: u32,
        announced: u32,
    },
    #[error(
        "{origin}: revolution {revolution} angle index {angle_index}: angle index outside 0..{points_per_rev}"
    )]
    AngleIndexOutOfRange {
        origin: String,
        revolution: u32,
        angle_index: u32,
        points_per_rev: u32,
    },
    #[error(
        "{origin}: revolution {revolution} angle index {angle_index} ({angle_deg}°): lift {lift_mm} mm is not finite"
    )]
    NonFiniteLift {
        origin: String,
        revolution: u32,
        angle_index: u32,
        angle_deg: f64,
        lift_mm: f64,
    },
    #[error(
        "{origin}: revolution {revolution} angle index {angle_index} ({angle_deg}°): read more than once"
    )]
    DuplicateReading {
        origin: String,
        revolution: u32,
        angle_index: u32,
        angle_deg: f64,
    },
    #[error(
        "{origin}: revolution {revolution} angle index {angle_index} ({angle_deg}°): missing ({missing_total} readings missing in all)"
    )]
    MissingReading {
        origin: String,
        revolution: u32,
        angle_index: u32,
        angle_deg: f64,
        missing_total: u64,
    },
    #[error(
        "{origin}: only {remaining} revolutions agree within {limit_um} µm, at least {minimum} needed"
    )]
    TooFewAgreeingRevolutions {
        origin: String,
        remaining: u32,
        minimum: u32,
        limit_um: f64,
        dropped: Vec<DroppedRevolution>,
    },
}

/// A revolution left out of the average, and why.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DroppedRevolution {
    pub revolution: u32,
    /// Largest |lift − per-angle median of all revolutions| over the revolution, µm.
    pub max_deviation_um: f64,
    /// Where that largest deviation occurs, degrees.
    pub at_angle_deg: f64,
    /// The same in words, for people and logs.
    pub reason: String,
}

/// A checked measurement: every revolution complete, every angle index exactly once,
/// all lifts finite. Built only by [`assemble`].
#[derive(Debug, Clone, PartialEq)]
pub struct RevolutionGrid {
    origin: String,
    points_per_rev: u32,
    revolutions: u32,
    /// Revolution-major: `lift_mm[r · points_per_rev + k]`.
    lift_mm: Vec<f64>,
}

/// The per-angle mean of the agreeing revolutions, with their spread.
#[derive(Debug, Clone, PartialEq)]
pub struct AveragedMeasurement {
    pub origin: String,
    pub points_per_rev: u32,
    /// Mean lift per angle index over the revolutions used, mm.
    pub mean_lift_mm: Vec<f64>,
    /// Per-angle sample standard deviation (n − 1) of the revolutions used, µm.
    pub repeatability_std_um: Vec<f64>,
    /// Per-angle range (max − min) of the revolutions used, µm.
    pub repeatability_range_um: Vec<f64>,
    /// Revolution numbers that went into the mean, ascending.
    pub revolutions_used: Vec<u32>,
    pub dropped_revolutions: Vec<DroppedRevolution>,
}

/// Angle of an index on a grid of `points_per_rev` equal steps, degrees.
pub(crate) fn angle_deg(angle_index: u32, points_per_rev: u32) -> f64 {
    f64::from(angle_index) * 360.0 / f64::from(points_per_rev)
}

impl AssemblyLimits {
    fn validate(&self) -> Result<(), MeasurementError> {
        if self.min_revolutions < 2 {
            return Err(MeasurementError::InvalidLimits {
                field: "min_revolutions",
                value: f64::from(self.min_revolutions),
                reason: "at least 2 revolutions are needed for a spread",
            });
        }
        if !(self.revolution_limit_um.is_finite() && self.revolution_limit_um > 0.0) {
            return Err(MeasurementError::InvalidLimits {
                field: "revolution_limit_um",
                value: self.revolution_limit_um,
                reason: "must be finite and positive",
            });
        }
        Ok(())
    }
}

/// Checks a raw measurement for completeness and puts it on a grid.
///
/// Rejects, naming the first offending reading: 0 points per revolution, fewer revolutions
/// announced than `limits.min_revolutions`, then (in arrival order) a revolution number
/// outside the announced ones, an angle index outside `0..points_per_rev`, a non-finite
/// lift, then a reading that arrives twice, then the first missing (revolution, angle
/// index) in ascending order. The raw measurement is only borrowed: on rejection the
/// caller still holds it.
pub fn assemble(
    raw: &RawMeasurement,
    limits: &AssemblyLimits,
) -> Result<RevolutionGrid, MeasurementError> {
    limits.validate()?;
    let origin = || raw.origin.clone();
    let n = raw.header.points_per_rev;
    let revs = raw.header.revolutions;
    if n == 0 {
        return Err(MeasurementError::NoPointsPerRevolution { origin: origin() });
    }
    if revs < limits.min_revolutions {
        return Err(MeasurementError::TooFewRevolutions {
            origin: origin(),
            announced: revs,
            minimum: limits.min_revolutions,
        });
    }
    for s in &raw.samples {
        if s.revolution >= revs {
            return Err(MeasurementError::RevolutionOutOfRange {
                origin: origin(),
                revolution: s.revolution,
                angle_index: s.angle_index,
                announced: revs,
            });
        }
        if s.angle_index >= n {
            return Err(MeasurementError::AngleIndexOutOfRange {
                origin: origin(),
                revolution: s.revolution,
                angle_index: s.angle_index,
                points_per_rev: n,
            });
        }
        if !s.lift_mm.is_finite() {
            return Err(MeasurementError::NonFiniteLift {
                origin: origin(),
                revolution: s.revolution,
                angle_index: s.angle_index,
                angle_deg: angle_deg(s.angle_index, n),
                lift_mm: s.lift_mm,
            });
        }
    }
    let expected = u64::from(n) * u64::from(revs);
    // A header may announce far more readings than arrived; only allocate a grid as large
    // as the samples already in memory, otherwise find the fault by sorting.
    if expected > raw.samples.len() as u64 {
        return Err(fault_by_sorting(raw, expected));
    }
    let len = usize::try_from(expected).expect("bounded by the sample count");
    let stride = n as usize;
    let mut lift_mm = vec![0.0; len];
    let mut seen = vec![false; len];
    for s in &raw.samples {
        let i = s.revolution as usize * stride + s.angle_index as usize;
        if seen[i] {
            return Err(duplicate(raw, s));
        }
        seen[i] = true;
        lift_mm[i] = s.lift_mm;
    }
    // No duplicates and at least `expected` samples: every cell is filled.
    Ok(RevolutionGrid {
        origin: raw.origin.clone(),
        points_per_rev: n,
        revolutions: revs,
        lift_mm,
    })
}

fn duplicate(raw: &RawMeasurement, s: &RawSample) -> MeasurementError {
    MeasurementError::DuplicateReading {
        origin: raw.origin.clone(),
        revolution: s.revolution,
        angle_index: s.angle_index,
        angle_deg: angle_deg(s.angle_index, raw.header.points_per_rev),
    }
}

/// Finds the duplicate or gap in a measurement known to lack readings, without a grid.
/// Reports the same duplicate as the grid path would (the earliest repeated arrival).
fn fault_by_sorting(raw: &RawMeasurement, expected: u64) -> MeasurementError {
    let mut keys: Vec<(u32, u32, usize)> = raw
        .samples
        .iter()
        .enumerate()
        .map(|(pos, s)| (s.revolution, s.angle_index, pos))
        .collect();
    keys.sort_unstable();
    let repeated = keys
        .windows(2)
        .filter(|w| (w[0].0, w[0].1) == (w[1].0, w[1].1))
        .map(|w| w[1].2)
        .min();
    if let Some(pos) = repeated {
        return duplicate(raw, &raw.samples[pos]);
    }
    let n = raw.header.points_per_rev;
    let next = |(r, k): (u32, u32)| if k + 1 == n { (r + 1, 0) } else { (r, k + 1) };
    let mut want = (0, 0);
    for &(r, k, _) in &keys {
        if (r, k) != want {
            break;
        }
        want = next(want);
    }
    MeasurementError::MissingReading {
        origin: raw.origin.clone(),
        revolution: want.0,
        angle_index: want.1,
        angle_deg: angle_deg(want.1, n),
        missing_total: expected - keys.len() as u64,
    }
}

/// Assembles and averages in one go: [`assemble`] then [`RevolutionGrid::average`].
pub fn check_and_average(
    raw: &RawMeasurement,
    limits: &AssemblyLimits,
) -> Result<AveragedMeasurement, MeasurementError> {
    assemble(raw, limits)?.average(limits)
}

impl RevolutionGrid {
    pub fn origin(&self) -> &str {
        &self.origin
    }

    pub fn points_per_rev(&self) -> u32 {
        self.points_per_rev
    }

    pub fn revolutions(&self) -> u32 {
        self.revolutions
    }

    /// The lifts of one revolution by angle index, mm; `None` past the last revolution.
    pub fn revolution_lift_mm(&self, revolution: u32) -> Option<&[f64]> {
        let n = self.points_per_rev as usize;
        let start = revolution as usize * n;
        self.lift_mm.get(start..start + n)
    }

    /// Drops disagreeing revolutions, then takes the per-angle mean, sample standard
    /// deviation and range of the rest.
    ///
    /// Rule: at every angle the median over all revolutions is formed; a revolution whose
    /// largest |lift − median| exceeds `limits.revolution_limit_um` is dropped. The median
    /// stays with the majority as long as fewer than half the revolutions are off at an
    /// angle, so one bad revolution among three or more cannot pull the reference towards
    /// itself (a mean would, by 1/n of its fault, and could drag good revolutions over the
    /// limit). The maximum over angles catches a local bump (dirt, chatter mark) as well as
    /// a whole-revolution offset (probe slip). One pass, no re-iteration: the rule does not
    /// depend on the order of revolutions. With two revolutions the median is their mean,
    /// so both or neither are dropped.
    pub(crate) fn average(
        &self,
        limits: &AssemblyLimits,
    ) -> Result<AveragedMeasurement, MeasurementError> {
        limits.validate()?;
        let n = self.points_per_rev as usize;
        let revs = self.revolutions as usize;
        let limit_mm = limits.revolution_limit_um / 1000.0;
        let worst = self.worst_deviations();
        let mut used = Vec::with_capacity(revs);
        let mut dropped = Vec::new();
        for (r, &(dev_mm, k)) in worst.iter().enumerate() {
            let revolution = r as u32;
            if dev_mm > limit_mm {
                let at_angle_deg = angle_deg(k as u32, self.points_per_rev);
                let max_deviation_um = dev_mm * 1000.0;
                dropped.push(DroppedRevolution {
                    revolution,
                    max_deviation_um,
                    at_angle_deg,
                    reason: format!(
                        "deviates {max_deviation_um:.2} µm from the per-angle median of all \
                         revolutions at {at_angle_deg}° (limit {} µm)",
                        limits.revolution_limit_um
                    ),
                });
            } else {
                used.push(revolution);
            }
        }
        if (used.len() as u32) < limits.min_revolutions {
            return Err(MeasurementError::TooFewAgreeingRevolutions {
                origin: self.origin.clone(),
                remaining: used.len() as u32,
                minimum: limits.min_revolutions,
                limit_um: limits.revolution_limit_um,
                dropped,
            });
        }
        // Row by row (each revolution is contiguous), so the loops stream and vectorise.
        let rows: Vec<&[f64]> = used
            .iter()
            .map(|&r| &self.lift_mm[r as usize * n..(r as usize + 1) * n])
            .collect();
        let (mean_lift_mm, std_um, range_um) = per_angle_statistics(&rows, n);
        Ok(AveragedMeasurement {
            origin: self.origin.clone(),
            points_per_rev: self.points_per_rev,
            mean_lift_mm,
            repeatability_std_um: std_um,
            repeatability_range_um: range_um,
            revolutions_used: used,
            dropped_revolutions: dropped,
        })
    }

    /// Each revolution's largest deviation from the per-angle median of all revolutions,
    /// mm, and the angle index where it is.
    fn worst_deviations(&self) -> Vec<(f64, usize)> {
        let n = self.points_per_rev as usize;
        let revs = self.revolutions as usize;
        let mut column = vec![0.0; revs];
        let median_mm: Vec<f64> = (0..n)
            .map(|k| {
                for (r, v) in column.iter_mut().enumerate() {
                    *v = self.lift_mm[r * n + k];
                }
                median(&mut column)
            })
            .collect();
        self.lift_mm
            .chunks_exact(n)
            .map(|row| {
                let deviations = row.iter().zip(&median_mm).map(|(v, m)| (v - m).abs());
                deviations
                    .enumerate()
                    .fold((0.0, 0), |w, (k, d)| if d > w.0 { (d, k) } else { w })
            })
            .collect()
    }
}

/// Median of a non-empty slice of finite values (reorders the slice). An insertion sort:
/// the slice is one value per revolution, a handful.
fn median(values: &mut [f64]) -> f64 {
    for i in 1..values.len() {
        let mut j = i;
        while j > 0 && values[j - 1] > values[j] {
            values.swap(j - 1, j);
            j -= 1;
        }
    }
    let m = values.len() / 2;
    if values.len() % 2 == 1 {
        values[m]
    } else {
        0.5 * (values[m - 1] + values[m])
    }
}

impl AveragedMeasurement {
    /// Angle of index `k` on this measurement's grid, degrees.
    pub(crate) fn angle_deg(&self, k: u32) -> f64 {
        angle_deg(k, self.points_per_rev)
    }
}

/// Per angle over the revolutions used: the mean lift (mm), the standard deviation and the
/// range (µm).
fn per_angle_statistics(rows: &[&[f64]], n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let count = rows.len() as f64;
    let mut mean_lift_mm = vec![0.0; n];
    let mut lo = vec![f64::INFINITY; n];
    let mut hi = vec![f64::NEG_INFINITY; n];
    for row in rows {
        for (k, &v) in row.iter().enumerate() {
            mean_lift_mm[k] += v;
            lo[k] = lo[k].min(v);
            hi[k] = hi[k].max(v);
        }
    }
    mean_lift_mm.iter_mut().for_each(|m| *m /= count);
    let mut ss = vec![0.0; n];
    for row in rows {
        for ((s, &v), &m) in ss.iter_mut().zip(row.iter()).zip(&mean_lift_mm) {
            *s += (v - m) * (v - m);
        }
    }
    let std_um: Vec<f64> = ss
        .iter()
        .map(|s| (s / (count - 1.0)).sqrt() * 1000.0)
        .collect();
    let range_um: Vec<f64> = hi.iter().zip(&lo).map(|(h, l)| (h - l) * 1000.0).collect();
    (mean_lift_mm, std_um, range_um)
}

#[cfg(test)]
mod master_tests {
    use super::is_master_part;

    #[test]
    fn master_parts_are_named_by_their_prefix_in_any_case() {
        for part in ["MASTER", "MASTER-1", "master-7", "Master_A"] {
            assert!(is_master_part(part), "{part}");
        }
        for part in ["1234", "MASTE", "P-MASTER", "", "ÄMASTER"] {
            assert!(!is_master_part(part), "{part}");
        }
    }
}
