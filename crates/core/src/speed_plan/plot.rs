//! The speed plan as an SVG chart: above, C speed against C angle, planned and at the
//! fastest constant speed; below, each limit's usage along the plan (100 % = at the limit).
//! Plain SVG 1.1 with inline styles, like the setup drawing, so it opens anywhere and the
//! dashboard can inline it.

use super::{Constraint, SpeedPlan};
use std::fmt::Write as _;

const WIDTH_PX: f64 = 900.0;
const LEFT_PX: f64 = 70.0;
const RIGHT_PX: f64 = 20.0;
const SPEED_TOP_PX: f64 = 50.0;
const SPEED_H_PX: f64 = 200.0;
const USAGE_TOP_PX: f64 = 300.0;
const USAGE_H_PX: f64 = 200.0;
const HEIGHT_PX: f64 = 600.0;

/// One colour per limit, in [`Constraint::ALL`] order (Tableau 10, readable when printed).
const COLOURS: [&str; 6] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#d62728",
];
const PLAN_STROKE: &str = "#1f6fb4";
const CONSTANT_STROKE: &str = "#6b6b6b";

/// The chart of `plan`, titled `title` (escaped here).
pub fn render_plan_svg(plan: &SpeedPlan, title: &str) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH_PX}\" height=\"{HEIGHT_PX}\" viewBox=\"0 0 {WIDTH_PX} {HEIGHT_PX}\" font-family=\"sans-serif\">"
    );
    let _ = writeln!(o, "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>");
    let _ = writeln!(
        o,
        "<text x=\"{LEFT_PX}\" y=\"24\" font-size=\"15\">{}</text>",
        escape(title)
    );
    speed_panel(&mut o, plan);
    usage_panel(&mut o, plan);
    o.push_str("</svg>\n");
    o
}

/// The top panel: the planned C speed against the fastest constant one, with their legend.
fn speed_panel(o: &mut String, plan: &SpeedPlan) {
    let speed_max = plan
        .points
        .iter()
        .map(|p| p.speed_rpm)
        .fold(plan.constant.speed_rpm, f64::max);
    let speed_top = nice_ceiling(speed_max * 1.05);
    frame(o, SPEED_TOP_PX, SPEED_H_PX, speed_top, "C speed, rpm");
    let constant: Vec<(f64, f64)> = plan
        .points
        .iter()
        .map(|p| (p.c_deg, plan.constant.speed_rpm))
        .collect();
    polyline(
        o,
        &constant,
        SPEED_TOP_PX,
        SPEED_H_PX,
        speed_top,
        CONSTANT_STROKE,
        "6 4",
    );
    let speed: Vec<(f64, f64)> = plan.points.iter().map(|p| (p.c_deg, p.speed_rpm)).collect();
    polyline(
        o,
        &speed,
        SPEED_TOP_PX,
        SPEED_H_PX,
        speed_top,
        PLAN_STROKE,
        "",
    );
    let legend = [
        (
            PLAN_STROKE,
            "",
            format!("planned: {:.3} s per revolution", plan.revolution_s()),
        ),
        (
            CONSTANT_STROKE,
            "6 4",
            format!(
                "fastest constant: {:.2} rpm, {:.3} s ({} binds)",
                plan.constant.speed_rpm,
                plan.constant.revolution_s,
                plan.constant.binding.name()
            ),
        ),
    ];
    for (i, (colour, dash, text)) in legend.iter().enumerate() {
        legend_row(
            o,
            LEFT_PX + 10.0 + 400.0 * i as f64,
            SPEED_TOP_PX - 8.0,
            colour,
            dash,
            text,
        );
    }
}

/// The bottom panel: each limit's usage in per cent over C, with the 100 % line.
fn usage_panel(o: &mut String, plan: &SpeedPlan) {
    frame(o, USAGE_TOP_PX, USAGE_H_PX, 110.0, "usage of each limit, %");
    let limit_line = [(0.0, 100.0), (360.0, 100.0)];
    polyline(
        o,
        &limit_line,
        USAGE_TOP_PX,
        USAGE_H_PX,
        110.0,
        "#000",
        "2 3",
    );
    for (c, colour) in Constraint::ALL.iter().zip(COLOURS) {
        let usage: Vec<(f64, f64)> = plan
            .points
            .iter()
            .map(|p| (p.c_deg, 100.0 * p.usage[*c as usize]))
            .collect();
        polyline(o, &usage, USAGE_TOP_PX, USAGE_H_PX, 110.0, colour, "");
    }
    for (i, (c, colour)) in Constraint::ALL.iter().zip(COLOURS).enumerate() {
        let x = LEFT_PX + 10.0 + 270.0 * (i % 3) as f64;
        let y = USAGE_TOP_PX + USAGE_H_PX + 50.0 + 20.0 * (i / 3) as f64;
        let text = format!("{} (max {:.1} %)", c.name(), 100.0 * plan.max_usage(*c));
        legend_row(o, x, y, colour, "", &text);
    }
}

fn x_px(c_deg: f64) -> f64 {
    LEFT_PX + c_deg / 360.0 * (WIDTH_PX - LEFT_PX - RIGHT_PX)
}

fn y_px(value: f64, top: f64, height: f64, max: f64) -> f64 {
    top + height * (1.0 - (value / max).clamp(0.0, 1.0))
}

/// Axes, grid every 45° and five value ticks, the axis label.
fn frame(o: &mut String, top: f64, height: f64, max: f64, label: &str) {
    let right = WIDTH_PX - RIGHT_PX;
    let _ = writeln!(
        o,
        "<rect x=\"{LEFT_PX}\" y=\"{top}\" width=\"{}\" height=\"{height}\" fill=\"none\" stroke=\"#888\"/>",
        right - LEFT_PX
    );
    for k in 0..=8 {
        let (x, deg) = (x_px(45.0 * k as f64), 45 * k);
        let _ = writeln!(
            o,
            "<line x1=\"{x:.1}\" y1=\"{top}\" x2=\"{x:.1}\" y2=\"{}\" stroke=\"#e0e0e0\"/><text x=\"{x:.1}\" y=\"{}\" font-size=\"11\" text-anchor=\"middle\">{deg}°</text>",
            top + height,
            top + height + 14.0
        );
    }
    for k in 0..=5 {
        let value = max * k as f64 / 5.0;
        let y = y_px(value, top, height, max);
        let _ = writeln!(
            o,
            "<text x=\"{}\" y=\"{:.1}\" font-size=\"11\" text-anchor=\"end\">{}</text>",
            LEFT_PX - 6.0,
            y + 4.0,
            trim(value)
        );
    }
    let _ = writeln!(
        o,
        "<text x=\"16\" y=\"{:.1}\" font-size=\"12\" transform=\"rotate(-90 16 {:.1})\" text-anchor=\"middle\">{}</text>",
        top + height / 2.0,
        top + height / 2.0,
        escape(label)
    );
    let _ = writeln!(
        o,
        "<text x=\"{:.1}\" y=\"{}\" font-size=\"11\" text-anchor=\"middle\">C, degrees</text>",
        x_px(180.0),
        top + height + 28.0
    );
}

fn polyline(
    o: &mut String,
    points: &[(f64, f64)],
    top: f64,
    height: f64,
    max: f64,
    colour: &str,
    dash: &str,
) {
    let mut d = String::new();
    for (i, (c, v)) in points
        .iter()
        .filter(|(c, v)| c.is_finite() && v.is_finite())
        .enumerate()
    {
        let _ = write!(
            d,
            "{}{:.1} {:.1}",
            if i == 0 { "M" } else { "L" },
            x_px(*c),
            y_px(*v, top, height, max)
        );
    }
    let dash = if dash.is_empty() {
        String::new()
    } else {
        format!(" stroke-dasharray=\"{dash}\"")
    };
    let _ = writeln!(
        o,
        "<path d=\"{d}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.5\"{dash}/>"
    );
}

fn legend_row(o: &mut String, x: f64, y: f64, colour: &str, dash: &str, text: &str) {
    let dash = if dash.is_empty() {
        String::new()
    } else {
        format!(" stroke-dasharray=\"{dash}\"")
    };
    let _ = writeln!(
        o,
        "<line x1=\"{x:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"{colour}\" stroke-width=\"2\"{dash}/><text x=\"{:.1}\" y=\"{y:.1}\" font-size=\"12\">{}</text>",
        y - 4.0,
        x + 24.0,
        y - 4.0,
        x + 30.0,
        escape(text)
    );
}

/// The smallest 1, 2 or 5 × 10^k at or above `value` (> 0), for the speed axis.
fn nice_ceiling(value: f64) -> f64 {
    if !(value.is_finite() && value > 0.0) {
        return 1.0;
    }
    let base = 10f64.powf(value.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * base)
        .find(|v| *v >= value)
        .unwrap_or(10.0 * base)
}

fn trim(value: f64) -> String {
    let s = format!("{value:.1}");
    s.strip_suffix(".0").map_or(s.clone(), str::to_string)
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
