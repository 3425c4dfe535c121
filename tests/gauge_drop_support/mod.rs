//! Shared helpers of the drop-folder tests: fixture text, listings, CSV writers and a
//! drop folder driven by explicit instants.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use camloop::gauge::{DropEvent, DropFolder, DropOptions, GaugeDbc, Rejection};

pub const FIXTURE: &str = "M3_P1234_L2_20240501T101500.csv";

/// A measurement as a complete drop-folder CSV: its identity and counts in the metadata
/// comments, marked done with `# end`.
pub fn measurement_csv(raw: &camloop::core::measure::RawMeasurement) -> String {
    let h = &raw.header;
    let mut text = format!(
        "# machine={} part={} lobe={}\n# points_per_rev={} revolutions={}\nrev,angle_deg,lift_mm\n",
        h.machine, h.part, h.lobe, h.points_per_rev, h.revolutions
    );
    for s in &raw.samples {
        let angle = f64::from(s.angle_index) * 360.0 / f64::from(h.points_per_rev);
        text.push_str(&format!("{},{angle},{}\n", s.revolution, s.lift_mm));
    }
    text.push_str("# end\n");
    text
}

pub fn fixture_text(name: &str) -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Entry names of `dir`, sorted, lossy.
pub fn names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("list")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// A CSV body (no metadata): `points` readings of each revolution label in `labels`, lift
/// a smooth function of label and angle.
pub fn rows(labels: impl IntoIterator<Item = u32>, points: u32) -> String {
    let mut text = String::from("rev,angle_deg,lift_mm\n");
    for label in labels {
        for k in 0..points {
            let angle = f64::from(k) * 360.0 / f64::from(points);
            let lift = 3.0 * (1.0 - angle.to_radians().cos()) + 1e-4 * f64::from(label);
            text.push_str(&format!("{label},{angle:.6},{lift:.6}\n"));
        }
    }
    text
}

/// A drop folder with `stable_ms` and the default size limit, and the instant it started.
pub struct Folder {
    pub folder: DropFolder,
    pub t0: Instant,
}

impl Folder {
    pub fn open(inbox: &Path, stable_ms: u64) -> Self {
        Self::with(
            inbox,
            DropOptions {
                stable_ms,
                ..DropOptions::default()
            },
        )
    }

    pub fn with(inbox: &Path, options: DropOptions) -> Self {
        let folder = DropFolder::open(inbox, GaugeDbc::builtin(), options).expect("open");
        Self {
            folder,
            t0: Instant::now(),
        }
    }

    /// One poll, `ms` after the start.
    pub fn at(&mut self, ms: u64) -> Vec<DropEvent> {
        self.folder.poll_at(self.t0 + Duration::from_millis(ms))
    }
}

/// The paths of accepted events; panics on any other event.
pub fn accepted(events: &[DropEvent]) -> Vec<PathBuf> {
    events
        .iter()
        .map(|e| match e {
            DropEvent::Accepted { path, .. } => path.clone(),
            other => panic!("expected only accepted files: {other:?}"),
        })
        .collect()
}

/// (file name moved to, reason) of rejected events; panics on any other event.
pub fn rejected(events: &[DropEvent]) -> Vec<(String, String)> {
    events
        .iter()
        .map(|e| match e {
            DropEvent::Rejected {
                moved_to, reason, ..
            } => (
                moved_to
                    .file_name()
                    .expect("name")
                    .to_string_lossy()
                    .into_owned(),
                reason.to_string(),
            ),
            other => panic!("expected only rejected files: {other:?}"),
        })
        .collect()
}

/// The one rejection's typed reason.
pub fn only_rejection(events: &[DropEvent]) -> &Rejection {
    match events {
        [DropEvent::Rejected { reason, .. }] => reason,
        other => panic!("expected one rejection: {other:?}"),
    }
}
