//! Measurement files as CSV (`rev,angle_deg,lift_mm`), as a control or gauge PC writes them
//! into the drop folder: a pure parser from text (plus the file name) to a measurement.
//!
//! Rules:
//! - UTF-8 (a leading BOM is skipped), LF or CRLF, `,` between fields. Blank lines are
//!   ignored; lines starting with `#` are comments.
//! - An optional header row `rev,angle_deg,lift_mm` (any case) before the first data row.
//! - Data rows: `rev` a 0-based whole number, `angle_deg` in [0, 360), `lift_mm` finite with
//!   |lift| ≤ 1000. Rows are kept in file order (the arrival order).
//! - Identity: a metadata comment `# machine=M3 part=P1234 lobe=L2` names all three;
//!   otherwise the file name must be `MACHINE_PART_LOBE[_anything].csv` (fields split on
//!   `_`). A comment carrying any of the keys `machine part lobe points_per_rev revolutions`
//!   is a metadata comment and may only hold `key=value` tokens with those keys.
//! - `points_per_rev` from metadata, else the number of distinct angles in the file. Every
//!   angle must lie on the grid 360°/points_per_rev within 1e-6°; it becomes the angle index.
//! - `revolutions` from metadata (then every `rev` must be below it), else highest `rev` + 1.

use crate::core::measure::{MeasurementHeader, RawMeasurement, RawSample};

use super::assemble::{MAX_POINTS_PER_REV, MAX_REVOLUTIONS, MAX_SAMPLES};
use super::serial::MAX_ABS_LIFT_MM;

/// How far an angle may lie from its grid point, in degrees.
pub const GRID_TOLERANCE_DEG: f64 = 1e-6;
const MAX_ID_CHARS: usize = 32;
const KEYS: [&str; 5] = ["machine", "part", "lobe", "points_per_rev", "revolutions"];

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
    #[error("rev {revolution} is not below the {revolutions} revolutions announced")]
    RevolutionBeyond { revolution: u32, revolutions: u32 },
    #[error(
        "metadata token {found:?} is not key=value with a key among machine, part, lobe, \
         points_per_rev, revolutions"
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
    #[error("metadata names {given} but not {missing}: give machine, part and lobe together")]
    PartialIdentity { given: String, missing: String },
    #[error("{found} points per revolution is outside 1..={MAX_POINTS_PER_REV}")]
    PointsPerRev { found: u64 },
    #[error("{found} revolutions is outside 1..={MAX_REVOLUTIONS}")]
    Revolutions { found: u64 },
}

#[derive(Debug, Default)]
struct Metadata {
    ids: [Option<String>; 3],
    points_per_rev: Option<u32>,
    revolutions: Option<u32>,
}

struct Row {
    line: usize,
    revolution: u32,
    angle_deg: f64,
    lift_mm: f64,
}

/// Parses a CSV measurement. `file_name` (without directories) supplies the identity when
/// no metadata comment does; `origin` is copied into the measurement.
pub fn parse_measurement_csv(
    text: &str,
    file_name: &str,
    origin: &str,
) -> Result<RawMeasurement, CsvError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut meta = Metadata::default();
    let mut rows: Vec<Row> = Vec::new();
    let mut seen_data_or_header = false;
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let at = |error| CsvError::Line { line, error };
        let trimmed = raw.trim();
        if trimmed.is_empty() {
            continue;
        }
        if let Some(comment) = trimmed.strip_prefix('#') {
            read_metadata(comment, &mut meta).map_err(at)?;
            continue;
        }
        let first_row = !seen_data_or_header;
        seen_data_or_header = true;
        if first_row && trimmed.starts_with(|c: char| c.is_ascii_alphabetic()) {
            if is_header(trimmed) {
                continue;
            }
            return Err(at(CsvLineError::UnexpectedHeader {
                found: clip(trimmed),
            }));
        }
        if rows.len() as u64 >= MAX_SAMPLES {
            return Err(CsvError::TooManySamples);
        }
        rows.push(parse_row(line, trimmed).map_err(at)?);
    }
    if rows.is_empty() {
        return Err(CsvError::NoSamples);
    }
    let [machine, part, lobe] = identity(meta.ids, file_name)?;
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
    let revolutions = match meta.revolutions {
        Some(r) => r,
        None => {
            let found = rows
                .iter()
                .map(|r| u64::from(r.revolution))
                .max()
                .unwrap_or(0)
                + 1;
            u32::try_from(found)
                .ok()
                .filter(|r| *r <= MAX_REVOLUTIONS)
                .ok_or(CsvError::Revolutions { found })?
        }
    };
    let step_deg = 360.0 / f64::from(points_per_rev);
    let mut samples = Vec::with_capacity(rows.len());
    for row in rows {
        let at = |error| CsvError::Line {
            line: row.line,
            error,
        };
        if row.revolution >= revolutions {
            return Err(at(CsvLineError::RevolutionBeyond {
                revolution: row.revolution,
                revolutions,
            }));
        }
        let index = (row.angle_deg / step_deg).round();
        if (row.angle_deg - index * step_deg).abs() > GRID_TOLERANCE_DEG
            || index >= f64::from(points_per_rev)
        {
            return Err(at(CsvLineError::OffGrid {
                angle_deg: row.angle_deg,
                step_deg,
                points_per_rev,
            }));
        }
        // 0 ≤ index < points_per_rev ≤ 100 000 by the checks above.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let angle_index = index as u32;
        samples.push(RawSample {
            revolution: row.revolution,
            angle_index,
            lift_mm: row.lift_mm,
        });
    }
    Ok(RawMeasurement {
        header: MeasurementHeader {
            machine,
            part,
            lobe,
            revolutions,
            points_per_rev,
        },
        samples,
        origin: origin.to_owned(),
    })
}

fn is_header(line: &str) -> bool {
    let fields: Vec<String> = line.split(',').map(|f| f.trim().to_lowercase()).collect();
    fields == ["rev", "angle_deg", "lift_mm"]
}

fn parse_row(line: usize, text: &str) -> Result<Row, CsvLineError> {
    let fields: Vec<&str> = text.split(',').map(str::trim).collect();
    let [rev, angle, lift] = fields.as_slice() else {
        return Err(CsvLineError::FieldCount {
            found: fields.len(),
        });
    };
    let revolution = rev
        .bytes()
        .all(|b| b.is_ascii_digit())
        .then(|| rev.parse::<u32>().ok())
        .flatten()
        .ok_or_else(|| CsvLineError::Revolution { found: clip(rev) })?;
    let angle_deg = angle
        .parse::<f64>()
        .ok()
        .filter(|a| (0.0..360.0).contains(a))
        .ok_or_else(|| CsvLineError::Angle { found: clip(angle) })?;
    let lift_mm = lift
        .parse::<f64>()
        .ok()
        .filter(|l| l.abs() <= MAX_ABS_LIFT_MM)
        .ok_or_else(|| CsvLineError::Lift { found: clip(lift) })?;
    Ok(Row {
        line,
        revolution,
        angle_deg,
        lift_mm,
    })
}

fn read_metadata(comment: &str, meta: &mut Metadata) -> Result<(), CsvLineError> {
    let tokens: Vec<&str> = comment.split_whitespace().collect();
    let is_meta = tokens.iter().any(|t| {
        t.split_once('=')
            .is_some_and(|(key, _)| KEYS.contains(&key))
    });
    if !is_meta {
        return Ok(());
    }
    for token in tokens {
        let Some((key, value)) = token
            .split_once('=')
            .and_then(|(k, v)| KEYS.iter().find(|known| **known == k).map(|k| (*k, v)))
        else {
            return Err(CsvLineError::MetadataToken { found: clip(token) });
        };
        let bad = |expected| CsvLineError::MetadataValue {
            key,
            found: clip(value),
            expected,
        };
        match key {
            "machine" | "part" | "lobe" => {
                if !valid_id(value) {
                    return Err(bad("1–32 characters of A–Z a–z 0–9 . _ -"));
                }
                let slot = match key {
                    "machine" => &mut meta.ids[0],
                    "part" => &mut meta.ids[1],
                    _ => &mut meta.ids[2],
                };
                set_once(slot, value.to_owned(), key)?;
            }
            "points_per_rev" => {
                let v = whole(value, 1, MAX_POINTS_PER_REV)
                    .ok_or_else(|| bad("a whole number in 1..=100000"))?;
                set_once(&mut meta.points_per_rev, v, key)?;
            }
            _ => {
                let v = whole(value, 1, MAX_REVOLUTIONS)
                    .ok_or_else(|| bad("a whole number in 1..=1000"))?;
                set_once(&mut meta.revolutions, v, key)?;
            }
        }
    }
    Ok(())
}

fn set_once<T: PartialEq>(
    slot: &mut Option<T>,
    value: T,
    key: &'static str,
) -> Result<(), CsvLineError> {
    match slot {
        Some(existing) if *existing != value => Err(CsvLineError::MetadataConflict { key }),
        _ => {
            *slot = Some(value);
            Ok(())
        }
    }
}

fn whole(text: &str, min: u32, max: u32) -> Option<u32> {
    text.bytes()
        .all(|b| b.is_ascii_digit())
        .then(|| text.parse::<u32>().ok())
        .flatten()
        .filter(|v| (min..=max).contains(v))
}

fn valid_id(text: &str) -> bool {
    (1..=MAX_ID_CHARS).contains(&text.len())
        && text
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-'))
}

fn identity(ids: [Option<String>; 3], file_name: &str) -> Result<[String; 3], CsvError> {
    const NAMES: [&str; 3] = ["machine", "part", "lobe"];
    match ids {
        [Some(m), Some(p), Some(l)] => Ok([m, p, l]),
        [None, None, None] => {
            let stem = file_name
                .rsplit_once('.')
                .map_or(file_name, |(stem, _)| stem);
            let fields: Vec<&str> = stem.split('_').collect();
            match fields.as_slice() {
                [m, p, l, ..] if [m, p, l].iter().all(|f| valid_id(f)) => {
                    Ok([(*m).to_owned(), (*p).to_owned(), (*l).to_owned()])
                }
                _ => Err(CsvError::NoIdentity {
                    file_name: file_name.to_owned(),
                }),
            }
        }
        partial => {
            let pick = |present: bool| {
                NAMES
                    .iter()
                    .zip(&partial)
                    .filter(|(_, v)| v.is_some() == present)
                    .map(|(n, _)| *n)
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            Err(CsvError::PartialIdentity {
                given: pick(true),
                missing: pick(false),
            })
        }
    }
}

/// Distinct angles, treating angles closer than the grid tolerance as one.
fn distinct_angles(rows: &[Row]) -> usize {
    let mut angles: Vec<f64> = rows.iter().map(|r| r.angle_deg).collect();
    angles.sort_by(f64::total_cmp);
    angles.dedup_by(|a, b| (*a - *b).abs() <= GRID_TOLERANCE_DEG);
    angles.len()
}

fn clip(text: &str) -> String {
    const MAX: usize = 40;
    match text.char_indices().nth(MAX) {
        Some((cut, _)) => format!("{}…", &text[..cut]),
        None => text.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str, name: &str) -> Result<RawMeasurement, String> {
        parse_measurement_csv(text, name, "drop").map_err(|e| e.to_string())
    }

    #[test]
    fn identity_from_the_file_name_and_grid_from_the_angles() {
        let m = parse(
            "\u{feff}rev, Angle_deg ,LIFT_MM\r\n0,0,0.0\r\n0,90,1.5\r\n0,180.0000004,3\r\n\
             0,270,1.5\r\n1,0,0.01\r\n",
            "M3_P1234_L2_20240501.csv",
        )
        .expect("valid");
        assert_eq!(
            (
                m.header.machine.as_str(),
                m.header.part.as_str(),
                m.header.lobe.as_str()
            ),
            ("M3", "P1234", "L2")
        );
        assert_eq!((m.header.revolutions, m.header.points_per_rev), (2, 4));
        let got: Vec<(u32, u32, f64)> = m
            .samples
            .iter()
            .map(|s| (s.revolution, s.angle_index, s.lift_mm))
            .collect();
        assert_eq!(
            got,
            [
                (0, 0, 0.0),
                (0, 1, 1.5),
                (0, 2, 3.0),
                (0, 3, 1.5),
                (1, 0, 0.01)
            ]
        );
        assert_eq!(m.origin, "drop");
    }

    #[test]
    fn metadata_comments_override_the_file_name() {
        let m = parse(
            "# machine=G7 part=X-9 lobe=pin.1\n# free text comment\n#points_per_rev=8 revolutions=3\n\
             0,45,0.5\n2,315,-0.001\n",
            "scan.csv",
        )
        .expect("valid");
        assert_eq!(
            (
                m.header.machine.as_str(),
                m.header.part.as_str(),
                m.header.lobe.as_str()
            ),
            ("G7", "X-9", "pin.1")
        );
        assert_eq!((m.header.revolutions, m.header.points_per_rev), (3, 8));
        assert_eq!(m.samples[1].angle_index, 7);
    }

    #[test]
    fn errors_name_the_line() {
        let name = "M3_P1_L1.csv";
        let cases = [
            (
                "0,0,0\n0,1\n",
                "line 2: expected 3 fields rev,angle_deg,lift_mm, found 2",
            ),
            (
                "revolution,angle,lift\n0,0,0\n",
                "line 1: expected the header rev,angle_deg,lift_mm or a data row, found \
                 \"revolution,angle,lift\"",
            ),
            (
                "0,0,0\n-1,1,0\n",
                "line 2: rev \"-1\" is not a whole number ≥ 0",
            ),
            (
                "0,360,0\n",
                "line 1: angle \"360\" is not a number in [0, 360) degrees",
            ),
            (
                "0,NaN,0\n",
                "line 1: angle \"NaN\" is not a number in [0, 360) degrees",
            ),
            (
                "0,0,inf\n",
                "line 1: lift \"inf\" is not a finite number of mm within ±1000",
            ),
            (
                "# points_per_rev=360\n0,0,0\n\n0,1.5,0\n",
                "line 4: angle 1.5° is not on the 1° grid of 360 points per revolution \
                 (tolerance 0.000001°)",
            ),
            (
                "0,0,0\n0,120,0\n0,200,0\n",
                "line 3: angle 200° is not on the 120° grid of 3 points per revolution \
                 (tolerance 0.000001°)",
            ),
            (
                "# revolutions=3\n3,0,0\n",
                "line 2: rev 3 is not below the 3 revolutions announced",
            ),
            (
                "# machine=M3 shift=night\n0,0,0\n",
                "line 1: metadata token \"shift=night\" is not key=value with a key among \
                 machine, part, lobe, points_per_rev, revolutions",
            ),
            (
                "# points_per_rev=0\n",
                "line 1: metadata points_per_rev=\"0\" is invalid: a whole number in 1..=100000",
            ),
            (
                "# lobe=L1\n# lobe=L2\n",
                "line 2: metadata lobe given twice with different values",
            ),
            ("# only comments\n\n", "no data rows"),
            (
                "# machine=M3\n0,0,0\n",
                "metadata names machine but not part, lobe: give machine, part and lobe \
                 together",
            ),
        ];
        for (text, expected) in cases {
            assert_eq!(parse(text, name), Err(expected.to_owned()), "{text:?}");
        }
        assert_eq!(
            parse("0,0,0\n", "lobe scan.csv"),
            Err(
                "machine, part and lobe unknown: add a `# machine=… part=… lobe=…` comment \
                 line or name the file MACHINE_PART_LOBE[_…].csv (file name \"lobe scan.csv\")"
                    .to_owned()
            )
        );
    }
}
