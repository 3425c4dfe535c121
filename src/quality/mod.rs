//! Process quality of the stored history: capability of each characteristic over a window
//! of parts, the control charts and their run rules, and the type-1 gauge study of master
//! runs. The statistics are the core's (`core::capability`); this module picks the window
//! from the store and the limits from the recipe.
//!
//! Master runs (part ids `MASTER…`, [`crate::core::measure::is_master_part`]) are never
//! production parts: a capability window skips them, a gauge study takes only them.

pub mod limits;
pub mod render;
mod sheet;
pub mod study;

use crate::core::capability::{
    self, Capability, Characteristic, PartValues, chart::ChartLimits, chart::ChartPoint,
};
use crate::core::ids::PartId;
use crate::core::measure::is_master_part;
use crate::names::{FeatureName, MachineName};
use crate::store::{
    MAX_PAGE, MeasurementDetail, MeasurementId, MeasurementStage, Store, StoreError,
};
pub use limits::{CharacteristicLimits, FeatureLimits};
pub use sheet::{Drawings, FeatureSheet, FeatureSheets};

/// Fewer values than this and a capability figure is indicative only: shown, but marked.
///
/// The AIAG SPC manual asks a capability study for 25 or more subgroups holding 100 or more
/// values. Each part here is a subgroup of one (the individuals chart), so 25 subgroups would
/// be only 25 values: the value count is what binds. The lower 95 % bounds show why: for an
/// estimated Cpk of 1.33, Bissell's bound is 1.17 at 100 values (12 % below the estimate),
/// 1.00 at 25 and 0.67 at 7; Cp's chi-square bound is 0.88·Cp at 100, 0.52·Cp at 7. The
/// expected ppm extrapolates the fitted model far into its tail and is the least settled of
/// all. The default window (125 parts) meets the minimum.
pub const MIN_CAPABILITY_VALUES: usize = 100;

/// Which parts of a feature's history a study takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Window {
    /// The newest this many production parts (at most [`MAX_PAGE`]).
    pub last: u32,
    pub since: Option<jiff::Timestamp>,
    pub until: Option<jiff::Timestamp>,
    /// Only parts after the machine's newest wheel dressing.
    pub since_dressing: bool,
    /// Only parts after the feature's recipe last changed (the store's newest snapshot).
    pub since_recipe_change: bool,
}

impl Default for Window {
    fn default() -> Self {
        Self {
            last: 125,
            since: None,
            until: None,
            since_dressing: false,
            since_recipe_change: false,
        }
    }
}

/// A stored part as the studies see it.
#[derive(Debug, Clone, PartialEq)]
pub struct PartRow {
    pub id: MeasurementId,
    pub part: PartId,
    pub received_at: jiff::Timestamp,
    pub max_profile_error_um: f64,
    pub base_radius_error_um: f64,
    pub phase_error_deg: f64,
    pub error_um: Vec<f64>,
}

impl PartRow {
    /// The part's row, its error curve read from the analysis the measurement stored. An
    /// analysis without the field is an error naming the measurement, never an empty curve:
    /// a renamed field would otherwise empty every study without a word.
    fn from_detail(d: &MeasurementDetail) -> Result<Self, StoreError> {
        let s = &d.summary;
        let report = StoredReport::parse(&d.analysis_json).map_err(|e| {
            StoreError::invalid("analysis_json", format!("measurement {}: {e}", s.id.0))
        })?;
        Ok(Self {
            id: s.id,
            part: s.part.clone(),
            received_at: s.received_at,
            max_profile_error_um: s.max_profile_error_um,
            base_radius_error_um: s.base_radius_error_um,
            phase_error_deg: s.phase_error_deg,
            error_um: report.error_um,
        })
    }

    /// Characteristic `c` of this part, for a feature at `phase_deg` on the shaft.
    pub fn value(&self, c: Characteristic, phase_deg: f64) -> Option<f64> {
        c.value(&PartValues {
            max_profile_error_um: self.max_profile_error_um,
            base_radius_error_um: self.base_radius_error_um,
            phase_error_deg: self.phase_error_deg,
            error_um: &self.error_um,
            phase_deg,
        })
    }
}

/// What the quality module reads of the analysis a measurement stored: the fields of the
/// core's report (`core::analysis::LobeReport`, which the measurement keeps as JSON) it uses,
/// each required.
#[derive(Debug, serde::Deserialize)]
struct StoredReport {
    /// Measured − nominal lift per angle, µm (`LobeReport::error_um`).
    error_um: Vec<f64>,
}

impl StoredReport {
    fn parse(analysis_json: &str) -> Result<Self, serde_json::Error> {
        serde_json::from_str(analysis_json)
    }
}

/// The window's finished parts (stage `final`; in-process rows are never judged), oldest
/// first: production parts, or (with `masters`) master runs only.
/// Also returns the start the window took, if any, and how many of the other kind it skipped.
pub(crate) async fn window_rows(
    store: &Store,
    machine: &MachineName,
    lobe: &FeatureName,
    window: &Window,
    masters: bool,
) -> Result<(Vec<PartRow>, Option<jiff::Timestamp>, usize), StoreError> {
    let mut since = window.since;
    if window.since_dressing
        && let Some(d) = store.dressings(machine, 1).await?.first()
    {
        since = since.max(Some(d.at));
    }
    if window.since_recipe_change
        && let Some(f) = store
            .features(machine)
            .await?
            .iter()
            .find(|f| f.lobe == *lobe)
    {
        since = since.max(Some(f.created_at));
    }
    let (start, until) = (
        since.unwrap_or(jiff::Timestamp::MIN),
        window.until.unwrap_or(jiff::Timestamp::MAX),
    );
    let wanted = window.last.clamp(1, MAX_PAGE) as usize;
    let (mut rows, mut skipped, mut before) = (Vec::new(), 0usize, None);
    while rows.len() < wanted {
        let batch = store
            .feature_measurements(machine, lobe, (start, until), before, 500)
            .await?;
        let Some(last) = batch.last() else { break };
        before = Some(last.summary.id);
        for d in &batch {
            // Only finished parts are judged: an in-process measurement has stock on.
            if d.summary.stage != MeasurementStage::Final {
                continue;
            }
            if is_master_part(&d.summary.part) == masters {
                if rows.len() < wanted {
                    rows.push(PartRow::from_detail(d)?);
                }
            } else {
                skipped += 1;
            }
        }
    }
    rows.reverse();
    Ok((rows, since, skipped))
}

/// One characteristic's study over the window.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CharacteristicStudy {
    pub characteristic: Characteristic,
    pub unit: &'static str,
    pub limits: CharacteristicLimits,
    pub capability: Option<Capability>,
    /// Why there is no capability, or no index: in words.
    pub note: Option<String>,
    /// The statistics rest on fewer than [`MIN_CAPABILITY_VALUES`] values: the figures are
    /// indicative only.
    pub indicative: bool,
    /// The I-MR/EWMA chart: limits from the window's first
    /// [`capability::chart::BASELINE_PARTS`] parts.
    pub chart: Option<Chart>,
}

/// A characteristic's chart over the window.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Chart {
    pub limits: ChartLimits,
    pub part: Vec<PartId>,
    pub points: Vec<ChartPoint>,
}

/// Capability (and, with `with_chart`, the chart) of every characteristic of `rows`.
pub fn study(
    rows: &[PartRow],
    limits: &FeatureLimits,
    with_chart: bool,
) -> Vec<CharacteristicStudy> {
    limits
        .items
        .iter()
        .map(|l| {
            let c = l.characteristic;
            let (parts, values): (Vec<PartId>, Vec<f64>) = rows
                .iter()
                .filter_map(|r| r.value(c, limits.phase_deg).map(|v| (r.part.clone(), v)))
                .unzip();
            let result = capability::assess(&values, l.limits, c.bounded_at_zero());
            let note = match &result {
                Err(e) => Some(e.to_string()),
                Ok(cap) => cap.no_index.map(|why| {
                    l.none_because
                        .map_or(why.to_string(), |b| format!("{b}: no index"))
                }),
            };
            let resolution = capability::chart::resolution(&l.limits);
            let chart = with_chart
                .then(|| chart_of(&parts, &values, resolution, c))
                .flatten();
            CharacteristicStudy {
                characteristic: c,
                unit: c.unit(),
                limits: l.clone(),
                indicative: result.as_ref().is_ok_and(|c| c.n < MIN_CAPABILITY_VALUES),
                capability: result.ok(),
                note,
                chart,
            }
        })
        .collect()
}

/// Why a window's figures are indicative, when any characteristic's are: the fewest values
/// and the minimum. The CLI prints it after "indicative only: ", the dashboard after the same
/// words in bold.
pub(crate) fn indicative_reason(items: &[CharacteristicStudy]) -> Option<String> {
    let n = items
        .iter()
        .filter(|it| it.indicative)
        .filter_map(|it| it.capability.as_ref().map(|c| c.n))
        .min()?;
    Some(format!(
        "{n} values, fewer than the {MIN_CAPABILITY_VALUES} a capability study needs (AIAG SPC \
         manual: 25 subgroups, 100 values); the indices, their bounds and the expected ppm \
         are estimates from too few parts"
    ))
}

fn chart_of(parts: &[PartId], values: &[f64], resolution: f64, c: Characteristic) -> Option<Chart> {
    let base = &values[..values.len().min(capability::chart::BASELINE_PARTS)];
    let limits = ChartLimits::from_baseline_shaped(base, resolution, c.chart_shape())?;
    Some(Chart {
        limits,
        part: parts.to_vec(),
        points: capability::chart::evaluate(values, &limits),
    })
}

#[cfg(test)]
mod tests {
    use super::StoredReport;
    use crate::core::analysis::{LobeOptions, analyse_lobe};
    use crate::core::measure::AveragedMeasurement;

    /// The record reads the core's own report as a measurement stores it: a field renamed
    /// in the core fails here, not as empty studies in the field.
    #[test]
    fn the_record_reads_the_cores_report() {
        let n = 360;
        let grid: Vec<f64> = (0..n).map(|k| k as f64 * 360.0 / n as f64).collect();
        // A smooth nominal (mm, and its slope per degree); the part measures 4 µm above it
        // everywhere, so the unfitted error is 4 µm at every angle.
        let nominal = |psi: f64| {
            let r = psi.to_radians();
            (2.0 + r.cos(), -r.sin() * std::f64::consts::PI / 180.0)
        };
        let avg = AveragedMeasurement {
            origin: "test".into(),
            points_per_rev: n as u32,
            mean_lift_mm: grid.iter().map(|&p| nominal(p).0 + 0.004).collect(),
            repeatability_std_um: vec![0.2; n],
            repeatability_range_um: vec![0.5; n],
            revolutions_used: vec![0, 1, 2],
            dropped_revolutions: Vec::new(),
        };
        let report = analyse_lobe(&avg, &nominal, &LobeOptions::default()).unwrap();
        let stored = serde_json::to_string(&report).unwrap();
        let read = StoredReport::parse(&stored).unwrap();
        assert_eq!(read.error_um.len(), n);
        // 4 µm within float rounding of a 3 mm lift (1e-9 µm is far below any gauge).
        assert!(
            read.error_um.iter().all(|e| (e - 4.0).abs() < 1e-9),
            "{read:?}"
        );
    }

    /// An analysis without the field is an error that names it, never an empty curve.
    #[test]
    fn a_missing_field_is_an_error_naming_it() {
        let e = StoredReport::parse(r#"{"profile_error_um":[1.0]}"#).unwrap_err();
        assert!(e.to_string().contains("missing field `error_um`"), "{e}");
    }
}
