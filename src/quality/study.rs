//! The type-1 gauge study of a feature from its master runs: every signed characteristic
//! with a two-sided tolerance (size, timing; a pin's index angle, stroke, diameter), against
//! the master's reference value 0 (the master is the nominal part, so each deviation's
//! reference is zero).

use super::{FeatureLimits, PartRow};
use crate::core::capability::Characteristic;
use crate::core::capability::gauge_study::{GaugeStudy, type1};

/// Why the magnitudes get no type-1 study.
const MAGNITUDE: &str = "a largest |deviation| over the profile: on a perfect master it is the \
    largest of the gauge's noise, not a reading of a reference value, so a type-1 study does not \
    apply (the gauge's repeatability per angle is in every measurement's report)";

/// The study of one characteristic.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub(crate) struct GaugeItem {
    pub characteristic: Characteristic,
    pub unit: &'static str,
    pub study: Option<GaugeStudy>,
    /// Why there is no study, or what to keep in mind reading it.
    pub note: Option<String>,
}

/// The studies of every characteristic of `rows` (master runs, oldest first).
pub(crate) fn gauge_studies(rows: &[PartRow], limits: &FeatureLimits) -> Vec<GaugeItem> {
    limits
        .items
        .iter()
        .map(|l| {
            let c = l.characteristic;
            let values: Vec<f64> = rows
                .iter()
                .filter_map(|r| r.value(c, limits.phase_deg))
                .collect();
            let (study, note) = match (l.limits.lower, l.limits.upper) {
                _ if c.bounded_at_zero() => (None, Some(MAGNITUDE.to_string())),
                (Some(lo), Some(up)) => match type1(&values, 0.0, up - lo) {
                    Ok(s) => (Some(s), None),
                    Err(e) => (None, Some(e.to_string())),
                },
                _ => (
                    None,
                    Some(l.none_because.unwrap_or("no tolerance").to_string() + ": no study"),
                ),
            };
            GaugeItem {
                characteristic: c,
                unit: c.unit(),
                study,
                note,
            }
        })
        .collect()
}
