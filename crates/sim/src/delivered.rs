//! The cell's control side: each table camloop makes is rendered as the programs the service
//! delivers (table subprogram with alternating numbers, main program that couples what it
//! defines), kept in an in-memory share, and run by the simulated [`Control`]. What the cell
//! grinds is the table the control couples, so a defect in the programs or the coupling shows
//! up in the cell's figures, as it would on the machine.

use super::{CommandedTable, Control, ControlError};
use camloop_core::compensate::{Feature, GuardedTable};
use camloop_core::program::{
    MainProgramSettings, ProgramSettings, SettingsErrors, TableError, next_table_number,
    render_main_program,
};
use std::collections::BTreeMap;

const TABLE_PROGRAM: &str = "CELL_TABLE";
const TABLE_PAIR: (u32, u32) = (1, 2);

/// Why a table could not reach the simulated control's coupling.
#[derive(Debug, thiserror::Error)]
pub enum DeliveryError {
    #[error("table program: {0}")]
    Table(#[from] TableError),
    #[error("main program: {0}")]
    Main(#[from] SettingsErrors),
    #[error("control: {0}")]
    Control(#[from] ControlError),
}

/// An in-memory share and the control that runs it.
#[derive(Debug, Clone, Default)]
pub(crate) struct DeliveredTables {
    files: BTreeMap<String, String>,
    control: Control,
    table_number: u32,
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
}
