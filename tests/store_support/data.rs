//! Predictable inputs for the store tests: every value derives from a part number, so a
//! test can compute what must come back.

use camloop::names::MachineName;
use camloop::store::{
    HistoryFilter, MeasurementStage, MeasurementSummary, NewMeasurement, NewTableVersion, Store,
    Verdict, VersionStatus,
};
use sha2::{Digest, Sha256};

/// Blob quantisation is 0.1 µm = 1e-4 mm, so a stored lift is within half of that.
pub const LIFT_TOL_MM: f64 = 0.5e-4 + 1e-12;

/// SHA-256 of `text`, computed here independently of the core's digest.
pub fn sha_of(text: &str) -> camloop::digest::Sha256 {
    let hex: String = Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    hex.parse().unwrap()
}

/// Unix milliseconds as an instant (the test values are all within jiff's years).
pub fn ms(unix_ms: i64) -> jiff::Timestamp {
    jiff::Timestamp::from_millisecond(unix_ms).unwrap()
}

/// A measurement whose values all derive from `n`, so the test can predict every column.
pub fn measurement(machine: &str, lobe: &str, n: u32, received_at_ms: i64) -> NewMeasurement {
    let points = 36;
    let lift = |rev: u32, i: u32| {
        let a = f64::from(i) * 10.0_f64.to_radians();
        4.0 * (1.0 - a.cos()) + 1e-3 * f64::from(n) + 1e-4 * f64::from(rev)
    };
    let raw: Vec<Vec<f64>> = (0..3)
        .map(|rev| (0..points).map(|i| lift(rev, i)).collect())
        .collect();
    let averaged = (0..points).map(|i| lift(1, i)).collect();
    NewMeasurement {
        machine: MachineName::new(machine).unwrap(),
        part: format!("P-{n:05}").parse().unwrap(),
        lobe: lobe.parse().unwrap(),
        received_at: ms(received_at_ms),
        verdict: if n.is_multiple_of(4) {
            Verdict::Fail
        } else {
            Verdict::Pass
        },
        max_profile_error_um: 1.5 + f64::from(n) * 0.25,
        base_radius_error_um: -0.5,
        phase_error_deg: 0.01 * f64::from(n),
        revolutions_used: 3,
        stage: MeasurementStage::Final,
        points_per_rev: points,
        origin: "test".into(),
        sha256: sha_of(&format!("{machine}/{lobe}/{n}")),
        recipe_snapshot: None,
        raw_lift_mm: raw,
        averaged_lift_mm: averaged,
        analysis_json: format!(
            r#"{{"part":{n},"max_error_um":{}}}"#,
            1.5 + f64::from(n) * 0.25
        ),
    }
}

pub fn filter(machine: &str) -> HistoryFilter {
    HistoryFilter::new(machine.parse().unwrap(), 7)
}

/// Follows cursors to the end; checks each page's size against the limit.
pub async fn all_pages(store: &Store, mut f: HistoryFilter) -> Vec<MeasurementSummary> {
    let mut out = Vec::new();
    loop {
        let page = store.measurement_history(&f).await.unwrap();
        assert!(page.items.len() <= f.limit as usize);
        if page.next_cursor.is_some() {
            assert_eq!(
                page.items.len(),
                f.limit as usize,
                "only the last page is short"
            );
        }
        out.extend(page.items);
        match page.next_cursor {
            Some(c) => f.cursor = Some(c),
            None => return out,
        }
    }
}

/// A table version whose first status is `status` (the store's name: "waiting", "pushed",
/// "refused") because "checks passed", at 5 000 ms.
pub fn table(
    lobe: &str,
    parent: Option<camloop::core::ids::TableVersion>,
    text: &str,
    status: &str,
) -> NewTableVersion {
    NewTableVersion {
        version: None,
        machine: MachineName::new("M1").unwrap(),
        lobe: lobe.parse().unwrap(),
        parent_version: parent,
        table_number: 11,
        program_text: text.into(),
        learning_params_json: r#"{"gain":0.6}"#.into(),
        reason: "learned".into(),
        status: VersionStatus::from_column(status, "checks passed".into(), 5_000).unwrap(),
        created_at: ms(5_000),
    }
}
