//! The machine set-up every generated program states before it cuts and undoes at its end:
//! work offset, radius or diameter X, tool and offset, spindle, feed mode and coolant.
//!
//! A generator puts [`Setup::start`] before its first move and [`Setup::end`] after its
//! last; the dialects write each [`MachineStmt`] in their own words, and
//! [`crate::safety::check`] proves the order on the program itself. Units and plane are the
//! program's header line (`G71`/`G21` with the plane's G code), written by every dialect.

use thiserror::Error;

use crate::ir::Stmt;

/// How X words are read on a lathe.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum XMode {
    /// X is a radius (SINUMERIK `DIAMOF`, ISO `G8`).
    Radius,
    /// X is a diameter (SINUMERIK `DIAMON`, ISO `G7`); the program's own values stay radii
    /// and the dialect writes them doubled.
    Diameter,
}

/// The unit of every F word that follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FeedMode {
    /// G94: mm per minute.
    PerMinute,
    /// G95: mm per revolution of the spindle.
    PerRevolution,
}

impl FeedMode {
    /// The unit as the program's comments and reports name it.
    pub fn unit(self) -> &'static str {
        match self {
            FeedMode::PerMinute => "mm/min",
            FeedMode::PerRevolution => "mm/rev",
        }
    }
}

/// Sense of the spindle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpindleDirection {
    /// M3.
    Cw,
    /// M4.
    Ccw,
}

/// Spindle speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SpindleSpeed {
    /// G96: constant cutting speed, limited in rpm (SINUMERIK `LIMS=`, LinuxCNC `D`).
    ConstantSurface { speed_m_min: f64, limit_rpm: f64 },
    /// G97: fixed rpm.
    Rpm(f64),
}

/// The spindle as started.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spindle {
    pub speed: SpindleSpeed,
    pub direction: SpindleDirection,
}

/// Coolant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coolant {
    /// M8.
    Flood,
    /// M7.
    Mist,
    /// No coolant (M9 is still written at the end).
    Off,
}

/// Tool and offset: SINUMERIK `T<n> D<d>`, ISO `T<n> M6 G43 H<d>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ToolCall {
    pub number: u32,
    pub offset: u32,
    /// Write M6 (a machine whose tool change needs it, as most milling spindles do);
    /// ISO always writes it, since LinuxCNC loads a tool only with M6.
    pub change: bool,
}

/// A machine-state statement of a program.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MachineStmt {
    /// G54 … G59 (1 … 6).
    WorkOffset(u8),
    XMode(XMode),
    Tool(ToolCall),
    SpindleOn(Spindle),
    SpindleOff,
    FeedMode(FeedMode),
    Coolant(Coolant),
    /// A machine's own M function (a planer's hydraulics, A's sense, the tool lifter):
    /// `M<code>`, with LinuxCNC's `P<n>` where the code takes one (M64/M65 outputs).
    MFunction {
        code: u16,
        p: Option<u16>,
        what: &'static str,
    },
}

/// The set-up a program starts with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setup {
    /// 1 … 6 for G54 … G59.
    pub work_offset: u8,
    /// Radius or diameter X; `None` on a machine without a lathe X (milling, planing).
    pub x_mode: Option<XMode>,
    pub tool: ToolCall,
    pub spindle: Spindle,
    pub feed_mode: FeedMode,
    pub coolant: Coolant,
}

/// Why a set-up is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SetupError {
    #[error("work offset G{got} is not one of G54 to G59")]
    WorkOffset { got: u32 },
    #[error("{field} is {value}: it must be a whole number from 1 to 99")]
    Number { field: &'static str, value: u32 },
    #[error("{field} is {value}: it must be a number > 0")]
    Speed { field: &'static str, value: f64 },
}

impl Setup {
    /// A lathe's usual start: G54, radius X, T1 D1, G96 at 180 m/min up to 3000 rpm, M3,
    /// G95, flood coolant.
    pub fn turning() -> Self {
        Setup {
            work_offset: 1,
            x_mode: Some(XMode::Radius),
            tool: ToolCall {
                number: 1,
                offset: 1,
                change: false,
            },
            spindle: Spindle {
                speed: SpindleSpeed::ConstantSurface {
                    speed_m_min: 180.0,
                    limit_rpm: 3000.0,
                },
                direction: SpindleDirection::Cw,
            },
            feed_mode: FeedMode::PerRevolution,
            coolant: Coolant::Flood,
        }
    }

    /// A milling spindle's usual start: G54, T1 D1 with M6, 3000 rpm M3, G94, flood.
    pub fn milling() -> Self {
        Setup {
            work_offset: 1,
            x_mode: None,
            tool: ToolCall {
                number: 1,
                offset: 1,
                change: true,
            },
            spindle: Spindle {
                speed: SpindleSpeed::Rpm(3000.0),
                direction: SpindleDirection::Cw,
            },
            feed_mode: FeedMode::PerMinute,
            coolant: Coolant::Flood,
        }
    }

    /// Numbers in range, speeds positive and finite.
    pub fn check(&self) -> Result<(), SetupError> {
        if !(1..=6).contains(&self.work_offset) {
            return Err(SetupError::WorkOffset {
                got: 53 + u32::from(self.work_offset),
            });
        }
        for (field, value) in [
            ("tool number", self.tool.number),
            ("tool offset", self.tool.offset),
        ] {
            if !(1..=99).contains(&value) {
                return Err(SetupError::Number { field, value });
            }
        }
        let speeds = match self.spindle.speed {
            SpindleSpeed::ConstantSurface {
                speed_m_min,
                limit_rpm,
            } => vec![
                ("cutting speed (m/min)", speed_m_min),
                ("spindle limit (rpm)", limit_rpm),
            ],
            SpindleSpeed::Rpm(rpm) => vec![("spindle speed (rpm)", rpm)],
        };
        for (field, value) in speeds {
            if !(value.is_finite() && value > 0.0) {
                return Err(SetupError::Speed { field, value });
            }
        }
        Ok(())
    }

    /// The safe start, in the order a machinist writes it: offset and X mode, tool, the
    /// feed mode before any F, spindle, coolant.
    pub fn start(&self) -> Vec<Stmt> {
        let mut s = vec![Stmt::Machine(MachineStmt::WorkOffset(self.work_offset))];
        if let Some(m) = self.x_mode {
            s.push(Stmt::Machine(MachineStmt::XMode(m)));
        }
        s.extend([
            Stmt::Machine(MachineStmt::Tool(self.tool)),
            Stmt::Machine(MachineStmt::FeedMode(self.feed_mode)),
            Stmt::Machine(MachineStmt::SpindleOn(self.spindle)),
        ]);
        if self.coolant != Coolant::Off {
            s.push(Stmt::Machine(MachineStmt::Coolant(self.coolant)));
        }
        s
    }

    /// The safe end: coolant off, spindle off (the dialect then ends the program).
    pub fn end(&self) -> Vec<Stmt> {
        vec![
            Stmt::Machine(MachineStmt::Coolant(Coolant::Off)),
            Stmt::Machine(MachineStmt::SpindleOff),
        ]
    }

    /// One header line saying what the set-up is, for the program's comments.
    pub fn describe(&self) -> String {
        let spindle = match self.spindle.speed {
            SpindleSpeed::ConstantSurface {
                speed_m_min,
                limit_rpm,
            } => format!("G96 {speed_m_min} m/min up to {limit_rpm} rpm"),
            SpindleSpeed::Rpm(rpm) => format!("G97 {rpm} rpm"),
        };
        format!(
            "set-up: G{} T{} D{}, {spindle}, feed in {}",
            53 + u32::from(self.work_offset),
            self.tool.number,
            self.tool.offset,
            self.feed_mode.unit()
        )
    }
}
