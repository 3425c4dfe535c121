//! What the service shows of a configured feature beyond the store, computed once from its
//! recipe: tolerance bands, base radius, the setup drawing and speed-plan chart, each
//! characteristic's limits. The dashboard draws it, the DFQ export takes its limits.

use crate::core::analysis::ToleranceBand;
use crate::names::{FeatureName, MachineName};
use crate::recipe::FeatureSetup;
use std::collections::BTreeMap;
use std::sync::Arc;

/// What the dashboard knows of a configured feature beyond the store: its tolerance bands,
/// base radius and setup drawing, computed once at start.
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureSheet {
    /// The bands the analysis judges against (the analysis default when the recipe has none).
    pub bands: Vec<ToleranceBand>,
    pub base_radius_mm: Option<f64>,
    /// The setup drawing (SVG); `None` when the geometry could not be drawn.
    pub setup_svg: Option<String>,
    /// The speed plan's chart (SVG) when the recipe has `[speed_plan] enabled = true`.
    pub speed_plan_svg: Option<String>,
    /// Each characteristic's limits from the recipe (capability and charts).
    pub limits: super::FeatureLimits,
}

/// Per (machine, feature) name.
pub type FeatureSheets = Arc<BTreeMap<(MachineName, FeatureName), FeatureSheet>>;

impl FeatureSheet {
    pub fn from_setup(s: &FeatureSetup) -> Self {
        let bands = if s.bands.is_empty() {
            let band = crate::core::analysis::LobeOptions::default().default_band_um;
            vec![ToleranceBand::everywhere(band)]
        } else {
            s.bands.clone()
        };
        let base_radius_mm = match &s.feature {
            crate::core::compensate::Feature::Cam(c) => Some(c.base_radius_mm),
            crate::core::compensate::Feature::Pin(_) => None,
        };
        let setup_svg = s.feature.part(&s.nominal).ok().and_then(|part| {
            crate::core::setup::setup_view(&part, &[0.0, 90.0, 180.0, 270.0], &s.label)
                .ok()
                .map(|v| crate::core::svg::render_setup_svg(&v))
        });
        let speed_plan_svg = s
            .speed_plan
            .enabled
            .then(|| s.feature.part(&s.nominal).ok())
            .flatten()
            .and_then(|part| {
                let limits = s.speed_plan.limits(&s.limits);
                crate::core::speed_plan::plan(&part, &limits).ok()
            })
            .map(|plan| crate::core::speed_plan::plot::render_plan_svg(&plan, &s.label));
        Self {
            bands,
            base_radius_mm,
            setup_svg,
            speed_plan_svg,
            limits: super::FeatureLimits::from_setup(s),
        }
    }

    /// The half-width of the band when the feature has one symmetric band all round: the
    /// limit of its max |profile error|.
    pub fn symmetric_band_um(&self) -> Option<f64> {
        match self.bands.as_slice() {
            [b] if (b.lower_um + b.upper_um).abs() < 1e-9
                && b.upper_um > 0.0
                && (b.to_deg - b.from_deg - 360.0).abs() < 1e-9 =>
            {
                Some(b.upper_um)
            }
            _ => None,
        }
    }
}
