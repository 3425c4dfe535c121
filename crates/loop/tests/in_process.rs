//! The decision before the finish, without I/O: a measurement of the part in the machine
//! becomes a table order made from the learned correction plus this part's step (the memory
//! untouched); no whole cycle, another part, another lobe or too few revolutions give no
//! order, with the reason.

// Shared by the loop's tests; this one needs no machine, so not all of it.
#[allow(dead_code)]
mod support;

use camloop_core::cycle::finish::FinishRefused;
use camloop_core::cycle::{CycleProgram, CycleSettings, Stage, StageKind};
use camloop_loop::LoopMemory;
use camloop_loop::in_process::{
    SamePart, SamePartRefused, same_part_order, stock_after_measure_mm,
};
use camloop_loop::machine::Program;
use support::{Recipe, WHEEL_MM, at, grind};

fn stage(kind: StageKind, infeed_mm: Option<f64>, revolutions: f64) -> Stage {
    Stage {
        kind,
        infeed_per_rev_mm: None,
        infeed_mm,
        revolutions,
        c_speed_rpm: None,
        speed_plan: false,
        wheel_speed_m_s: None,
        dwell_s: 0.0,
    }
}

/// The demo recipe's cycle: 0.2 mm of stock, 0.02 mm of it after the measurement.
fn cycle(program: CycleProgram) -> CycleSettings {
    CycleSettings {
        program,
        stock_mm: 0.2,
        approach_mm: 0.1,
        approach_feed_mm_per_rev: 0.05,
        lift_off_mm: 2.0,
        wheel_speed_m_s: 35.0,
        wheel_max_speed_m_s: 50.0,
        wheel_spindle: 1,
        gauge_m_codes: (62, 63),
        handshake_timeout_s: 5.0,
        x_travel_mm: None,
        same_part_gain: 0.9,
        stages: vec![
            stage(StageKind::Rough, Some(0.15), 10.0),
            stage(StageKind::SemiFinish, Some(0.03), 4.0),
            stage(StageKind::Measure, None, 3.0),
            stage(StageKind::Finish, Some(0.02), 4.0),
            stage(StageKind::SparkOut, None, 3.0),
        ],
    }
}

#[test]
fn the_stock_after_the_measurement_is_the_later_stages_infeed() {
    let c = cycle(CycleProgram::Whole);
    let stock = stock_after_measure_mm(&c).unwrap();
    assert!((stock - 0.02).abs() < 1e-12, "{stock}");
    let mut none = c;
    none.stages.retain(|s| s.kind != StageKind::Measure);
    assert_eq!(stock_after_measure_mm(&none), None);
}

#[test]
fn the_part_in_the_machine_gets_its_finish_table_and_nothing_is_learned() {
    let recipe = Recipe::new();
    let setup = recipe.setup();
    let memory = LoopMemory::new(WHEEL_MM);
    let whole = cycle(CycleProgram::Whole);
    let mut raw = grind(0, &[0.0; 360], false);
    // 20 µm of stock on, read as size.
    for s in &mut raw.samples {
        s.lift_mm += 0.02;
    }
    let part = raw.header.part.clone();
    let input = SamePart {
        setup: &setup,
        cycle: Some(&whole),
        memory: &memory,
        feature: raw.header.lobe.trim(),
        part: &part,
        waited_s: 0.2,
    };
    let order = same_part_order(&input, &raw, at(0)).expect("a finish table");
    assert!(matches!(order.program, Program::Table { .. }));
    // The order carries the step; the memory it was made from is as it was.
    assert_eq!(memory, LoopMemory::new(WHEEL_MM));
    let moved = order
        .next
        .correction_um
        .iter()
        .map(|c| c.abs())
        .fold(0.0, f64::max);
    // The measured error is 8 µm at order 2 and 3 µm at order 3 (the stock taken out as
    // size): a step of gain 0.9 moves the correction by several µm, far from 0.
    assert!(moved > 3.0, "largest correction {moved} µm");
    assert!(
        order.reason.contains("same-part finish table"),
        "{}",
        order.reason
    );

    // Refusals: no whole cycle, another part, another lobe, too few revolutions.
    let table_only = cycle(CycleProgram::TableOnly);
    let refused = |cycle: Option<&CycleSettings>, part: &str, feature: &str, raw| {
        let input = SamePart {
            cycle,
            part,
            feature,
            ..input
        };
        same_part_order(&input, raw, at(0)).unwrap_err()
    };
    let lobe = raw.header.lobe.trim().to_string();
    assert_eq!(refused(None, &part, &lobe, &raw), SamePartRefused::NoCycle);
    assert_eq!(
        refused(Some(&table_only), &part, &lobe, &raw),
        SamePartRefused::NoCycle
    );
    assert!(matches!(
        refused(Some(&whole), "other", &lobe, &raw),
        SamePartRefused::Finish(FinishRefused::WrongPart { .. })
    ));
    assert!(matches!(
        refused(Some(&whole), &part, "EX9", &raw),
        SamePartRefused::Finish(FinishRefused::WrongFeature { .. })
    ));
    let late = SamePart {
        waited_s: 5.0,
        ..input
    };
    assert!(matches!(
        same_part_order(&late, &raw, at(0)).unwrap_err(),
        SamePartRefused::TooLate { .. }
    ));
    let mut two = raw.clone();
    two.samples.retain(|s| s.revolution < 2);
    two.header.revolutions = 2;
    assert!(matches!(
        refused(Some(&whole), &part, &lobe, &two),
        SamePartRefused::Finish(_)
    ));
}
