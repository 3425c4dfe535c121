//! Program delivery to the controller's file share: atomic, verified pushes with a kept,
//! append-only version history and rollback. A version that cannot be delivered waits in the
//! state folder (superseded by a newer one); the service's machine task retries it between
//! parts, so nothing is lost while the share is missing, read-only or full.
//!
//! # Push protocol (per version)
//! 1. The version's text is stored in the state folder (temporary folder, files flushed,
//!    renamed to `versions/vNNNNNN`, folder flushed), then its manifest line is appended and
//!    flushed. From here it is never lost: it waits until delivered or superseded.
//! 2. Every file is written to `<share>/.camloop-tmp-<random>` and flushed (`fsync`).
//! 3. A `delivering` line is appended; from here the control may see the version.
//! 4. Each temporary is renamed over its program file, in request order; the share folder
//!    is flushed.
//! 5. Every file is read back and its SHA-256 compared with the manifest; a `pushed` line
//!    is appended (flushed with the next line: losing it only repeats the delivery).
//!
//! A rename within one folder is atomic, so the control sees either the previous complete
//! file or the new complete file, never a partial one, whenever the process dies. Between
//! the renames of a multi-file version the control can see the new subprogram with the old
//! main program (hence: main program last). Temporaries left by a killed run are removed at
//! the next start (only names starting with `.camloop-tmp-`).
//!
//! # State folder layout (camloop's own, never the share)
//! ```text
//! <state>/manifest.jsonl            append-only JSON lines, one record each (see manifest)
//! <state>/versions/v000001/CAM_T1.SPF   kept text of version 1, one file per program file
//! <state>/versions/v000002/...
//! <state>/versions/.camloop-tmp-*   a version being stored (removed at start if left over)
//! ```
//! The share holds only program files: each version's files overwrite the same names, so
//! with alternating `CAM_T1.SPF` / `CAM_T2.SPF` it holds both tables (the previous one may be
//! the one the control runs) and the main program. One camloop process per state folder and
//! per share: start-up cleanup would remove another process's temporaries.
//!
//! # Table numbers
//! A version must define [`Share::next_table_number`]: the other table of the configured
//! pair than the newest version that may be on the share (it reached step 3, confirmed or
//! not). Any other number is recorded as refused, so the table the control may be using is
//! never redefined.

mod compact;
mod error;
mod fence;
mod fs;
mod manifest;
mod request;
mod state;
mod store;

pub use compact::{ARCHIVE_FILE, COMPACT_AFTER_LINES, Checkpoint};
pub use error::{PushError, ShareError, StateError};
pub use fence::{Fence, Held, read_epoch as fence_epoch};
pub use fs::{RealFs, ShareFs, TEMP_PREFIX, lower_hex, sha256_hex};
pub use manifest::{
    FileRecord, History, Loaded, Record, VersionRecord, VersionState, VersionStatus,
    load as load_manifest,
};
pub use request::{OpenReport, ProgramFile, PushRequest, Pushed, Submitted};
pub(crate) use state::version_dir;
pub use store::{Clock, MANIFEST_FILE, Share, ShareConfig, VERSIONS_DIR};

/// Version `n` for the share's unit tests (they count versions from 1).
#[cfg(test)]
fn test_version(n: u64) -> crate::core::ids::TableVersion {
    crate::core::ids::TableVersion::new(n).expect("versions count from 1")
}
