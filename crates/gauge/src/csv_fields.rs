//! Field-level rules of the CSV measurement format: data rows, the header row, metadata
//! comments and identity from the file name. The file-level rules live in `csv_file`.

use super::assemble::{MAX_POINTS_PER_REV, MAX_REVOLUTIONS};
use super::csv_file::{CsvError, CsvLineError, GRID_TOLERANCE_DEG};
use super::serial::MAX_ABS_LIFT_MM;

const MAX_ID_CHARS: usize = 32;
const KEYS: [&str; 6] = [
    "machine",
    "part",
    "lobe",
    "points_per_rev",
    "revolutions",
    "master",
];

#[derive(Debug, Default)]
pub(super) struct Metadata {
    pub(super) ids: [Option<String>; 3],
    pub(super) points_per_rev: Option<u32>,
    pub(super) revolutions: Option<u32>,
    /// `master=<id>`: the part id of a master run (see [`master_part`]).
    pub(super) master: Option<String>,
}

pub(super) struct Row {
    pub(super) line: usize,
    pub(super) revolution: u32,
    pub(super) angle_deg: f64,
    pub(super) lift_mm: f64,
}

pub(super) fn is_header(line: &str) -> bool {
    let fields: Vec<String> = line.split(',').map(|f| f.trim().to_lowercase()).collect();
    fields == ["rev", "angle_deg", "lift_mm"]
}

// Hand-written on purpose, not the `csv` crate: the file holds numbers only (no quoting to
// handle), and a line may end in a `# note` or be a `# key=value` metadata line, which the crate's `comment` option cannot
// express (it skips only lines that start with the comment byte). A split keeps the line
// number and the field in every error without a second pass.
pub(super) fn parse_row(line: usize, text: &str) -> Result<Row, CsvLineError> {
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

pub(super) fn read_metadata(comment: &str, meta: &mut Metadata) -> Result<(), CsvLineError> {
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
            "master" => {
                let part = master_part(value).ok_or_else(|| {
                    bad("1–25 characters of A–Z a–z 0–9 . _ - (a part MASTER-id)")
                })?;
                set_once(&mut meta.master, part, key)?;
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

pub(super) fn set_once<T: PartialEq>(
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

pub(super) fn whole(text: &str, min: u32, max: u32) -> Option<u32> {
    text.bytes()
        .all(|b| b.is_ascii_digit())
        .then(|| text.parse::<u32>().ok())
        .flatten()
        .filter(|v| (min..=max).contains(v))
}

pub(super) fn valid_id(text: &str) -> bool {
    (1..=MAX_ID_CHARS).contains(&text.len())
        && text
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-'))
}

/// The part id a `# master=<id>` line gives: `<id>` when it already reads as a master run
/// (`MASTER…`, any case), else `MASTER-<id>`, so that the service and every listing tell it
/// from a production part by its id alone; `None` when that is no valid id (at most 32).
pub(super) fn master_part(id: &str) -> Option<String> {
    let part = if camloop_core::measure::is_master_part(id) {
        id.to_owned()
    } else {
        format!("{}-{id}", camloop_core::measure::MASTER_PART_PREFIX)
    };
    (valid_id(id) && valid_id(&part)).then_some(part)
}

/// Machine, part and lobe from the metadata, else from the file name; a `master=` line
/// names the part (it is the master run's), and a `part=` that differs from it is refused
/// rather than one of the two dropped.
pub(super) fn identity(
    mut ids: [Option<String>; 3],
    master: Option<String>,
    file_name: &str,
) -> Result<[String; 3], CsvError> {
    let Some(master) = master else {
        return named_identity(ids, file_name);
    };
    if let Some(part) = ids[1].as_ref().filter(|p| **p != master) {
        return Err(CsvError::MasterConflict {
            part: part.clone(),
            master,
        });
    }
    if ids[0].is_some() || ids[2].is_some() {
        ids[1] = Some(master.clone());
    }
    let [machine, _, lobe] = named_identity(ids, file_name)?;
    Ok([machine, master, lobe])
}

fn named_identity(ids: [Option<String>; 3], file_name: &str) -> Result<[String; 3], CsvError> {
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
pub(super) fn distinct_angles(rows: &[Row]) -> usize {
    let mut angles: Vec<f64> = rows.iter().map(|r| r.angle_deg).collect();
    angles.sort_by(f64::total_cmp);
    angles.dedup_by(|a, b| (*a - *b).abs() <= GRID_TOLERANCE_DEG);
    angles.len()
}

pub(super) fn clip(text: &str) -> String {
    const MAX: usize = 40;
    match text.char_indices().nth(MAX) {
        Some((cut, _)) => format!("{}…", &text[..cut]),
        None => text.to_owned(),
    }
}
