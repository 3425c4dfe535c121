//! Process quality of the stored history: capability of each characteristic over a window
//! of parts, the control charts and their run rules, and the type-1 gauge study of master
//! runs. The statistics are the core's (`core::capability`); this module picks the window
//! from the store and the limits from the recipe.
//!
//! Master runs (part ids `MASTER…`, [`crate::core::measure::is_master_part`]) are never
//! production parts: a capability window skips them, a gauge study takes only them.

pub mod limits;
pub mod render;
pub mod study;

use crate::core::capability::{
    self, Capability, Characteristic, PartValues, chart::ChartLimits, chart::ChartPoint,
};
use crate::core::measure::is_master_part;
use crate::names::{FeatureName, MachineName};
use crate::store::{MAX_PAGE, MeasurementDetail, MeasurementId, Store};
pub use limits::{CharacteristicLimits, FeatureLimits};

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
    pub since_ms: Option<jiff::Timestamp>,
    pub until_ms: Option<jiff::Timestamp>,
    /// Only parts after the machine's newest wheel dressing.
    pub since_dressing: bool,
    /// Only parts after the feature's recipe last changed (the store's newest snapshot).
    pub since_recipe_change: bool,
}

impl Default for Window {
    fn default() -> Self {
        Self {
            last: 125,
            since_ms: None,
            until_ms: None,
            since_dressing: false,
            since_recipe_change: false,
        }
    }
}

/// A stored part as the studies see it.
#[derive(Debug, Clone, PartialEq)]
pub struct PartRow {
    pub id: MeasurementId,
    pub part: String,
    pub received_at_ms: jiff::Timestamp,
    pub max_profile_error_um: f64,
    pub base_radius_error_um: f64,
    pub phase_error_deg: f64,
    pub error_um: Vec<f64>,
}

impl PartRow {
    fn from_detail(d: &MeasurementDetail) -> Self {
        #[derive(serde::Deserialize)]
        struct Report {
            #[serde(default)]
            error_um: Vec<f64>,
        }
        let s = &d.summary;
        Self {
            id: s.id,
            part: s.part.clone(),
            received_at_ms: s.received_at_ms,
            max_profile_error_um: s.max_profile_error_um,
            base_radius_error_um: s.base_radius_error_um,
            phase_error_deg: s.phase_error_deg,
            error_um: serde_json::from_str::<Report>(&d.analysis_json)
                .map(|r| r.error_um)
                .unwrap_or_default(),
        }
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

/// The window's parts, oldest first: production parts, or (with `masters`) master runs only.
/// Also returns the start the window took, if any, and how many of the other kind it skipped.
pub(crate) async fn window_rows(
    store: &Store,
    machine: &MachineName,
    lobe: &FeatureName,
    window: &Window,
    masters: bool,
) -> Result<(Vec<PartRow>, Option<jiff::Timestamp>, usize), crate::store::StoreError> {
    let mut since = window.since_ms;
    if window.since_dressing
        && let Some(d) = store.dressings(machine, 1).await?.first()
    {
        since = since.max(Some(d.at_ms));
    }
    if window.since_recipe_change
        && let Some(f) = store
            .features(machine)
            .await?
            .iter()
            .find(|f| f.lobe == *lobe)
    {
        since = since.max(Some(f.created_at_ms));
    }
    let (start, until) = (
        since.unwrap_or(jiff::Timestamp::MIN),
        window.until_ms.unwrap_or(jiff::Timestamp::MAX),
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
            if is_master_part(&d.summary.part) == masters {
                if rows.len() < wanted {
                    rows.push(PartRow::from_detail(d));
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
    pub part: Vec<String>,
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
            let (parts, values): (Vec<String>, Vec<f64>) = rows
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

fn chart_of(parts: &[String], values: &[f64], resolution: f64, c: Characteristic) -> Option<Chart> {
    let base = &values[..values.len().min(capability::chart::BASELINE_PARTS)];
    let limits = ChartLimits::from_baseline_shaped(base, resolution, c.chart_shape())?;
    Some(Chart {
        limits,
        part: parts.to_vec(),
        points: capability::chart::evaluate(values, &limits),
    })
}
