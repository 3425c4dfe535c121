//! SVG drawing of a grinding setup (part, wheel positions, wheel-centre path): an overview
//! of the whole setup beside a zoom on the part, with legend, scale bars and the C axis.
//!
//! Wheels (R 200–400 mm) dwarf a cam (20–40 mm): at one scale either the tangency or the
//! setup is unreadable. So the drawing has two panels: left, everything at one scale with
//! full wheel circles and a dashed frame marking the zoom window; right, the zoom window
//! around the part, where each wheel shows as the arc that reaches the part (clipped to the
//! panel), so the tangency and the contact points are visible.
//!
//! Coordinates are mm in the part frame, y up. Each panel is a nested `<svg>` whose viewBox is
//! in mm; geometry sits in a `scale(1,-1)` group, text outside it at (x, −y) so it is not
//! mirrored. Line widths, marks and text are converted to mm per panel so they look the same
//! size on screen in both panels.

use std::fmt::Write as _;

/// What to draw. Non-finite coordinates and non-positive radii are skipped (and counted in
/// the legend), never a panic.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SetupView {
    pub title: String,
    /// Closed polyline of the part outline, mm, part frame (the last point joins the first).
    pub part_outline_mm: Vec<(f64, f64)>,
    /// Extra circles: base circle, pin outline, …
    pub circles: Vec<SetupCircle>,
    /// Closed polyline of the wheel centre over one revolution, mm.
    pub wheel_centre_path_mm: Vec<(f64, f64)>,
    pub wheels: Vec<WheelPosition>,
}

/// An extra circle, e.g. the base circle (dashed) or a pin outline.
#[derive(Debug, Clone, PartialEq)]
pub struct SetupCircle {
    pub centre_mm: (f64, f64),
    pub radius_mm: f64,
    /// Legend text; circles with the same label share one legend row.
    pub label: String,
    pub dashed: bool,
}

/// The wheel at one angle.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelPosition {
    pub centre_mm: (f64, f64),
    pub radius_mm: f64,
    /// Shown beside the centre (overview) and the contact point (zoom), e.g. "c = 90°".
    pub label: String,
    /// Where the wheel touches the part, if known.
    pub contact_mm: Option<(f64, f64)>,
}

const WIDTH_PX: f64 = 1200.0;
const PANEL_W_PX: f64 = 570.0;
const PANEL_H_PX: f64 = 520.0;
const PANEL_Y_PX: f64 = 64.0;
const OVERVIEW_X_PX: f64 = 20.0;
const ZOOM_X_PX: f64 = 610.0;
const LEGEND_ROW_PX: f64 = 20.0;

const PART_FILL: &str = "#d9d9d9";
const WHEEL_FILL: &str = "#c8b68e";
const WHEEL_STROKE: &str = "#7a6435";
const PATH_STROKE: &str = "#1f6fb4";
const CIRCLE_STROKE: &str = "#6b6b6b";
const CONTACT_FILL: &str = "#d62728";
const AXIS_STROKE: &str = "#2a9d4a";

/// Render `view` as a standalone SVG document (UTF-8, 1200 px wide).
pub fn render_setup_svg(view: &SetupView) -> String {
    let clean = Clean::from(view);
    let overview = Panel::fit(OVERVIEW_X_PX, clean.overview_box(), 0.06);
    let zoom = Panel::fit(ZOOM_X_PX, clean.zoom_box(), 0.2);
    let legend = clean.legend_rows();
    let legend_top = PANEL_Y_PX + PANEL_H_PX + 24.0;
    let rows_per_column = legend.len().div_ceil(2);
    let height = legend_top + rows_per_column as f64 * LEGEND_ROW_PX + 16.0;

    let mut o = String::new();
    o.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    w(
        &mut o,
        format_args!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH_PX}\" height=\"{height}\" viewBox=\"0 0 {WIDTH_PX} {height}\" font-family=\"sans-serif\">\n"
        ),
    );
    w(
        &mut o,
        format_args!("<rect width=\"{WIDTH_PX}\" height=\"{height}\" fill=\"white\"/>\n"),
    );
    w(
        &mut o,
        format_args!(
            "<text x=\"20\" y=\"30\" font-size=\"20\">{}</text>\n",
            esc(&view.title)
        ),
    );
    for (panel, caption) in [
        (&overview, "whole setup"),
        (&zoom, "zoom on the part: wheels clipped to the window"),
    ] {
        w(
            &mut o,
            format_args!(
                "<text x=\"{}\" y=\"{}\" font-size=\"13\" fill=\"#444\">{caption}</text>\n",
                panel.x_px,
                PANEL_Y_PX - 8.0
            ),
        );
    }
    clean.draw_panel(&mut o, &overview, "overview", Some(&zoom));
    clean.draw_panel(&mut o, &zoom, "zoom", None);
    for panel in [&overview, &zoom] {
        panel.frame_and_scale_bar(&mut o);
    }
    draw_legend(&mut o, &legend, legend_top);
    o.push_str("</svg>\n");
    o
}

/// The view with unusable items removed.
struct Clean<'a> {
    outline: Vec<(f64, f64)>,
    path: Vec<(f64, f64)>,
    circles: Vec<&'a SetupCircle>,
    wheels: Vec<&'a WheelPosition>,
    skipped: usize,
}

impl<'a> From<&'a SetupView> for Clean<'a> {
    fn from(v: &'a SetupView) -> Self {
        let finite = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite();
        let round = |c: (f64, f64), r: f64| finite(&c) && r.is_finite() && r > 0.0;
        let outline: Vec<_> = v.part_outline_mm.iter().copied().filter(finite).collect();
        let path: Vec<_> = v
            .wheel_centre_path_mm
            .iter()
            .copied()
            .filter(finite)
            .collect();
        let circles: Vec<_> = v
            .circles
            .iter()
            .filter(|c| round(c.centre_mm, c.radius_mm))
            .collect();
        let wheels: Vec<_> = v
            .wheels
            .iter()
            .filter(|c| round(c.centre_mm, c.radius_mm))
            .collect();
        let bad_contacts = wheels
            .iter()
            .filter(|wh| wh.contact_mm.is_some_and(|p| !finite(&p)))
            .count();
        let skipped = (v.part_outline_mm.len() - outline.len())
            + (v.wheel_centre_path_mm.len() - path.len())
            + (v.circles.len() - circles.len())
            + (v.wheels.len() - wheels.len())
            + bad_contacts;
        Clean {
            outline,
            path,
            circles,
            wheels,
            skipped,
        }
    }
}

/// Axis-aligned box, mm.
#[derive(Debug, Clone, Copy)]
struct BBox {
    min: (f64, f64),
    max: (f64, f64),
}

impl BBox {
    fn around_origin() -> Self {
        BBox {
            min: (0.0, 0.0),
            max: (0.0, 0.0),
        }
    }
    fn add(&mut self, p: (f64, f64)) {
        self.min = (self.min.0.min(p.0), self.min.1.min(p.1));
        self.max = (self.max.0.max(p.0), self.max.1.max(p.1));
    }
    fn add_circle(&mut self, c: (f64, f64), r: f64) {
        self.add((c.0 - r, c.1 - r));
        self.add((c.0 + r, c.1 + r));
    }
}

impl Clean<'_> {
    fn contacts(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.wheels
            .iter()
            .filter_map(|wh| wh.contact_mm)
            .filter(|p| p.0.is_finite() && p.1.is_finite())
    }

    /// Everything, full wheels included, and the rotation centre.
    fn overview_box(&self) -> BBox {
        let mut b = self.zoom_box();
        self.path.iter().for_each(|p| b.add(*p));
        self.wheels
            .iter()
            .for_each(|wh| b.add_circle(wh.centre_mm, wh.radius_mm));
        b
    }

    /// The part, the extra circles, the contact points and the rotation centre.
    fn zoom_box(&self) -> BBox {
        let mut b = BBox::around_origin();
        self.outline.iter().for_each(|p| b.add(*p));
        self.circles
            .iter()
            .for_each(|c| b.add_circle(c.centre_mm, c.radius_mm));
        self.contacts().for_each(|p| b.add(p));
        b
    }

    fn draw_panel(&self, o: &mut String, p: &Panel, id: &str, zoom_window: Option<&Panel>) {
        let (vx, vy, vw, vh) = (p.min_x, -p.max_y, p.w_mm(), p.h_mm());
        w(
            o,
            format_args!(
                "<svg id=\"{id}\" x=\"{}\" y=\"{PANEL_Y_PX}\" width=\"{PANEL_W_PX}\" height=\"{PANEL_H_PX}\" viewBox=\"{} {} {} {}\">\n",
                p.x_px,
                n(vx),
                n(vy),
                n(vw),
                n(vh)
            ),
        );
        let px = |v: f64| n(v / p.scale);
        o.push_str("<g transform=\"scale(1,-1)\">\n");
        for wh in &self.wheels {
            let (cx, cy) = wh.centre_mm;
            w(
                o,
                format_args!(
                    "<circle class=\"wheel\" cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"{WHEEL_FILL}\" fill-opacity=\"0.35\" stroke=\"{WHEEL_STROKE}\" stroke-width=\"{}\"/>\n",
                    n(cx),
                    n(cy),
                    n(wh.radius_mm),
                    px(1.2)
                ),
            );
            let arm = 5.0 / p.scale;
            w(
                o,
                format_args!(
                    "<path class=\"wheel-centre\" d=\"M{} {}H{}M{} {}V{}\" stroke=\"{WHEEL_STROKE}\" stroke-width=\"{}\"/>\n",
                    n(cx - arm),
                    n(cy),
                    n(cx + arm),
                    n(cx),
                    n(cy - arm),
                    n(cy + arm),
                    px(1.0)
                ),
            );
            if let Some((qx, qy)) = wh.contact_mm.filter(|q| q.0.is_finite() && q.1.is_finite()) {
                w(
                    o,
                    format_args!(
                        "<line class=\"contact-normal\" x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{CONTACT_FILL}\" stroke-width=\"{}\" stroke-opacity=\"0.6\"/>\n",
                        n(cx),
                        n(cy),
                        n(qx),
                        n(qy),
                        px(0.8)
                    ),
                );
            }
        }
        // Over the wheels' fill, so the path keeps its colour.
        if !self.path.is_empty() {
            w(
                o,
                format_args!(
                    "<polygon class=\"wheel-centre-path\" points=\"{}\" fill=\"none\" stroke=\"{PATH_STROKE}\" stroke-width=\"{}\" stroke-dasharray=\"{} {}\"/>\n",
                    points(&self.path),
                    px(1.2),
                    px(6.0),
                    px(4.0)
                ),
            );
        }
        for c in &self.circles {
            let dash = if c.dashed {
                format!(" stroke-dasharray=\"{} {}\"", px(5.0), px(3.0))
            } else {
                String::new()
            };
            w(
                o,
                format_args!(
                    "<circle class=\"extra-circle\" cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"none\" stroke=\"{CIRCLE_STROKE}\" stroke-width=\"{}\"{dash}/>\n",
                    n(c.centre_mm.0),
                    n(c.centre_mm.1),
                    n(c.radius_mm),
                    px(1.0)
                ),
            );
        }
        if !self.outline.is_empty() {
            w(
                o,
                format_args!(
                    "<polygon class=\"part\" points=\"{}\" fill=\"{PART_FILL}\" fill-opacity=\"0.8\" stroke=\"black\" stroke-width=\"{}\" stroke-linejoin=\"round\"/>\n",
                    points(&self.outline),
                    px(1.5)
                ),
            );
        }
        for (qx, qy) in self.contacts() {
            w(
                o,
                format_args!(
                    "<circle class=\"contact\" cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"{CONTACT_FILL}\"/>\n",
                    n(qx),
                    n(qy),
                    px(3.0)
                ),
            );
        }
        let arm = 16.0 / p.scale;
        w(
            o,
            format_args!(
                "<path class=\"rotation-centre\" d=\"M{} 0H{}M0 {}V{}\" stroke=\"{AXIS_STROKE}\" stroke-width=\"{}\" stroke-dasharray=\"{} {} {} {}\"/>\n",
                n(-arm),
                n(arm),
                n(-arm),
                n(arm),
                px(1.2),
                px(8.0),
                px(2.0),
                px(2.0),
                px(2.0)
            ),
        );
        if let Some(z) = zoom_window {
            w(
                o,
                format_args!(
                    "<rect class=\"zoom-window\" x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#444\" stroke-width=\"{}\" stroke-dasharray=\"{} {}\"/>\n",
                    n(z.min_x),
                    n(z.max_y - z.h_mm()),
                    n(z.w_mm()),
                    n(z.h_mm()),
                    px(1.0),
                    px(4.0),
                    px(3.0)
                ),
            );
        }
        o.push_str("</g>\n");
        // Labels, not mirrored: at (x, −y) in the viewBox.
        let font = 12.0 / p.scale;
        for wh in &self.wheels {
            let anchor = if zoom_window.is_some() {
                Some(wh.centre_mm)
            } else {
                wh.contact_mm.filter(|q| q.0.is_finite() && q.1.is_finite())
            };
            if let Some((lx, ly)) = anchor {
                w(
                    o,
                    format_args!(
                        "<text class=\"wheel-label\" x=\"{}\" y=\"{}\" font-size=\"{}\">{}</text>\n",
                        n(lx + 6.0 / p.scale),
                        n(-ly - 6.0 / p.scale),
                        n(font),
                        esc(&wh.label)
                    ),
                );
            }
        }
        o.push_str("</svg>\n");
    }

    fn legend_rows(&self) -> Vec<(Glyph, String)> {
        let mut rows = vec![(Glyph::Part, "part outline".to_owned())];
        let mut seen: Vec<(&str, bool)> = Vec::new();
        for c in &self.circles {
            if !seen.contains(&(c.label.as_str(), c.dashed)) {
                seen.push((c.label.as_str(), c.dashed));
                rows.push((Glyph::Circle { dashed: c.dashed }, c.label.clone()));
            }
        }
        if !self.path.is_empty() {
            rows.push((
                Glyph::Path,
                "wheel-centre path over one revolution".to_owned(),
            ));
        }
        if !self.wheels.is_empty() {
            let k = self.wheels.len();
            let s = if k == 1 { "" } else { "s" };
            rows.push((
                Glyph::Wheel,
                format!("grinding wheel, {k} position{s} (+ = centre)"),
            ));
        }
        if self.contacts().next().is_some() {
            rows.push((
                Glyph::Contact,
                "contact point, line to the wheel centre".to_owned(),
            ));
        }
        rows.push((Glyph::Axis, "rotation centre (C axis)".to_owned()));
        rows.push((
            Glyph::ZoomWindow,
            "zoom window shown on the right".to_owned(),
        ));
        if self.skipped > 0 {
            rows.push((
                Glyph::None,
                format!(
                    "{} item(s) with non-finite values or radius <= 0 not drawn",
                    self.skipped
                ),
            ));
        }
        rows.push((Glyph::None, "mm, part frame, y up".to_owned()));
        rows
    }
}

/// One panel: where it sits on the page and which mm window it shows.
#[derive(Debug, Clone, Copy)]
struct Panel {
    x_px: f64,
    min_x: f64,
    max_y: f64,
    /// px per mm.
    scale: f64,
}

impl Panel {
    /// The window around `b` plus `margin` (fraction of its larger side, at least 1 mm), widened
    /// to the panel's aspect ratio.
    fn fit(x_px: f64, b: BBox, margin: f64) -> Panel {
        let (w, h) = (b.max.0 - b.min.0, b.max.1 - b.min.1);
        let pad = (margin * w.max(h)).max(1.0);
        let (w, h) = (w + 2.0 * pad, h + 2.0 * pad);
        let scale = (PANEL_W_PX / w).min(PANEL_H_PX / h);
        let (cx, cy) = ((b.min.0 + b.max.0) / 2.0, (b.min.1 + b.max.1) / 2.0);
        Panel {
            x_px,
            min_x: cx - PANEL_W_PX / scale / 2.0,
            max_y: cy + PANEL_H_PX / scale / 2.0,
            scale,
        }
    }
    fn w_mm(&self) -> f64 {
        PANEL_W_PX / self.scale
    }
    fn h_mm(&self) -> f64 {
        PANEL_H_PX / self.scale
    }

    fn frame_and_scale_bar(&self, o: &mut String) {
        w(
            o,
            format_args!(
                "<rect x=\"{}\" y=\"{PANEL_Y_PX}\" width=\"{PANEL_W_PX}\" height=\"{PANEL_H_PX}\" fill=\"none\" stroke=\"#888\"/>\n",
                self.x_px
            ),
        );
        let len_mm = nice_length(self.w_mm() / 4.0);
        let len_px = len_mm * self.scale;
        let (x0, y) = (self.x_px + 16.0, PANEL_Y_PX + PANEL_H_PX - 16.0);
        w(
            o,
            format_args!(
                "<g class=\"scale-bar\"><path d=\"M{} {}V{}H{}V{}\" fill=\"none\" stroke=\"black\" stroke-width=\"1.5\"/><text x=\"{}\" y=\"{}\" font-size=\"12\" text-anchor=\"middle\">{} mm</text></g>\n",
                n(x0),
                n(y - 6.0),
                n(y),
                n(x0 + len_px),
                n(y - 6.0),
                n(x0 + len_px / 2.0),
                n(y - 9.0),
                trim_number(len_mm)
            ),
        );
    }
}

/// The largest 1, 2 or 5 × 10^k not above `target` (mm).
fn nice_length(target: f64) -> f64 {
    let k = target.log10().floor();
    let base = 10f64.powf(k);
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * base)
        .find(|v| *v <= target)
        .unwrap_or(base)
}

#[derive(Debug, Clone, Copy)]
enum Glyph {
    Part,
    Circle { dashed: bool },
    Path,
    Wheel,
    Contact,
    Axis,
    ZoomWindow,
    None,
}

fn draw_legend(o: &mut String, rows: &[(Glyph, String)], top: f64) {
    let per_column = rows.len().div_ceil(2);
    o.push_str("<g class=\"legend\" font-size=\"13\">\n");
    for (i, (glyph, text)) in rows.iter().enumerate() {
        let x = if i < per_column {
            OVERVIEW_X_PX
        } else {
            ZOOM_X_PX
        };
        let y = top + (i % per_column) as f64 * LEGEND_ROW_PX;
        let (gx, gy) = (x + 4.0, y - 4.0);
        let sample = match glyph {
            Glyph::Part => format!(
                "<rect x=\"{gx}\" y=\"{}\" width=\"28\" height=\"10\" fill=\"{PART_FILL}\" stroke=\"black\" stroke-width=\"1.5\"/>",
                gy - 5.0
            ),
            Glyph::Circle { dashed } => format!(
                "<line x1=\"{gx}\" y1=\"{gy}\" x2=\"{}\" y2=\"{gy}\" stroke=\"{CIRCLE_STROKE}\" stroke-width=\"1.5\"{}/>",
                gx + 28.0,
                if *dashed {
                    " stroke-dasharray=\"5 3\""
                } else {
                    ""
                }
            ),
            Glyph::Path => format!(
                "<line x1=\"{gx}\" y1=\"{gy}\" x2=\"{}\" y2=\"{gy}\" stroke=\"{PATH_STROKE}\" stroke-width=\"1.5\" stroke-dasharray=\"6 4\"/>",
                gx + 28.0
            ),
            Glyph::Wheel => format!(
                "<rect x=\"{gx}\" y=\"{}\" width=\"28\" height=\"10\" fill=\"{WHEEL_FILL}\" fill-opacity=\"0.35\" stroke=\"{WHEEL_STROKE}\" stroke-width=\"1.2\"/>",
                gy - 5.0
            ),
            Glyph::Contact => format!(
                "<line x1=\"{gx}\" y1=\"{gy}\" x2=\"{}\" y2=\"{gy}\" stroke=\"{CONTACT_FILL}\" stroke-opacity=\"0.6\"/><circle cx=\"{gx}\" cy=\"{gy}\" r=\"3\" fill=\"{CONTACT_FILL}\"/>",
                gx + 28.0
            ),
            Glyph::Axis => format!(
                "<path d=\"M{gx} {gy}H{}M{} {}V{}\" stroke=\"{AXIS_STROKE}\" stroke-width=\"1.2\"/>",
                gx + 28.0,
                gx + 14.0,
                gy - 7.0,
                gy + 7.0
            ),
            Glyph::ZoomWindow => format!(
                "<rect x=\"{gx}\" y=\"{}\" width=\"28\" height=\"10\" fill=\"none\" stroke=\"#444\" stroke-dasharray=\"4 3\"/>",
                gy - 5.0
            ),
            Glyph::None => String::new(),
        };
        w(
            o,
            format_args!(
                "{sample}<text x=\"{}\" y=\"{y}\">{}</text>\n",
                x + 42.0,
                esc(text)
            ),
        );
    }
    o.push_str("</g>\n");
}

fn points(ps: &[(f64, f64)]) -> String {
    let mut s = String::with_capacity(ps.len() * 16);
    for (i, (x, y)) in ps.iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{},{}", n(*x), n(*y));
    }
    s
}

/// A coordinate with 3 decimals (1 µm in mm), trailing zeros trimmed, never `-0`.
fn n(v: f64) -> String {
    trim_number((v * 1000.0).round() / 1000.0)
}

fn trim_number(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_owned()
    } else {
        s.to_owned()
    }
}

/// XML text escaping.
fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            // Control characters are not allowed in XML 1.0 text.
            c if c.is_control() => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

fn w(o: &mut String, args: std::fmt::Arguments<'_>) {
    // Writing into a String cannot fail.
    let _ = o.write_fmt(args);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_lengths() {
        assert_eq!(nice_length(180.0), 100.0);
        assert_eq!(nice_length(240.0), 200.0);
        assert_eq!(nice_length(7.3), 5.0);
        assert_eq!(nice_length(0.31), 0.2);
    }

    #[test]
    fn numbers_are_trimmed() {
        assert_eq!(n(12.0), "12");
        assert_eq!(n(-0.0001), "0");
        assert_eq!(n(1.23456), "1.235");
        assert_eq!(n(-250.5), "-250.5");
    }
}
