//! The records a machine writes: events, measurements as the journal keeps them, rejects
//! kept on disk with their reason.

use super::super::journal::{EventKind, Pending};
use crate::core::digest::Sha256;
use crate::core::measure::RawMeasurement;
use crate::names::MachineName;
use crate::store::EventLevel;
use std::path::Path;

pub(super) fn event(
    machine: &MachineName,
    at_ms: jiff::Timestamp,
    level: EventLevel,
    kind: EventKind,
    message: String,
) -> Pending {
    Pending::Event {
        machine: machine.clone(),
        at_ms,
        level,
        kind,
        message,
    }
}

/// Raw lifts per revolution, in revolution order (samples are complete after the checks).
pub(super) fn raw_revolutions(raw: &RawMeasurement) -> Vec<Vec<f64>> {
    let n = raw.header.points_per_rev as usize;
    let revs = raw.header.revolutions as usize;
    let mut out = vec![vec![0.0; n]; revs];
    for s in &raw.samples {
        if let Some(slot) = out
            .get_mut(s.revolution as usize)
            .and_then(|r| r.get_mut(s.angle_index as usize))
        {
            *slot = s.lift_mm;
        }
    }
    out
}

/// A rejected measurement is kept as CSV in `<dir>` with its reason beside it, named by its
/// content identity (so a repeat overwrites rather than piles up).
pub(super) fn keep_reject(
    dir: &Path,
    raw: &RawMeasurement,
    sha: &Sha256,
    reason: &str,
) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut csv = format!(
        "# machine={} part={} lobe={}\n# points_per_rev={} revolutions={}\n# origin: {}\nrev,angle_deg,lift_mm\n",
        raw.header.machine,
        raw.header.part,
        raw.header.lobe,
        raw.header.points_per_rev,
        raw.header.revolutions,
        raw.origin.replace('\n', " ")
    );
    for s in &raw.samples {
        let angle = f64::from(s.angle_index) * 360.0 / f64::from(raw.header.points_per_rev.max(1));
        csv.push_str(&format!("{},{angle},{}\n", s.revolution, s.lift_mm));
    }
    let hex = sha.to_string();
    let stem = &hex[..16];
    std::fs::write(dir.join(format!("{stem}.csv")), csv)?;
    std::fs::write(
        dir.join(format!("{stem}.reason.txt")),
        format!("{reason}\n"),
    )
}
