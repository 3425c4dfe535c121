//! The simulated control runs the speed plan's programs as the control would: the table
//! program returns both numbers, the main program couples C and X to the virtual axis by
//! them, and what the run reports is what the rendered text defines (read back from the
//! text by the control, compared here with the tables the text was rendered from).

use camloop_core::speed_plan::render::{
    VaProgramSettings, render_va_main_program, render_va_table_program,
};
use camloop_core::table::PolySegment;
use camloop_sim::{Control, TableShape};

mod demo_plan;

const TABLE: &str = "DEMO_CAM_IN1_PLAN";

fn settings(x_table: u32, c_table: u32) -> VaProgramSettings {
    VaProgramSettings {
        name: TABLE.into(),
        virtual_axis: "VA".into(),
        x_axis: "X".into(),
        c_axis: "C".into(),
        x_decimals: 4,
        c_decimals: 4,
        x_table,
        c_table,
        ..VaProgramSettings::default()
    }
}

/// Largest difference of two segment lists in start, value and cubic terms; the text holds
/// 4 decimals for values and 6 for the higher terms, so 1e-4 bounds a faithful reading.
fn max_difference(read: &TableShape, rendered: &[PolySegment]) -> f64 {
    let TableShape::Poly(read) = read else {
        panic!("the control read a G1 table: {read:?}");
    };
    assert_eq!(read.len(), rendered.len());
    read.iter()
        .zip(rendered)
        .flat_map(|(a, b)| {
            [
                a.c_start_deg - b.c_start_deg,
                a.c_end_deg - b.c_end_deg,
                a.x0_mm - b.x0_mm,
                a.a2_mm - b.a2_mm,
                a.a3_mm - b.a3_mm,
            ]
        })
        .fold(0.0f64, |m, d| m.max(d.abs()))
}

#[test]
fn the_control_couples_c_and_x_to_the_virtual_axis_by_the_returned_numbers() {
    let tables = demo_plan::tables();
    let mut control = Control::new();
    // Two versions with alternating numbers, as the service delivers them.
    for (x_table, c_table) in [(1, 3), (2, 4), (1, 3)] {
        let s = settings(x_table, c_table);
        let table_text = render_va_table_program(&tables, &s).unwrap();
        let main = render_va_main_program("CAMLOOP_GRIND", &s, tables.va_speed_rpm, 1.0).unwrap();
        let load = |name: &str| (name == TABLE).then(|| table_text.clone());
        let coupled = control.run(&main, &load).unwrap();
        assert_eq!(coupled.table_number, x_table);
        assert_eq!(coupled.c_table_number, Some(c_table));
        assert!(max_difference(&coupled.shape, &tables.x_segments) < 1e-4);
        let c_law = coupled.c_law.as_ref().expect("C follows the virtual axis");
        assert!(max_difference(c_law, &tables.c_segments) < 1e-4);
        // FA[VA] is written with 3 decimals of degrees per minute.
        assert!((coupled.c_speed_rpm - tables.va_speed_rpm).abs() < 1e-3 / 360.0);
        assert_eq!(coupled.revolutions, 1.0);
    }
    assert_eq!(control.defined_tables(), [1, 2, 3, 4]);
}

#[test]
fn an_old_table_program_with_one_number_is_refused_by_the_plan_main_program() {
    let tables = demo_plan::tables();
    let s = settings(1, 2);
    let main = render_va_main_program("CAMLOOP_GRIND", &s, tables.va_speed_rpm, 1.0).unwrap();
    // The table program's PROC takes one number where the main program hands two.
    let table_text = render_va_table_program(&tables, &s)
        .unwrap()
        .replace(", VAR INT CL_TNO_C)", ")");
    let load = |name: &str| (name == TABLE).then(|| table_text.clone());
    let err = Control::new().run(&main, &load).unwrap_err();
    assert_eq!(err.program, TABLE);
    assert!(
        err.to_string()
            .contains("called with 2 arguments for 1 parameters"),
        "{err}"
    );
}

#[test]
fn c_cannot_be_positioned_while_it_follows_the_virtual_axis() {
    let tables = demo_plan::tables();
    let s = settings(1, 2);
    let table_text = render_va_table_program(&tables, &s).unwrap();
    let main = render_va_main_program("CAMLOOP_GRIND", &s, tables.va_speed_rpm, 1.0)
        .unwrap()
        .replace("WAITP(VA)\n", "WAITP(VA)\nPOS[C]=DC(CL_C) FA[C]=3600\n");
    let load = |name: &str| (name == TABLE).then(|| table_text.clone());
    let err = Control::new().run(&main, &load).unwrap_err();
    assert!(err.fault.is_alarm(), "{err}");
    assert!(err.to_string().contains("C is coupled"), "{err}");
}
