//! Reading one measurement from a file: `.csv` (drop-folder format) or `.log` (candump),
//! chosen by extension, with errors that name the file.
//!
//! The size is checked from the file's metadata before it is opened, and a CSV file is parsed
//! line by line through a bounded buffer, so reading holds the parsed samples and one line,
//! never the whole text. A candump log is read whole (its decoder works on text), which the
//! size limit bounds.

use std::ffi::OsStr;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use camloop_core::measure::RawMeasurement;

use super::candump::{CandumpIssue, read_candump_measurements};
use super::csv_file::{Completeness, CsvError, CsvParser};
use super::dbc::GaugeDbc;

/// Largest measurement file [`read_measurement_file`] reads (a 10 × 360 CSV is about 150 kB,
/// a candump log of 3 × 360 about 50 kB). The drop folder has its own limit.
pub const MAX_FILE_BYTES: u64 = 16 * 1024 * 1024;

/// Longest line of a CSV file, bytes (a data row is about 25).
pub(crate) const MAX_LINE_BYTES: usize = 4096;

/// Why a measurement file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum GaugeError {
    #[error("cannot read measurement file {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("measurement file {path} is {bytes} bytes, over the limit of {limit} bytes")]
    TooLarge {
        path: String,
        bytes: u64,
        limit: u64,
    },
    #[error("measurement file {path} line {line} is longer than {MAX_LINE_BYTES} bytes")]
    LineTooLong { path: String, line: usize },
    #[error("measurement file {path} line {line} is not utf-8 text")]
    NotText { path: String, line: usize },
    #[error("measurement file {path} has no .csv or .log extension")]
    UnknownKind { path: String },
    #[error("measurement file {path}: {source}")]
    Csv { path: String, source: CsvError },
    #[error("candump log {path}: {source}")]
    Candump {
        path: String,
        source: Box<CandumpIssue>,
    },
    #[error("candump log {path} holds {count} complete measurements; exactly one was expected")]
    NotOneMeasurement { path: String, count: usize },
}

/// A measurement read from a file, with what the file says about its completeness (a
/// candump log says nothing: its completeness is `None`).
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementFile {
    pub measurement: RawMeasurement,
    pub completeness: Option<Completeness>,
}

/// Reads one measurement from `path`: `.csv` files by the drop-folder rules (identity from
/// a metadata comment or the file name), `.log` files as candump logs decoded with `dbc`,
/// which must hold exactly one complete measurement and nothing malformed (frames of other
/// ids are ignored). Files over [`MAX_FILE_BYTES`] are refused unread. The measurement's
/// origin is the path as given.
pub fn read_measurement_file(path: &Path, dbc: &GaugeDbc) -> Result<RawMeasurement, GaugeError> {
    open_measurement_file(path, dbc, MAX_FILE_BYTES).map(|f| f.measurement)
}

/// [`read_measurement_file`] with a size limit of `max_bytes`, keeping the completeness.
pub fn open_measurement_file(
    path: &Path,
    dbc: &GaugeDbc,
    max_bytes: u64,
) -> Result<MeasurementFile, GaugeError> {
    let shown = shown_path(path);
    let kind = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(kind.as_deref(), Some("csv" | "log")) {
        return Err(GaugeError::UnknownKind { path: shown });
    }
    let io = |source| GaugeError::Io {
        path: shown_path(path),
        source,
    };
    let bytes = std::fs::metadata(path).map_err(io)?.len();
    if bytes > max_bytes {
        return Err(GaugeError::TooLarge {
            path: shown,
            bytes,
            limit: max_bytes,
        });
    }
    // The limit again while reading, for a file that grows after the metadata was read.
    let file = std::fs::File::open(path).map_err(io)?.take(max_bytes + 1);
    if kind.as_deref() == Some("csv") {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        return read_csv(BufReader::new(file), &name, &shown, max_bytes);
    }
    read_candump(file, dbc, &shown, max_bytes)
}

fn read_csv(
    mut reader: impl BufRead,
    name: &str,
    shown: &str,
    max_bytes: u64,
) -> Result<MeasurementFile, GaugeError> {
    let mut parser = CsvParser::new();
    let mut line = Vec::with_capacity(128);
    let mut total: u64 = 0;
    loop {
        line.clear();
        let read = (&mut reader)
            .take(MAX_LINE_BYTES as u64 + 1)
            .read_until(b'\n', &mut line)
            .map_err(|source| GaugeError::Io {
                path: shown.to_owned(),
                source,
            })?;
        if read == 0 {
            break;
        }
        total += read as u64;
        let number = parser.line() + 1;
        if total > max_bytes {
            return Err(GaugeError::TooLarge {
                path: shown.to_owned(),
                bytes: total,
                limit: max_bytes,
            });
        }
        if line.len() > MAX_LINE_BYTES && line.last() != Some(&b'\n') {
            return Err(GaugeError::LineTooLong {
                path: shown.to_owned(),
                line: number,
            });
        }
        let text = std::str::from_utf8(&line).map_err(|_| GaugeError::NotText {
            path: shown.to_owned(),
            line: number,
        })?;
        parser.push_line(text).map_err(|source| GaugeError::Csv {
            path: shown.to_owned(),
            source,
        })?;
    }
    let parsed = parser
        .finish(name, shown)
        .map_err(|source| GaugeError::Csv {
            path: shown.to_owned(),
            source,
        })?;
    Ok(MeasurementFile {
        measurement: parsed.measurement,
        completeness: Some(parsed.completeness),
    })
}

fn read_candump(
    mut file: impl Read,
    dbc: &GaugeDbc,
    shown: &str,
    max_bytes: u64,
) -> Result<MeasurementFile, GaugeError> {
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes)
        .map_err(|source| GaugeError::Io {
            path: shown.to_owned(),
            source,
        })?;
    if bytes.len() as u64 > max_bytes {
        return Err(GaugeError::TooLarge {
            path: shown.to_owned(),
            bytes: bytes.len() as u64,
            limit: max_bytes,
        });
    }
    let text = String::from_utf8(bytes).map_err(|e| GaugeError::NotText {
        path: shown.to_owned(),
        line: 1 + e.as_bytes()[..e.utf8_error().valid_up_to()]
            .iter()
            .filter(|b| **b == b'\n')
            .count(),
    })?;
    let mut report = read_candump_measurements(&text, dbc, shown);
    if let Some(source) = report.issues.into_iter().next() {
        return Err(GaugeError::Candump {
            path: shown.to_owned(),
            source: Box::new(source),
        });
    }
    match report.measurements.len() {
        1 => Ok(MeasurementFile {
            measurement: report.measurements.remove(0),
            completeness: None,
        }),
        count => Err(GaugeError::NotOneMeasurement {
            path: shown.to_owned(),
            count,
        }),
    }
}

/// A path for messages: as displayed, and when its file name is not UTF-8 (shown with
/// U+FFFD) also the name's bytes escaped, so the operator can find the file.
pub(crate) fn shown_path(path: &Path) -> String {
    let shown = path.display().to_string();
    match path.file_name() {
        Some(name) if name.to_str().is_none() => {
            format!("{shown} (file name bytes \"{}\")", escaped_name(name))
        }
        _ => shown,
    }
}

/// A file name's bytes with everything but printable ASCII escaped (`\xff`).
pub(crate) fn escaped_name(name: &OsStr) -> String {
    name.as_encoded_bytes()
        .iter()
        .flat_map(|b| std::ascii::escape_default(*b))
        .map(char::from)
        .collect()
}
