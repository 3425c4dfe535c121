//! Q-DAS AQDEF export (`.dfq`): the SPC exchange file the plants' quality tools read. Pure:
//! typed series in, the file's text out.
//!
//! One file describes one part (K1001/K1002) and, per ground feature, four characteristics:
//! max error (nothing fitted), profile error (max |error| after the datum fit), size (base
//! radius error) and phase. Each is a variable characteristic (K2004 = 0) with nominal 0,
//! its unit and decimals, and its limits where the recipe gives them: the profile error's
//! upper limit is the tolerance band when the feature has one symmetric band all round
//! (otherwise no limits are written rather than a wrong one); the max error's upper limit,
//! the size's and the phase's ± limits from the recipe's optional tolerances. The
//! magnitudes (max error, profile error) get the lower limit 0. Values are written in
//! K-field notation (K0001 value, K0002 attribute, K0004 time, K0014 part ident), so every
//! value names its characteristic; times are UTC.

use crate::core::ids::PartId;
use crate::names::{FeatureName, MachineName};
use std::fmt::Write as _;

/// Longest texts the format allows in the fields written (published field list).
const PART_NUMBER_CHARS: usize = 30;
const PART_DESCRIPTION_CHARS: usize = 80;
const CHARACTERISTIC_NUMBER_CHARS: usize = 40;
const CHARACTERISTIC_DESCRIPTION_CHARS: usize = 80;
const UNIT_CHARS: usize = 20;
const PART_IDENT_CHARS: usize = 40;

/// K0002 attribute of a value that is present.
const VALID: u32 = 0;
/// K0002 attribute of a placeholder: the part has no value for it (shown as missing).
const PLACEHOLDER: u32 = 255;

/// Why a file could not be written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(crate) enum DfqError {
    #[error("nothing to export: no feature has measurements")]
    Empty,
    #[error("{feature}: {field} is not a finite number")]
    NotFinite {
        /// Which value: machine, feature and part.
        feature: String,
        field: &'static str,
    },
}

/// One measured part of a feature.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DfqRow {
    pub received_at: jiff::Timestamp,
    /// What identifies the part (K0014): its number as the gauge reported it.
    pub part_ident: PartId,
    /// Largest |measured − nominal| with nothing fitted, µm; `None` when unknown.
    pub max_error_um: Option<f64>,
    pub profile_error_um: f64,
    pub size_error_um: f64,
    pub phase_error_deg: f64,
}

/// A feature (lobe or pin) of a machine and its measured parts, oldest first.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DfqSeries {
    pub machine: MachineName,
    pub feature: FeatureName,
    /// The profile tolerance as (lower, upper) µm, when the feature has one band all round.
    pub profile_band_um: Option<(f64, f64)>,
    /// The recipe's other tolerances, where it gives them.
    pub limits: DfqLimits,
    pub rows: Vec<DfqRow>,
}

/// The recipe's tolerances of the other characteristics (the same limits `camloop
/// capability` uses), so a quality tool computes the same indices.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct DfqLimits {
    /// Upper limit of the max |error| (nothing fitted), µm.
    pub max_error_um: Option<f64>,
    /// ± limit of the size (base radius) error, µm.
    pub size_um: Option<f64>,
    /// ± limit of the phase (timing) error, degrees.
    pub phase_deg: Option<f64>,
}

impl DfqLimits {
    /// From a lobe's limits (the pin characteristics have no column of their own here).
    pub(crate) fn from_feature(l: &crate::quality::FeatureLimits) -> Self {
        use crate::core::capability::Characteristic as C;
        let upper = |c| l.of(c).and_then(|i| i.limits.upper);
        Self {
            max_error_um: upper(C::MaxError),
            size_um: upper(C::Size),
            phase_deg: upper(C::Timing).or(upper(C::IndexAngle)),
        }
    }
}

/// A stored measurement as a row: the max error (nothing fitted) comes from its analysis
/// report when that is given and readable.
pub(crate) fn row_from(
    m: &crate::store::MeasurementSummary,
    analysis_json: Option<&str>,
) -> DfqRow {
    #[derive(serde::Deserialize)]
    struct Report {
        error_um: Vec<f64>,
    }
    let max_error_um = analysis_json
        .and_then(|j| serde_json::from_str::<Report>(j).ok())
        .filter(|r| !r.error_um.is_empty())
        .map(|r| r.error_um.iter().fold(0.0f64, |a, e| a.max(e.abs())));
    DfqRow {
        received_at: m.received_at,
        part_ident: m.part.clone(),
        max_error_um,
        profile_error_um: m.max_profile_error_um,
        size_error_um: m.base_radius_error_um,
        phase_error_deg: m.phase_error_deg,
    }
}

/// A characteristic as written: K2001, K2002, K2142, K2022 and the limits.
struct Characteristic {
    number: String,
    description: String,
    unit: &'static str,
    decimals: u32,
    /// Lower limit; `None` with an upper limit: 0, the characteristic is a magnitude.
    lower: Option<f64>,
    upper: Option<f64>,
    value: fn(&DfqRow) -> Option<f64>,
}

fn characteristics(s: &DfqSeries) -> [Characteristic; 4] {
    let id = format!("{}.{}", s.machine, s.feature);
    let band = s.profile_band_um.and_then(|(lo, hi)| {
        // Max |profile error| against one symmetric band: the upper limit is its half-width.
        ((lo + hi).abs() < 1e-9 && hi > 0.0).then_some(hi)
    });
    [
        Characteristic {
            number: format!("{id}.MAXERR"),
            description: format!("{} {} max error (unfitted)", s.machine, s.feature),
            unit: "µm",
            decimals: 3,
            lower: None,
            upper: s.limits.max_error_um,
            value: |r| r.max_error_um,
        },
        Characteristic {
            number: format!("{id}.PROFILE"),
            description: format!("{} {} profile error max |e|", s.machine, s.feature),
            unit: "µm",
            decimals: 3,
            lower: None,
            upper: band,
            value: |r| Some(r.profile_error_um),
        },
        Characteristic {
            number: format!("{id}.SIZE"),
            description: format!("{} {} size (base radius error)", s.machine, s.feature),
            unit: "µm",
            decimals: 3,
            lower: s.limits.size_um.map(|t| -t),
            upper: s.limits.size_um,
            value: |r| Some(r.size_error_um),
        },
        Characteristic {
            number: format!("{id}.PHASE"),
            description: format!("{} {} phase error", s.machine, s.feature),
            unit: "°",
            decimals: 4,
            lower: s.limits.phase_deg.map(|t| -t),
            upper: s.limits.phase_deg,
            value: |r| Some(r.phase_error_deg),
        },
    ]
}

/// The `.dfq` text for `part` (K1001) described as `description` (K1002), with the series'
/// characteristics numbered 1, 2, … in order. Lines end with CR LF, as the format's
/// reference files do.
pub(crate) fn write_dfq(
    part: &str,
    description: &str,
    series: &[DfqSeries],
) -> Result<String, DfqError> {
    if series.iter().all(|s| s.rows.is_empty()) {
        return Err(DfqError::Empty);
    }
    let mut head = String::new();
    let mut values = String::new();
    let mut k = 0usize;
    line(&mut head, "K0100", None, &(series.len() * 4).to_string());
    line(&mut head, "K1001", None, &text(part, PART_NUMBER_CHARS));
    line(
        &mut head,
        "K1002",
        None,
        &text(description, PART_DESCRIPTION_CHARS),
    );
    for s in series {
        for c in characteristics(s) {
            k += 1;
            describe(&mut head, k, &c);
            for r in &s.rows {
                check_row(s, r)?;
                let v = (c.value)(r);
                let (shown, attribute) = match v {
                    Some(v) => (format!("{v:.*}", c.decimals as usize), VALID),
                    None => ("0".to_string(), PLACEHOLDER),
                };
                line(&mut values, "K0001", Some(k), &shown);
                line(&mut values, "K0002", Some(k), &attribute.to_string());
                line(&mut values, "K0004", Some(k), &time(r.received_at));
                line(
                    &mut values,
                    "K0014",
                    Some(k),
                    &text(&r.part_ident, PART_IDENT_CHARS),
                );
            }
        }
    }
    Ok(head + &values)
}

fn describe(out: &mut String, k: usize, c: &Characteristic) {
    line(
        out,
        "K2001",
        Some(k),
        &text(&c.number, CHARACTERISTIC_NUMBER_CHARS),
    );
    line(
        out,
        "K2002",
        Some(k),
        &text(&c.description, CHARACTERISTIC_DESCRIPTION_CHARS),
    );
    line(out, "K2004", Some(k), "0");
    line(out, "K2022", Some(k), &c.decimals.to_string());
    line(out, "K2101", Some(k), "0");
    if let Some(upper) = c.upper {
        // A magnitude's lower limit is its natural bound 0, written as before.
        let lower = c
            .lower
            .map_or("0".to_string(), |l| format!("{l:.*}", c.decimals as usize));
        line(out, "K2110", Some(k), &lower);
        line(
            out,
            "K2111",
            Some(k),
            &format!("{upper:.*}", c.decimals as usize),
        );
    }
    line(out, "K2142", Some(k), &text(c.unit, UNIT_CHARS));
}

fn check_row(s: &DfqSeries, r: &DfqRow) -> Result<(), DfqError> {
    let fields = [
        ("profile error", Some(r.profile_error_um)),
        ("size error", Some(r.size_error_um)),
        ("phase error", Some(r.phase_error_deg)),
        ("max error", r.max_error_um),
    ];
    for (field, v) in fields {
        if v.is_some_and(|v| !v.is_finite()) {
            return Err(DfqError::NotFinite {
                feature: format!("{}.{} part {}", s.machine, s.feature, r.part_ident),
                field,
            });
        }
    }
    Ok(())
}

fn line(out: &mut String, key: &str, index: Option<usize>, value: &str) {
    match index {
        Some(i) => {
            let _ = write!(out, "{key}/{i} {value}\r\n");
        }
        None => {
            let _ = write!(out, "{key} {value}\r\n");
        }
    }
}

/// A text field: control characters (line breaks would end the field) become spaces, and it
/// is cut to the field's length in characters.
fn text(value: &str, max_chars: usize) -> String {
    let clean: String = value
        .chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .take(max_chars)
        .collect();
    clean.trim().to_string()
}

/// `DD.MM.YYYY/HH:MM:SS` (K0004), UTC.
fn time(at: jiff::Timestamp) -> String {
    crate::clock::utc_format(at, "%d.%m.%Y/%H:%M:%S")
}

#[cfg(test)]
mod tests;
