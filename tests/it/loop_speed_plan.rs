//! The closed loop with the C speed plan on (`[speed_plan] enabled = true`): the simulated
//! cell delivers the two-table program and the main program that couples C and X to the
//! virtual axis, the simulated control runs them, and the grinder's servo lag follows the
//! planned C speed at each angle. Learning is unchanged (lift-domain correction, timing in C):
//! at a fixed plan the speed-dependent lag is a repeatable shape, learned like any other.
//! The demo lobe must converge below 1.3 µm from the 4th part as it does at constant speed,
//! across two dressings (the plan is made again for each new wheel radius, the correction is
//! kept).

use crate::sim_support::demo_cell;
use camloop::sim::GrinderConfig;
use camloop::sim::cell::{self, CellRun, CellSetup, Method};

const PARTS: u32 = 100;

fn setup(enabled: bool) -> CellSetup {
    let grinder = GrinderConfig {
        dress_every_parts: 40,
        ..GrinderConfig::default()
    };
    let mut setup = demo_cell(grinder, 7);
    setup.speed_plan.enabled = enabled;
    setup
}

fn worst_from_part_4(run: &CellRun, figure: impl Fn(&cell::PartFigures) -> f64) -> f64 {
    run.parts[3..].iter().map(figure).fold(0.0f64, f64::max)
}

#[test]
fn the_demo_lobe_converges_with_the_plan_on_as_at_constant_speed() {
    let planned = cell::run(&setup(true), Method::Camloop, PARTS).unwrap();
    let constant = cell::run(&setup(false), Method::Camloop, PARTS).unwrap();
    for (name, run) in [("planned", &planned), ("constant", &constant)] {
        let first: Vec<String> = run.parts[..6]
            .iter()
            .map(|p| format!("{:.2}", p.max_profile_error_um))
            .collect();
        println!(
            "{name}: parts 1-6 profile {first:?} µm; from part 4 worst profile {:.3} µm, lift {:.3} µm",
            worst_from_part_4(run, |p| p.max_profile_error_um),
            worst_from_part_4(run, |p| p.max_lift_error_um)
        );
        let worst = run.parts[3..]
            .iter()
            .max_by(|a, b| a.max_lift_error_um.total_cmp(&b.max_lift_error_um))
            .map(|p| (p.part, p.dressed));
        println!("{name}: worst lift from part 4 on part (number, dressed after) {worst:?}");
        assert!(run.stopped.is_none(), "{name}: {:?}", run.stopped);
        assert_eq!(run.parts.len(), PARTS as usize);
        assert_eq!(run.parts.iter().filter(|p| p.dressed).count(), 2);
    }
    // Uncompensated, the constant-speed lag is nearly a phase, which the datum fit takes
    // out; the planned lag varies along the profile (C runs up to about 3 times faster off
    // the flanks), so more of it is shape: measured 9.8 against 3.0 µm on part 1.
    assert!(
        planned.parts[0].max_profile_error_um > 2.0 * constant.parts[0].max_profile_error_um,
        "{:?} {:?}",
        planned.parts[0],
        constant.parts[0]
    );
    for p in &planned.parts[3..] {
        assert!(
            p.max_profile_error_um < 1.3 && p.max_lift_error_um < 1.3,
            "part {}: profile {:.3} µm, lift {:.3} µm ({})",
            p.part,
            p.max_profile_error_um,
            p.max_lift_error_um,
            p.action
        );
    }
}
