//! The feature page's capability panel: per characteristic a histogram of the newest 125
//! production parts with the limits and the fitted model's expected counts, the indices
//! with their lower 95 % bounds, and the individuals chart with its limits and the points
//! the run rules flagged; then the latest type-1 gauge study of the master runs.

use super::FeatureSheet;
use super::charts::{Line, LineChart, Mark};
use super::pages::esc;
use crate::core::capability::{Capability, Index};
use crate::quality::{self, CharacteristicStudy, Window, study::GaugeItem};
use crate::store::{Store, StoreError};
use std::fmt::Write as _;

const W: f64 = 320.0;
const H: f64 = 170.0;
const BINS: usize = 16;

/// The panel's HTML.
pub(super) async fn panel(
    store: &Store,
    machine: &str,
    lobe: &str,
    sheet: &FeatureSheet,
) -> Result<String, StoreError> {
    let (rows, _, _) =
        quality::window_rows(store, machine, lobe, &Window::default(), false).await?;
    let items = quality::study(&rows, &sheet.limits, true);
    let master = Window {
        last: 50,
        ..Window::default()
    };
    let (masters, _, _) = quality::window_rows(store, machine, lobe, &master, true).await?;
    let mut s = format!(
        r#"<section aria-labelledby="cap-h"><h2 id="cap-h">Capability (newest {} parts)</h2><p class="legend-text">Bars: parts per bin; line: the model's expected count; dashed red: the recipe's limits. Indices with their lower 95 % bound in brackets. API: <code>/api/v1/machines/{m}/features/{l}/capability?window=parts:125&amp;chart=true</code>.</p>"#,
        rows.len(),
        m = esc(machine),
        l = esc(lobe)
    );
    s.push_str(&indices_table(&items));
    for it in &items {
        let name = it.characteristic.as_str();
        let _ = write!(s, r#"<div class="pair"><figure>{}</figure>"#, histogram(it));
        if let Some(chart) = &it.chart {
            let l = chart.limits;
            let flagged: Vec<Mark> = chart
                .points
                .iter()
                .enumerate()
                .filter(|(_, p)| !p.fired.is_empty())
                .map(|(i, p)| Mark {
                    x: i as f64 + 1.0,
                    label: p
                        .fired
                        .iter()
                        .map(|r| r.as_str())
                        .collect::<Vec<_>>()
                        .join(","),
                    class: "flagged",
                })
                .collect();
            let svg = LineChart {
                title: format!(
                    "{name}: individuals chart, limits from the first {} parts",
                    l.baseline_parts
                ),
                x_label: "part in window".into(),
                y_label: it.unit.into(),
                lines: vec![Line {
                    name: name.into(),
                    class: "profile",
                    points: chart
                        .points
                        .iter()
                        .enumerate()
                        .map(|(i, p)| (i as f64 + 1.0, p.value))
                        .collect(),
                }],
                limits: vec![
                    (l.lower, "LCL".into()),
                    (l.center, "centre".into()),
                    (l.upper, "UCL".into()),
                ],
                marks: flagged,
            }
            .svg();
            let _ = write!(s, "<figure>{svg}</figure>");
        }
        s.push_str("</div>");
    }
    s.push_str("</section>");
    s.push_str(&gauge_section(
        &quality::study::gauge_studies(&masters, &sheet.limits),
        masters.len(),
    ));
    Ok(s)
}

fn idx(i: Option<Index>) -> String {
    i.map_or("–".into(), |i| {
        format!("{:.2} ({:.2})", i.value, i.lower_95)
    })
}

fn indices_table(items: &[CharacteristicStudy]) -> String {
    let mut s = String::from(
        r#"<table id="capability"><thead><tr><th scope="col">Characteristic</th><th scope="col">n</th><th scope="col">Mean</th><th scope="col">σ within</th><th scope="col">σ overall</th><th scope="col">Model</th><th scope="col">Cp</th><th scope="col">Cpk</th><th scope="col">Pp</th><th scope="col">Ppk</th><th scope="col">Expected out</th><th scope="col">Observed out</th><th scope="col">Note</th></tr></thead><tbody>"#,
    );
    for it in items {
        let c = it.capability.as_ref();
        let ix = c.and_then(|c| c.indices.as_ref());
        let f = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.4}"));
        let _ = write!(
            s,
            "<tr><th scope=\"row\">{} ({})</th><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            it.characteristic.as_str(),
            it.unit,
            c.map_or("–".into(), |c| c.n.to_string()),
            f(c.map(|c| c.mean)),
            f(c.map(|c| c.sigma_within)),
            f(c.map(|c| c.sigma_overall)),
            c.map_or("–", |c| c.model.name()),
            idx(ix.and_then(|i| i.cp)),
            idx(ix.map(|i| i.cpk)),
            idx(ix.and_then(|i| i.pp)),
            idx(ix.map(|i| i.ppk)),
            ix.map_or("–".into(), |i| format!(
                "{:.1} ppm",
                i.expected_share_out * 1e6
            )),
            ix.map_or("–".into(), |i| format!(
                "{:.1} %",
                i.observed_share_out * 100.0
            )),
            esc(it.note.as_deref().unwrap_or("")),
        );
    }
    s.push_str("</tbody></table>");
    s
}

/// Bars of the window's values, the limits, and the model's expected count per bin.
fn histogram(it: &CharacteristicStudy) -> String {
    let name = it.characteristic.as_str();
    let Some(c) = &it.capability else {
        return format!(
            "<p>{name}: no histogram ({})</p>",
            esc(it.note.as_deref().unwrap_or(""))
        );
    };
    let lo = c.min.min(c.limits.lower.unwrap_or(c.min));
    let hi = c.max.max(c.limits.upper.unwrap_or(c.max));
    let (lo, hi) = if hi > lo {
        (lo, hi)
    } else {
        (lo - 1.0, hi + 1.0)
    };
    let width = (hi - lo) / BINS as f64;
    let counts = bin_counts(it, c, lo, width);
    let expected: Vec<f64> = (0..BINS)
        .map(|b| {
            let a = lo + b as f64 * width;
            c.n as f64 * (c.model_cdf(a + width) - c.model_cdf(a))
        })
        .collect();
    let top = counts
        .iter()
        .map(|&n| n as f64)
        .chain(expected.iter().copied())
        .fold(1.0, f64::max);
    let px = |x: f64| 10.0 + (x - lo) / (hi - lo) * (W - 20.0);
    let py = |y: f64| H - 20.0 - y / top * (H - 40.0);
    let mut s = format!(
        r#"<svg class="chart" viewBox="0 0 {W} {H}" role="img" aria-label="{name} histogram"><title>{name}: histogram, limits and {} model</title>"#,
        c.model.name()
    );
    for (b, &n) in counts.iter().enumerate() {
        let x = px(lo + b as f64 * width);
        let _ = write!(
            s,
            r#"<rect class="bar" x="{x:.1}" y="{:.1}" width="{:.1}" height="{:.1}"/>"#,
            py(n as f64),
            (W - 20.0) / BINS as f64 - 1.0,
            H - 20.0 - py(n as f64)
        );
    }
    let curve: Vec<String> = expected
        .iter()
        .enumerate()
        .map(|(b, &e)| format!("{:.1},{:.1}", px(lo + (b as f64 + 0.5) * width), py(e)))
        .collect();
    let _ = write!(
        s,
        r#"<polyline class="line phase" fill="none" points="{}"/>"#,
        curve.join(" ")
    );
    for (v, label) in [(c.limits.lower, "LSL"), (c.limits.upper, "USL")] {
        if let Some(v) = v {
            let x = px(v);
            let _ = write!(
                s,
                r#"<line class="limit" x1="{x:.1}" x2="{x:.1}" y1="16" y2="{:.1}"/><text x="{x:.1}" y="12" text-anchor="middle">{label} {v}</text>"#,
                H - 20.0
            );
        }
    }
    let _ = write!(
        s,
        r#"<text x="10" y="{:.1}">{name}, {}: {:.4} … {:.4}</text></svg>"#,
        H - 4.0,
        it.unit,
        lo,
        hi
    );
    s
}

fn bin_counts(it: &CharacteristicStudy, c: &Capability, lo: f64, width: f64) -> Vec<usize> {
    let mut counts = vec![0usize; BINS];
    let values = it
        .chart
        .as_ref()
        .map(|ch| ch.points.iter().map(|p| p.value).collect::<Vec<_>>());
    for v in values.unwrap_or_default() {
        let b = (((v - lo) / width).floor().max(0.0) as usize).min(BINS - 1);
        counts[b] += 1;
    }
    debug_assert!(counts.iter().sum::<usize>() <= c.n);
    counts
}

fn gauge_section(items: &[GaugeItem], runs: usize) -> String {
    let mut s = format!(
        r#"<section aria-labelledby="gauge-h"><h2 id="gauge-h">Gauge study (type 1, latest {runs} master runs)</h2>"#
    );
    if runs == 0 {
        s.push_str("<p>No master runs yet: measure the master part (part id MASTER…) to study the gauge.</p></section>");
        return s;
    }
    s.push_str(r#"<table id="gauge-study"><thead><tr><th scope="col">Characteristic</th><th scope="col">n</th><th scope="col">Tolerance</th><th scope="col">Bias</th><th scope="col">s</th><th scope="col">Cg</th><th scope="col">Cgk</th><th scope="col">Verdict</th></tr></thead><tbody>"#);
    for it in items {
        let name = it.characteristic.as_str();
        match &it.study {
            Some(g) => {
                let _ = write!(
                    s,
                    "<tr><th scope=\"row\">{name} ({})</th><td>{}</td><td>{:.4}</td><td>{:.4}</td><td>{:.4}</td><td>{:.2}</td><td>{:.2}</td><td>{}</td></tr>",
                    it.unit,
                    g.n,
                    g.tolerance,
                    g.bias,
                    g.sigma,
                    g.cg,
                    g.cgk,
                    if g.capable {
                        "capable (≥ 1.33)"
                    } else {
                        "not capable"
                    }
                );
            }
            None => {
                let _ = write!(
                    s,
                    "<tr><th scope=\"row\">{name} ({})</th><td colspan=\"7\">{}</td></tr>",
                    it.unit,
                    esc(it.note.as_deref().unwrap_or("no study"))
                );
            }
        }
    }
    s.push_str("</tbody></table><p class=\"legend-text\">Cg = 0.2·T/6s, Cgk = (0.1·T − |bias|)/3s against the master's reference 0.</p></section>");
    s
}
