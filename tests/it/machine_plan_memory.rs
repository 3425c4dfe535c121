//! With the C speed plan, a restart learns which plan the table in force was made for from
//! the loop's memory, never by reading the share's program back: the same plan delivers
//! nothing new even when the program on the share says another speed, and a plan the recipe
//! changed (a lower removal rate, so a slower virtual axis) is delivered again.

use crate::machine_support::{demo_lobe_setup, start_machine};
use camloop::core::program::fmt_fixed;
use camloop::recipe::FeatureSetup;
use camloop::service::machine::MachineLoop;
use camloop::service::metrics::Metrics;
use std::sync::Arc;

/// The demo lobe ground with the plan at removal rate `q_w` (mm³/(mm·s)); C's tables take
/// the numbers after X's.
fn planned(q_w: f64) -> FeatureSetup {
    let mut setup = demo_lobe_setup();
    setup.speed_plan.enabled = true;
    setup.speed_plan.q_w_max_mm3_mm_s = q_w;
    let (a, b) = setup.table_pair;
    setup.c_table_pair = Some((a.max(b) + 1, a.max(b) + 2));
    setup
}

fn in_force(m: &MachineLoop) -> (Option<u64>, Option<String>) {
    let memory = m.features()[0].memory();
    (
        memory.in_force_version.map(|v| v.get()),
        memory.in_force_va_speed_rpm.map(|r| fmt_fixed(r, 4)),
    )
}

#[tokio::test]
async fn a_restart_takes_the_plan_of_the_table_in_force_from_the_memory() {
    let dir = tempfile::tempdir().unwrap();
    let metrics = Arc::new(Metrics::default());
    let m = start_machine(dir.path(), "P1", vec![planned(2.36)], metrics.clone()).await;
    let (version, rpm) = in_force(&m);
    assert_eq!(version, Some(1), "the nominal table");
    let rpm = rpm.expect("the plan's speed is kept with the table in force");
    let program = m.features()[0]
        .share_dir()
        .join(format!("{}.SPF", m.features()[0].setup().program.name));
    drop(m);

    // The program on the share altered to say another speed: nothing reads it back.
    let text = std::fs::read_to_string(&program).unwrap();
    let line = format!("VA at {rpm} rpm");
    assert!(text.contains(&line), "{text}");
    std::fs::write(&program, text.replace(&line, "VA at 1.0000 rpm")).unwrap();
    let m = start_machine(dir.path(), "P1", vec![planned(2.36)], metrics.clone()).await;
    assert_eq!(
        in_force(&m),
        (Some(1), Some(rpm.clone())),
        "same plan: nothing new"
    );
    drop(m);

    let m = start_machine(dir.path(), "P1", vec![planned(1.2)], metrics).await;
    let (version, slower) = in_force(&m);
    assert_eq!(version, Some(2), "a changed plan is delivered again");
    let slower = slower.expect("its speed is kept");
    assert!(
        slower.parse::<f64>().unwrap() < rpm.parse::<f64>().unwrap(),
        "{slower} rpm at the lower removal rate, {rpm} before"
    );
}
