//! Tests of the cycle's settings checks and its removal-rate and X checks.

use super::limits::{CycleContext, limit_problems, stage_load};
use super::*;
use crate::compensate::AxisLimits;
use crate::geometry::{CrankpinGeometry, Part};
use crate::speed_plan::{ProfileSamples, SpeedPlanSettings};
use std::f64::consts::PI;

/// The demo cycle: 0.25 mm of stock in rough, semi-finish, measure, finish, spark-out.
fn demo() -> CycleSettings {
    serde_json::from_str(
        r#"{
        "stock_mm": 0.25,
        "stages": [
            {"kind": "rough", "infeed_per_rev_mm": 0.02, "revolutions": 10},
            {"kind": "semi-finish", "infeed_mm": 0.04, "revolutions": 4},
            {"kind": "measure", "revolutions": 3, "c_speed_rpm": 10},
            {"kind": "finish", "infeed_mm": 0.01, "revolutions": 1, "dwell_s": 0.2},
            {"kind": "spark-out", "revolutions": 2}
        ]}"#,
    )
    .unwrap()
}

#[test]
fn the_demo_cycle_is_sound_and_resolves_its_infeeds() {
    let cycle = demo();
    assert_eq!(cycle.problems(false), Vec::<String>::new());
    let stages = cycle.resolved(30.0);
    let totals: Vec<f64> = stages.iter().map(|s| s.infeed_mm).collect();
    for (got, want) in totals.iter().zip([0.2, 0.04, 0.0, 0.01, 0.0]) {
        assert!((got - want).abs() < 1e-12, "{totals:?}");
    }
    assert!((stages[1].infeed_per_rev_mm - 0.01).abs() < 1e-12);
    assert_eq!(stages[2].c_speed_rpm, Some(10.0));
    assert_eq!(stages[0].c_speed_rpm, Some(30.0), "the recipe's speed");
    assert_eq!(stages[0].wheel_speed_m_s, 35.0, "the cycle's default");
    assert_eq!(cycle.measure_stage(), Some(2));
}

#[test]
fn infeeds_that_do_not_add_up_to_the_stock_are_refused_naming_both() {
    let mut cycle = demo();
    cycle.stock_mm = 0.3;
    let p = cycle.problems(false);
    assert_eq!(
        p,
        ["cycle.stages: the infeeds add up to 0.2500 mm, cycle.stock_mm is 0.3000 mm"]
    );
}

#[test]
fn each_stage_problem_names_its_key() {
    let mut cycle = demo();
    cycle.stages[0].infeed_mm = Some(0.2);
    cycle.stages[2].infeed_per_rev_mm = Some(0.001);
    cycle.stages[2].revolutions = 2.0;
    cycle.stages[3].speed_plan = true;
    cycle.stages[3].wheel_speed_m_s = Some(60.0);
    cycle.stages[4].dwell_s = -1.0;
    let p = cycle.problems(false);
    let want = [
        "cycle.stages[0] (rough): give infeed_per_rev_mm or infeed_mm, not both",
        "cycle.stages[2] (measure): a measure stage takes no infeed",
        "cycle.stages[2] (measure).revolutions = 2: the gauge needs at least 3 revolutions",
        "cycle.stages[3] (finish).speed_plan: needs [speed_plan] enabled = true",
        "cycle.stages[3] (finish).wheel_speed_m_s = 60: above cycle.wheel_max_speed_m_s = 50",
        "cycle.stages[4] (spark-out).dwell_s = -1: must be ≥ 0",
    ];
    for w in want {
        assert!(p.iter().any(|x| x == w), "missing {w:?} in {p:#?}");
    }
}

#[test]
fn a_measurement_without_a_finish_after_it_is_refused() {
    let mut cycle = demo();
    cycle.stages.remove(3);
    cycle.stock_mm = 0.24;
    let p = cycle.problems(false);
    assert!(
        p.contains(&"cycle.stages[2] (measure): a measurement before the finish needs a finish stage after it".to_string()),
        "{p:#?}"
    );
}

fn round_pin(radius_mm: f64) -> ProfileSamples {
    let part = Part::crankpin(CrankpinGeometry {
        throw_mm: 0.0,
        pin_radius_mm: radius_mm,
        wheel_radius_mm: 250.0,
    })
    .unwrap();
    ProfileSamples::new(&part).unwrap()
}

/// On a round part Q′w is the annulus one revolution removes, π((r + a)² − r²), times the
/// revolutions per second: an independent formula for the planner's per-angle one.
#[test]
fn removal_rate_on_a_round_part_is_the_annulus_per_second() {
    let (r, a, rpm) = (20.0, 0.02, 30.0);
    let load = stage_load(&round_pin(r), a, rpm);
    let want = PI * ((r + a).powi(2) - r * r) * rpm / 60.0;
    // 1e-5 relative: the contact's arc per radian comes from exact points 0.002° apart.
    assert!(
        (load.q_w_mm3_mm_s - want).abs() < 1e-5 * want,
        "{} vs {want}",
        load.q_w_mm3_mm_s
    );
    // A round part does not move X: only the infeed does.
    assert!((load.x_velocity_mm_s - a * rpm / 60.0).abs() < 1e-9);
}

#[test]
fn a_stage_over_the_removal_limit_is_refused_with_its_rate_and_key() {
    let samples = round_pin(20.0);
    let axis = AxisLimits::default();
    let plan = SpeedPlanSettings::default();
    let ctx = CycleContext {
        samples: &samples,
        axis: &axis,
        plan: &plan,
        x_offset_mm: 0.0,
    };
    // 0.02 mm/rev at 30 rpm on r = 20 mm: 1.258 mm³/(mm·s), under 2.36.
    assert_eq!(limit_problems(&demo(), &ctx), Vec::<String>::new());
    let mut cycle = demo();
    cycle.stages[0].infeed_per_rev_mm = Some(0.04);
    cycle.stages[0].revolutions = 5.0;
    let p = limit_problems(&cycle, &ctx);
    assert_eq!(p.len(), 1, "{p:#?}");
    assert!(
        p[0].starts_with("cycle.stages[0] (rough): Q'w 2.5")
            && p[0].ends_with("exceeds speed_plan.q_w_max_mm3_mm_s = 2.36"),
        "{}",
        p[0]
    );
}

#[test]
fn x_travel_is_checked_with_the_stock_and_lift_off_added() {
    let samples = round_pin(20.0);
    let axis = AxisLimits::default();
    let plan = SpeedPlanSettings::default();
    let ctx = CycleContext {
        samples: &samples,
        axis: &axis,
        plan: &plan,
        x_offset_mm: 0.0,
    };
    let mut cycle = demo();
    // The round part's program X is 0 all round; lift-off 2 mm is the highest X.
    cycle.x_travel_mm = Some((-1.0, 1.5));
    let p = limit_problems(&cycle, &ctx);
    assert_eq!(
        p,
        [
            "cycle.x_travel_mm = [-1, 1.5]: X reaches 2.0000 mm with the stock, approach and lift-off added"
        ]
    );
    cycle.x_travel_mm = Some((-1.0, 2.5));
    assert!(limit_problems(&cycle, &ctx).is_empty());
}

#[test]
fn a_stage_on_the_plan_may_take_no_more_than_the_plans_stock() {
    let samples = round_pin(20.0);
    let axis = AxisLimits::default();
    let plan = SpeedPlanSettings {
        enabled: true,
        stock_mm: 0.005,
        ..SpeedPlanSettings::default()
    };
    let ctx = CycleContext {
        samples: &samples,
        axis: &axis,
        plan: &plan,
        x_offset_mm: 0.0,
    };
    let mut cycle = demo();
    cycle.stages[3].speed_plan = true;
    assert!(cycle.problems(true).is_empty());
    let p = limit_problems(&cycle, &ctx);
    assert_eq!(
        p,
        [
            "cycle.stages[3] (finish): 0.01 mm/rev on the speed plan, which holds Q'w for speed_plan.stock_mm = 0.005 mm"
        ]
    );
}
