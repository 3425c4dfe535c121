//! The whole-cycle program with finish and spark-out on the speed plan, run by the simulated
//! control: the stages before the measurement couple X to C by the constant-speed table
//! program's number, the stages on the plan couple C and X to the virtual axis by the two
//! numbers the plan's table program has just returned (this part's finish tables when camloop
//! answered the handshake, the tables in force otherwise), and the infeed is superimposed on
//! the coupled X over VA's revolutions.

use camloop_core::cycle::CycleSettings;
use camloop_core::program::syntax::lines;
use camloop_core::program::{
    CycleMachine, CyclePlan, CycleStation, MainProgramSettings, ProgramSettings, READY_PROGRAM,
    check_ending, render_cycle_program, render_ready_program,
};
use camloop_core::speed_plan::render::{VaProgramSettings, render_va_table_program};
use camloop_core::speed_plan::tables::VaTables;
use camloop_sim::{Control, CycleEvent, CycleRun};
use std::cell::Cell;

mod cos_table;

mod demo_plan;

const TABLE: &str = "DEMO_CAM_IN1";
const PLAN: &str = "DEMO_CAM_IN1_P";

fn cycle() -> CycleSettings {
    serde_json::from_str(
        r#"{
        "stock_mm": 0.25,
        "handshake_timeout_s": 5,
        "stages": [
            {"kind": "rough", "infeed_per_rev_mm": 0.02, "revolutions": 10},
            {"kind": "semi-finish", "infeed_mm": 0.03, "revolutions": 3},
            {"kind": "measure", "revolutions": 3, "c_speed_rpm": 10},
            {"kind": "finish", "infeed_mm": 0.02, "revolutions": 2, "speed_plan": true},
            {"kind": "spark-out", "revolutions": 3, "speed_plan": true}
        ]}"#,
    )
    .unwrap()
}

fn va_settings(x_table: u32, c_table: u32) -> VaProgramSettings {
    VaProgramSettings {
        name: PLAN.into(),
        x_table,
        c_table,
        ..VaProgramSettings::default()
    }
}

fn main_program(va_speed_rpm: f64) -> String {
    let cycle = cycle();
    let table = ProgramSettings {
        name: TABLE.into(),
        ..ProgramSettings::default()
    };
    let plan = va_settings(5, 7);
    let machine = CycleMachine {
        cycle: &cycle,
        c_speed_rpm: 30.0,
        wheel_radius_mm: 250.0,
        clear_x_mm: 14.0,
    };
    let stations = [CycleStation {
        table: &table,
        label: "IN1",
        z_mm: 20.0,
        plan: Some(CyclePlan {
            table: &plan,
            va_speed_rpm,
        }),
    }];
    render_cycle_program(&MainProgramSettings::default(), &machine, &stations).unwrap()
}

/// A constant-speed table version `number`: X = 0.5·cos(c) over 36 points.
fn constant_table(number: u32) -> String {
    cos_table::cos_table(TABLE, number, 0.5)
}

/// Runs the cycle with camloop answering after `answer_after` polls (never when `None`): the
/// answer is a new version of both table programs (constant table 2, plan tables 6 and 8,
/// where the version in force has 1, 5 and 7) and a ready count of 1.
fn run(tables: &VaTables, answer_after: Option<u32>) -> CycleRun {
    let main = main_program(tables.va_speed_rpm);
    let polls = Cell::new(0u32);
    let answered = || answer_after.is_some_and(|k| polls.get() > k);
    let (c1, c2) = (constant_table(1), constant_table(2));
    let p1 = render_va_table_program(tables, &va_settings(5, 7)).unwrap();
    let p2 = render_va_table_program(tables, &va_settings(6, 8)).unwrap();
    let load = |name: &str| -> Option<String> {
        match name {
            READY_PROGRAM => {
                polls.set(polls.get() + 1);
                Some(render_ready_program(u64::from(answered())))
            }
            TABLE => Some(if answered() { c2.clone() } else { c1.clone() }),
            PLAN => Some(if answered() { p2.clone() } else { p1.clone() }),
            _ => None,
        }
    };
    let mut control = Control::new();
    control.enable_overlay();
    let run = control.run_cycle(&main, &load).unwrap();
    assert_eq!(control.position("X"), 14.0, "the program ends retracted");
    run
}

/// (X table, C table, leading speed rpm, offset at the start, infeed, revolutions).
type Grind = (u32, Option<u32>, f64, f64, f64, f64);

fn grinds(run: &CycleRun) -> Vec<Grind> {
    run.ground
        .iter()
        .map(|g| {
            (
                g.table_number,
                g.c_table_number,
                g.c_speed_rpm,
                g.x_offset_mm,
                g.x_infeed_mm,
                g.revolutions,
            )
        })
        .collect()
}

fn assert_grinds(got: &[Grind], want: &[Grind]) {
    assert_eq!(got.len(), want.len(), "{got:?}");
    for (g, w) in got.iter().zip(want) {
        // Millimetres and degrees with 4 decimals; F with 3 decimals of degrees per minute.
        let close = (g.2 - w.2).abs() < 1e-3 / 360.0
            && (g.3 - w.3).abs() < 1e-9
            && (g.4 - w.4).abs() < 1e-9
            && (g.5 - w.5).abs() < 1e-9;
        assert!(
            close && g.0 == w.0 && g.1 == w.1,
            "{g:?} vs {w:?} in {got:?}"
        );
    }
}

#[test]
fn finish_and_spark_out_couple_this_parts_plan_tables_with_the_infeed_on_x() {
    let tables = demo_plan::tables();
    let va = tables.va_speed_rpm;
    let run = run(&tables, Some(3));
    assert_grinds(
        &grinds(&run),
        &[
            (1, None, 30.0, 0.35, -0.1, 2.0),
            (1, None, 30.0, 0.25, -0.2, 10.0),
            (1, None, 30.0, 0.05, -0.03, 3.0),
            // After the measurement: this part's plan tables (X 6, C 8), VA at the plan's speed.
            (6, Some(8), va, 0.12, -0.1, 2.0),
            (6, Some(8), va, 0.02, -0.02, 2.0),
            (6, Some(8), va, 0.0, 0.0, 3.0),
        ],
    );
    // What the control couples on the plan is the plan's time law as rendered.
    let finish = &run.ground[4];
    assert!(finish.planned_speed().is_some());
    let turned = CycleEvent::Turned {
        revolutions: 3.0,
        c_speed_rpm: 10.0,
    };
    let at = |e: &CycleEvent| run.events.iter().position(|x| x == e).unwrap();
    assert!(at(&CycleEvent::Ground(2)) < at(&turned));
    assert!(at(&turned) < at(&CycleEvent::Ground(3)));
}

#[test]
fn after_the_timeout_the_plan_stages_grind_with_the_tables_in_force() {
    let tables = demo_plan::tables();
    let got = grinds(&run(&tables, None));
    assert_eq!(got.len(), 6);
    assert!(
        got[..3].iter().all(|g| g.0 == 1 && g.1.is_none()),
        "{got:?}"
    );
    assert!(
        got[3..].iter().all(|g| g.0 == 5 && g.1 == Some(7)),
        "{got:?}"
    );
}

/// The text: every line read back by the SINUMERIK reader, the plan program declared with
/// its two numbers, the couplings to VA released at the start, and the ending check passed.
#[test]
fn the_plan_cycle_program_reads_back_and_ends_retracted() {
    let text = main_program(49.5);
    for l in lines(&text) {
        l.statement()
            .unwrap_or_else(|e| panic!("line {}: {e:?}\n{text}", l.number));
    }
    check_ending(&text, "X", 14.0).unwrap();
    // C turns to the plan's start only with X clear of the part: the last X move before
    // each POS[C] is the absolute retract to the clear X.
    let all: Vec<&str> = text.lines().collect();
    let turns: Vec<usize> = (0..all.len())
        .filter(|&i| all[i].starts_with("POS[C]"))
        .collect();
    assert!(!turns.is_empty(), "{text}");
    for i in turns {
        let last_x = all[..i]
            .iter()
            .rev()
            .find(|l| l.contains(" X="))
            .unwrap_or_else(|| panic!("no X move before line {}", i + 1));
        assert!(
            last_x.starts_with("G90 G0 X=14.0000"),
            "C turns at line {} after {last_x:?}\n{text}",
            i + 1
        );
    }
    for want in [
        "DEF INT CL_TNO, CL_SEEN, CL_READY, CL_NEW, CL_WAIT, CL_TNO_C\n",
        "EXTERN DEMO_CAM_IN1_P(VAR INT, VAR INT)\n",
        "LEADOF(C,VA)\n",
        "DEMO_CAM_IN1_P(CL_TNO,CL_TNO_C) ; defines the plan's newest tables, returns their numbers\n",
        "LEADON(C,VA,CL_TNO_C)\nLEADON(X,VA,CL_TNO)\nFGROUP(VA)",
        "G91 G1 VA=720.0000 X=-0.0200 F=17820.000\n",
        "G91 G1 VA=1080.0000 F=17820.000\n",
    ] {
        assert!(text.contains(want), "{want:?} not in\n{text}");
    }
}
