//! `camloop export --format dfq`: the exported measurements as a Q-DAS AQDEF file, one
//! series per (machine, feature) of one part (recipe), the profile tolerance taken from the
//! service configuration's recipes when they can be read.

use crate::config::Config;
use crate::dfq::{DfqSeries, row_from, write_dfq};
use crate::names::{FeatureName, MachineName};
use crate::recipe::Recipe;
use crate::store::{MeasurementDetail, Store};
use anyhow::bail;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A series of the file: one feature of one machine (ordered as their text, as the file's
/// series are).
type SeriesKey = (MachineName, FeatureName);

/// The recipe (part) name of each (machine, feature) among `rows`, from the store's recipe
/// snapshots.
pub(crate) async fn recipe_parts(
    store: &Store,
    rows: &[MeasurementDetail],
) -> anyhow::Result<BTreeMap<SeriesKey, String>> {
    let machines: BTreeSet<&MachineName> = rows.iter().map(|d| &d.summary.machine).collect();
    let mut out = BTreeMap::new();
    for m in machines {
        for f in store.features(m).await? {
            out.insert((m.clone(), f.lobe), f.part.to_string());
        }
    }
    Ok(out)
}

/// How to write the file.
pub(crate) struct DfqExport<'a> {
    /// (machine, feature) → recipe name, see [`recipe_parts`].
    pub recipes: &'a BTreeMap<SeriesKey, String>,
    /// The part to export when the range holds several.
    pub part: Option<&'a str>,
    /// The service configuration, for the tolerance bands.
    pub config: &'a Path,
}

impl DfqExport<'_> {
    /// The `.dfq` text of `rows` (oldest first).
    pub fn text(&self, rows: &[MeasurementDetail]) -> anyhow::Result<String> {
        let recipe = |d: &MeasurementDetail| {
            let key = (d.summary.machine.clone(), d.summary.lobe.clone());
            self.recipes.get(&key).cloned().unwrap_or_default()
        };
        let parts: BTreeSet<String> = rows.iter().map(recipe).collect();
        let part = match (self.part, parts.len()) {
            (Some(p), _) => p.to_string(),
            (None, 1) => parts.iter().next().cloned().unwrap_or_default(),
            (None, 0) => bail!("nothing to export: no measurement in the range"),
            (None, _) => bail!(
                "the range holds parts {}; a .dfq file describes one part: give --part",
                parts.into_iter().collect::<Vec<_>>().join(", ")
            ),
        };
        let bands = profile_bands(self.config);
        let mut series: BTreeMap<SeriesKey, DfqSeries> = BTreeMap::new();
        // Master runs are the gauge study's, not production parts.
        let production = |d: &&MeasurementDetail| {
            recipe(d) == part && !crate::core::measure::is_master_part(&d.summary.part)
        };
        for d in rows.iter().filter(production) {
            let s = &d.summary;
            let key = (s.machine.clone(), s.lobe.clone());
            let band = bands.get(&key);
            series
                .entry(key)
                .or_insert_with(|| DfqSeries {
                    machine: s.machine.clone(),
                    feature: s.lobe.clone(),
                    profile_band_um: band.and_then(|b| b.0),
                    limits: band.map(|b| b.1).unwrap_or_default(),
                    rows: Vec::new(),
                })
                .rows
                .push(row_from(s, Some(&d.analysis_json)));
        }
        let series: Vec<DfqSeries> = series.into_values().collect();
        Ok(write_dfq(
            &part,
            &format!("{part} (camloop export)"),
            &series,
        )?)
    }
}

/// A feature's profile band (lower, upper) µm when it has one all round, and its other
/// limits.
type FeatureLimitsDfq = (Option<(f64, f64)>, crate::dfq::DfqLimits);

/// (lower, upper) µm of each configured feature's profile band when it has one all round,
/// and its other limits; empty when the configuration or a recipe cannot be read (the file
/// is then written without limits).
fn profile_bands(config: &Path) -> BTreeMap<SeriesKey, FeatureLimitsDfq> {
    let mut out = BTreeMap::new();
    let Ok(text) = std::fs::read_to_string(config) else {
        return out;
    };
    let Ok(config) = Config::parse(&text, config, |_| None) else {
        return out;
    };
    for m in &config.machines {
        let path = config.resolve(&m.recipe);
        let Ok(recipe) = Recipe::load(&path) else {
            continue;
        };
        for lobe in crate::config::machine_features(&recipe, m).unwrap_or_default() {
            let Ok(setup) = recipe.feature_setup(&path, &lobe) else {
                continue;
            };
            let sheet = crate::quality::FeatureSheet::from_setup(&setup);
            let band = sheet.symmetric_band_um().map(|b| (-b, b));
            let limits = crate::dfq::DfqLimits::from_feature(&sheet.limits);
            out.insert((m.name.clone(), setup.name), (band, limits));
        }
    }
    out
}
