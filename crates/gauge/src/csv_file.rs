//! Measurement files as CSV (`rev,angle_deg,lift_mm`), as a control or gauge PC writes them
//! into the drop folder: a pure, line-at-a-time parser ([`CsvParser`]) from text (plus the
//! file name) to a measurement and what the file says about its own completeness.
//!
//! Rules:
//! - UTF-8 (a leading BOM is skipped), LF or CRLF, `,` between fields. Blank lines are
//!   ignored; lines starting with `#` are comments.
//! - An optional header row `rev,angle_deg,lift_mm` (any case) before the first data row.
//! - Data rows: `rev` a whole number, `angle_deg` in [0, 360), `lift_mm` finite with
//!   |lift| ≤ 1000. Rows are kept in file order (the arrival order).
//! - Revolution numbers are labels: any consecutive run (0, 1, 2 or 1, 2, 3 or 17, 18, 19)
//!   is accepted and mapped to 0-based revolutions in order of their labels. A gap (1, 2, 4)
//!   is refused, naming the missing revolution.
//! - Identity: a metadata comment `# machine=M3 part=P1234 lobe=L2` names all three;
//!   otherwise the file name must be `MACHINE_PART_LOBE[_anything].csv` (fields split on
//!   `_`). A comment carrying any of the keys `machine part lobe points_per_rev revolutions
//!   master` is a metadata comment and may only hold `key=value` tokens with those keys.
//!   `master=<id>` marks a master run: its part is `MASTER-<id>` (`<id>` if it reads MASTER…).
//! - `points_per_rev` from metadata, else the number of distinct angles in the file. Every
//!   angle must lie on the grid 360°/points_per_rev within 1e-6°; it becomes the angle index.
//! - `revolutions` from metadata (then the labels may span at most that many), else the
//!   number of labels found.
//! - The comment line `# end` (any case) says the writer is done; only blank lines may
//!   follow it. A file is complete when it has that marker, or when it declares
//!   `revolutions` and holds every angle of every declared revolution ([`Completeness`]).

use camloop_core::measure::{MeasurementHeader, RawMeasurement, RawSample};

use super::assemble::{MAX_POINTS_PER_REV, MAX_REVOLUTIONS, MAX_SAMPLES};
use super::csv_fields::{
    Metadata, Row, clip, distinct_angles, identity, is_header, parse_row, read_metadata,
};
use super::serial::MAX_ABS_LIFT_MM;

/// How far an angle may lie from its grid point, in degrees.
pub const GRID_TOLERANCE_DEG: f64 = 1e-6;

/// What is wrong with one line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CsvLineError {
    #[error("expected 3 fields rev,angle_deg,lift_mm, found {found}")]
    FieldCount { found: usize },
    #[error("expected the header rev,angle_deg,lift_mm or a data row, found {found:?}")]
    UnexpectedHeader { found: String },
    #[error("rev {found:?} is not a whole number ≥ 0")]
    Revolution { found: String },
    #[error("angle {found:?} is not a number in [0, 360) degrees")]
    Angle { found: String },
    #[error("lift {found:?} is not a finite number of mm within ±{MAX_ABS_LIFT_MM}")]
    Lift { found: String },
    #[error(
        "angle {angle_deg}° is not on the {step_deg}° grid of {points_per_rev} points per \
         revolution (tolerance {GRID_TOLERANCE_DEG}°)"
    )]
    OffGrid {
        angle_deg: f64,
        step_deg: f64,
        points_per_rev: u32,
    },
    #[error(
        "rev {revolution} is revolution {count} counting from rev {first}, more than the \
         {revolutions} revolutions announced"
    )]
    RevolutionBeyond {
        revolution: u32,
        first: u32,
        count: u64,
        revolutions: u32,
    },
    #[error(
        "metadata token {found:?} is not key=value with a key among machine, part, lobe, \
         points_per_rev, revolutions, master"
    )]
    MetadataToken { found: String },
    #[error("metadata {key}={found:?} is invalid: {expected}")]
    MetadataValue {
        key: &'static str,
        found: String,
        expected: &'static str,
    },
    #[error("metadata {key} given twice with different values")]
    MetadataConflict { key: &'static str },
    #[error("found {found:?} after the `# end` marker on line {end_line}")]
    AfterEnd { end_line: usize, found: String },
}

/// Why a CSV file is not a measurement.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CsvError {
    #[error("line {line}: {error}")]
    Line { line: usize, error: CsvLineError },
    #[error("no data rows")]
    NoSamples,
    #[error("more than {MAX_SAMPLES} data rows")]
    TooManySamples,
    #[error(
        "machine, part and lobe unknown: add a `# machine=… part=… lobe=…` comment line or \
         name the file MACHINE_PART_LOBE[_…].csv (file name {file_name:?})"
    )]
    NoIdentity { file_name: String },
    /// The file's two labels as written: refused before either is checked, so both stay text.
    #[error("part={part:?} and master={master:?} disagree: a master run's part is the master")]
    MasterConflict { part: String, master: String },
    #[error("metadata names {given} but not {missing}: give machine, part and lobe together")]
    PartialIdentity { given: String, missing: String },
    #[error("{found} points per revolution is outside 1..={MAX_POINTS_PER_REV}")]
    PointsPerRev { found: u64 },
    #[error("{found} revolutions is outside 1..={MAX_REVOLUTIONS}")]
    Revolutions { found: u64 },
    /// Labels are not consecutive; `from` and `to` are neighbours among the labels present.
    #[error("revolutions jump from {from} to {to}: {}", missing_labels(*.from, *.to))]
    RevolutionGap { from: u32, to: u32 },
}

fn missing_labels(from: u32, to: u32) -> String {
    let (first, last) = (from.saturating_add(1), to.saturating_sub(1));
    if first == last {
        format!("revolution {first} is missing")
    } else {
        format!("revolutions {first} to {last} are missing")
    }
}

/// What a CSV file says about whether its writer had finished.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Completeness {
    /// The `# end` marker line was present.
    pub end_marker: bool,
    /// `revolutions=` from the metadata comment, if given.
    pub declared_revolutions: Option<u32>,
    /// Distinct revolution labels present.
    pub revolutions_found: u32,
    /// Distinct (revolution, angle) readings present.
    pub readings_found: u64,
    /// Readings a file with every revolution complete holds: declared (or found)
    /// revolutions × points per revolution.
    pub readings_expected: u64,
    /// The last line ended with a newline. A last line without one may be cut short by a
    /// writer still at work (`1.2` of `1.234567`), so it does not count as complete.
    pub last_line_ended: bool,
}

impl Completeness {
    /// Every declared revolution holds every angle.
    pub fn declared_count_met(&self) -> bool {
        self.declared_revolutions.is_some() && self.readings_found == self.readings_expected
    }

    /// The file itself says it is whole: an end marker, or the declared count met with the
    /// last line ended.
    pub fn is_complete(&self) -> bool {
        self.end_marker || (self.declared_count_met() && self.last_line_ended)
    }
}

/// A parsed CSV file: the measurement and its completeness.
#[derive(Debug, Clone, PartialEq)]
pub struct CsvMeasurement {
    pub measurement: RawMeasurement,
    pub completeness: Completeness,
}

/// A CSV measurement read one line at a time, so a reader holds only the parsed rows (never
/// the whole text). Feed lines in file order with [`CsvParser::push_line`], then
/// [`CsvParser::finish`]. The first error ends the parse.
#[derive(Default)]
pub struct CsvParser {
    meta: Metadata,
    rows: Vec<Row>,
    line: usize,
    seen_data_or_header: bool,
    end_line: Option<usize>,
    last_line_ended: bool,
}

impl CsvParser {
    pub fn new() -> Self {
        Self::default()
    }

    /// Lines pushed so far (the number of the last one).
    pub fn line(&self) -> usize {
        self.line
    }

    /// Takes the next line, with its line ending if it has one (`\n` or `\r\n`): whether the
    /// last line ended is part of the [`Completeness`].
    pub fn push_line(&mut self, raw: &str) -> Result<(), CsvError> {
        self.line += 1;
        self.last_line_ended = raw.ends_with('\n');
        let line = self.line;
        let at = |error| CsvError::Line { line, error };
        let raw = if line == 1 {
            raw.strip_prefix('\u{feff}').unwrap_or(raw)
        } else {
            raw
        };
        let trimmed = raw.trim();
        if trimmed.is_empty() {
            return Ok(());
        }
        if let Some(end_line) = self.end_line {
            return Err(at(CsvLineError::AfterEnd {
                end_line,
                found: clip(trimmed),
            }));
        }
        if let Some(comment) = trimmed.strip_prefix('#') {
            if comment.trim().eq_ignore_ascii_case("end") {
                self.end_line = Some(line);
                return Ok(());
            }
            return read_metadata(comment, &mut self.meta).map_err(at);
        }
        let first_row = !self.seen_data_or_header;
        self.seen_data_or_header = true;
        if first_row && trimmed.starts_with(|c: char| c.is_ascii_alphabetic()) {
            if is_header(trimmed) {
                return Ok(());
            }
            return Err(at(CsvLineError::UnexpectedHeader {
                found: clip(trimmed),
            }));
        }
        if self.rows.len() as u64 >= MAX_SAMPLES {
            return Err(CsvError::TooManySamples);
        }
        self.rows.push(parse_row(line, trimmed).map_err(at)?);
        Ok(())
    }

    /// Checks the whole file and builds the measurement. `file_name` (without directories)
    /// supplies the identity when no metadata comment does; `origin` is copied into the
    /// measurement.
    pub fn finish(self, file_name: &str, origin: &str) -> Result<CsvMeasurement, CsvError> {
        let Self {
            meta,
            rows,
            end_line,
            last_line_ended,
            ..
        } = self;
        if rows.is_empty() {
            return Err(CsvError::NoSamples);
        }
        let [machine, part, lobe] = identity(meta.ids, meta.master, file_name)?;
        let points_per_rev = match meta.points_per_rev {
            Some(p) => p,
            None => {
                let found = distinct_angles(&rows);
                u32::try_from(found)
                    .ok()
                    .filter(|p| (1..=MAX_POINTS_PER_REV).contains(p))
                    .ok_or(CsvError::PointsPerRev {
                        found: found as u64,
                    })?
            }
        };
        let labels = Labels::of(&rows)?;
        let revolutions = match meta.revolutions {
            Some(announced) => {
                labels.check_within(&rows, announced)?;
                announced
            }
            None => u32::try_from(labels.count)
                .ok()
                .filter(|r| *r <= MAX_REVOLUTIONS)
                .ok_or(CsvError::Revolutions {
                    found: labels.count,
                })?,
        };
        let samples = on_grid(&rows, labels.first, points_per_rev)?;
        let completeness = Completeness {
            end_marker: end_line.is_some(),
            declared_revolutions: meta.revolutions,
            revolutions_found: u32::try_from(labels.count).unwrap_or(u32::MAX),
            readings_found: distinct_readings(&samples),
            readings_expected: u64::from(revolutions) * u64::from(points_per_rev),
            last_line_ended,
        };
        Ok(CsvMeasurement {
            measurement: RawMeasurement {
                header: MeasurementHeader {
                    machine,
                    part,
                    lobe,
                    revolutions,
                    points_per_rev,
                },
                samples,
                origin: origin.to_owned(),
            },
            completeness,
        })
    }
}

/// Parses a CSV measurement held in memory (see [`CsvParser`] for files).
pub fn parse_measurement_csv(
    text: &str,
    file_name: &str,
    origin: &str,
) -> Result<RawMeasurement, CsvError> {
    let mut parser = CsvParser::new();
    for line in text.split_inclusive('\n') {
        parser.push_line(line)?;
    }
    parser.finish(file_name, origin).map(|m| m.measurement)
}

/// The revolution labels present: the lowest and how many consecutive ones from it.
struct Labels {
    first: u32,
    count: u64,
}

impl Labels {
    fn of(rows: &[Row]) -> Result<Self, CsvError> {
        let mut labels: Vec<u32> = rows.iter().map(|r| r.revolution).collect();
        labels.sort_unstable();
        labels.dedup();
        if let Some(pair) = labels.windows(2).find(|w| w[1] - w[0] > 1) {
            return Err(CsvError::RevolutionGap {
                from: pair[0],
                to: pair[1],
            });
        }
        Ok(Self {
            first: labels.first().copied().unwrap_or(0),
            count: labels.len() as u64,
        })
    }

    /// Refuses, at its line, the first row whose label lies beyond `announced` revolutions.
    fn check_within(&self, rows: &[Row], announced: u32) -> Result<(), CsvError> {
        match rows
            .iter()
            .find(|r| u64::from(r.revolution - self.first) >= u64::from(announced))
        {
            Some(row) => Err(CsvError::Line {
                line: row.line,
                error: CsvLineError::RevolutionBeyond {
                    revolution: row.revolution,
                    first: self.first,
                    count: u64::from(row.revolution - self.first) + 1,
                    revolutions: announced,
                },
            }),
            None => Ok(()),
        }
    }
}

/// Samples with 0-based revolutions (label − `first`) and grid indices, in file order.
fn on_grid(rows: &[Row], first: u32, points_per_rev: u32) -> Result<Vec<RawSample>, CsvError> {
    let step_deg = 360.0 / f64::from(points_per_rev);
    let mut samples = Vec::with_capacity(rows.len());
    for row in rows {
        let index = (row.angle_deg / step_deg).round();
        if (row.angle_deg - index * step_deg).abs() > GRID_TOLERANCE_DEG
            || index >= f64::from(points_per_rev)
        {
            return Err(CsvError::Line {
                line: row.line,
                error: CsvLineError::OffGrid {
                    angle_deg: row.angle_deg,
                    step_deg,
                    points_per_rev,
                },
            });
        }
        // 0 ≤ index < points_per_rev ≤ 100 000 by the checks above.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let angle_index = index as u32;
        samples.push(RawSample {
            revolution: row.revolution - first,
            angle_index,
            lift_mm: row.lift_mm,
        });
    }
    Ok(samples)
}

/// Distinct (revolution, angle index) pairs.
fn distinct_readings(samples: &[RawSample]) -> u64 {
    let mut keys: Vec<u64> = samples
        .iter()
        .map(|s| (u64::from(s.revolution) << 32) | u64::from(s.angle_index))
        .collect();
    keys.sort_unstable();
    keys.dedup();
    keys.len() as u64
}

#[cfg(test)]
mod tests;
