//! Why the drop folder rejected a file ([`Rejection`], also the text of its reason file) and
//! why it could not do its own work ([`DropFolderError`]).

use super::dressing::DressingError;
use super::drop_names::EntryKind;
use super::file::GaugeError;

/// Why a file in the drop folder was moved to `rejected/`. The display text is what the
/// reason file holds; paths are shown with a non-UTF-8 name's bytes escaped.
#[derive(Debug, thiserror::Error)]
pub enum Rejection {
    #[error(
        "file {path} is {bytes} bytes, over the drop folder's limit of {limit} bytes: \
         not read"
    )]
    TooLarge {
        path: String,
        bytes: u64,
        limit: u64,
    },
    #[error(
        "measurement file {path} declares {declared} revolutions of {points_per_rev} points \
         but holds {found} revolutions ({readings_found} of {readings_expected} readings) {}",
        incomplete_why(*.end_marker, *.stable_ms)
    )]
    Incomplete {
        path: String,
        declared: u32,
        points_per_rev: u32,
        /// Revolution labels present.
        found: u32,
        readings_found: u64,
        readings_expected: u64,
        /// The writer said it was done.
        end_marker: bool,
        /// Otherwise: how long the file stayed unchanged, ms.
        stable_ms: u64,
    },
    #[error(transparent)]
    Measurement(GaugeError),
    #[error(transparent)]
    Dressing(DressingError),
    #[error("{path} is {kind}, not a regular file: moved aside without opening or following it")]
    NotAFile { path: String, kind: EntryKind },
}

fn incomplete_why(end_marker: bool, stable_ms: u64) -> String {
    if end_marker {
        "and ends with the `# end` marker".to_owned()
    } else {
        format!("and has not changed for {stable_ms} ms")
    }
}

/// Why the drop folder could not be used or could not move a file.
#[derive(Debug, thiserror::Error)]
pub enum DropFolderError {
    #[error("drop folder {path} unusable: {source}")]
    Unusable {
        path: String,
        source: std::io::Error,
    },
    #[error("cannot list drop folder {path}: {source}")]
    List {
        path: String,
        source: std::io::Error,
    },
    #[error("{path} is not a file handed out by this drop folder and not yet settled")]
    NotClaimed { path: String },
    #[error("cannot move {from} to {to}: {source}")]
    Move {
        from: String,
        to: String,
        source: std::io::Error,
    },
    #[error("cannot write the reason file {path} ({reason}): {source}")]
    ReasonFile {
        path: String,
        reason: String,
        source: std::io::Error,
    },
}
