//! Settings of the generated programs (names, axes, table number, decimals, axis mapping) and
//! their validation, which reports every problem at once.

use std::fmt;

use serde::Deserialize;
use thiserror::Error;

use super::names::{AxisNameError, ProgramNameError, validate_axis_name, validate_program_name};

/// Allowed decimals for X. Fewer than 3 would round X by 0.5 µm or more, the size of the
/// corrections camloop writes; more than 9 is below any position resolution of the control.
pub(crate) const X_DECIMALS: std::ops::RangeInclusive<u8> = 3..=9;
/// Allowed decimals for C. 0 is allowed for whole-degree tables; more than 9 is meaningless.
pub(crate) const C_DECIMALS: std::ops::RangeInclusive<u8> = 0..=9;

/// Where the control keeps a curve table (5th `CTABDEF` argument). Without it the control
/// uses its default from MD20905.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
pub enum TableMemory {
    /// Battery-backed memory: the table survives power-off.
    #[serde(rename = "SRAM", alias = "sram")]
    Sram,
    /// Dynamic memory: the table is lost at power-off and must be defined again.
    #[serde(rename = "DRAM", alias = "dram")]
    Dram,
}

impl TableMemory {
    /// The keyword as written in `CTABDEF`.
    pub(crate) fn keyword(self) -> &'static str {
        match self {
            TableMemory::Sram => "SRAM",
            TableMemory::Dram => "DRAM",
        }
    }
}

/// Sense of the machine's C axis relative to the part frame. In configuration files it is
/// written as `1` (same sense) or `-1` (reversed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(try_from = "i64")]
pub enum CDirection {
    /// C turns in the part frame's sense: `C = offset + c`.
    #[default]
    Same,
    /// C turns against it: `C = offset − c`.
    Reversed,
}

impl CDirection {
    /// +1.0 or −1.0.
    pub(crate) fn sign(self) -> f64 {
        match self {
            CDirection::Same => 1.0,
            CDirection::Reversed => -1.0,
        }
    }
}

impl TryFrom<i64> for CDirection {
    type Error = String;
    fn try_from(value: i64) -> Result<Self, Self::Error> {
        match value {
            1 => Ok(CDirection::Same),
            -1 => Ok(CDirection::Reversed),
            other => Err(format!("c_direction is {other}: it must be 1 or -1")),
        }
    }
}

/// Where a table program came from, written as `; key: value` comment lines right after its
/// `PROC` line so that a program found on the control can be traced to its version, its
/// recipe and the correction it carries. Values are made printable with
/// [`super::comment_text`] when written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Provenance {
    /// camloop's version (`CARGO_PKG_VERSION`).
    pub camloop_version: String,
    /// Table version number on the share (`v<N>` in the program).
    pub table_version: u64,
    /// The version this one was learned from or rolled back to; `None` for the first.
    pub parent_version: Option<u64>,
    /// Creation time, RFC 3339 UTC, passed in: the core reads no clock.
    pub created_utc: String,
    /// Recipe name.
    pub recipe: String,
    /// Lobe or pin of the recipe.
    pub feature: crate::names::FeatureName,
    /// SHA-256 of the correction the table carries.
    pub correction_sha256: crate::digest::Sha256,
}

/// How a curve-table subprogram is written. `Default` gives a valid program: `CAMLOOP_TABLE`,
/// X following C, table 1, control's default memory, 4 decimals for X (0.1 µm) and C
/// (0.0001°), a control resolution of 10000 increments per mm and per degree, no axis
/// offsets, no comment lines, no provenance.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProgramSettings {
    /// Subprogram name (file `<NAME>_SPF`); see [`validate_program_name`] for the rules.
    pub name: String,
    /// Following axis (the wheel head), default `X`.
    pub following_axis: String,
    /// Leading axis (the work spindle in axis mode), default `C`.
    pub leading_axis: String,
    /// Curve table number, at least 1. Use [`super::next_table_number`] to alternate.
    pub table_number: u32,
    /// Table memory; `None` leaves the 5th `CTABDEF` argument out.
    pub memory: Option<TableMemory>,
    /// Decimals written for X (mm), in [`X_DECIMALS`].
    pub x_decimals: u8,
    /// Decimals written for C (degrees), in [`C_DECIMALS`].
    pub c_decimals: u8,
    /// The control's computational resolution of linear axes, increments per mm (MD10200
    /// `INT_INCR_PER_MM`), ≥ 1. The control rounds positions to it [K]; `x_decimals` may not
    /// be finer.
    pub x_increments_per_mm: u32,
    /// The control's computational resolution of rotary axes, increments per degree (MD10210
    /// `INT_INCR_PER_DEG`), ≥ 1. The "C changes in every block" check is made at it.
    pub c_increments_per_deg: u32,
    /// Sense of C relative to the part frame.
    pub c_direction: CDirection,
    /// Added to the (signed) part-frame angle, degrees: `C = wrap360(c_offset_deg ± c)`.
    pub c_offset_deg: f64,
    /// Added to every X at the program boundary, mm.
    pub x_offset_mm: f64,
    /// Comment lines written after `PROC` (part, source, version, checksum, …), without `;`.
    /// Printable ASCII only.
    pub comment_lines: Vec<String>,
    /// Provenance block written after `PROC`; set by the caller for each version, never read
    /// from configuration.
    #[serde(skip)]
    pub provenance: Option<Provenance>,
}

impl Default for ProgramSettings {
    fn default() -> Self {
        Self {
            name: "CAMLOOP_TABLE".to_owned(),
            following_axis: "X".to_owned(),
            leading_axis: "C".to_owned(),
            table_number: 1,
            memory: None,
            x_decimals: 4,
            c_decimals: 4,
            x_increments_per_mm: 10_000,
            c_increments_per_deg: 10_000,
            c_direction: CDirection::Same,
            c_offset_deg: 0.0,
            x_offset_mm: 0.0,
            comment_lines: Vec::new(),
            provenance: None,
        }
    }
}

/// One problem with the settings.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SettingError {
    #[error(transparent)]
    Name(#[from] ProgramNameError),
    #[error(transparent)]
    Axis(#[from] AxisNameError),
    #[error("following and leading axis are both `{name}`")]
    SameAxis { name: String },
    #[error("table_number is 0: curve table numbers start at 1")]
    TableNumberZero,
    #[error("{field} is {value}: allowed {min} to {max}")]
    Decimals {
        field: &'static str,
        value: u8,
        min: u8,
        max: u8,
    },
    #[error("{field} is {value}: it must be a finite number")]
    NotFinite { field: &'static str, value: f64 },
    #[error("{field} is {value}: it must be greater than 0")]
    NotPositive { field: &'static str, value: f64 },
    #[error(
        "comment line {line} has {ch:?} at column {column}: only printable ASCII is written into a program"
    )]
    Comment {
        line: usize,
        column: usize,
        ch: char,
    },
    #[error("the program would be unsafe to load: {0}")]
    Unsafe(String),
    #[error("a shaft program needs at least one feature")]
    NoFeatures,
    #[error("main program name `{name}` is the same as the table subprogram's")]
    MainSameAsTable { name: String },
    #[error("{field} is 0: the control's resolution is at least 1 increment per unit")]
    ResolutionZero { field: &'static str },
    #[error(
        "{decimals_field} is {decimals}, finer than the control's resolution ({resolution_field} is {increments}): the control would round the written values"
    )]
    FinerThanResolution {
        decimals_field: &'static str,
        decimals: u8,
        resolution_field: &'static str,
        increments: u32,
    },
}

/// Every problem found in one validation, in field order. Displayed joined by "; ".
#[derive(Debug, Clone, PartialEq, Error)]
pub struct SettingsErrors(pub Vec<SettingError>);

impl fmt::Display for SettingsErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str("; ")?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

/// Validated settings with names in their canonical upper-case form.
#[derive(Debug, Clone)]
pub(crate) struct Resolved<'a> {
    pub name: String,
    pub following: String,
    pub leading: String,
    pub settings: &'a ProgramSettings,
}

impl ProgramSettings {
    /// Check every setting; all problems are reported at once.
    pub fn validate(&self) -> Result<(), SettingsErrors> {
        self.resolve().map(|_| ())
    }

    /// Program C of a part-frame angle, degrees in [0, 360):
    /// `wrap360(c_offset_deg + sign · c_deg)`. With the default settings and `c_deg` in
    /// [0, 360) the result is `c_deg` exactly. Values within 1e-9° below 360 wrap to 0 so that
    /// floating-point noise cannot move the start of the table to the end of the period.
    pub fn c_prog_deg(&self, c_deg: f64) -> f64 {
        wrap360(self.c_offset_deg + self.c_direction.sign() * c_deg)
    }

    /// Program X of a part-frame X, mm: `x_mm + x_offset_mm`.
    pub fn x_prog_mm(&self, x_mm: f64) -> f64 {
        x_mm + self.x_offset_mm
    }

    /// `c_prog` (degrees, as written) in the control's increments, rounded as the control
    /// rounds it.
    pub(crate) fn c_increments(&self, c_prog: f64) -> i64 {
        // A position of 1e9 degrees is far outside any table: saturating is harmless.
        (c_prog * f64::from(self.c_increments_per_deg)).round() as i64
    }

    /// Every setting checked, the table number included.
    pub(crate) fn resolve(&self) -> Result<Resolved<'_>, SettingsErrors> {
        self.resolve_with(true)
    }

    /// Every setting checked except the table number, which the main program never writes.
    pub(crate) fn resolve_for_main(&self) -> Result<Resolved<'_>, SettingsErrors> {
        self.resolve_with(false)
    }

    fn resolve_with(&self, table_number: bool) -> Result<Resolved<'_>, SettingsErrors> {
        let mut errors = Vec::new();
        let name = validate_program_name(&self.name)
            .map_err(|e| errors.push(e.into()))
            .ok();
        let following = validate_axis_name("following", &self.following_axis)
            .map_err(|e| errors.push(e.into()))
            .ok();
        let leading = validate_axis_name("leading", &self.leading_axis)
            .map_err(|e| errors.push(e.into()))
            .ok();
        if let (Some(f), Some(l)) = (&following, &leading)
            && f == l
        {
            errors.push(SettingError::SameAxis { name: f.clone() });
        }
        if table_number && self.table_number == 0 {
            errors.push(SettingError::TableNumberZero);
        }
        check_decimals(&mut errors, "x_decimals", self.x_decimals, X_DECIMALS);
        check_decimals(&mut errors, "c_decimals", self.c_decimals, C_DECIMALS);
        check_resolution(
            &mut errors,
            ("x_decimals", self.x_decimals, X_DECIMALS),
            ("x_increments_per_mm", self.x_increments_per_mm),
        );
        check_resolution(
            &mut errors,
            ("c_decimals", self.c_decimals, C_DECIMALS),
            ("c_increments_per_deg", self.c_increments_per_deg),
        );
        check_finite(&mut errors, "c_offset_deg", self.c_offset_deg);
        check_finite(&mut errors, "x_offset_mm", self.x_offset_mm);
        check_comments(&mut errors, &self.comment_lines);
        match (name, following, leading) {
            (Some(name), Some(following), Some(leading)) if errors.is_empty() => Ok(Resolved {
                name,
                following,
                leading,
                settings: self,
            }),
            _ => Err(SettingsErrors(errors)),
        }
    }
}

/// `v` wrapped into [0, 360) degrees; see [`ProgramSettings::c_prog_deg`].
pub(crate) fn wrap360(v: f64) -> f64 {
    let r = v.rem_euclid(360.0);
    // rem_euclid can return 360.0 itself for tiny negative inputs; +0.0 turns −0.0 into 0.0.
    if r >= 360.0 - 1e-9 { 0.0 } else { r + 0.0 }
}

fn check_decimals(
    errors: &mut Vec<SettingError>,
    field: &'static str,
    value: u8,
    range: std::ops::RangeInclusive<u8>,
) {
    if !range.contains(&value) {
        errors.push(SettingError::Decimals {
            field,
            value,
            min: *range.start(),
            max: *range.end(),
        });
    }
}

/// A written step of 10^−decimals must not be finer than one increment: 10^decimals ≤
/// increments per unit. Decimals outside their range are reported by [`check_decimals`]
/// alone.
fn check_resolution(
    errors: &mut Vec<SettingError>,
    (decimals_field, decimals, range): (&'static str, u8, std::ops::RangeInclusive<u8>),
    (resolution_field, increments): (&'static str, u32),
) {
    if increments == 0 {
        errors.push(SettingError::ResolutionZero {
            field: resolution_field,
        });
    } else if range.contains(&decimals) && 10f64.powi(i32::from(decimals)) > f64::from(increments) {
        errors.push(SettingError::FinerThanResolution {
            decimals_field,
            decimals,
            resolution_field,
            increments,
        });
    }
}

pub(crate) fn check_finite(errors: &mut Vec<SettingError>, field: &'static str, value: f64) {
    if !value.is_finite() {
        errors.push(SettingError::NotFinite { field, value });
    }
}

pub(crate) fn check_positive(errors: &mut Vec<SettingError>, field: &'static str, value: f64) {
    if !value.is_finite() {
        errors.push(SettingError::NotFinite { field, value });
    } else if value <= 0.0 {
        errors.push(SettingError::NotPositive { field, value });
    }
}

/// Comment lines go into the program after `;`: a line break would end the comment and turn
/// the rest into a block, and non-ASCII text may not survive the control's character set.
pub(crate) fn check_comments(errors: &mut Vec<SettingError>, lines: &[String]) {
    for (i, line) in lines.iter().enumerate() {
        if let Some((col, ch)) = line
            .chars()
            .enumerate()
            .find(|(_, ch)| !(' '..='~').contains(ch))
        {
            errors.push(SettingError::Comment {
                line: i + 1,
                column: col + 1,
                ch,
            });
        }
    }
}
