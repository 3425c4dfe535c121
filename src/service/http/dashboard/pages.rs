//! The pages as HTML (maud: every value is escaped by construction): the layout, the plant overview and the table versions page (the
//! feature page is in `feature.rs`). Every page has one live region that the script
//! replaces with `?fragment=1` of the same address when a part arrives.

use super::charts::{Line, LineChart, sparkline};
use super::data::diff_um;
use super::overview::{OverviewPage, OverviewRow};
use crate::store::StoredTableVersion;
use maud::{DOCTYPE, Markup, html};

/// `YYYY-MM-DD HH:MM:SS` UTC.
pub(super) fn when(at: jiff::Timestamp) -> String {
    crate::clock::utc_format(at, "%Y-%m-%d %H:%M:%S")
}

/// The address of a feature's pages.
pub(super) fn feature_url(machine: &str, lobe: &str) -> String {
    format!("/machines/{machine}/features/{lobe}")
}

/// The head and the body's frame every page shares: the title, the one stylesheet and the
/// one script (no inline script or style: the CSP forbids them), the breadcrumb.
pub(super) fn shell(title: &str, crumbs: Markup, header: Markup, main: Markup) -> String {
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                meta name="viewport" content="width=device-width, initial-scale=1";
                title { (title) " · camloop" }
                link rel="icon" href="/assets/icon.svg" type="image/svg+xml";
                link rel="stylesheet" href="/assets/app.css";
                script src="/assets/app.js" defer {}
            }
            body {
                header {
                    nav aria-label="breadcrumb" { a href="/" { "camloop" } (crumbs) }
                    (header)
                }
                main { h1 { (title) } (main) }
                p id="notice" role="alert" hidden {}
            }
        }
    }
    .into_string()
}

/// The whole page around `live` (the region the script refreshes, from `live_url`) and
/// `rest` (forms and drawings that stay while the page lives). With `fragment`, only `live`.
pub(super) fn page(
    title: &str,
    crumbs: Markup,
    live_url: &str,
    scope: (&str, &str),
    live: Markup,
    rest: Markup,
    fragment: bool,
) -> String {
    if fragment {
        return live.into_string();
    }
    let header = html! {
        p id="who" { a href="/signin" { "Sign in" } }
        p id="live-status" role="status" { "live: connecting" }
    };
    let main = html! {
        div id="live" data-url=(live_url) data-machine=(scope.0) data-lobe=(scope.1) { (live) }
        (rest)
    };
    shell(title, crumbs, header, main)
}

/// The CSV and JSON links of a chart's data.
pub(super) fn downloads(base: &str, chart: &str, extra: &str) -> Markup {
    html! {
        p class="downloads" {
            "Data: "
            a href={ (base) "/data?chart=" (chart) "&format=csv" (extra) } download { "CSV" }
            " · "
            a href={ (base) "/data?chart=" (chart) "&format=json" (extra) } download { "JSON" }
        }
    }
}

/// The newest part of an overview row, its worst error and the table in force.
fn overview_cells(r: &OverviewRow) -> Markup {
    let last = r.recent.last();
    html! {
        td {
            @match last {
                Some(p) => { "part " (p.part) " · #" (p.id.0) " · " (when(p.received_at)) }
                None => "—",
            }
        }
        td {
            @match (last, r.band_um) {
                (Some(p), Some(b)) => {
                    span class={ "err " (p.verdict.as_str()) } data-last-error-um=(p.max_profile_error_um) { (format!("{:.2}", p.max_profile_error_um)) }
                    " µm of ±" (b) " µm (" (format!("{:.0}", p.max_profile_error_um / b * 100.0)) " %)"
                }
                (Some(p), None) => {
                    span class={ "err " (p.verdict.as_str()) } data-last-error-um=(p.max_profile_error_um) { (format!("{:.2}", p.max_profile_error_um)) }
                    " µm (" (p.verdict.as_str()) ")"
                }
                (None, _) => "—",
            }
        }
        td {
            @match &r.in_force {
                Some(v) => { "v" (v.version) " (T" (v.table_number) ")" }
                None => "—",
            }
        }
    }
}

/// The plant's size, its machines in alarm (on every page), and the links to the other
/// pages when there is more than one.
fn overview_pages(p: &OverviewPage) -> Markup {
    html! {
        p id="plant" {
            (p.machines) @if p.machines == 1 { " machine, " } @else { " machines, " }
            (p.features) @if p.features == 1 { " feature" } @else { " features" }
            @if p.pages > 1 { "; page " (p.page) " of " (p.pages) }
            @if !p.alarms.is_empty() {
                "; in alarm: "
                @for (i, (m, n)) in p.alarms.iter().enumerate() {
                    @if i > 0 { ", " }
                    a href={ "/?page=" (n) } { (m) }
                }
            }
        }
        @if p.pages > 1 {
            nav id="pages" aria-label="overview pages" {
                @for n in 1..=p.pages {
                    @if n == p.page { strong { (n) } } @else { a href={ "/?page=" (n) } { (n) } }
                    " "
                }
            }
        }
    }
}

pub(super) fn overview(p: &OverviewPage, fragment: bool) -> String {
    let rows = &p.rows;
    let live = html! {
        (overview_pages(p))
        table id="machines" {
            caption { "Every machine and feature, newest part first" }
            thead { tr {
                th scope="col" { "Machine" } th scope="col" { "Feature" } th scope="col" { "State" }
                th scope="col" { "Current part" } th scope="col" { "Worst error, last part" }
                th scope="col" { "Table on the control" } th scope="col" { "Last 50 parts (max profile error, µm)" }
            } }
            tbody {
                @for r in rows {
                    @let url = feature_url(&r.machine, &r.lobe);
                    @let values: Vec<f64> = r.recent.iter().map(|p| p.max_profile_error_um).collect();
                    tr data-machine=(r.machine) data-lobe=(r.lobe) data-last-id=(r.recent.last().map_or(0, |p| p.id.0)) {
                        th scope="row" { a href=(url) { (r.machine) } }
                        td { a href=(url) { (r.lobe) } }
                        td { span class={ "state " (r.state.as_str().replace(' ', "-")) } { (r.state.as_str()) } }
                        (overview_cells(r))
                        td { (sparkline(&values, r.band_um, &format!("{} {}: last {} parts", r.machine, r.lobe, values.len()))) }
                    }
                }
            }
        }
        @if rows.is_empty() {
            p { "No machine is configured or recorded yet." }
        }
    };
    let live_url = match p.page {
        1 => "/".to_string(),
        n => format!("/?page={n}"),
    };
    page(
        "Plant overview",
        html! {},
        &live_url,
        ("", ""),
        live,
        html! {},
        fragment,
    )
}

/// The versions table of a feature's page, newest first.
fn versions_table(lobe: &str, base: &str, api: &str, versions: &[StoredTableVersion]) -> Markup {
    html! {
        table id="versions" {
            caption { "Table versions, newest first" }
            thead { tr {
                th scope="col" { "Version" } th scope="col" { "Parent" } th scope="col" { "Table" }
                th scope="col" { "Status" } th scope="col" { "Reason" } th scope="col" { "Made" }
                th scope="col" { "Program (SHA-256)" } th scope="col" { "Rollback" }
            } }
            tbody {
                @for v in versions {
                    @let n = v.version;
                    tr data-version=(n) {
                        th scope="row" { a href={ (base) "/versions?v=" (n) } { "v" (n) } }
                        td { @match v.parent_version { Some(p) => { "v" (p) }, None => "—" } }
                        td { "T" (v.table_number) }
                        td title=(v.status.why()) { (v.status.name()) }
                        td { (v.reason) }
                        td { (when(v.created_at)) }
                        td {
                            a href={ (api) "/tables/" (n) "/program" } download={ (lobe) "_v" (n) ".spf" } title=(v.sha256) {
                                (v.sha256.to_string()[..12]) "…"
                            }
                        }
                        td { button type="button" class="rollback" data-url={ (api) "/rollback" } data-version=(n) { "Roll back to v" (n) } }
                    }
                }
            }
        }
    }
}

/// The table versions page of a feature, with the X difference of version `shown` to its
/// parent.
pub(super) fn versions(
    machine: &str,
    lobe: &str,
    versions: &[StoredTableVersion],
    shown: Option<i64>,
    fragment: bool,
) -> String {
    let base = feature_url(machine, lobe);
    let api = format!("/api/v1/machines/{machine}/lobes/{lobe}");
    // Without a version asked for, the newest with a parent, also after a refresh.
    let asked = shown;
    let shown = shown.or_else(|| {
        versions
            .iter()
            .find(|v| v.parent_version.is_some())
            .map(|v| v.version.to_i64())
    });
    let pair = shown.and_then(|s| {
        let newer = versions.iter().find(|v| v.version.to_i64() == s)?;
        let older = versions
            .iter()
            .find(|v| Some(v.version) == newer.parent_version)?;
        Some((newer, older))
    });
    let diff = pair.and_then(|(n, o)| Some((n, o, diff_um(n, o)?)));
    let live = html! {
        (versions_table(lobe, &base, &api, versions))
        @match diff {
            Some((n, o, points)) => {
                (LineChart {
                    title: format!("X of v{} minus X of v{}", n.version, o.version),
                    x_label: "C, °".into(),
                    y_label: "ΔX, µm".into(),
                    lines: vec![Line { name: "ΔX".into(), class: "diff", points }],
                    limits: vec![],
                    marks: vec![],
                }.svg())
                (downloads(&base, "diff", &format!("&v={}", n.version)))
            }
            None => p { "No version with a parent to compare yet." },
        }
    };
    let crumbs = html! { " › " a href=(base) { (machine) " " (lobe) } " › versions" };
    let rest = html! {
        p class="hint" { "Rollback delivers the chosen version again as a new version; it needs an engineer signed in (top right)." }
        p id="rollback-result" role="status" {}
    };
    page(
        &format!("{machine} {lobe}: table versions"),
        crumbs,
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
