//! The whole-cycle main program: its text for the demo cycle, read back by the SINUMERIK
//! reader line by line, and the settings it refuses.

use camloop_core::cycle::CycleSettings;
use camloop_core::program::syntax::lines;
use camloop_core::program::{
    CycleMachine, CycleProgramError, CycleStation, EndingError, MainProgramSettings,
    ProgramSettings, check_ending, render_cycle_program, render_ready_program, wheel_rpm,
};

fn demo_cycle() -> CycleSettings {
    serde_json::from_str(
        r#"{
        "stock_mm": 0.25,
        "stages": [
            {"kind": "rough", "infeed_per_rev_mm": 0.02, "revolutions": 10},
            {"kind": "semi-finish", "infeed_mm": 0.03, "revolutions": 3},
            {"kind": "measure", "revolutions": 3, "c_speed_rpm": 10},
            {"kind": "finish", "infeed_mm": 0.02, "revolutions": 2, "wheel_speed_m_s": 40},
            {"kind": "spark-out", "revolutions": 2, "dwell_s": 0.5}
        ]}"#,
    )
    .unwrap()
}

fn table() -> ProgramSettings {
    ProgramSettings {
        name: "DEMO_CAM".into(),
        ..ProgramSettings::default()
    }
}

fn render(cycle: &CycleSettings) -> Result<String, CycleProgramError> {
    let table = table();
    let machine = CycleMachine {
        cycle,
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
    render_cycle_program(&MainProgramSettings::default(), &machine, &stations)
}

#[test]
fn the_demo_cycle_program_runs_every_stage_in_order_and_reads_back() {
    let text = render(&demo_cycle()).unwrap();
    // Every line is one the SINUMERIK reader accepts.
    for l in lines(&text) {
        l.statement()
            .unwrap_or_else(|e| panic!("line {}: {e:?}\n{text}", l.number));
    }
    let order = [
        "G90 G94 G71 ; absolute, feed per minute, metric",
        "M1=3 S1=1336.9 ; wheel spindle on, 35 m/s",
        "M8 ; coolant on",
        "DEMO_CAM(CL_TNO)",
        "CL_OFF=0.3500 ; stock 0.2500 mm and air gap 0.1000 mm above the curve",
        "$SA_LEAD_OFFSET_OUT_POS[X]=CL_OFF",
        "LEADON(X,C,CL_TNO)",
        "G91 G1 C=720.0000 X=-0.1000 F=10800.000 ; approach: the air gap",
        "G91 G1 C=3600.0000 X=-0.2000 F=10800.000",
        "G91 G1 C=1080.0000 X=-0.0300 F=10800.000",
        "G91 G0 X=2.0000 ; lift off",
        "FGROUP() ; the feed back to the path axes",
        "LEADOF(X,C)",
        "CAMLOOP_READY(CL_SEEN)",
        "M62 ; gauge in",
        "POS[C]=IC(1080.0000) FA[C]=3600.000",
        "M63 ; gauge out",
        "IF CL_WAIT<50 GOTOB CL_HS1",
        "CL_GO1:",
        "DEMO_CAM(CL_TNO)",
        "CL_OFF=0.1200 ; stock 0.0200 mm",
        "LEADON(X,C,CL_TNO)",
        "S1=1527.9",
        "G91 G1 C=720.0000 X=-0.0200 F=10800.000",
        "G91 G1 C=720.0000 F=10800.000",
        "G4 F=0.500",
        "G91 G0 X=2.0000 ; lift off",
        "LEADOF(X,C)",
        "$SA_LEAD_OFFSET_OUT_POS[X]=0 ; the output offset back to 0",
        "G90 G0 X=13.0000 ; retract clear of the part",
        "M9 ; coolant off",
        "M1=5 ; wheel spindle stop",
        "M30",
    ];
    let mut from = 0;
    for want in order {
        let at = text[from..]
            .find(want)
            .unwrap_or_else(|| panic!("`{want}` missing after byte {from}:\n{text}"));
        from += at + want.len();
    }
    // 35 m/s on a 250 mm wheel: 35 / (2π · 0.25) · 60 = 1336.9 rpm.
    assert!((wheel_rpm(35.0, 250.0) - 1336.90).abs() < 0.01);
}

/// The program does not end 2 mm off the part after the lift-off: once uncoupled, X goes
/// back to the clear X by an absolute rapid move, and the ending check finds it there and
/// would refuse the text without it.
#[test]
fn the_cycle_program_ends_retracted_to_the_clear_x() {
    let text = render(&demo_cycle()).unwrap();
    check_ending(&text, "X", 13.0).unwrap();
    let tail: Vec<&str> = text.lines().rev().take(4).collect();
    assert_eq!(
        tail,
        [
            "M30",
            "M1=5 ; wheel spindle stop",
            "M9 ; coolant off",
            "G90 G0 X=13.0000 ; retract clear of the part",
        ]
    );
    // Without any retract to the clear X (the uncouplings' included).
    let unretracted: String = text
        .lines()
        .filter(|l| !l.starts_with("G90 G0 X=13.0000"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(matches!(
        check_ending(&unretracted, "X", 13.0),
        Err(EndingError::NotRetracted { .. })
    ));
}

#[test]
fn a_stage_on_the_plan_without_the_features_plan_is_refused_naming_both() {
    let mut cycle = demo_cycle();
    cycle.stages[3].speed_plan = true;
    let err = render(&cycle).unwrap_err();
    assert_eq!(
        err.to_string(),
        "cycle.stages[3] (finish): on the speed plan, but feature IN1 has no plan tables"
    );
}

/// One feature: no resume (as the one-feature main program); the R parameter is read only
/// by a program of several features.
#[test]
fn a_one_feature_cycle_program_has_no_resume() {
    let text = render(&demo_cycle()).unwrap();
    assert!(
        !text.contains("R90") && !text.contains("CAMLOOP_RESUME"),
        "{text}"
    );
}

#[test]
fn an_unsound_cycle_writes_no_program() {
    let mut cycle = demo_cycle();
    cycle.stock_mm = 0.3;
    let err = render(&cycle).unwrap_err();
    assert!(
        err.to_string().contains("cycle.stock_mm is 0.3000 mm"),
        "{err}"
    );
}

#[test]
fn the_ready_program_returns_its_count() {
    let text = render_ready_program(7);
    assert!(text.starts_with("%_N_CAMLOOP_READY_SPF\n;$PATH=/_N_SPF_DIR\n"));
    assert!(text.contains("PROC CAMLOOP_READY(VAR INT CL_READY) SAVE\n"));
    assert!(text.contains("\nCL_READY=7\nRET\n"));
}

/// A feature's plan must be its own table program over the cycle's axes, at a real speed:
/// each fault is refused naming the feature, and nothing is written.
#[test]
fn a_plan_that_does_not_fit_its_feature_is_refused_naming_it() {
    use camloop_core::program::CyclePlan;
    use camloop_core::speed_plan::render::VaProgramSettings;
    let mut cycle = demo_cycle();
    cycle.stages[3].speed_plan = true;
    let table = table();
    let machine = CycleMachine {
        cycle: &cycle,
        c_speed_rpm: 30.0,
        wheel_radius_mm: 250.0,
        clear_x_mm: 13.0,
    };
    let refused = |plan: VaProgramSettings, va_speed_rpm: f64| {
        let stations = [CycleStation {
            table: &table,
            label: "IN1",
            z_mm: 20.0,
            plan: Some(CyclePlan {
                table: &plan,
                va_speed_rpm,
            }),
        }];
        render_cycle_program(&MainProgramSettings::default(), &machine, &stations)
            .unwrap_err()
            .to_string()
    };
    let own = || VaProgramSettings {
        name: "DEMO_CAM_P".into(),
        ..VaProgramSettings::default()
    };
    let same_name = refused(
        VaProgramSettings {
            name: "DEMO_CAM".into(),
            ..own()
        },
        50.0,
    );
    assert!(
        same_name.contains("feature IN1: the plan's table program DEMO_CAM must differ"),
        "{same_name}"
    );
    let other_axis = refused(
        VaProgramSettings {
            x_axis: "X2".into(),
            ..own()
        },
        50.0,
    );
    assert!(
        other_axis.contains("feature IN1: the plan couples X2 and C to VA"),
        "{other_axis}"
    );
    let no_speed = refused(own(), f64::NAN);
    assert!(
        no_speed.contains("feature IN1: virtual axis speed NaN rpm"),
        "{no_speed}"
    );
}
