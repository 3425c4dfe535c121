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

/// The issue's goal: the first part within 1 µm after its finish, every part from the third
/// within 0.5 µm (max lift error on the 0.1° grid, nothing fitted), each finish ground with
/// its own finish table; without the measurement the first part is the machine's
/// uncompensated error (16 µm at constant speed, as the simulator's defaults are made to give).
fn assert_goal(with: &[CyclePart], without: &[CyclePart]) {
    assert!(with[0].max_lift_error_um <= 1.0, "{:?}", with[0]);
    assert!(max_from(with, 3) <= 0.5, "{}", max_from(with, 3));
    assert!(
        with.iter()
            .all(|p| p.in_process.starts_with("finish table"))
    );
    assert!(without[0].max_lift_error_um > 10.0, "{:?}", without[0]);
}

#[test]
fn measuring_before_the_finish_makes_the_first_part_right() {
    let with = cycle_cell::run(&setup(true, 2), PARTS).unwrap();
    let without = cycle_cell::run(&setup(false, 2), PARTS).unwrap();
    print("with", &with);
    print("without", &without);
    // The issue's goal: the first part within 1 µm after its finish, every part from the
    // third within 0.5 µm (max lift error on the 0.1° grid, nothing fitted).
    assert_goal(&with, &without);
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

/// The demo cycle with its spark-outs and finish on the speed plan, made for the finish's
/// 5 µm a revolution (a stage on the plan may take no more than the plan's `stock_mm`).
///
/// Two changes from the cycle at constant speed, both measured here:
/// - **The spark-out before the measurement runs on the plan too.** The part the gauge reads
///   must carry the servo lag the finish will: at constant speed before it and on the plan
///   after, the same-part step takes the constant-speed lag's timing off the finish (42 µm
///   on every part).
/// - **Both spark-outs take 6 revolutions.** On the plan C turns up to 120 rpm, so the wheel
///   head's compliance K (∝ C speed) is up to 4 times the 30 rpm one and the deflection falls
///   by only K/(1 + K) ≈ 0.3–0.4 a revolution. With 2 and 3 revolutions the residuals at the
///   measurement and at the end differ by about 0.4 µm, which the same-part step puts into
///   every finish (0.5–0.65 µm from the 3rd part); with 6 and 6 they are below 0.01 µm.
/// - `same_part_gain = 0.99`: the first part is 58 µm off on the plan (the lag grows with C
///   speed), and 0.97 leaves 3 % of it (1.8 µm).
fn on_the_plan() -> CycleCellSetup {
    let mut s = setup(true, 2);
    s.cell.speed_plan = SpeedPlanSettings {
        enabled: true,
        stock_mm: 0.005,
        ..SpeedPlanSettings::default()
    };
    for k in [2, 4, 5] {
        s.cycle.stages[k].speed_plan = true;
    }
    s.cycle.stages[2].revolutions = 6.0;
    s.cycle.stages[5].revolutions = 6.0;
    s.cycle.same_part_gain = 0.99;
    s
}

/// Spark-outs and finish on the plan, through the cycle program the simulated control runs
/// (C and X coupled to VA by the plan's tables, the infeed on X's overlay, the stock removed
/// at the plan's C speed at each degree): the goal holds, and the part's coupled revolutions
/// are 16 at 30 rpm (approach, rough, semi-finish) and 20 of the plan's revolution (approach
/// and spark-out before the measurement, approach, finish and spark-out after it).
#[test]
fn on_the_speed_plan_the_first_part_is_right_and_the_cycle_is_shorter() {
    use camloop_core::geometry::Part;
    use camloop_core::lift::LiftCurve;
    let planned = on_the_plan();
    let Feature::Cam(g) = planned.cell.feature else {
        unreachable!()
    };
    let part = Part::cam(g, LiftCurve::new(&planned.cell.nominal)).unwrap();
    let limits = planned.cell.speed_plan.limits(&planned.cell.limits);
    let rev_s = camloop_core::speed_plan::plan(&part, &limits)
        .unwrap()
        .law
        .period_s();
    let with = cycle_cell::run(&planned, PARTS).unwrap();
    let mut part_to_part = on_the_plan();
    part_to_part.measure_before_finish = false;
    let without = cycle_cell::run(&part_to_part, PARTS).unwrap();
    let constant = cycle_cell::run(&setup(true, 2), 1).unwrap();
    print("plan", &with);
    print("plan, part to part only", &without);
    assert_goal(&with, &without);
    eprintln!(
        "per part: coupled {:.2} s at constant speed, {:.2} s with the plan ({rev_s:.4} s a revolution); measurement {:.1} s, wait {:.1} s",
        constant[0].grind_s, with[0].grind_s, with[0].measure_s, with[0].dwell_s
    );
    // VA's speed is written with 3 decimals of degrees per minute.
    let want = 16.0 * 2.0 + 20.0 * rev_s;
    assert!(
        (with[0].grind_s - want).abs() < 1e-3,
        "{} vs {want}",
        with[0].grind_s
    );
    assert!(with[0].grind_s < constant[0].grind_s);
}
