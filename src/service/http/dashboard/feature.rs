//! The machine / feature page: trend over parts with the tolerance and the dressings and
//! table versions marked, the latest part (polar and unrolled with bands and the current
//! correction), events with acknowledgement, the dressing form and the setup drawing.

use super::FeatureSheet;
use super::charts::{Line, LineChart, Mark, polar};
use super::data::FeatureData;
use super::pages::{downloads, feature_url, page, when};
use crate::store::MeasurementSummary;
use maud::{Markup, PreEscaped, html};

/// The trend's time unit for a span of parts: its name and length in ms.
fn unit(span_ms: i64) -> (&'static str, f64) {
    if span_ms < 120_000 {
        ("s", 1000.0)
    } else if span_ms < 3 * 3_600_000 {
        ("min", 60_000.0)
    } else {
        ("h", 3_600_000.0)
    }
}

fn trend_chart(
    title: &str,
    y_label: &str,
    class: &'static str,
    parts: &[MeasurementSummary],
    value: fn(&MeasurementSummary) -> f64,
    limits: Vec<(f64, String)>,
    marks: &[Mark],
) -> Markup {
    // The chart's x axis is in milliseconds before the newest part.
    let newest = parts.last().map_or(0, |p| p.received_at.as_millisecond());
    let oldest = parts.first().map_or(0, |p| p.received_at.as_millisecond());
    let (name, ms) = unit(newest - oldest);
    LineChart {
        title: title.into(),
        x_label: format!("time, {name} before the newest part"),
        y_label: y_label.into(),
        lines: vec![Line {
            name: title.into(),
            class,
            points: parts
                .iter()
                .map(|p| {
                    let at_ms = p.received_at.as_millisecond();
                    ((at_ms - newest) as f64 / ms, value(p))
                })
                .collect(),
        }],
        limits,
        marks: marks
            .iter()
            .map(|m| Mark {
                x: m.x,
                label: m.label.clone(),
                class: m.class,
            })
            .collect(),
    }
    .svg()
}

fn trend(d: &FeatureData, sheet: Option<&FeatureSheet>, base: &str) -> Markup {
    let Some(first) = d.parts.first() else {
        return html! { p { "No part measured yet." } };
    };
    let newest = d.parts.last().map_or(first.received_at, |p| p.received_at);
    let in_range = |t: jiff::Timestamp| t >= first.received_at && t <= newest;
    let (_, ms) = unit(newest.as_millisecond() - first.received_at.as_millisecond());
    let x = |t: jiff::Timestamp| (t.as_millisecond() - newest.as_millisecond()) as f64 / ms;
    let mut marks: Vec<Mark> = d
        .dressings
        .iter()
        .filter(|d| in_range(d.at))
        .map(|d| Mark {
            x: x(d.at),
            label: format!("dressed {:.3} → {:.3} mm", d.old_radius_mm, d.new_radius_mm),
            class: "dressing",
        })
        .collect();
    marks.extend(
        d.versions
            .iter()
            .filter(|v| in_range(v.created_at))
            .map(|v| Mark {
                x: x(v.created_at),
                label: format!("table v{} ({})", v.version, v.reason),
                class: "version",
            }),
    );
    let band = sheet.and_then(FeatureSheet::symmetric_band_um);
    let limits = band
        .map(|b| vec![(b, format!("tolerance {b} µm"))])
        .unwrap_or_default();
    html! {
        section aria-labelledby="trend-h" {
            h2 id="trend-h" { "Trend over the last " (d.parts.len()) " parts" }
            p class="legend-text" { "Dashed red: tolerance. Blue marks: table versions; orange marks: dressings." }
            (trend_chart("max profile error", "µm", "profile", &d.parts, |p| p.max_profile_error_um, limits, &marks))
            (trend_chart("size (base radius error)", "µm", "size", &d.parts, |p| p.base_radius_error_um, vec![], &marks))
            (trend_chart("phase error", "°", "phase", &d.parts, |p| p.phase_error_deg, vec![], &marks))
            (downloads(base, "trend", ""))
        }
    }
}

fn latest(d: &FeatureData, sheet: Option<&FeatureSheet>, base: &str) -> Markup {
    let Some(l) = &d.latest else {
        return html! {};
    };
    let c = &l.curves;
    let n = c.angle_deg.len();
    if n == 0 || c.error_um.len() != n || l.lift_mm.len() != n {
        return html! { p { "The latest part's report has no error curve." } };
    }
    let nominal: Vec<f64> = (0..n)
        .map(|i| l.lift_mm[i] - c.error_um[i] / 1000.0)
        .collect();
    let r0 = sheet.and_then(|s| s.base_radius_mm).unwrap_or(20.0);
    let mut lines = vec![
        Line {
            name: "error".into(),
            class: "error",
            points: c
                .angle_deg
                .iter()
                .copied()
                .zip(c.error_um.iter().copied())
                .collect(),
        },
        Line {
            name: "profile error".into(),
            class: "profile",
            points: c
                .angle_deg
                .iter()
                .copied()
                .zip(c.profile_error_um.iter().copied())
                .collect(),
        },
    ];
    let k = d.learning.correction_um.len();
    if k > 0 {
        lines.push(Line {
            name: "correction".into(),
            class: "correction",
            points: (0..k)
                .map(|j| (j as f64 * 360.0 / k as f64, d.learning.correction_um[j]))
                .collect(),
        });
    }
    let mut limits = Vec::new();
    for b in sheet.map(|s| s.bands.as_slice()).unwrap_or_default() {
        limits.push((
            b.upper_um,
            format!("band {}–{}°: upper {} µm", b.from_deg, b.to_deg, b.upper_um),
        ));
        limits.push((
            b.lower_um,
            format!("band {}–{}°: lower {} µm", b.from_deg, b.to_deg, b.lower_um),
        ));
    }
    let unrolled = LineChart {
        title: format!("part #{}: error against angle", l.summary.id.0),
        x_label: "gauge angle, °".into(),
        y_label: "µm".into(),
        lines,
        limits,
        marks: vec![],
    };
    html! {
        section aria-labelledby="latest-h" {
            h2 id="latest-h" {
                "Latest part #" (l.summary.id.0) " (" (l.summary.verdict.as_str()) ", " (when(l.summary.received_at)) ")"
            }
            div class="pair" {
                (polar(&c.angle_deg, &nominal, &c.error_um, r0))
                (unrolled.svg())
            }
            (downloads(base, "latest", ""))
        }
    }
}

fn events(d: &FeatureData, machine: &str) -> Markup {
    html! {
        section aria-labelledby="events-h" {
            h2 id="events-h" { "Events and alarms" }
            table id="events" {
                thead { tr {
                    th scope="col" { "When" } th scope="col" { "Level" } th scope="col" { "Kind" }
                    th scope="col" { "Message" } th scope="col" { "Acknowledged" }
                } }
                tbody {
                    @for (e, ack) in &d.events {
                        tr class=(e.level.as_str()) {
                            td { (when(e.at)) }
                            td { (e.level.as_str()) }
                            td { (e.kind.as_str()) }
                            td { (e.message) }
                            td {
                                @match ack {
                                    Some(a) => { (when(a.at)) " (" (a.source) ")" }
                                    None => {
                                        button type="button" class="ack" data-url={ "/api/v1/machines/" (machine) "/events/" (e.id.0) "/ack" } { "Acknowledge" }
                                    }
                                }
                            }
                        }
                    }
                    @if d.events.is_empty() {
                        tr { td colspan="5" { "No events." } }
                    }
                }
            }
        }
    }
}

pub(super) fn feature(
    machine: &str,
    lobe: &str,
    d: &FeatureData,
    sheet: Option<&FeatureSheet>,
    fragment: bool,
    capability: Markup,
) -> String {
    let base = feature_url(machine, lobe);
    let in_force = d
        .versions
        .iter()
        .find(|v| matches!(v.status, crate::store::VersionStatus::Pushed { .. }))
        .map_or("none yet".into(), |v| {
            format!("v{} (T{}): {}", v.version, v.table_number, v.reason)
        });
    let live = html! {
        p class="summary" {
            "Table on the control: " strong { (in_force) }
            " · " a href={ (base) "/versions" } { "table versions" }
            " · " a href={ (base) "/export.dfq" } download { "Q-DAS export (.dfq)" }
        }
        (trend(d, sheet, &base))
        (latest(d, sheet, &base))
        (events(d, machine))
    };
    // The drawings are SVG documents the core renders (escaping its own text): kept as they are.
    let setup = sheet.and_then(|s| s.setup_svg.as_deref());
    let plan = sheet.and_then(|s| s.speed_plan_svg.as_deref());
    let rest = html! {
        (capability)
        section aria-labelledby="dress-h" {
            h2 id="dress-h" { "Report a dressing" }
            form id="dressing" data-url={ "/api/v1/machines/" (machine) "/dressings" } {
                label for="radius" { "New wheel radius, mm" } " "
                input id="radius" name="wheel_radius_mm" type="number" step="0.001" min="5" max="1000" required;
                " " button type="submit" { "Report dressing" }
            }
            p id="dressing-result" role="status" {}
        }
        section aria-labelledby="setup-h" {
            h2 id="setup-h" { "Setup drawing" }
            div class="setup" {
                @match setup {
                    Some(svg) => (PreEscaped(svg)),
                    None => p { "No setup drawing: the feature is not configured in this service." },
                }
            }
        }
        @if let Some(svg) = plan {
            section aria-labelledby="plan-h" {
                h2 id="plan-h" { "Speed plan" }
                div class="setup" { (PreEscaped(svg)) }
            }
        }
    };
    let crumbs = html! { " › " (machine) " " (lobe) };
    page(
        &format!("{machine} {lobe}"),
        crumbs,
        &base,
        (machine, lobe),
        live,
        rest,
        fragment,
    )
}
