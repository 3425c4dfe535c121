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

mod legend;
mod panel;

use legend::draw_legend;
use panel::Panel;

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
    use super::panel::nice_length;
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
