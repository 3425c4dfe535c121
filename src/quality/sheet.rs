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
    /// The setup drawing (SVG); `None` when the geometry could not be drawn. Shared by the
    /// features that show the same drawing (see [`Drawings`]).
    pub setup_svg: Option<Arc<str>>,
    /// The speed plan's chart (SVG) when the recipe has `[speed_plan] enabled = true`.
    pub speed_plan_svg: Option<Arc<str>>,
    /// Each characteristic's limits from the recipe (capability and charts).
    pub limits: super::FeatureLimits,
}

/// Per (machine, feature) name.
pub type FeatureSheets = Arc<BTreeMap<(MachineName, FeatureName), FeatureSheet>>;

/// Setup drawings made so far, by what they show (label, geometry, nominal lift): a plant's
/// machines of one recipe show the same few drawings, so each is made once and shared
/// rather than made and kept for every feature of every machine (at 500 machines × 8
/// lobes, 4,000 drawings took 20 s before the listener served).
#[derive(Debug, Default)]
pub struct Drawings(Vec<(DrawingKey, Option<Arc<str>>)>);

/// What a setup drawing is made from.
#[derive(Debug)]
struct DrawingKey {
    label: String,
    feature: crate::core::compensate::Feature,
    nominal: crate::core::lift::LiftTable,
}

impl Drawings {
    /// `s`'s setup drawing, made once per distinct label, geometry and nominal lift.
    fn setup_svg(&mut self, s: &FeatureSetup) -> Option<Arc<str>> {
        let same =
            |k: &DrawingKey| k.label == s.label && k.feature == s.feature && k.nominal == s.nominal;
        if let Some((_, svg)) = self.0.iter().find(|(k, _)| same(k)) {
            return svg.clone();
        }
        let svg: Option<Arc<str>> = s.feature.part(&s.nominal).ok().and_then(|part| {
            crate::core::setup::setup_view(&part, &[0.0, 90.0, 180.0, 270.0], &s.label)
                .ok()
                .map(|v| Arc::from(crate::core::svg::render_setup_svg(&v)))
        });
        let key = DrawingKey {
            label: s.label.clone(),
            feature: s.feature,
            nominal: s.nominal.clone(),
        };
        self.0.push((key, svg.clone()));
        svg
    }
}

impl FeatureSheet {
    pub fn from_setup(s: &FeatureSetup) -> Self {
        Self::from_setup_drawn(s, &mut Drawings::default())
    }

    /// [`Self::from_setup`], its setup drawing taken from `drawings` when one was made for
    /// the same inputs.
    pub fn from_setup_drawn(s: &FeatureSetup, drawings: &mut Drawings) -> Self {
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
        let setup_svg = drawings.setup_svg(s);
        let speed_plan_svg = s
            .speed_plan
            .enabled
            .then(|| s.feature.part(&s.nominal).ok())
            .flatten()
            .and_then(|part| {
                let limits = s.speed_plan.limits(&s.limits);
                crate::core::speed_plan::plan(&part, &limits).ok()
            })
            .map(|plan| {
                Arc::from(crate::core::speed_plan::plot::render_plan_svg(
                    &plan, &s.label,
                ))
            });
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recipe::Recipe;
    use std::path::Path;

    /// Two machines of the demo camshaft: each lobe's drawing is made once and shared by the
    /// second machine's same lobe, and it is the drawing a sheet of its own would have.
    #[test]
    fn machines_of_one_recipe_share_each_lobe_drawing() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
        let setups = Recipe::load(&path).unwrap().feature_setups(&path).unwrap();
        let mut drawings = Drawings::default();
        let first: Vec<FeatureSheet> = setups
            .iter()
            .map(|s| FeatureSheet::from_setup_drawn(s, &mut drawings))
            .collect();
        let second: Vec<FeatureSheet> = setups
            .iter()
            .map(|s| FeatureSheet::from_setup_drawn(s, &mut drawings))
            .collect();
        assert_eq!(drawings.0.len(), setups.len(), "one drawing per lobe label");
        for ((a, b), s) in first.iter().zip(&second).zip(&setups) {
            let (a_svg, b_svg) = (a.setup_svg.as_ref().unwrap(), b.setup_svg.as_ref().unwrap());
            assert!(
                Arc::ptr_eq(a_svg, b_svg),
                "{}: shared, not made again",
                s.name
            );
            assert_eq!(*a, FeatureSheet::from_setup(s), "{}", s.name);
        }
        // Each lobe's drawing carries its own label.
        assert_ne!(first[0].setup_svg, first[2].setup_svg);
    }
}
