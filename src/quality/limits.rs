//! Each characteristic's specification limits, from the feature's recipe, or why it has none.

use crate::core::analysis::{LobeOptions, ToleranceBand};
use crate::core::capability::{Characteristic, Limits};
use crate::recipe::{FeatureSetup, FeatureTolerances};

/// A characteristic's limits, or the reason the recipe gives none.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CharacteristicLimits {
    pub characteristic: Characteristic,
    pub limits: Limits,
    /// Set when `limits` is empty: why, in the recipe's words.
    pub none_because: Option<&'static str>,
}

/// The limits of every characteristic of one feature, in the characteristics' order.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FeatureLimits {
    pub pin: bool,
    /// Where the feature's 0° is on the shaft, degrees (the gauge reads in the shaft's frame).
    pub phase_deg: f64,
    pub items: Vec<CharacteristicLimits>,
}

impl FeatureLimits {
    pub fn from_setup(s: &FeatureSetup) -> Self {
        let sym = |t: f64| Limits {
            lower: Some(-t),
            upper: Some(t),
        };
        let upper = |t: f64| Limits {
            lower: None,
            upper: Some(t),
        };
        let given = |c, l| (c, Ok(l));
        let entries: Vec<(Characteristic, Result<Limits, &'static str>)> =
            match s.tolerances {
                FeatureTolerances::Lobe {
                    timing_deg,
                    size_um,
                    max_error_um,
                } => vec![
                (
                    Characteristic::MaxError,
                    max_error_um
                        .map(upper)
                        .ok_or("the recipe gives no max_error_tolerance_um"),
                ),
                (
                    Characteristic::ProfileError,
                    profile_upper(&s.bands).map(upper).ok_or(
                        "the recipe's profile bands differ along the lobe: no single upper limit",
                    ),
                ),
                (
                    Characteristic::Size,
                    size_um.map(sym).ok_or("the recipe gives no size_tolerance_um"),
                ),
                given(Characteristic::Timing, sym(timing_deg)),
            ],
                FeatureTolerances::Pin {
                    index_deg,
                    stroke_um,
                    roundness_um,
                    diameter_um,
                } => vec![
                    given(Characteristic::Roundness, upper(roundness_um)),
                    given(Characteristic::IndexAngle, sym(index_deg)),
                    given(Characteristic::Stroke, sym(stroke_um)),
                    (
                        Characteristic::Diameter,
                        diameter_um
                            .map(sym)
                            .ok_or("the recipe gives no diameter_tolerance_um"),
                    ),
                ],
            };
        Self {
            pin: matches!(s.tolerances, FeatureTolerances::Pin { .. }),
            phase_deg: s.phase_deg,
            items: entries
                .into_iter()
                .map(|(characteristic, l)| CharacteristicLimits {
                    characteristic,
                    limits: l.unwrap_or_default(),
                    none_because: l.err(),
                })
                .collect(),
        }
    }

    /// The limits of `c`; empty when the feature has none for it.
    pub fn of(&self, c: Characteristic) -> Option<&CharacteristicLimits> {
        self.items.iter().find(|i| i.characteristic == c)
    }
}

/// The upper limit of max |profile error|: the half-width of one symmetric band all round
/// (the analysis default band when the recipe has none).
fn profile_upper(bands: &[ToleranceBand]) -> Option<f64> {
    match bands {
        [] => Some(LobeOptions::default().default_band_um),
        [b] if (b.lower_um + b.upper_um).abs() < 1e-9
            && b.upper_um > 0.0
            && (b.to_deg - b.from_deg - 360.0).abs() < 1e-9 =>
        {
            Some(b.upper_um)
        }
        _ => None,
    }
}
