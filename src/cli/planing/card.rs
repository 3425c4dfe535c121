//! The planing process card: one TOML file holding every parameter of a planing job, read
//! with `--job` and written with `--save-job`, each key under the comment that says what it
//! is, so the card a machinist keeps beside the machine explains itself.

use crate::core::generate::planing::{MCode, PlaningJob, PlaningMCodes, RotorFace};
use crate::core::generate::setup::{Coolant, ToolCall};
use serde::Deserialize;
use std::fmt::Write as _;

/// The card as read and written.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Card {
    pub name: String,
    pub rotor: Rotor,
    pub stroke: Stroke,
    pub machine: Machine,
    pub output: Output,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Rotor {
    pub segments: u32,
    pub pitch_radius_mm: f64,
    pub z_peak_mm: f64,
    pub z_valley_mm: f64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Stroke {
    pub ratio_deg_per_mm: f64,
    pub x_start_mm: f64,
    pub x_end_mm: f64,
    pub over_travel_front_mm: f64,
    pub over_travel_rear_mm: f64,
    pub z_clear_mm: f64,
    pub feed_mm_min: f64,
    pub tolerance_um: f64,
    pub min_points_per_arc: u32,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Machine {
    pub work_offset: u8,
    pub tool: u32,
    pub tool_offset: u32,
    pub coolant: bool,
    pub mark_parameter_iso: u16,
    pub hydraulics_on_m: Option<String>,
    pub hydraulics_off_m: Option<String>,
    pub a_forward_m: Option<String>,
    pub a_reverse_m: Option<String>,
    pub lift_on_m: Option<String>,
    pub lift_off_m: Option<String>,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Output {
    /// `sinumerik` or `iso`.
    pub dialect: String,
    /// `program` (commanded X, A and Z per point) or `table` (SINUMERIK curve tables).
    pub form: String,
    pub table_number: u32,
}

impl Card {
    /// The job the card describes; an M code that does not read is named with its key.
    pub fn job(&self) -> anyhow::Result<PlaningJob> {
        let (r, s, m) = (&self.rotor, &self.stroke, &self.machine);
        Ok(PlaningJob {
            name: self.name.clone(),
            work_offset: m.work_offset,
            tool: ToolCall {
                number: m.tool,
                offset: m.tool_offset,
                change: false,
            },
            coolant: if m.coolant {
                Coolant::Flood
            } else {
                Coolant::Off
            },
            face: RotorFace {
                segments: r.segments,
                pitch_radius_mm: r.pitch_radius_mm,
                z_peak_mm: r.z_peak_mm,
                z_valley_mm: r.z_valley_mm,
            },
            ratio_deg_per_mm: s.ratio_deg_per_mm,
            x_start_mm: s.x_start_mm,
            x_end_mm: s.x_end_mm,
            over_travel_front_mm: s.over_travel_front_mm,
            over_travel_rear_mm: s.over_travel_rear_mm,
            z_clear_mm: s.z_clear_mm,
            feed_mm_min: s.feed_mm_min,
            tolerance_um: s.tolerance_um,
            min_points_per_arc: s.min_points_per_arc,
            m_codes: PlaningMCodes {
                hydraulics_on: m_code("hydraulics_on_m", &m.hydraulics_on_m)?,
                hydraulics_off: m_code("hydraulics_off_m", &m.hydraulics_off_m)?,
                a_forward: m_code("a_forward_m", &m.a_forward_m)?,
                a_reverse: m_code("a_reverse_m", &m.a_reverse_m)?,
                lift_on: m_code("lift_on_m", &m.lift_on_m)?,
                lift_off: m_code("lift_off_m", &m.lift_off_m)?,
            },
            mark_parameter_iso: m.mark_parameter_iso,
        })
    }

    /// The card as TOML, every key under its comment; [`Card`] reads it back unchanged.
    pub fn to_toml(&self) -> String {
        let (r, s) = (&self.rotor, &self.stroke);
        let mut w = Writer(String::new());
        w.0.push_str(
            "# camloop planing process card: every parameter of one planing job.\n\
             # `camloop planing --job THIS.toml` writes its program; `--save-job` writes a card.\n",
        );
        w.key(
            "name",
            &format!("{:?}", self.name),
            "program name (SINUMERIK rules: letters, digits, _; at most 24)",
        );
        w.section("rotor", "the end face: identical arcs, each a circular arc in the developed section at the pitch radius, from a lobe peak down to the valley and up to the next peak");
        w.key(
            "segments",
            &r.segments.to_string(),
            "arcs round the end face",
        );
        w.key(
            "pitch_radius_mm",
            &float(r.pitch_radius_mm),
            "radius at which the developed section is taken, mm",
        );
        w.key(
            "z_peak_mm",
            &float(r.z_peak_mm),
            "Z of the lobe peaks (where one arc meets the next), mm",
        );
        w.key(
            "z_valley_mm",
            &float(r.z_valley_mm),
            "Z of the valley in the middle of each arc, mm",
        );
        w.section(
            "stroke",
            "the ram's stroke along X and A coupled to it, A = A_k + ratio * (X - x_start)",
        );
        w.key("ratio_deg_per_mm", &float(s.ratio_deg_per_mm), "degrees of A per mm of X; ratio * (x_end - x_start) must equal one arc, 360 / segments");
        w.key(
            "x_start_mm",
            &float(s.x_start_mm),
            "X where the tool meets the part, mm",
        );
        w.key(
            "x_end_mm",
            &float(s.x_end_mm),
            "X where the tool leaves the part, mm",
        );
        w.key(
            "over_travel_front_mm",
            &float(s.over_travel_front_mm),
            "run-up before x_start, A already coupled, so A reverses outside the part, mm",
        );
        w.key(
            "over_travel_rear_mm",
            &float(s.over_travel_rear_mm),
            "run-out after x_end, A still coupled, mm",
        );
        w.key(
            "z_clear_mm",
            &float(s.z_clear_mm),
            "Z of the lifted tool for the return stroke and the index; above z_peak_mm",
        );
        w.key(
            "feed_mm_min",
            &float(s.feed_mm_min),
            "cutting feed along the stroke, mm/min (G94)",
        );
        w.key(
            "tolerance_um",
            &float(s.tolerance_um),
            "largest height error of a straight move against the face, um",
        );
        w.key(
            "min_points_per_arc",
            &s.min_points_per_arc.to_string(),
            "control points per stroke at least, whatever the tolerance allows",
        );
        self.machine_and_output(&mut w);
        w.0
    }

    /// The `[machine]` and `[output]` tables of [`Card::to_toml`].
    fn machine_and_output(&self, w: &mut Writer) {
        let (m, o) = (&self.machine, &self.output);
        w.section("machine", "the planer; M codes differ from machine to machine: \"M60\", or on LinuxCNC \"M64 P0\" (digital output 0 on); leave one out and no block is written for it");
        w.key(
            "work_offset",
            &m.work_offset.to_string(),
            "1 to 6 for G54 to G59",
        );
        w.key("tool", &m.tool.to_string(), "tool number (T)");
        w.key(
            "tool_offset",
            &m.tool_offset.to_string(),
            "tool offset (SINUMERIK D, ISO H)",
        );
        w.key(
            "coolant",
            &m.coolant.to_string(),
            "true: flood coolant (M8) while planing",
        );
        w.key("mark_parameter_iso", &m.mark_parameter_iso.to_string(), "ISO parameter that keeps the arcs done between runs (100 to 5000); list it in LinuxCNC's var file, or it is not kept. SINUMERIK uses R50");
        for (key, v, what) in [
            (
                "hydraulics_on_m",
                &m.hydraulics_on_m,
                "M code: hydraulics on, before the first stroke",
            ),
            (
                "hydraulics_off_m",
                &m.hydraulics_off_m,
                "M code: hydraulics off, after the last stroke",
            ),
            (
                "a_forward_m",
                &m.a_forward_m,
                "M code: A's sense for the cutting stroke",
            ),
            (
                "a_reverse_m",
                &m.a_reverse_m,
                "M code: A reversed for the return",
            ),
            (
                "lift_on_m",
                &m.lift_on_m,
                "M code: tool lifter up, for the return stroke",
            ),
            (
                "lift_off_m",
                &m.lift_off_m,
                "M code: tool lifter down, before the cut",
            ),
        ] {
            match v {
                Some(code) => w.key(key, &format!("{code:?}"), what),
                None => {
                    let _ = writeln!(w.0, "# {what}\n# {key} = (none: no block is written)");
                }
            }
        }
        w.section("output", "what is written");
        w.key(
            "dialect",
            &format!("{:?}", o.dialect),
            "\"sinumerik\" or \"iso\" (LinuxCNC)",
        );
        w.key("form", &format!("{:?}", o.form), "\"program\": X, A and Z commanded per point; \"table\": SINUMERIK curve tables, A and Z following X (the hydraulic-ram planer)");
        w.key(
            "table_number",
            &o.table_number.to_string(),
            "first curve table (A); the next one is Z (form \"table\")",
        );
    }
}

/// `M<code>` or `M<code> P<n>`.
fn m_code(key: &str, text: &Option<String>) -> anyhow::Result<Option<MCode>> {
    let Some(t) = text else { return Ok(None) };
    let bad = || anyhow::anyhow!("machine.{key} is {t:?}: write \"M<code>\" or \"M<code> P<n>\"");
    let mut words = t.split_whitespace();
    let code = words
        .next()
        .and_then(|w| w.strip_prefix('M'))
        .and_then(|n| n.parse().ok())
        .ok_or_else(bad)?;
    let p = match words.next() {
        Some(w) => Some(
            w.strip_prefix('P')
                .and_then(|n| n.parse().ok())
                .ok_or_else(bad)?,
        ),
        None => None,
    };
    if words.next().is_some() {
        return Err(bad());
    }
    Ok(Some(MCode { code, p }))
}

/// A float as TOML reads it back to the same value (always with a decimal point).
fn float(v: f64) -> String {
    format!("{v:?}")
}

struct Writer(String);

impl Writer {
    fn section(&mut self, name: &str, what: &str) {
        let _ = writeln!(self.0, "\n# {what}\n[{name}]");
    }
    fn key(&mut self, key: &str, value: &str, what: &str) {
        let _ = writeln!(self.0, "# {what}\n{key} = {value}");
    }
}
