//! The feature page's capability panel: per characteristic a histogram of the newest 125
//! production parts with the limits and the fitted model's expected counts, the indices
//! with their lower 95 % bounds, and the individuals chart with its limits and the points
//! the run rules flagged; then the latest type-1 gauge study of the master runs.

use super::FeatureSheet;
use super::charts::{Line, LineChart, Mark};
use crate::core::capability::{Capability, Index};
use crate::names::{FeatureName, MachineName};
use crate::quality::{self, CharacteristicStudy, Window, study::GaugeItem};
use crate::store::{Store, StoreError};
use maud::{Markup, html};

const W: f64 = 320.0;
const H: f64 = 170.0;
const BINS: usize = 16;

/// The panel's HTML.
pub(super) async fn panel(
    store: &Store,
    machine: &MachineName,
    lobe: &FeatureName,
    sheet: &FeatureSheet,
) -> Result<Markup, StoreError> {
    let (rows, _, _) =
        quality::window_rows(store, machine, lobe, &Window::default(), false).await?;
    let items = quality::study(&rows, &sheet.limits, true);
    let master = Window {
        last: 50,
        ..Window::default()
    };
    let (masters, _, _) = quality::window_rows(store, machine, lobe, &master, true).await?;
    let gauge = quality::study::gauge_studies(&masters, &sheet.limits);
    Ok(html! {
        section aria-labelledby="cap-h" {
            h2 id="cap-h" { "Capability (newest " (rows.len()) " parts)" }
            p class="legend-text" {
                "Bars: parts per bin; line: the model's expected count; dashed red: the recipe's limits. Indices with their lower 95 % bound in brackets. API: "
                code { "/api/v1/machines/" (machine) "/features/" (lobe) "/capability?window=parts:125&chart=true" }
                "."
            }
            @if let Some(why) = quality::indicative_reason(&items) {
                p id="capability-indicative" class="indicative" role="note" {
                    strong { "Indicative only: " } (why) "."
                }
            }
            (indices_table(&items))
            @for it in &items {
                div class="pair" {
                    figure { (histogram(it)) }
                    @if let Some(chart) = individuals(it) {
                        figure { (chart) }
                    }
                }
            }
        }
        (gauge_section(&gauge, masters.len()))
    })
}

/// The individuals chart of a characteristic with the points the run rules flagged.
fn individuals(it: &CharacteristicStudy) -> Option<Markup> {
    let name = it.characteristic.as_str();
    let chart = it.chart.as_ref()?;
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
    Some(svg)
}

fn idx(i: Option<Index>) -> String {
    i.map_or("–".into(), |i| {
        format!("{:.2} ({:.2})", i.value, i.lower_95)
    })
}

fn indices_table(items: &[CharacteristicStudy]) -> Markup {
    let f = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.4}"));
    html! {
        table id="capability" {
            thead { tr {
                @for h in ["Characteristic", "n", "Mean", "σ within", "σ overall", "Model", "Cp", "Cpk", "Pp", "Ppk", "Expected out", "Observed out", "Note"] {
                    th scope="col" { (h) }
                }
            } }
            tbody {
                @for it in items {
                    @let c = it.capability.as_ref();
                    @let ix = c.and_then(|c| c.indices.as_ref());
                    tr {
                        th scope="row" { (it.characteristic.as_str()) " (" (it.unit) ")" }
                        td { (c.map_or("–".into(), |c| c.n.to_string())) }
                        td { (f(c.map(|c| c.mean))) }
                        td { (f(c.map(|c| c.sigma_within))) }
                        td { (f(c.map(|c| c.sigma_overall))) }
                        td { (c.map_or("–", |c| c.model.name())) }
                        td { (idx(ix.and_then(|i| i.cp))) }
                        td { (idx(ix.map(|i| i.cpk))) }
                        td { (idx(ix.and_then(|i| i.pp))) }
                        td { (idx(ix.map(|i| i.ppk))) }
                        td { (ix.map_or("–".into(), |i| format!("{:.1} ppm", i.expected_share_out * 1e6))) }
                        td { (ix.map_or("–".into(), |i| format!("{:.1} %", i.observed_share_out * 100.0))) }
                        td {
                            @if it.indicative { "indicative (n < " (quality::MIN_CAPABILITY_VALUES) ") " }
                            (it.note.as_deref().unwrap_or(""))
                        }
                    }
                }
            }
        }
    }
}

/// Bars of the window's values, the limits, and the model's expected count per bin.
fn histogram(it: &CharacteristicStudy) -> Markup {
    let name = it.characteristic.as_str();
    let Some(c) = &it.capability else {
        return html! { p { (name) ": no histogram (" (it.note.as_deref().unwrap_or("")) ")" } };
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
    let d1 = |v: f64| format!("{v:.1}");
    let curve: Vec<String> = expected
        .iter()
        .enumerate()
        .map(|(b, &e)| format!("{:.1},{:.1}", px(lo + (b as f64 + 0.5) * width), py(e)))
        .collect();
    html! {
        svg class="chart" viewBox={ "0 0 " (W) " " (H) } role="img" aria-label={ (name) " histogram" } {
            title { (name) ": histogram, limits and " (c.model.name()) " model" }
            @for (b, &n) in counts.iter().enumerate() {
                rect class="bar" x=(d1(px(lo + b as f64 * width))) y=(d1(py(n as f64)))
                    width=(d1((W - 20.0) / BINS as f64 - 1.0)) height=(d1(H - 20.0 - py(n as f64))) {}
            }
            polyline class="line phase" fill="none" points=(curve.join(" ")) {}
            @for (v, label) in [(c.limits.lower, "LSL"), (c.limits.upper, "USL")] {
                @if let Some(v) = v {
                    line class="limit" x1=(d1(px(v))) x2=(d1(px(v))) y1="16" y2=(d1(H - 20.0)) {}
                    text x=(d1(px(v))) y="12" text-anchor="middle" { (label) " " (v) }
                }
            }
            text x="10" y=(d1(H - 4.0)) { (name) ", " (it.unit) ": " (format!("{lo:.4} … {hi:.4}")) }
        }
    }
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

fn gauge_section(items: &[GaugeItem], runs: usize) -> Markup {
    html! {
        section aria-labelledby="gauge-h" {
            h2 id="gauge-h" { "Gauge study (type 1, latest " (runs) " master runs)" }
            @if runs == 0 {
                p { "No master runs yet: measure the master part (part id MASTER…) to study the gauge." }
            } @else {
                table id="gauge-study" {
                    thead { tr {
                        @for h in ["Characteristic", "n", "Tolerance", "Bias", "s", "Cg", "Cgk", "Verdict"] {
                            th scope="col" { (h) }
                        }
                    } }
                    tbody { @for it in items { (gauge_row(it)) } }
                }
                p class="legend-text" { "Cg = 0.2·T/6s, Cgk = (0.1·T − |bias|)/3s against the master's reference 0." }
            }
        }
    }
}

fn gauge_row(it: &GaugeItem) -> Markup {
    let name = it.characteristic.as_str();
    html! {
        tr {
            th scope="row" { (name) " (" (it.unit) ")" }
            @match &it.study {
                Some(g) => {
                    td { (g.n) }
                    td { (format!("{:.4}", g.tolerance)) }
                    td { (format!("{:.4}", g.bias)) }
                    td { (format!("{:.4}", g.sigma)) }
                    td { (format!("{:.2}", g.cg)) }
                    td { (format!("{:.2}", g.cgk)) }
                    td { (if g.capable { "capable (≥ 1.33)" } else { "not capable" }) }
                }
                None => td colspan="7" { (it.note.as_deref().unwrap_or("no study")) },
            }
        }
    }
}
