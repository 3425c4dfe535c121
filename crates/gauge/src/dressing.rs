//! Wheel-dressing reports: a one-line TOML file (`*.dressing.toml`) that the control's
//! dressing cycle writes into the drop folder, read with errors naming the file and line.

use std::path::Path;

use camloop_core::compensate::WheelRadiusError;
use camloop_core::learn::DresserInfeedError;

use super::file::shown_path;

/// Suffix of a wheel-dressing report (any case).
pub const DRESSING_SUFFIX: &str = ".dressing.toml";

/// Largest dressing report read, bytes (a report is one line).
pub(crate) const MAX_DRESSING_BYTES: u64 = 64 * 1024;

/// A wheel-dressing report, written by the control's dressing cycle (or whoever dresses)
/// into the drop folder, one line (and optionally the `# end` marker line):
///
/// ```toml
/// wheel_radius_mm = 249.998
/// infeed_um = 20.1
/// ```
///
/// `infeed_um`, the radius the dresser removed as it measured it (its infeed from first
/// contact), is optional; with it the loop knows the size step of the dressing.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DressingReport {
    /// The wheel radius after dressing, as the control now believes it, mm.
    pub wheel_radius_mm: f64,
    /// The dresser's measured infeed (radius removed), µm.
    #[serde(default)]
    pub infeed_um: Option<f64>,
}

/// Why a dressing report could not be used.
#[derive(Debug, thiserror::Error)]
pub enum DressingError {
    #[error("cannot read dressing report {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error(
        "dressing report {path} is {bytes} bytes, over the limit of {MAX_DRESSING_BYTES} bytes"
    )]
    TooLarge { path: String, bytes: u64 },
    #[error("dressing report {path} is not utf-8 text")]
    NotText { path: String },
    #[error("dressing report {path}{}: {message}", line_text(*.line))]
    Syntax {
        path: String,
        line: Option<usize>,
        message: String,
    },
    #[error("dressing report {path}: {source}")]
    Radius {
        path: String,
        source: WheelRadiusError,
    },
    #[error("dressing report {path}: {source}")]
    Infeed {
        path: String,
        source: DresserInfeedError,
    },
}

fn line_text(line: Option<usize>) -> String {
    line.map(|l| format!(" line {l}")).unwrap_or_default()
}

/// A dressing report and whether it ends with the `# end` marker line (then it is known to
/// be complete without waiting for it to stay unchanged).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DressingFile {
    pub report: DressingReport,
    pub end_marker: bool,
}

/// Reads a dressing report; errors name the file and, for syntax, the line.
pub fn read_dressing_file(path: &Path) -> Result<DressingReport, DressingError> {
    open_dressing_file(path).map(|f| f.report)
}

/// [`read_dressing_file`], also telling whether the file carries the `# end` marker.
pub fn open_dressing_file(path: &Path) -> Result<DressingFile, DressingError> {
    let shown = || shown_path(path);
    let io = |source| DressingError::Io {
        path: shown(),
        source,
    };
    let bytes = std::fs::metadata(path).map_err(io)?.len();
    if bytes > MAX_DRESSING_BYTES {
        return Err(DressingError::TooLarge {
            path: shown(),
            bytes,
        });
    }
    let raw = std::fs::read(path).map_err(io)?;
    let text = String::from_utf8(raw).map_err(|_| DressingError::NotText { path: shown() })?;
    let report: DressingReport = toml::from_str(&text).map_err(|e| DressingError::Syntax {
        path: shown(),
        line: e.span().map(|s| text[..s.start].matches('\n').count() + 1),
        message: e.message().trim_end_matches('\n').to_owned(),
    })?;
    camloop_core::compensate::check_wheel_radius(report.wheel_radius_mm).map_err(|source| {
        DressingError::Radius {
            path: shown(),
            source,
        }
    })?;
    if let Some(infeed) = report.infeed_um {
        camloop_core::learn::check_dresser_infeed(infeed).map_err(|source| {
            DressingError::Infeed {
                path: shown(),
                source,
            }
        })?;
    }
    let end_marker = text.lines().any(|l| {
        l.trim()
            .strip_prefix('#')
            .is_some_and(|c| c.trim().eq_ignore_ascii_case("end"))
    });
    Ok(DressingFile { report, end_marker })
}
