//! Reading one measurement from a file: `.csv` (drop-folder format) or `.log` (candump),
//! chosen by extension, with errors that name the file.

use std::path::Path;

use crate::core::measure::RawMeasurement;

use super::candump::{CandumpIssue, read_candump_measurements};
use super::csv_file::{CsvError, parse_measurement_csv};
use super::dbc::GaugeDbc;

/// Largest measurement file read (a 3 × 360 CSV is about 25 kB, a candump log about 50 kB).
pub const MAX_FILE_BYTES: u64 = 64 * 1024 * 1024;

/// Why a measurement file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum GaugeError {
    #[error("cannot read measurement file {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("measurement file {path} is larger than the {MAX_FILE_BYTES} bytes allowed")]
    TooLarge { path: String },
    #[error("measurement file {path} is not utf-8 text")]
    NotText { path: String },
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

/// Reads one measurement from `path`: `.csv` files by the drop-folder rules (identity from
/// a metadata comment or the file name), `.log` files as candump logs decoded with `dbc`,
/// which must hold exactly one complete measurement and nothing malformed (frames of other
/// ids are ignored). The measurement's origin is the path as given.
pub fn read_measurement_file(path: &Path, dbc: &GaugeDbc) -> Result<RawMeasurement, GaugeError> {
    let shown = path.display().to_string();
    let kind = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(kind.as_deref(), Some("csv" | "log")) {
        return Err(GaugeError::UnknownKind { path: shown });
    }
    let text = read_text(path)?;
    if kind.as_deref() == Some("csv") {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        return parse_measurement_csv(&text, &name, &shown).map_err(|source| GaugeError::Csv {
            path: shown,
            source,
        });
    }
    let mut report = read_candump_measurements(&text, dbc, &shown);
    if let Some(source) = report.issues.into_iter().next() {
        return Err(GaugeError::Candump {
            path: shown,
            source: Box::new(source),
        });
    }
    match report.measurements.len() {
        1 => Ok(report.measurements.remove(0)),
        count => Err(GaugeError::NotOneMeasurement { path: shown, count }),
    }
}

/// Reads a file as UTF-8 text, refusing files over [`MAX_FILE_BYTES`].
pub(crate) fn read_text(path: &Path) -> Result<String, GaugeError> {
    use std::io::Read;
    let shown = || path.display().to_string();
    let io = |source| GaugeError::Io {
        path: shown(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let mut bytes = Vec::new();
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(GaugeError::TooLarge { path: shown() });
    }
    String::from_utf8(bytes).map_err(|_| GaugeError::NotText { path: shown() })
}
