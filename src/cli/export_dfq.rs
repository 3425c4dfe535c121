//! `camloop export --format dfq`: the exported measurements as a Q-DAS AQDEF file, one
//! series per (machine, feature), the profile tolerance taken from the service
//! configuration's recipes when they can be read.

use crate::config::Config;
use crate::dfq::{DfqSeries, row_from, write_dfq};
use crate::recipe::Recipe;
use crate::store::MeasurementDetail;
use anyhow::bail;
use std::collections::BTreeMap;
use std::path::Path;

/// The `.dfq` text of `rows` (oldest first), which must all be of one part.
pub fn dfq_text(rows: &[MeasurementDetail], config: &Path) -> anyhow::Result<String> {
    let parts: std::collections::BTreeSet<&str> =
        rows.iter().map(|d| d.summary.part.as_str()).collect();
    if parts.len() > 1 {
        let list: Vec<&str> = parts.into_iter().collect();
        bail!(
            "the range holds parts {}; a .dfq file describes one part: give --part",
            list.join(", ")
        );
    }
    let Some(part) = parts.into_iter().next() else {
        bail!("nothing to export: no measurement in the range");
    };
    let bands = profile_bands(config);
    let mut series: BTreeMap<(String, String), DfqSeries> = BTreeMap::new();
    for d in rows {
        let s = &d.summary;
        let key = (s.machine.clone(), s.lobe.clone());
        series
            .entry(key.clone())
            .or_insert_with(|| DfqSeries {
                machine: s.machine.clone(),
                feature: s.lobe.clone(),
                profile_band_um: bands.get(&key).copied(),
                rows: Vec::new(),
            })
            .rows
            .push(row_from(s, Some(&d.analysis_json)));
    }
    let series: Vec<DfqSeries> = series.into_values().collect();
    Ok(write_dfq(
        part,
        &format!("{part} (camloop export)"),
        &series,
    )?)
}

/// (lower, upper) µm of each configured feature that has one band all round; empty when
/// the configuration or a recipe cannot be read (the file is then written without limits).
fn profile_bands(config: &Path) -> BTreeMap<(String, String), (f64, f64)> {
    let mut out = BTreeMap::new();
    let Ok(text) = std::fs::read_to_string(config) else {
        return out;
    };
    let Ok(config) = Config::parse(&text, config, |_| None) else {
        return out;
    };
    for m in &config.machines {
        let path = config.resolve(&m.recipe);
        let Ok(setup) = Recipe::load(&path).and_then(|r| r.feature_setup(&path, &m.lobe)) else {
            continue;
        };
        if let Some(b) = crate::service::http::FeatureSheet::from_setup(&setup).symmetric_band_um()
        {
            out.insert((m.name.clone(), m.lobe.clone()), (-b, b));
        }
    }
    out
}
