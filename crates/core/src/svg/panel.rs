//! One panel of the setup drawing: the nested `<svg>` with its mm viewBox, the wheels, the
//! path, circles, part and contacts in the mirrored group, and the labels outside it.

use super::{
    AXIS_STROKE, BBox, CIRCLE_STROKE, CONTACT_FILL, Clean, PANEL_H_PX, PANEL_W_PX, PANEL_Y_PX,
    PART_FILL, PATH_STROKE, WHEEL_FILL, WHEEL_STROKE, esc, n, points, trim_number, w,
};

impl Clean<'_> {
    pub(super) fn draw_panel(
        &self,
        o: &mut String,
        p: &Panel,
        id: &str,
        zoom_window: Option<&Panel>,
    ) {
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
        o.push_str("<g transform=\"scale(1,-1)\">\n");
        self.draw_wheels(o, p);
        self.draw_shapes(o, p);
        draw_marks(o, p, zoom_window);
        o.push_str("</g>\n");
        self.draw_labels(o, p, zoom_window.is_some());
        o.push_str("</svg>\n");
    }

    /// Each wheel: its circle, centre cross and the line to its contact point.
    fn draw_wheels(&self, o: &mut String, p: &Panel) {
        let px = |v: f64| n(v / p.scale);
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
    }

    /// The wheel-centre path, the extra circles, the part and the contact points.
    fn draw_shapes(&self, o: &mut String, p: &Panel) {
        let px = |v: f64| n(v / p.scale);
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
    }

    /// The wheels' labels: at the centre in the overview, at the contact in the zoom.
    fn draw_labels(&self, o: &mut String, p: &Panel, overview: bool) {
        // Labels, not mirrored: at (x, −y) in the viewBox.
        let font = 12.0 / p.scale;
        for wh in &self.wheels {
            let anchor = if overview {
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
    }
}

/// The rotation centre and, in the overview, the zoom window.
fn draw_marks(o: &mut String, p: &Panel, zoom_window: Option<&Panel>) {
    let px = |v: f64| n(v / p.scale);
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
}

/// One panel: where it sits on the page and which mm window it shows.
#[derive(Debug, Clone, Copy)]
pub(super) struct Panel {
    pub(super) x_px: f64,
    pub(super) min_x: f64,
    pub(super) max_y: f64,
    /// px per mm.
    pub(super) scale: f64,
}

impl Panel {
    /// The window around `b` plus `margin` (fraction of its larger side, at least 1 mm), widened
    /// to the panel's aspect ratio.
    pub(super) fn fit(x_px: f64, b: BBox, margin: f64) -> Panel {
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
    pub(super) fn w_mm(&self) -> f64 {
        PANEL_W_PX / self.scale
    }
    pub(super) fn h_mm(&self) -> f64 {
        PANEL_H_PX / self.scale
    }

    pub(super) fn frame_and_scale_bar(&self, o: &mut String) {
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
pub(super) fn nice_length(target: f64) -> f64 {
    let k = target.log10().floor();
    let base = 10f64.powf(k);
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * base)
        .find(|v| *v <= target)
        .unwrap_or(base)
}
