//! The cell's control side: each table camloop makes is rendered as the programs the service
//! delivers (table subprogram with alternating numbers, main program that couples what it
//! defines), kept in an in-memory share, and run by the simulated [`Control`]. What the cell
//! grinds is the table the control couples, so a defect in the programs or the coupling shows
//! up in the cell's figures, as it would on the machine.

use super::{CommandedTable, Control, ControlError};
use camloop_core::compensate::{Feature, GuardError, GuardedTable};
use camloop_core::geometry::{GeometryError, Part};
use camloop_core::program::{
    MainProgramSettings, ProgramSettings, SettingsErrors, TableError, next_table_number,
    render_main_program,
};
use camloop_core::speed_plan::render::{
    VaProgramError, VaProgramSettings, render_va_main_program, render_va_table_program,
};
use camloop_core::speed_plan::tables::VaTables;
use std::collections::BTreeMap;

const TABLE_PROGRAM: &str = "CELL_TABLE";
const TABLE_PAIR: (u32, u32) = (1, 2);
/// The C table's numbers with a speed plan, alternating like the X table's.
const C_TABLE_PAIR: (u32, u32) = (3, 4);
const MAIN_PROGRAM: &str = "CELL_GRIND";
/// The virtual leading axis of a speed plan.
const VIRTUAL_AXIS: &str = "VA";

/// Why a table could not reach the simulated control's coupling.
#[derive(Debug, thiserror::Error)]
pub enum DeliveryError {
    #[error("table program: {0}")]
    Table(#[from] TableError),
    #[error("main program: {0}")]
    Main(#[from] SettingsErrors),
    #[error("control: {0}")]
    Control(#[from] ControlError),
    #[error("speed plan tables: {0}")]
    Plan(#[from] GeometryError),
    /// The corrected X table over VA exceeds an X limit: refused, never delivered.
    #[error("{0}")]
    Guard(#[from] GuardError),
    #[error("speed plan program: {0}")]
    PlanProgram(#[from] VaProgramError),
}

/// An in-memory share and the control that runs it.
#[derive(Debug, Clone, Default)]
pub(crate) struct DeliveredTables {
    files: BTreeMap<String, String>,
    control: Control,
    table_number: u32,
    c_table_number: u32,
}

impl DeliveredTables {
    /// Delivers `table` as the next version and returns what the control couples.
    pub(crate) fn deliver(
        &mut self,
        table: &GuardedTable,
        feature: Feature,
    ) -> Result<CommandedTable, DeliveryError> {
        let settings = ProgramSettings {
            name: TABLE_PROGRAM.to_string(),
            table_number: next_table_number(self.table_number, TABLE_PAIR),
            ..ProgramSettings::default()
        };
        let text = table.render(&settings)?;
        let main = render_main_program(&MainProgramSettings::default(), &settings)?;
        self.files.insert(TABLE_PROGRAM.to_string(), text);
        self.table_number = settings.table_number;
        let files = &self.files;
        let coupled = self
            .control
            .run(&main, &|name: &str| files.get(name).cloned())?;
        Ok(CommandedTable {
            shape: coupled.shape,
            x_zero_mm: feature.x_zero_mm(),
            wheel_radius_mm: feature.wheel_radius_mm(),
            plan: None,
        })
    }

    /// Delivers `tables`, the tables over VA of a guarded table with the planned C speed
    /// (already checked against the X limits, see `camloop_core::turn::planned_tables`),
    /// made for the commanded part `commanded`: the two-table program and the main program
    /// that couples C and X to the virtual axis, run by the control.
    pub(crate) fn deliver_planned(
        &mut self,
        tables: &VaTables,
        commanded: &Part,
    ) -> Result<CommandedTable, DeliveryError> {
        let defaults = ProgramSettings::default();
        let settings = VaProgramSettings {
            name: TABLE_PROGRAM.to_string(),
            virtual_axis: VIRTUAL_AXIS.to_string(),
            x_axis: defaults.following_axis.clone(),
            c_axis: defaults.leading_axis.clone(),
            x_decimals: usize::from(defaults.x_decimals),
            c_decimals: usize::from(defaults.c_decimals),
            x_table: next_table_number(self.table_number, TABLE_PAIR),
            c_table: next_table_number(self.c_table_number, C_TABLE_PAIR),
            ..VaProgramSettings::default()
        };
        let text = render_va_table_program(tables, &settings)?;
        let main = render_va_main_program(MAIN_PROGRAM, &settings, tables.va_speed_rpm, 1.0)?;
        self.files.insert(TABLE_PROGRAM.to_string(), text);
        (self.table_number, self.c_table_number) = (settings.x_table, settings.c_table);
        let files = &self.files;
        let coupled = self
            .control
            .run(&main, &|name: &str| files.get(name).cloned())?;
        Ok(CommandedTable {
            plan: coupled.planned_speed(),
            shape: coupled.shape,
            x_zero_mm: commanded.x_zero_mm(),
            wheel_radius_mm: commanded.wheel_radius_mm(),
        })
    }
}
