//! The whole cycle on the simulated cell, demo lobe, shafts 1–12: with the measurement
//! before the finish (this part's finish table) and without it (part-to-part learning
//! only), the finished part judged on the 0.1° grid; and the handshake answered too late.

use camloop_core::compensate::{AxisLimits, Feature, TableRequest};
use camloop_core::cycle::CycleSettings;
use camloop_core::fit::TableForm;
use camloop_core::geometry::{CamGeometry, Follower};
use camloop_core::learn::LearningParams;
use camloop_core::lift::LiftTable;
use camloop_core::speed_plan::SpeedPlanSettings;
use camloop_sim::GrinderConfig;
use camloop_sim::cell::CellSetup;
use camloop_sim::cycle_cell::{self, CycleCellSetup, CyclePart};

const INTAKE: &str = include_str!("../../../config/parts/demo-intake-lobe.csv");
const PARTS: u32 = 12;

/// The cycle of `config/parts/demo-lobe-in-process.toml`.
fn cycle() -> CycleSettings {
    serde_json::from_str(
        r#"{
        "stock_mm": 0.2,
        "same_part_gain": 0.97,
        "stages": [
            {"kind": "rough", "infeed_per_rev_mm": 0.015, "revolutions": 10},
            {"kind": "semi-finish", "infeed_mm": 0.03, "revolutions": 4},
            {"kind": "spark-out", "revolutions": 2},
            {"kind": "measure", "revolutions": 3, "c_speed_rpm": 10},
            {"kind": "finish", "infeed_mm": 0.02, "revolutions": 4},
            {"kind": "spark-out", "revolutions": 3}
        ]}"#,
    )
    .unwrap()
}

/// The same cycle without the spark-out and the measurement before the finish.
fn without_measurement() -> CycleSettings {
    let mut c = cycle();
    c.stages.remove(3);
    c.stages.remove(2);
    c
}

fn setup(measure_before_finish: bool, answer_polls: u32) -> CycleCellSetup {
    CycleCellSetup {
        cell: CellSetup {
            nominal: LiftTable::parse_csv(INTAKE, "demo-intake-lobe.csv").unwrap(),
            feature: Feature::Cam(CamGeometry {
                base_radius_mm: 20.0,
                follower: Follower::Flat,
                wheel_radius_mm: 250.0,
            }),
            request: TableRequest {
                points: 360,
                form: TableForm::Poly,
                poly_tolerance_um: 0.1,
            },
            params: LearningParams::default(),
            limits: AxisLimits::default(),
            grinder: GrinderConfig::default(),
            seed: 7,
            speed_plan: SpeedPlanSettings::default(),
        },
        cycle: if measure_before_finish {
            cycle()
        } else {
            without_measurement()
        },
        measure_before_finish,
        answer_polls,
        station: Default::default(),
    }
}

fn print(name: &str, parts: &[CyclePart]) {
    for p in parts {
        eprintln!(
            "{name} part {:2}: max lift error {:6.2} µm, profile {:5.2} µm; grind {:.1} s, measure {:.1} s, dwell {:.1} s; {} | {}",
            p.part,
            p.max_lift_error_um,
            p.max_profile_error_um,
            p.grind_s,
            p.measure_s,
            p.dwell_s,
            p.in_process,
            p.action
        );
    }
}

fn max_from(parts: &[CyclePart], first: u32) -> f64 {
    parts
        .iter()
        .filter(|p| p.part >= first)
        .map(|p| p.max_lift_error_um)
        .fold(0.0, f64::max)
}

#[test]
fn measuring_before_the_finish_makes_the_first_part_right() {
    let with = cycle_cell::run(&setup(true, 2), PARTS).unwrap();
    let without = cycle_cell::run(&setup(false, 2), PARTS).unwrap();
    print("with", &with);
    print("without", &without);
    // The issue's goal: the first part within 1 µm after its finish, every part from the
    // third within 0.5 µm (max lift error on the 0.1° grid, nothing fitted).
    assert!(with[0].max_lift_error_um <= 1.0, "{:?}", with[0]);
    assert!(max_from(&with, 3) <= 0.5, "{}", max_from(&with, 3));
    assert!(
        with.iter()
            .all(|p| p.in_process.starts_with("finish table"))
    );
    // Without it the first part is the machine's uncompensated error (16 µm, as the
    // simulator's defaults are made to give).
    assert!(without[0].max_lift_error_um > 10.0, "{:?}", without[0]);
    // The measurement's cost: the spark-out before it and the second approach (2 rev each
    // at 30 rpm), its 3 rev at 10 rpm, and the handshake's wait: camloop answers after 2
    // polls, the first asked before the measurement, so one 0.1 s dwell.
    let cost = with[0].grind_s + with[0].measure_s + with[0].dwell_s - without[0].grind_s;
    assert!((cost - (4.0 + 4.0 + 18.0 + 0.1)).abs() < 1e-9, "{cost}");
}

#[test]
fn an_answer_after_the_timeout_leaves_the_finish_with_the_table_in_force() {
    // 60 polls of 0.1 s: after the program's 5 s.
    let late = cycle_cell::run(&setup(true, 60), 2).unwrap();
    print("late", &late);
    assert!(late.iter().all(|p| p.in_process.starts_with("too late")));
    assert!((late[0].dwell_s - 5.0).abs() < 1e-9, "{}", late[0].dwell_s);
    // The first part is then what part-to-part learning alone gives.
    assert!(late[0].max_lift_error_um > 10.0);
    assert!(late[1].max_lift_error_um < 5.0);
}

/// The finish and spark-out revolutions on the speed plan (made for the finish's 5 µm per
/// revolution) instead of 30 rpm: the time they would take, from the plan's revolution.
#[test]
fn the_plan_shortens_the_finish_revolutions() {
    use camloop_core::geometry::Part;
    use camloop_core::lift::LiftCurve;
    let s = setup(true, 2);
    let Feature::Cam(g) = s.cell.feature else {
        unreachable!()
    };
    let part = Part::cam(g, LiftCurve::new(&s.cell.nominal)).unwrap();
    let plan_settings = SpeedPlanSettings {
        enabled: true,
        stock_mm: 0.005,
        ..SpeedPlanSettings::default()
    };
    let plan =
        camloop_core::speed_plan::plan(&part, &plan_settings.limits(&s.cell.limits)).unwrap();
    let rev_s = plan.law.period_s();
    let constant_s = 7.0 * 2.0;
    let planned_s = 7.0 * rev_s;
    eprintln!(
        "finish + spark-out, 7 rev: {constant_s:.2} s at 30 rpm, {planned_s:.2} s on the plan ({rev_s:.3} s a revolution)"
    );
    assert!(planned_s < constant_s);
}
