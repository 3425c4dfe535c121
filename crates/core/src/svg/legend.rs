//! The setup drawing's legend: a row per kind of item drawn, two columns under the panels.

use super::{
    AXIS_STROKE, CIRCLE_STROKE, CONTACT_FILL, Clean, LEGEND_ROW_PX, OVERVIEW_X_PX, PART_FILL,
    PATH_STROKE, WHEEL_FILL, WHEEL_STROKE, ZOOM_X_PX, esc, w,
};

impl Clean<'_> {
    pub(super) fn legend_rows(&self) -> Vec<(Glyph, String)> {
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

#[derive(Debug, Clone, Copy)]
pub(super) enum Glyph {
    Part,
    Circle { dashed: bool },
    Path,
    Wheel,
    Contact,
    Axis,
    ZoomWindow,
    None,
}

pub(super) fn draw_legend(o: &mut String, rows: &[(Glyph, String)], top: f64) {
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
