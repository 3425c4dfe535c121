//! The whole cycle with and without the measurement before the finish on every lobe of the
//! demo camshaft and every pin of the demo crankshaft, shafts 1–12: the worst feature per
//! shaft. Each feature runs in its own in-process cell with its station's errors (size and
//! lag growing along Z, its own order-2 harmonic), so the wheel's wear between the features
//! of one shaft is not shared. Printed with `--nocapture`.

use camloop::core::cycle::CycleSettings;
use camloop::core::cycle::limits::{CycleContext, limit_problems};
use camloop::core::speed_plan::ProfileSamples;
use camloop::recipe::Recipe;
use camloop::sim::GrinderConfig;
use camloop::sim::cell::CellSetup;
use camloop::sim::cycle_cell::{self, CycleCellSetup};
use std::path::Path;

const SHAFTS: u32 = 12;

fn demo_cycle() -> CycleSettings {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe-in-process.toml");
    Recipe::load(&path).unwrap().cycle.unwrap()
}

/// The worst max lift error per shaft over the recipe's features, with and without the
/// measurement before the finish.
fn worst_per_shaft(recipe_file: &str, same_part_gain: f64) -> (Vec<f64>, Vec<f64>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config/parts")
        .join(recipe_file);
    let recipe = Recipe::load(&path).unwrap();
    let grinder = GrinderConfig {
        c_speed_rpm: recipe.axis_limits.c_speed_rpm,
        ..GrinderConfig::default()
    };
    let mut worst = (vec![0.0f64; SHAFTS as usize], vec![0.0f64; SHAFTS as usize]);
    for setup in recipe.feature_setups(&path).unwrap() {
        let mut cycle = demo_cycle();
        cycle.same_part_gain = same_part_gain;
        // The demo cycle passes this feature's checks too.
        let part = setup.feature.part(&setup.nominal).unwrap();
        let samples = ProfileSamples::new(&part).unwrap();
        let ctx = CycleContext {
            samples: &samples,
            axis: &setup.limits,
            plan: &setup.speed_plan,
            x_offset_mm: 0.0,
        };
        assert_eq!(
            limit_problems(&cycle, &ctx),
            Vec::<String>::new(),
            "{}",
            setup.name
        );
        for (measure, out) in [(true, &mut worst.0), (false, &mut worst.1)] {
            let mut cycle = cycle.clone();
            if !measure {
                // Without the measurement: no spark-out before it, no measure stage.
                cycle.stages.remove(3);
                cycle.stages.remove(2);
            }
            let cell = CellSetup {
                nominal: setup.nominal.clone(),
                feature: setup.feature,
                request: setup.request,
                params: setup.params.clone(),
                limits: setup.limits.clone(),
                grinder: grinder.clone(),
                seed: 100 + setup.index as u64,
                speed_plan: setup.speed_plan,
            };
            let run = cycle_cell::run(
                &CycleCellSetup {
                    cell,
                    cycle,
                    measure_before_finish: measure,
                    answer_polls: 2,
                    station: grinder.shaft.station(setup.index, setup.z_mm),
                },
                SHAFTS,
            )
            .unwrap_or_else(|e| panic!("{}: {e}", setup.name));
            for (w, p) in out.iter_mut().zip(&run) {
                *w = w.max(p.max_lift_error_um);
            }
        }
    }
    worst
}

fn print(what: &str, (with, without): &(Vec<f64>, Vec<f64>)) {
    let row = |v: &[f64]| v.iter().map(|e| format!("{e:6.2}")).collect::<String>();
    eprintln!("{what}, worst feature per shaft 1–{SHAFTS}, max lift error µm");
    eprintln!("  measured before the finish: {}", row(with));
    eprintln!("  part to part only:          {}", row(without));
}

#[test]
fn the_camshafts_first_shaft_is_right_with_the_measurement_before_the_finish() {
    let worst = worst_per_shaft("demo-camshaft.toml", 0.97);
    print("demo camshaft (8 lobes)", &worst);
    let (with, without) = &worst;
    assert!(with[0] <= 1.0, "{with:?}");
    assert!(with[2..].iter().all(|e| *e <= 0.5), "{with:?}");
    assert!(without[0] > 10.0, "{without:?}");
}

/// The pins start 33 µm off at 10 rpm: at the camshaft's same-part gain of 0.97 the first
/// shaft's finish keeps 3 % of it (1.22 µm); at 0.99 it is right.
#[test]
fn the_crankshafts_first_shaft_is_right_with_the_measurement_before_the_finish() {
    let worst = worst_per_shaft("demo-crankshaft.toml", 0.99);
    print("demo crankshaft (4 pins, 10 rpm)", &worst);
    let (with, without) = &worst;
    assert!(with[0] <= 1.0, "{with:?}");
    assert!(with[2..].iter().all(|e| *e <= 0.5), "{with:?}");
    assert!(without[0] > with[0], "{without:?}");
}
