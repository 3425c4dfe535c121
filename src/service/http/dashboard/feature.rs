//! The machine / feature page: trend over parts with the tolerance and the dressings and
//! table versions marked, the latest part (polar and unrolled with bands and the current
//! correction), events with acknowledgement, the dressing form and the setup drawing.

use super::FeatureSheet;
use super::charts::{Line, LineChart, Mark, polar};
use super::data::FeatureData;
use super::pages::{downloads, esc, feature_url, page, when};
use crate::store::MeasurementSummary;
use std::fmt::Write as _;

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
) -> String {
    let newest = parts.last().map_or(0, |p| p.received_at_ms);
    let oldest = parts.first().map_or(0, |p| p.received_at_ms);
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
                .map(|p| ((p.received_at_ms - newest) as f64 / ms, value(p)))
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

fn trend(d: &FeatureData, sheet: Option<&FeatureSheet>, base: &str) -> String {
    let Some(first) = d.parts.first() else {
        return "<p>No part measured yet.</p>".into();
    };
    let newest = d.parts.last().map_or(0, |p| p.received_at_ms);
    let in_range = |t: i64| t >= first.received_at_ms && t <= newest;
    let (_, ms) = unit(newest - first.received_at_ms);
    let x = |t: i64| (t - newest) as f64 / ms;
    let mut marks: Vec<Mark> = d
        .dressings
        .iter()
        .filter(|d| in_range(d.at_ms))
        .map(|d| Mark {
            x: x(d.at_ms),
            label: format!("dressed {:.3} → {:.3} mm", d.old_radius_mm, d.new_radius_mm),
            class: "dressing",
        })
        .collect();
    marks.extend(
        d.versions
            .iter()
            .filter(|v| in_range(v.created_at_ms))
            .map(|v| Mark {
                x: x(v.created_at_ms),
                label: format!("table v{} ({})", v.version, v.reason),
                class: "version",
            }),
    );
    let band = sheet.and_then(FeatureSheet::symmetric_band_um);
    let limits = band
        .map(|b| vec![(b, format!("tolerance {b} µm"))])
        .unwrap_or_default();
    let mut s = format!(
        r#"<section aria-labelledby="trend-h"><h2 id="trend-h">Trend over the last {} parts</h2><p class="legend-text">Dashed red: tolerance. Blue marks: table versions; orange marks: dressings.</p>"#,
        d.parts.len()
    );
    s.push_str(&trend_chart(
        "max profile error",
        "µm",
        "profile",
        &d.parts,
        |p| p.max_profile_error_um,
        limits,
        &marks,
    ));
    s.push_str(&trend_chart(
        "size (base radius error)",
        "µm",
        "size",
        &d.parts,
        |p| p.base_radius_error_um,
        vec![],
        &marks,
    ));
    s.push_str(&trend_chart(
        "phase error",
        "°",
        "phase",
        &d.parts,
        |p| p.phase_error_deg,
        vec![],
        &marks,
    ));
    s.push_str(&downloads(base, "trend", ""));
    s.push_str("</section>");
    s
}

fn latest(d: &FeatureData, sheet: Option<&FeatureSheet>, base: &str) -> String {
    let Some(l) = &d.latest else {
        return String::new();
    };
    let c = &l.curves;
    let n = c.angle_deg.len();
    if n == 0 || c.error_um.len() != n || l.lift_mm.len() != n {
        return "<p>The latest part's report has no error curve.</p>".into();
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
    format!(
        r#"<section aria-labelledby="latest-h"><h2 id="latest-h">Latest part #{id} ({v}, {at})</h2><div class="pair">{p}{u}</div>{dl}</section>"#,
        id = l.summary.id.0,
        v = l.summary.verdict.as_str(),
        at = when(l.summary.received_at_ms),
        p = polar(&c.angle_deg, &nominal, &c.error_um, r0),
        u = unrolled.svg(),
        dl = downloads(base, "latest", ""),
    )
}

fn events(d: &FeatureData, machine: &str) -> String {
    let mut s = String::from(
        r#"<section aria-labelledby="events-h"><h2 id="events-h">Events and alarms</h2><table id="events"><thead><tr><th scope="col">When</th><th scope="col">Level</th><th scope="col">Kind</th><th scope="col">Message</th><th scope="col">Acknowledged</th></tr></thead><tbody>"#,
    );
    for (e, ack) in &d.events {
        let acked = match ack {
            Some(a) => format!("{} ({})", when(a.at_ms), esc(&a.source)),
            None => format!(
                r#"<button type="button" class="ack" data-url="/api/v1/machines/{m}/events/{id}/ack">Acknowledge</button>"#,
                m = esc(machine),
                id = e.id.0
            ),
        };
        let _ = write!(
            s,
            r#"<tr class="{lv}"><td>{at}</td><td>{lv}</td><td>{k}</td><td>{msg}</td><td>{acked}</td></tr>"#,
            at = when(e.at_ms),
            lv = e.level.as_str(),
            k = esc(e.kind.as_str()),
            msg = esc(&e.message),
        );
    }
    if d.events.is_empty() {
        s.push_str(r#"<tr><td colspan="5">No events.</td></tr>"#);
    }
    s.push_str("</tbody></table></section>");
    s
}

pub(super) fn feature(
    machine: &str,
    lobe: &str,
    d: &FeatureData,
    sheet: Option<&FeatureSheet>,
    fragment: bool,
    capability: &str,
) -> String {
    let base = feature_url(machine, lobe);
    let in_force = d
        .versions
        .iter()
        .find(|v| v.status == crate::store::TableStatus::Pushed)
        .map_or("none yet".into(), |v| {
            format!("v{} (T{}): {}", v.version, v.table_number, esc(&v.reason))
        });
    let mut live = format!(
        r#"<p class="summary">Table on the control: <strong>{in_force}</strong> · <a href="{b}/versions">table versions</a> · <a href="{b}/export.dfq" download>Q-DAS export (.dfq)</a></p>"#,
        b = esc(&base)
    );
    live.push_str(&trend(d, sheet, &base));
    live.push_str(&latest(d, sheet, &base));
    live.push_str(&events(d, machine));
    let setup = sheet
        .and_then(|s| s.setup_svg.as_deref())
        .unwrap_or("<p>No setup drawing: the feature is not configured in this service.</p>");
    let plan = sheet
        .and_then(|s| s.speed_plan_svg.as_deref())
        .map_or(String::new(), |svg| {
            format!(
                r#"<section aria-labelledby="plan-h"><h2 id="plan-h">Speed plan</h2><div class="setup">{svg}</div></section>"#
            )
        });
    let rest = format!(
        r#"{capability}<section aria-labelledby="dress-h"><h2 id="dress-h">Report a dressing</h2><form id="dressing" data-url="/api/v1/machines/{m}/dressings"><label for="radius">New wheel radius, mm</label> <input id="radius" name="wheel_radius_mm" type="number" step="0.001" min="5" max="1000" required> <button type="submit">Report dressing</button></form><p id="dressing-result" role="status"></p></section><section aria-labelledby="setup-h"><h2 id="setup-h">Setup drawing</h2><div class="setup">{setup}</div></section>{plan}"#,
        m = esc(machine)
    );
    let crumbs = format!(r#" › {} {}"#, esc(machine), esc(lobe));
    page(
        &format!("{machine} {lobe}"),
        &crumbs,
        &base,
        (machine, lobe),
        live,
        &rest,
        fragment,
    )
}
