//! The control charts' run rules on each new production part of a feature: events beside
//! the loop's alarms, which the loop's learning never reads.
//!
//! Per characteristic with a tolerance (a lobe's max error, profile error, size, timing; a
//! pin's roundness, index angle, stroke, diameter) the limits come from a baseline: the
//! [`BASELINE_PARTS`] production parts after the first [`WARMUP_PARTS`] this loop sees
//! since it started (the loop's start-up is not the process). The rules
//! (`core::capability::chart`) then run on every part after the baseline. The magnitudes
//! bounded at zero (max error, profile error, roundness) raise events on their upper side
//! only: a part nearer zero than usual is better, not a problem.

use super::FeatureLoop;
use super::records::event;
use crate::core::capability::chart::{BASELINE_PARTS, ChartLimits, Monitor, Rule, resolution};
use crate::core::capability::{Characteristic, PartValues};
use crate::core::turn::Measured;
use crate::quality::FeatureLimits;
use crate::service::journal::{EventKind, Pending};
use crate::store::EventLevel;
use tracing::warn;

/// Parts of a loop's start-up left out of the baseline.
pub(crate) const WARMUP_PARTS: usize = 5;

/// One characteristic's chart.
#[derive(Debug, Clone)]
struct Watched {
    characteristic: Characteristic,
    resolution: f64,
    baseline: Vec<f64>,
    monitor: Option<Monitor>,
}

/// Every characteristic's chart of one feature.
#[derive(Debug, Clone)]
pub(crate) struct ChartWatch {
    seen: usize,
    items: Vec<Watched>,
}

/// A rule that fired, for the event.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Fired {
    pub characteristic: Characteristic,
    pub rule: Rule,
    pub value: f64,
    pub limits: ChartLimits,
}

impl ChartWatch {
    /// The charts of the characteristics that have a tolerance in `limits`: the rules'
    /// resolution comes from it (see `core::capability::chart`).
    pub fn new(limits: &FeatureLimits) -> Self {
        Self {
            seen: 0,
            items: limits
                .items
                .iter()
                .filter(|l| l.none_because.is_none())
                .map(|l| Watched {
                    characteristic: l.characteristic,
                    resolution: resolution(&l.limits),
                    baseline: Vec::new(),
                    monitor: None,
                })
                .collect(),
        }
    }

    /// The next production part; returns the rules that fired on it.
    pub fn push(&mut self, part: &PartValues<'_>) -> Vec<Fired> {
        self.seen += 1;
        if self.seen <= WARMUP_PARTS {
            return Vec::new();
        }
        let mut out = Vec::new();
        for w in &mut self.items {
            let Some(x) = w.characteristic.value(part).filter(|x| x.is_finite()) else {
                continue;
            };
            match &mut w.monitor {
                Some(m) => {
                    let point = m.push(x);
                    // A magnitude bounded at zero below its centre is a better part than
                    // usual, never an alarm: only its upper side raises events.
                    if w.characteristic.bounded_at_zero() && x < m.limits().center {
                        continue;
                    }
                    out.extend(point.fired.into_iter().map(|rule| Fired {
                        characteristic: w.characteristic,
                        rule,
                        value: x,
                        limits: *m.limits(),
                    }));
                }
                None => {
                    w.baseline.push(x);
                    if w.baseline.len() >= BASELINE_PARTS {
                        w.monitor = ChartLimits::from_baseline_shaped(
                            &w.baseline,
                            w.resolution,
                            w.characteristic.chart_shape(),
                        )
                        .map(Monitor::new);
                        w.baseline.clear();
                    }
                }
            }
        }
        out
    }
}

impl FeatureLoop {
    /// The run rules on this production part: one event per rule that fired.
    pub(super) fn chart_events(
        &mut self,
        part: &str,
        measured: &Measured,
        at: jiff::Timestamp,
    ) -> Vec<Pending> {
        let report = &measured.report;
        let values = PartValues {
            max_profile_error_um: measured.max_profile_error_um,
            base_radius_error_um: report.base_radius_error_um,
            phase_error_deg: report.phase_error_deg,
            error_um: &report.error_um,
            phase_deg: self.setup.phase_deg,
        };
        self.charts
            .push(&values)
            .into_iter()
            .map(|f| {
                let c = f.characteristic;
                let message = format!(
                    "{} {}: {} at part {part} ({:.4} {}; centre {:.4}, 3σ limits {:.4} to {:.4})",
                    self.setup.name,
                    c.as_str(),
                    f.rule.describe(),
                    f.value,
                    c.unit(),
                    f.limits.center,
                    f.limits.lower,
                    f.limits.upper
                );
                warn!(machine = %self.name, lobe = %self.setup.name, characteristic = c.as_str(), rule = f.rule.as_str(), part, "run rule: {message}");
                event(&self.name, at, EventLevel::Warn, EventKind::RunRule, message)
            })
            .collect()
    }
}
