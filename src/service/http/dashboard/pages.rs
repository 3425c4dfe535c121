//! The pages as HTML text: the layout, the plant overview and the table versions page (the
//! feature page is in `feature.rs`). Every page has one live region that the script
//! replaces with `?fragment=1` of the same address when a part arrives.

use super::charts::{Line, LineChart, sparkline};
use super::data::{OverviewRow, diff_um};
use crate::store::TableVersion;
use std::fmt::Write as _;

/// Escapes text for HTML content and attribute values.
pub(crate) fn esc(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&#39;"),
            c => s.push(c),
        }
    }
    s
}

/// `YYYY-MM-DD HH:MM:SS` UTC.
pub(super) fn when(ms: i64) -> String {
    crate::clock::utc_format(ms, "%Y-%m-%d %H:%M:%S")
}

/// The address of a feature's pages.
pub(super) fn feature_url(machine: &str, lobe: &str) -> String {
    format!("/machines/{machine}/features/{lobe}")
}

/// The whole page around `live` (the region the script refreshes, from `live_url`) and
/// `rest` (forms and drawings that stay while the page lives). With `fragment`, only `live`.
pub(super) fn page(
    title: &str,
    crumbs: &str,
    live_url: &str,
    scope: (&str, &str),
    live: String,
    rest: &str,
    fragment: bool,
) -> String {
    if fragment {
        return live;
    }
    format!(
        r#"<!doctype html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>{t} · camloop</title><link rel="icon" href="/assets/icon.svg" type="image/svg+xml"><link rel="stylesheet" href="/assets/app.css"><script src="/assets/app.js" defer></script></head>
<body><header><nav aria-label="breadcrumb"><a href="/">camloop</a>{crumbs}</nav>
<p id="who"><a href="/signin">Sign in</a></p>
<p id="live-status" role="status">live: connecting</p></header>
<main><h1>{t}</h1><div id="live" data-url="{u}" data-machine="{m}" data-lobe="{l}">{live}</div>{rest}</main>
<p id="notice" role="alert" hidden></p></body></html>
"#,
        t = esc(title),
        u = esc(live_url),
        m = esc(scope.0),
        l = esc(scope.1),
    )
}

/// The CSV and JSON links of a chart's data.
pub(super) fn downloads(base: &str, chart: &str, extra: &str) -> String {
    format!(
        r#"<p class="downloads">Data: <a href="{b}/data?chart={c}&amp;format=csv{e}" download>CSV</a> · <a href="{b}/data?chart={c}&amp;format=json{e}" download>JSON</a></p>"#,
        b = esc(base),
        c = chart,
        e = esc(extra)
    )
}

pub(super) fn overview(rows: &[OverviewRow], fragment: bool) -> String {
    let mut live = String::from(
        r#"<table id="machines"><caption>Every machine and feature, newest part first</caption><thead><tr><th scope="col">Machine</th><th scope="col">Feature</th><th scope="col">State</th><th scope="col">Current part</th><th scope="col">Worst error, last part</th><th scope="col">Table on the control</th><th scope="col">Last 50 parts (max profile error, µm)</th></tr></thead><tbody>"#,
    );
    for r in rows {
        let url = feature_url(&r.machine, &r.lobe);
        let last = r.recent.last();
        let part = last.map_or("—".to_string(), |p| {
            format!(
                "part {} · #{} · {}",
                esc(&p.part),
                p.id.0,
                when(p.received_at_ms)
            )
        });
        let error = match (last, r.band_um) {
            (Some(p), Some(b)) => format!(
                r#"<span class="err {v}" data-last-error-um="{e}">{e:.2}</span> µm of ±{b} µm ({pc:.0} %)"#,
                v = p.verdict.as_str(),
                e = p.max_profile_error_um,
                pc = p.max_profile_error_um / b * 100.0
            ),
            (Some(p), None) => format!(
                r#"<span class="err {v}" data-last-error-um="{e}">{e:.2}</span> µm ({v})"#,
                v = p.verdict.as_str(),
                e = p.max_profile_error_um
            ),
            (None, _) => "—".into(),
        };
        let table = r.in_force.as_ref().map_or("—".into(), |v| {
            format!("v{} (T{})", v.version, v.table_number)
        });
        let values: Vec<f64> = r.recent.iter().map(|p| p.max_profile_error_um).collect();
        let spark = sparkline(
            &values,
            r.band_um,
            &format!("{} {}: last {} parts", r.machine, r.lobe, values.len()),
        );
        let _ = write!(
            live,
            r#"<tr data-machine="{m}" data-lobe="{l}" data-last-id="{id}"><th scope="row"><a href="{u}">{m}</a></th><td><a href="{u}">{l}</a></td><td><span class="state {sc}">{s}</span></td><td>{part}</td><td>{error}</td><td>{table}</td><td>{spark}</td></tr>"#,
            m = esc(&r.machine),
            l = esc(&r.lobe),
            u = esc(&url),
            id = last.map_or(0, |p| p.id.0),
            s = r.state.as_str(),
            sc = r.state.as_str().replace(' ', "-"),
        );
    }
    live.push_str("</tbody></table>");
    if rows.is_empty() {
        live.push_str("<p>No machine is configured or recorded yet.</p>");
    }
    page("Plant overview", "", "/", ("", ""), live, "", fragment)
}

/// The table versions page of a feature, with the X difference of version `shown` to its
/// parent.
pub(super) fn versions(
    machine: &str,
    lobe: &str,
    versions: &[TableVersion],
    shown: Option<i64>,
    fragment: bool,
) -> String {
    let base = feature_url(machine, lobe);
    let api = format!("/api/v1/machines/{machine}/lobes/{lobe}");
    let mut live = String::from(
        r#"<table id="versions"><caption>Table versions, newest first</caption><thead><tr><th scope="col">Version</th><th scope="col">Parent</th><th scope="col">Table</th><th scope="col">Status</th><th scope="col">Reason</th><th scope="col">Made</th><th scope="col">Program (SHA-256)</th><th scope="col">Rollback</th></tr></thead><tbody>"#,
    );
    for v in versions {
        let _ = write!(
            live,
            r#"<tr data-version="{n}"><th scope="row"><a href="{b}/versions?v={n}">v{n}</a></th><td>{p}</td><td>T{t}</td><td title="{why}">{s}</td><td>{r}</td><td>{at}</td><td><a href="{api}/tables/{n}/program" download="{lobe}_v{n}.spf" title="{sha}">{short}…</a></td><td><button type="button" class="rollback" data-url="{api}/rollback" data-version="{n}">Roll back to v{n}</button></td></tr>"#,
            n = v.version,
            b = esc(&base),
            p = v.parent_version.map_or("—".into(), |p| format!("v{p}")),
            t = v.table_number,
            why = esc(&v.status_why),
            s = v.status.as_str(),
            r = esc(&v.reason),
            at = when(v.created_at_ms),
            api = esc(&api),
            lobe = esc(lobe),
            sha = esc(&v.sha256),
            short = esc(v.sha256.get(..12).unwrap_or(&v.sha256)),
        );
    }
    live.push_str("</tbody></table>");
    // Without a version asked for, the newest with a parent, also after a refresh.
    let asked = shown;
    let shown = shown.or_else(|| {
        versions
            .iter()
            .find(|v| v.parent_version.is_some())
            .map(|v| v.version)
    });
    let pair = shown.and_then(|s| {
        let newer = versions.iter().find(|v| v.version == s)?;
        let older = versions
            .iter()
            .find(|v| Some(v.version) == newer.parent_version)?;
        Some((newer, older))
    });
    match pair.and_then(|(n, o)| Some((n, o, diff_um(n, o)?))) {
        Some((n, o, points)) => {
            let chart = LineChart {
                title: format!("X of v{} minus X of v{}", n.version, o.version),
                x_label: "C, °".into(),
                y_label: "ΔX, µm".into(),
                lines: vec![Line {
                    name: "ΔX".into(),
                    class: "diff",
                    points,
                }],
                limits: vec![],
                marks: vec![],
            };
            live.push_str(&chart.svg());
            live.push_str(&downloads(&base, "diff", &format!("&v={}", n.version)));
        }
        None => live.push_str("<p>No version with a parent to compare yet.</p>"),
    }
    let crumbs = format!(
        r#" › <a href="{b}">{m} {l}</a> › versions"#,
        b = esc(&base),
        m = esc(machine),
        l = esc(lobe)
    );
    let rest = r#"<p class="hint">Rollback delivers the chosen version again as a new version; it needs an engineer signed in (top right).</p><p id="rollback-result" role="status"></p>"#;
    page(
        &format!("{machine} {lobe}: table versions"),
        &crumbs,
        &format!(
            "{base}/versions{}",
            asked.map_or(String::new(), |v| format!("?v={v}"))
        ),
        (machine, lobe),
        live,
        rest,
        fragment,
    )
}
