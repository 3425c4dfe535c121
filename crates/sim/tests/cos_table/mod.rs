//! The control tests' constant-speed table version: X = amplitude·cos(c) over 36 points,
//! defined as table `number` by the table program `name`.

use camloop_core::program::{ProgramSettings, render_g1_table};
use camloop_core::table::TablePoint;

pub fn cos_table(name: &str, number: u32, amplitude_mm: f64) -> String {
    let points: Vec<TablePoint> = (0..36)
        .map(|k| {
            let c_deg = f64::from(k) * 10.0;
            let x_mm = amplitude_mm * c_deg.to_radians().cos();
            TablePoint {
                c_deg,
                d_mm: x_mm,
                x_mm,
            }
        })
        .collect();
    let settings = ProgramSettings {
        name: name.into(),
        table_number: number,
        ..ProgramSettings::default()
    };
    render_g1_table(&points, &settings).unwrap()
}
