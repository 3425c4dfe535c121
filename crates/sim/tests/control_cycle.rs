//! The simulated control runs the whole-cycle program as the control would: the wheel
//! spindle and coolant, the coupling with the stock held in the output offset, each stage's
//! infeed on X's overlay, the measurement, the handshake (answered, or timed out so the
//! finish grinds with the table in force), spark-out, lift-off and the end. The coupling
//! always takes the table the table program just defined.

use camloop_core::cycle::CycleSettings;
use camloop_core::program::{
    CycleMachine, CycleStation, MainProgramSettings, ProgramSettings, READY_PROGRAM,
    render_cycle_program, render_ready_program,
};
use camloop_sim::{Control, ControlFault, CycleEvent};
use std::cell::Cell;

mod cos_table;

const TABLE: &str = "DEMO_CAM";

fn cycle() -> CycleSettings {
    serde_json::from_str(
        r#"{
        "stock_mm": 0.25,
        "handshake_timeout_s": 5,
        "stages": [
            {"kind": "rough", "infeed_per_rev_mm": 0.02, "revolutions": 10},
            {"kind": "semi-finish", "infeed_mm": 0.03, "revolutions": 3},
            {"kind": "measure", "revolutions": 3, "c_speed_rpm": 10},
            {"kind": "finish", "infeed_mm": 0.02, "revolutions": 2},
            {"kind": "spark-out", "revolutions": 2}
        ]}"#,
    )
    .unwrap()
}

fn main_program() -> String {
    let cycle = cycle();
    let table = ProgramSettings {
        name: TABLE.into(),
        ..ProgramSettings::default()
    };
    let machine = CycleMachine {
        cycle: &cycle,
        c_speed_rpm: 30.0,
        wheel_radius_mm: 250.0,
        clear_x_mm: 13.0,
    };
    let stations = [CycleStation {
        table: &table,
        label: "IN1",
        z_mm: 20.0,
        plan: None,
    }];
    render_cycle_program(&MainProgramSettings::default(), &machine, &stations).unwrap()
}

/// A table version: X = amplitude·cos(c) over 36 points, defined as table `number`.
fn table_program(number: u32, amplitude_mm: f64) -> String {
    cos_table::cos_table(TABLE, number, amplitude_mm)
}

/// Runs the cycle with camloop answering the handshake after `answer_after` polls (never
/// when `None`): the answer is a new table version (number 2) and a ready count of 1.
fn run(
    answer_after: Option<u32>,
    overlay: bool,
) -> Result<camloop_sim::CycleRun, camloop_sim::ControlError> {
    let mut control = Control::new();
    if overlay {
        control.enable_overlay();
    }
    run_on(&mut control, answer_after)
}

/// [`run`] on `control`, which is left as the program leaves it.
fn run_on(
    control: &mut Control,
    answer_after: Option<u32>,
) -> Result<camloop_sim::CycleRun, camloop_sim::ControlError> {
    let main = main_program();
    let polls = Cell::new(0u32);
    let answered = || answer_after.is_some_and(|k| polls.get() > k);
    let (v1, v2) = (table_program(1, 0.5), table_program(2, 0.6));
    let load = |name: &str| -> Option<String> {
        match name {
            READY_PROGRAM => {
                polls.set(polls.get() + 1);
                Some(render_ready_program(u64::from(answered())))
            }
            TABLE => Some(if answered() { v2.clone() } else { v1.clone() }),
            _ => None,
        }
    };
    control.run_cycle(&main, &load)
}

/// (offset at the start, infeed, revolutions, table number) of every grind.
fn grinds(run: &camloop_sim::CycleRun) -> Vec<(f64, f64, f64, u32)> {
    run.ground
        .iter()
        .map(|g| (g.x_offset_mm, g.x_infeed_mm, g.revolutions, g.table_number))
        .collect()
}

fn assert_grinds(got: &[(f64, f64, f64, u32)], want: &[(f64, f64, f64, u32)]) {
    assert_eq!(got.len(), want.len(), "{got:?}");
    for (g, w) in got.iter().zip(want) {
        // The text holds 4 decimals of mm and degrees.
        let close =
            (g.0 - w.0).abs() < 1e-9 && (g.1 - w.1).abs() < 1e-9 && (g.2 - w.2).abs() < 1e-9;
        assert!(close && g.3 == w.3, "{g:?} vs {w:?} in {got:?}");
    }
}

#[test]
fn the_cycle_runs_every_stage_and_the_finish_couples_this_parts_table() {
    let run = run(Some(3), true).unwrap();
    // Approach, rough, semi-finish with table 1; after the measurement the table program
    // defines this part's finish table as 2, and the approach, finish and spark-out couple it.
    assert_grinds(
        &grinds(&run),
        &[
            (0.35, -0.1, 2.0, 1),
            (0.25, -0.2, 10.0, 1),
            (0.05, -0.03, 3.0, 1),
            (0.12, -0.1, 2.0, 2),
            (0.02, -0.02, 2.0, 2),
            (0.0, 0.0, 2.0, 2),
        ],
    );
    let dwell: f64 = run
        .events
        .iter()
        .filter_map(|e| match e {
            CycleEvent::Dwell(s) => Some(*s),
            _ => None,
        })
        .sum();
    // Asked before the measurement (call 1), then calls 2 and 3 unanswered with a 0.1 s
    // dwell after each, call 4 answered: 0.2 s waited.
    assert!((dwell - 0.2).abs() < 1e-9, "{dwell}");
    let turned = CycleEvent::Turned {
        revolutions: 3.0,
        c_speed_rpm: 10.0,
    };
    let at = |e: &CycleEvent| run.events.iter().position(|x| x == e).unwrap();
    assert!(at(&CycleEvent::MFunction(62)) < at(&turned));
    assert!(at(&turned) < at(&CycleEvent::MFunction(63)));
    assert!(at(&CycleEvent::Ground(2)) < at(&CycleEvent::MFunction(62)));
    assert!(at(&CycleEvent::MFunction(63)) < at(&CycleEvent::Ground(3)));
    assert_eq!(
        run.events.first(),
        Some(&CycleEvent::Spindle {
            spindle: 1,
            rpm: 1336.9
        })
    );
    assert_eq!(
        &run.events[run.events.len() - 2..],
        [
            CycleEvent::Coolant(false),
            CycleEvent::Spindle {
                spindle: 1,
                rpm: 0.0
            }
        ]
    );
}

/// The control is left with X at the clear X (13 mm here), not 2 mm off the part where the
/// lift-off put it, and the wheel and coolant stop only once X is there.
#[test]
fn the_program_leaves_x_retracted_to_the_clear_x() {
    let mut control = Control::new();
    control.enable_overlay();
    let run = run_on(&mut control, Some(3)).unwrap();
    assert_eq!(control.position("X"), 13.0);
    let main = main_program();
    let retract = main.rfind("G90 G0 X=13.0000").expect("a retract");
    let last_leadof = main.rfind("LEADOF(X,C)").unwrap();
    assert!(last_leadof < retract && retract < main.find("M9 ;").unwrap());
    assert_eq!(
        run.events.last(),
        Some(&CycleEvent::Spindle {
            spindle: 1,
            rpm: 0.0
        })
    );
}

#[test]
fn after_the_timeout_the_finish_grinds_with_the_table_in_force() {
    let run = run(None, true).unwrap();
    let got = grinds(&run);
    assert_eq!(got.len(), 6);
    // Never answered: the table program still defines version 1, and the finish couples it.
    assert!(got.iter().all(|g| g.3 == 1), "{got:?}");
    let waits = run
        .events
        .iter()
        .filter(|e| matches!(e, CycleEvent::Dwell(_)))
        .count();
    assert_eq!(waits, 50, "5 s in 0.1 s polls");
    // Answered only after the timeout: too late for this part.
    let late = self::run(Some(60), true).unwrap();
    assert!(grinds(&late).iter().all(|g| g.3 == 1));
}

#[test]
fn without_the_overlay_enabled_the_infeed_is_the_controls_alarm() {
    let err = run(Some(3), false).unwrap_err();
    assert_eq!(err.fault, ControlFault::AxisCoupled { axis: "X".into() });
    assert!(err.fault.is_alarm());
    let line = main_program().lines().nth(err.line - 1).unwrap().to_owned();
    assert!(line.starts_with("G91 G1 C=720.0000 X=-0.1000"), "{line}");
}

/// Two features: each cycle at its station, each coupling its own table program's number.
#[test]
fn a_shaft_runs_the_cycle_at_each_station() {
    let cycle = cycle();
    let tables = [
        ProgramSettings {
            name: "DEMO_CAM_IN1".into(),
            ..ProgramSettings::default()
        },
        ProgramSettings {
            name: "DEMO_CAM_EX1".into(),
            ..ProgramSettings::default()
        },
    ];
    let machine = CycleMachine {
        cycle: &cycle,
        c_speed_rpm: 30.0,
        wheel_radius_mm: 250.0,
        clear_x_mm: 13.0,
    };
    let stations = [
        CycleStation {
            table: &tables[0],
            label: "IN1",
            z_mm: 20.0,
            plan: None,
        },
        CycleStation {
            table: &tables[1],
            label: "EX1",
            z_mm: 50.0,
            plan: None,
        },
    ];
    let main = render_cycle_program(&MainProgramSettings::default(), &machine, &stations).unwrap();
    let in1 = table_program(1, 0.5).replace(TABLE, "DEMO_CAM_IN1");
    let ex1 = table_program(3, 0.7).replace(TABLE, "DEMO_CAM_EX1");
    let load = |name: &str| match name {
        READY_PROGRAM => Some(render_ready_program(0)),
        "DEMO_CAM_IN1" => Some(in1.clone()),
        "DEMO_CAM_EX1" => Some(ex1.clone()),
        _ => None,
    };
    let mut control = Control::new();
    control.enable_overlay();
    let run = control.run_cycle(&main, &load).unwrap();
    assert_eq!(run.ground.len(), 12);
    for (k, g) in run.ground.iter().enumerate() {
        let (z, number, by) = if k < 6 {
            (20.0, 1, "DEMO_CAM_IN1")
        } else {
            (50.0, 3, "DEMO_CAM_EX1")
        };
        assert_eq!(
            (g.z_mm, g.table_number, g.defined_by.as_str()),
            (z, number, by)
        );
    }
}

const SHAFT: [(&str, f64); 3] = [
    ("DEMO_CAM_IN1", 20.0),
    ("DEMO_CAM_EX1", 50.0),
    ("DEMO_CAM_IN2", 80.0),
];

/// The cycle program of the three features of [`SHAFT`].
fn shaft_program() -> String {
    let cycle = cycle();
    let tables: Vec<ProgramSettings> = SHAFT
        .iter()
        .map(|(name, _)| ProgramSettings {
            name: (*name).into(),
            ..ProgramSettings::default()
        })
        .collect();
    let machine = CycleMachine {
        cycle: &cycle,
        c_speed_rpm: 30.0,
        wheel_radius_mm: 250.0,
        clear_x_mm: 13.0,
    };
    let stations: Vec<CycleStation<'_>> = tables
        .iter()
        .zip(SHAFT)
        .map(|(table, (name, z_mm))| CycleStation {
            table,
            label: &name[9..],
            z_mm,
            plan: None,
        })
        .collect();
    render_cycle_program(&MainProgramSettings::default(), &machine, &stations).unwrap()
}

/// Runs the shaft's cycle program on `control`. The share holds every feature's table
/// program (numbers 1, 3, 5) except `missing` (the run stops at its call, as a shaft
/// interrupted there), the handshake's count 0 (every finish with the table in force), and,
/// when given, the resume subprogram naming feature `resume_at`.
fn run_shaft(
    control: &mut Control,
    missing: Option<usize>,
    resume_at: Option<usize>,
) -> Result<camloop_sim::CycleRun, camloop_sim::ControlError> {
    let main = shaft_program();
    let load = |name: &str| -> Option<String> {
        if name == READY_PROGRAM {
            return Some(render_ready_program(0));
        }
        if name == camloop_core::program::RESUME_PROGRAM {
            return resume_at.map(camloop_core::program::render_resume_program);
        }
        let k = SHAFT.iter().position(|(n, _)| *n == name)?;
        (missing != Some(k + 1)).then(|| table_program(2 * k as u32 + 1, 0.5).replace(TABLE, name))
    };
    control.run_cycle(&main, &load)
}

/// How many grinds each feature of [`SHAFT`] had in `runs` (by the station ground and the
/// program that defined the coupled table, which must agree).
fn grinds_per_feature(runs: &[&camloop_sim::CycleRun]) -> [usize; 3] {
    let mut count = [0; 3];
    for g in runs.iter().flat_map(|r| &r.ground) {
        let k = SHAFT.iter().position(|(_, z)| *z == g.z_mm).unwrap();
        assert_eq!(g.defined_by, SHAFT[k].0, "{g:?}");
        count[k] += 1;
    }
    count
}

/// A shaft interrupted after feature k and resumed through R90 = -1 (the resume subprogram
/// names feature k + 1): every feature is ground once, each with its whole cycle (6 coupled
/// passes: approach, rough, semi-finish, approach, finish, spark-out), and the run resets
/// R90, so the next start grinds a new shaft whole.
#[test]
fn an_interrupted_shaft_resumes_at_the_first_feature_without_a_gauge_record() {
    for k in 1..=2 {
        let mut control = Control::new();
        control.enable_overlay();
        let err = run_shaft(&mut control, Some(k + 1), None).unwrap_err();
        assert_eq!(
            err.fault,
            ControlFault::ProgramNotFound {
                name: SHAFT[k].0.into()
            }
        );
        let stopped = control
            .stopped_run()
            .expect("what ground before the stop")
            .clone();
        let mut want = [0; 3];
        want[..k].fill(6);
        assert_eq!(grinds_per_feature(&[&stopped]), want, "stopped after {k}");
        control.set_r_param(90, -1.0);
        let resumed = run_shaft(&mut control, None, Some(k + 1)).unwrap();
        assert!(control.stopped_run().is_none());
        assert_eq!(
            grinds_per_feature(&[&stopped, &resumed]),
            [6, 6, 6],
            "resumed at {}",
            k + 1
        );
        // The resumed run starts the wheel and coolant before it grinds, and ends retracted.
        assert!(matches!(resumed.events[0], CycleEvent::Spindle { rpm, .. } if rpm > 0.0));
        assert_eq!(resumed.events[1], CycleEvent::Coolant(true));
        assert_eq!(control.position("X"), 13.0);
        // R90 was reset by the resumed run: a plain start grinds the whole shaft (and needs
        // no resume subprogram).
        let next = run_shaft(&mut control, None, None).unwrap();
        assert_eq!(grinds_per_feature(&[&next]), [6, 6, 6]);
    }
}

/// R90 = k > 0 starts at feature k without asking the resume subprogram.
#[test]
fn the_operator_names_the_feature_to_start_at() {
    let mut control = Control::new();
    control.enable_overlay();
    control.set_r_param(90, 2.0);
    let run = run_shaft(&mut control, None, None).unwrap();
    assert_eq!(grinds_per_feature(&[&run]), [0, 6, 6]);
    let plain = run_shaft(&mut control, None, None).unwrap();
    assert_eq!(grinds_per_feature(&[&plain]), [6, 6, 6]);
}
