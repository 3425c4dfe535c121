//! Flags that shape the programs camloop writes: the SINUMERIK table programs of
//! `camloop table`, and the machine set-up shared by the other machines' generators.

use crate::core::generate::setup::{Coolant, Setup, SpindleDirection, SpindleSpeed};
use crate::core::program::{CDirection, MainProgramSettings, ProgramSettings, TableMemory};
use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MemoryArg {
    Sram,
    Dram,
}

#[derive(Debug, Clone, Args)]
pub struct ProgramArgs {
    /// Write the curve-table subprogram (SINUMERIK 840D sl transfer format).
    #[arg(long, global = true, value_name = "OUT.SPF")]
    pub program: Option<PathBuf>,
    /// Subprogram name (default: the --program file name without extension, upper case).
    #[arg(long, global = true, value_name = "NAME")]
    pub program_name: Option<String>,
    /// Write a main-program fragment that calls the table subprogram, couples X to C with the
    /// table it defined and grinds.
    #[arg(long, global = true, value_name = "OUT.MPF", requires = "program")]
    pub main_program: Option<PathBuf>,
    /// Curve-table number.
    #[arg(long, global = true, value_name = "N", default_value_t = 1)]
    pub table_number: u32,
    /// Table memory (CTABDEF's 5th argument); default: the control's MD20905.
    #[arg(long, global = true, value_enum)]
    pub memory: Option<MemoryArg>,
    /// Following axis name.
    #[arg(long, global = true, value_name = "AXIS", default_value = "X")]
    pub x_axis: String,
    /// Leading axis name.
    #[arg(long, global = true, value_name = "AXIS", default_value = "C")]
    pub c_axis: String,
    /// Decimals written for X (3 to 9).
    #[arg(long, global = true, value_name = "N", default_value_t = 4)]
    pub x_decimals: u8,
    /// Decimals written for C (0 to 9).
    #[arg(long, global = true, value_name = "N", default_value_t = 4)]
    pub c_decimals: u8,
    /// The control's linear resolution, increments per mm (MD10200); --x-decimals may not be
    /// finer.
    #[arg(long, global = true, value_name = "N", default_value_t = 10_000)]
    pub x_increments_per_mm: u32,
    /// The control's angular resolution, increments per degree (MD10210); --c-decimals may
    /// not be finer.
    #[arg(long, global = true, value_name = "N", default_value_t = 10_000)]
    pub c_increments_per_deg: u32,
    /// The machine's C turns against the part frame's angle sense.
    #[arg(long, global = true)]
    pub c_reversed: bool,
    /// Machine C at part angle 0°, degrees.
    #[arg(long, global = true, value_name = "DEG", default_value_t = 0.0)]
    pub c_offset_deg: f64,
    /// Added to every program X, mm.
    #[arg(long, global = true, value_name = "MM", default_value_t = 0.0)]
    pub x_offset_mm: f64,
    /// Revolutions of C in the main program.
    #[arg(long, global = true, value_name = "N", default_value_t = 3.0)]
    pub revolutions: f64,
}

impl ProgramArgs {
    /// Table settings; the name comes from --program-name or the --program file stem.
    pub fn table_settings(&self, comment_lines: Vec<String>) -> ProgramSettings {
        ProgramSettings {
            name: self
                .program_name
                .clone()
                .or_else(|| self.program.as_deref().and_then(stem_upper))
                .unwrap_or_else(|| ProgramSettings::default().name),
            following_axis: self.x_axis.clone(),
            leading_axis: self.c_axis.clone(),
            table_number: self.table_number,
            memory: self.memory.map(|m| match m {
                MemoryArg::Sram => TableMemory::Sram,
                MemoryArg::Dram => TableMemory::Dram,
            }),
            x_decimals: self.x_decimals,
            c_decimals: self.c_decimals,
            x_increments_per_mm: self.x_increments_per_mm,
            c_increments_per_deg: self.c_increments_per_deg,
            c_direction: if self.c_reversed {
                CDirection::Reversed
            } else {
                CDirection::Same
            },
            c_offset_deg: self.c_offset_deg,
            x_offset_mm: self.x_offset_mm,
            comment_lines,
            provenance: None,
        }
    }

    /// Main-program settings; the name is the --main-program file stem in upper case.
    pub(crate) fn main_settings(&self, c_speed_rpm: f64) -> Option<MainProgramSettings> {
        let path = self.main_program.as_deref()?;
        Some(MainProgramSettings {
            name: stem_upper(path).unwrap_or_else(|| MainProgramSettings::default().name),
            revolutions: self.revolutions,
            c_speed_rpm,
            ..MainProgramSettings::default()
        })
    }
}

fn stem_upper(path: &Path) -> Option<String> {
    path.file_stem().map(|s| s.to_string_lossy().to_uppercase())
}

/// Coolant as chosen on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CoolantArg {
    Flood,
    Mist,
    Off,
}

/// The safe start every generated program states (turning, turn-mill, planing): work
/// offset, tool and offset, spindle, coolant. The feed mode and the machine's defaults
/// come from the generator that flattens these flags in.
#[derive(Debug, Clone, Args)]
pub struct MachineSetupArgs {
    /// Work offset, 54 to 59 (G54 … G59).
    #[arg(long, global = true, value_name = "G", default_value_t = 54)]
    pub work_offset: u8,
    /// Tool number (T).
    #[arg(long, global = true, value_name = "T", default_value_t = 1)]
    pub tool: u32,
    /// Tool offset (SINUMERIK D, ISO H).
    #[arg(long, global = true, value_name = "D", default_value_t = 1)]
    pub tool_offset: u32,
    /// Constant cutting speed, m/min (G96); with --max-rpm. Default on a lathe.
    #[arg(long, global = true, value_name = "M_MIN", conflicts_with = "rpm")]
    pub surface_speed_m_min: Option<f64>,
    /// Spindle limit under G96, rpm (SINUMERIK LIMS, LinuxCNC G96 D).
    #[arg(long, global = true, value_name = "RPM")]
    pub max_rpm: Option<f64>,
    /// Fixed spindle speed, rpm (G97).
    #[arg(long, global = true, value_name = "RPM")]
    pub rpm: Option<f64>,
    /// Spindle counter-clockwise (M4) instead of clockwise (M3).
    #[arg(long, global = true)]
    pub spindle_ccw: bool,
    #[arg(long, global = true, value_enum, default_value_t = CoolantArg::Flood)]
    pub coolant: CoolantArg,
}

impl MachineSetupArgs {
    /// `defaults` with the flags given on the command line applied.
    pub fn setup(&self, defaults: Setup) -> Setup {
        let mut s = defaults;
        // Out of range stays out of range (Setup::check names it); no silent wrap.
        s.work_offset = self.work_offset.saturating_sub(53);
        s.tool.number = self.tool;
        s.tool.offset = self.tool_offset;
        let (default_speed, default_limit) = match defaults.spindle.speed {
            SpindleSpeed::ConstantSurface {
                speed_m_min,
                limit_rpm,
            } => (speed_m_min, limit_rpm),
            SpindleSpeed::Rpm(rpm) => (180.0, rpm),
        };
        if let Some(rpm) = self.rpm {
            s.spindle.speed = SpindleSpeed::Rpm(rpm);
        } else if self.surface_speed_m_min.is_some() || self.max_rpm.is_some() {
            s.spindle.speed = SpindleSpeed::ConstantSurface {
                speed_m_min: self.surface_speed_m_min.unwrap_or(default_speed),
                limit_rpm: self.max_rpm.unwrap_or(default_limit),
            };
        }
        if self.spindle_ccw {
            s.spindle.direction = SpindleDirection::Ccw;
        }
        s.coolant = match self.coolant {
            CoolantArg::Flood => Coolant::Flood,
            CoolantArg::Mist => Coolant::Mist,
            CoolantArg::Off => Coolant::Off,
        };
        s
    }
}
