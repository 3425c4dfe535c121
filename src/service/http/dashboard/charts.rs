//! Inline SVG charts, drawn on the server: line charts with axes, units, limit lines and
//! time-axis marks; sparklines; the polar plot of a lobe with its error magnified.

use maud::{Markup, html};
use std::fmt::Write as _;

const W: f64 = 640.0;
const H: f64 = 230.0;
const LEFT: f64 = 60.0;
const RIGHT: f64 = 14.0;
const TOP: f64 = 24.0;
const BOTTOM: f64 = 40.0;

/// One polyline of a chart.
pub(super) struct Line {
    pub name: String,
    /// CSS class: its colour.
    pub class: &'static str,
    pub points: Vec<(f64, f64)>,
}

/// A vertical mark on the x axis (a dressing, a table version).
pub(super) struct Mark {
    pub x: f64,
    pub label: String,
    pub class: &'static str,
}

/// A line chart: axes with their units, lines, horizontal limit lines and vertical marks.
pub(super) struct LineChart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub lines: Vec<Line>,
    /// Horizontal lines (tolerance limits): value and label.
    pub limits: Vec<(f64, String)>,
    pub marks: Vec<Mark>,
}

/// Round bounds and about five ticks covering `lo..hi`.
fn ticks(lo: f64, hi: f64) -> (f64, f64, Vec<f64>) {
    let (lo, hi) = if (hi - lo).abs() < 1e-12 {
        (lo - 1.0, hi + 1.0)
    } else {
        (lo, hi)
    };
    let raw = (hi - lo) / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let (a, b) = ((lo / step).floor() * step, (hi / step).ceil() * step);
    let n = ((b - a) / step).round() as usize;
    let t = (0..=n).map(|i| a + i as f64 * step).collect();
    (a, b, t)
}

fn fmt_tick(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// Data bounds to pixels.
struct Scale {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

impl Scale {
    fn px(&self, x: f64) -> f64 {
        LEFT + (x - self.x0) / (self.x1 - self.x0) * (W - LEFT - RIGHT)
    }

    fn py(&self, y: f64) -> f64 {
        TOP + (self.y1 - y) / (self.y1 - self.y0) * (H - TOP - BOTTOM)
    }
}

/// Smallest and largest finite value; (0, 1) when there is none.
fn range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    v.filter(|x| x.is_finite())
        .fold(None, |acc: Option<(f64, f64)>, x| match acc {
            None => Some((x, x)),
            Some((a, b)) => Some((a.min(x), b.max(x))),
        })
        .unwrap_or((0.0, 1.0))
}

/// A coordinate as the charts write it: one decimal.
fn d1(v: f64) -> String {
    format!("{v:.1}")
}

impl LineChart {
    pub(super) fn svg(&self) -> Markup {
        let points = || self.lines.iter().flat_map(|l| l.points.iter());
        let (x0, x1) = range(points().map(|p| p.0).chain(self.marks.iter().map(|m| m.x)));
        let (x0, x1) = if x1 > x0 {
            (x0, x1)
        } else {
            (x0 - 1.0, x0 + 1.0)
        };
        let (ylo, yhi) = range(points().map(|p| p.1).chain(self.limits.iter().map(|l| l.0)));
        let (y0, y1, yt) = ticks(ylo, yhi);
        let (_, _, xt) = ticks(x0, x1);
        let scale = Scale { x0, x1, y0, y1 };
        html! {
            svg class="chart" viewBox={ "0 0 " (W) " " (H) } role="img" aria-label=(self.title) {
                title { (self.title) }
                (self.axes(&scale, &xt, &yt))
                (self.overlays(&scale))
            }
        }
    }

    /// Grid, ticks, axes, their labels with units, and the title.
    fn axes(&self, sc: &Scale, xt: &[f64], yt: &[f64]) -> Markup {
        let b = H - BOTTOM;
        html! {
            @for &y in yt {
                line class="grid" x1=(LEFT) x2=(W - RIGHT) y1=(d1(sc.py(y))) y2=(d1(sc.py(y))) {}
                text class="tick" x=(LEFT - 4.0) y=(d1(sc.py(y) + 3.0)) text-anchor="end" { (fmt_tick(y)) }
            }
            @for &x in xt.iter().filter(|x| **x >= sc.x0 && **x <= sc.x1) {
                text class="tick" x=(d1(sc.px(x))) y=(H - BOTTOM + 14.0) text-anchor="middle" { (fmt_tick(x)) }
            }
            line class="axis" x1=(LEFT) x2=(LEFT) y1=(TOP) y2=(b) {}
            line class="axis" x1=(LEFT) x2=(W - RIGHT) y1=(b) y2=(b) {}
            text class="label" x=((LEFT + W - RIGHT) / 2.0) y=(H - 6.0) text-anchor="middle" { (self.x_label) }
            text class="label" transform={ "translate(14 " ((TOP + H - BOTTOM) / 2.0) ") rotate(-90)" } text-anchor="middle" { (self.y_label) }
            text class="title" x=(LEFT) y="15" { (self.title) }
        }
    }

    /// Marks, limit lines, then the data lines with their legend.
    fn overlays(&self, sc: &Scale) -> Markup {
        html! {
            @for m in &self.marks {
                line class={ "mark " (m.class) } x1=(d1(sc.px(m.x))) x2=(d1(sc.px(m.x))) y1=(TOP) y2=(H - BOTTOM) {
                    title { (m.label) }
                }
            }
            @for (y, label) in &self.limits {
                line class="limit" x1=(LEFT) x2=(W - RIGHT) y1=(d1(sc.py(*y))) y2=(d1(sc.py(*y))) {
                    title { (label) }
                }
            }
            @for (i, l) in self.lines.iter().enumerate() {
                @let pts: String = l
                    .points
                    .iter()
                    .filter(|p| p.1.is_finite())
                    .map(|p| format!("{:.1},{:.1} ", sc.px(p.0), sc.py(p.1)))
                    .collect();
                polyline class={ "line " (l.class) } points=(pts) {}
                text class={ "legend " (l.class) } x=(W - RIGHT - 120.0 * i as f64) y="15" text-anchor="end" { (l.name) }
            }
        }
    }
}

/// A small line of `values` (oldest first) with the tolerance `limit` as a dashed line.
pub(super) fn sparkline(values: &[f64], limit: Option<f64>, label: &str) -> Markup {
    let (w, h) = (150.0, 32.0);
    let top = values
        .iter()
        .copied()
        .chain(limit)
        .fold(0.0f64, f64::max)
        .max(1e-9);
    let n = values.len().max(2) as f64 - 1.0;
    let py = |v: f64| h - 2.0 - v / top * (h - 4.0);
    let pts: String = values
        .iter()
        .enumerate()
        .map(|(i, v)| format!("{:.1},{:.1} ", i as f64 / n * w, py(*v)))
        .collect();
    html! {
        svg class="spark" viewBox={ "0 0 " (w) " " (h) } role="img" aria-label=(label) {
            title { (label) }
            @if let Some(l) = limit {
                line class="limit" x1="0" x2=(w) y1=(d1(py(l))) y2=(d1(py(l))) {}
            }
            polyline class="line profile" points=(pts) {}
        }
    }
}

/// The lobe in polar form: nominal and measured radius `r0 + lift` at `angle_deg`, the
/// error drawn `magnification` times larger.
pub(super) fn polar(angle_deg: &[f64], nominal_mm: &[f64], error_um: &[f64], r0_mm: f64) -> Markup {
    let size = 320.0;
    let c = size / 2.0;
    let rmax = nominal_mm.iter().fold(0.0f64, |a, l| a.max(r0_mm + l));
    let emax = error_um.iter().fold(0.0f64, |a, e| a.max(e.abs())) / 1000.0;
    let magnification = magnification(rmax, emax);
    let scale = (c - 24.0) / (rmax + emax * magnification).max(1e-9);
    let path = |err: bool| -> String {
        let mut d = String::new();
        for (i, a) in angle_deg.iter().enumerate() {
            let r = r0_mm
                + nominal_mm[i]
                + if err {
                    error_um[i] / 1000.0 * magnification
                } else {
                    0.0
                };
            let (s, co) = a.to_radians().sin_cos();
            let _ = write!(
                d,
                "{}{:.1},{:.1} ",
                if i == 0 { "M" } else { "L" },
                c + r * co * scale,
                c - r * s * scale
            );
        }
        d.push('Z');
        d
    };
    let (e, m) = (size - 10.0, fmt_tick(magnification));
    html! {
        svg class="chart polar" viewBox={ "0 0 " (size) " " (size) } role="img" aria-label="Latest part, polar" {
            title { "Latest part: nominal and measured, error ×" (m) }
            line class="grid" x1=(c) x2=(c) y1="10" y2=(e) {}
            line class="grid" x1="10" x2=(e) y1=(c) y2=(c) {}
            path class="nominal" d=(path(false)) {}
            path class="measured" d=(path(true)) {}
            text class="label" x="8" y="16" { "error drawn ×" (m) }
            text class="legend nominal" x="8" y=(size - 24.0) { "— nominal" }
            text class="legend measured" x="8" y=(size - 10.0) { "— measured" }
            text class="tick" x=(e) y=(c - 4.0) text-anchor="end" { "0°" }
            text class="tick" x=(c + 4.0) y="30" { "90°" }
        }
    }
}

/// A 1–2–5 magnification that draws the largest error at about a tenth of the radius.
pub(super) fn magnification(radius_mm: f64, max_error_mm: f64) -> f64 {
    if max_error_mm <= 0.0 || radius_mm <= 0.0 {
        return 1.0;
    }
    let raw = 0.1 * radius_mm / max_error_mm;
    let mag = 10f64.powf(raw.log10().floor());
    [5.0, 2.0, 1.0]
        .iter()
        .map(|m| m * mag)
        .find(|m| *m <= raw)
        .unwrap_or(mag)
        .max(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_cover_the_range_in_round_steps() {
        // Span 10.2 over five ticks wants 2.04 per step: the next of 1, 2, 5 is 5.
        let (a, b, t) = ticks(-2.3, 7.9);
        assert_eq!((a, b), (-5.0, 10.0));
        assert_eq!(t, vec![-5.0, 0.0, 5.0, 10.0]);
        let (a, b, t) = ticks(0.12, 0.93);
        assert!(a <= 0.12 && b >= 0.93, "{a} {b}");
        let steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(steps.iter().all(|s| (s - 0.2).abs() < 1e-9), "{steps:?}");
    }

    #[test]
    fn magnification_draws_the_error_near_a_tenth_of_the_radius() {
        // 30 mm radius, 5 µm error: raw 600 → 500.
        assert_eq!(magnification(30.0, 0.005), 500.0);
        let m = magnification(30.0, 0.0021);
        let drawn = 0.0021 * m;
        assert!(drawn <= 3.0 && drawn > 3.0 / 2.5, "{m} draws {drawn} mm");
        assert_eq!(magnification(30.0, 0.0), 1.0);
    }
}
