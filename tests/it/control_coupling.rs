//! The simulated control runs the main program as the control would, across ten table
//! versions delivered to a real folder: the table it couples must always be the newest. The
//! same sequence with the old literal-number main program couples stale tables, which proves
//! the check can tell the two apart. Plus the control's alarms and strictness.

use camloop::core::fit::fit_poly;
use camloop::core::program::{
    MainProgramSettings, ProgramSettings, next_table_number, parse_table_program, render_g1_table,
    render_main_program, render_poly_table,
};
use camloop::core::table::TablePoint;
use camloop::sim::{Control, ControlError, ControlFault, Coupled, TableShape, table_shape};
use std::path::Path;

const TABLE: &str = "DEMO_CAM_TABLE";
const MAIN: &str = "CAMLOOP_GRIND";

/// One period of an analytic profile, 10° apart, with a constant correction per version so
/// that every version's X differs visibly (10 µm per version).
fn points(version: u32) -> Vec<TablePoint> {
    (0..36)
        .map(|i| {
            let c_deg = 10.0 * f64::from(i);
            let x_mm = 3.0 + 2.5 * c_deg.to_radians().cos() + 0.01 * f64::from(version);
            TablePoint {
                c_deg,
                d_mm: 250.0 + x_mm,
                x_mm,
            }
        })
        .collect()
}

fn settings(number: u32) -> ProgramSettings {
    ProgramSettings {
        name: TABLE.to_owned(),
        table_number: number,
        ..ProgramSettings::default()
    }
}

/// Version `version` as the core renders it: G1 for odd versions, POLY for even ones.
fn table_program(version: u32, number: u32) -> String {
    let pts = points(version);
    if version % 2 == 1 {
        render_g1_table(&pts, &settings(number)).unwrap()
    } else {
        render_poly_table(&fit_poly(&pts), &settings(number)).unwrap()
    }
}

fn main_program() -> String {
    let main = MainProgramSettings::default();
    assert_eq!(main.name, MAIN);
    render_main_program(&main, &settings(1)).unwrap()
}

/// Today's main-program fragment before the fix, kept literally: the table number written
/// in, the table called without a parameter.
const LITERAL_MAIN: &str = "%_N_CAMLOOP_GRIND_MPF
;$PATH=/_N_MPF_DIR
DEF REAL CL_C, CL_X, CL_SLOPE
DEMO_CAM_TABLE ; defines curve table 2
STOPRE ; read the actual C position below
CL_C=$AA_IW[C]
CL_X=CTAB(CL_C,2,CL_SLOPE) ; X on the curve at the current C
G90 G1 X=CL_X F=100.000
LEADON(X,C,2)
POS[C]=IC(1080.0000) FA[C]=3600.000 ; 3 rev at 10 rpm
WAITP(C)
LEADOF(X,C)
M30
";

/// The table program as it was before the fix: no parameter, no number assignment.
fn literal_table(text: &str) -> String {
    text.lines()
        .filter(|l| !l.starts_with("CL_TNO="))
        .map(|l| {
            if l.starts_with("PROC ") {
                format!("PROC {TABLE}")
            } else {
                l.to_owned()
            }
        })
        .map(|l| l + "\n")
        .collect()
}

/// The shape the rendered text defines, as the grinder would run it.
fn rendered_shape(text: &str) -> TableShape {
    table_shape(&parse_table_program(text).unwrap().shape)
}

fn x_at_zero(shape: &TableShape) -> f64 {
    match shape {
        TableShape::G1(points) => points[0].x_mm,
        TableShape::Poly(segments) => segments[0].x0_mm,
    }
}

/// Delivers each version's table into `dir` (overwriting the same file, as the share does)
/// and runs `main` from `dir` on one control; returns each version's number, rendered shape
/// and the run's outcome.
fn deliver_and_run(
    dir: &Path,
    main: &str,
    adapt: impl Fn(&str) -> String,
) -> Vec<(u32, TableShape, Result<Coupled, ControlError>)> {
    std::fs::write(dir.join(format!("{MAIN}.MPF")), main).unwrap();
    let load = |name: &str| std::fs::read_to_string(dir.join(format!("{name}.SPF"))).ok();
    let mut control = Control::new();
    let mut current = 0;
    let mut outcomes = Vec::new();
    for version in 1..=10 {
        let number = next_table_number(current, (1, 2));
        let text = table_program(version, number);
        std::fs::write(dir.join(format!("{TABLE}.SPF")), adapt(&text)).unwrap();
        let main_text = std::fs::read_to_string(dir.join(format!("{MAIN}.MPF"))).unwrap();
        outcomes.push((
            number,
            rendered_shape(&text),
            control.run(&main_text, &load),
        ));
        current = number;
    }
    assert_eq!(control.defined_tables(), [1, 2]);
    outcomes
}

#[test]
fn ten_versions_each_couple_the_newest_table() {
    let dir = tempfile::tempdir().unwrap();
    let outcomes = deliver_and_run(dir.path(), &main_program(), str::to_owned);
    let mut previous_x = f64::NAN;
    for (i, (number, shape, outcome)) in outcomes.into_iter().enumerate() {
        let version = i + 1;
        let coupled = outcome.unwrap_or_else(|e| panic!("version {version}: {e}"));
        assert_eq!(coupled.table_number, number, "version {version}");
        assert_eq!(coupled.shape, shape, "version {version}");
        // The version's own correction: X at C = 0 is 5.5 mm + 10 µm per version.
        let x0 = x_at_zero(&coupled.shape);
        assert!(
            (x0 - (5.5 + 0.01 * version as f64)).abs() < 1e-9,
            "version {version}: {x0}"
        );
        assert!((x0 - previous_x).abs() > 0.009 || version == 1);
        previous_x = x0;
        assert!((coupled.revolutions - 3.0).abs() < 1e-12);
        assert!((coupled.c_speed_rpm - 10.0).abs() < 1e-12);
    }
}

#[test]
fn the_literal_number_main_program_couples_stale_tables() {
    let dir = tempfile::tempdir().unwrap();
    let outcomes = deliver_and_run(dir.path(), LITERAL_MAIN, literal_table);
    let mut previous: Option<TableShape> = None;
    let mut wrong = 0;
    for (i, (number, shape, outcome)) in outcomes.into_iter().enumerate() {
        let version = i + 1;
        match (number, outcome) {
            // The literal number happens to be the one just defined.
            (2, Ok(coupled)) => assert_eq!(coupled.shape, shape, "version {version}"),
            // The first table 1: table 2 was never defined.
            (1, Err(e)) if version == 1 => {
                assert_eq!(e.fault, ControlFault::UndefinedTable { number: 2 });
                assert!(e.fault.is_alarm());
                wrong += 1;
            }
            // Every later table 1: the previous version's table 2 is ground.
            (1, Ok(coupled)) => {
                assert_eq!(coupled.table_number, 2, "version {version}");
                assert_ne!(coupled.shape, shape, "version {version}");
                assert_eq!(Some(&coupled.shape), previous.as_ref(), "version {version}");
                wrong += 1;
            }
            (n, other) => panic!("version {version}, table {n}: {other:?}"),
        }
        previous = Some(shape);
    }
    assert_eq!(wrong, 5, "every version that switched to table 1");
}

/// Runs `main` with `TABLE` resolved to `table`.
fn run_with(control: &mut Control, main: &str, table: &str) -> Result<Coupled, ControlError> {
    control.run(main, &|name: &str| {
        (name == TABLE).then(|| table.to_owned())
    })
}

#[test]
fn leadon_on_an_undefined_table_is_an_alarm() {
    let main = "%_N_T_MPF\nDEF INT N\nN=7\nLEADON(X,C,N)\nM30\n";
    let err = run_with(&mut Control::new(), main, "").unwrap_err();
    assert_eq!(
        (err.program.as_str(), err.line, &err.fault),
        ("T", 4, &ControlFault::UndefinedTable { number: 7 })
    );
    assert!(err.fault.is_alarm());
    assert_eq!(
        err.to_string(),
        "T line 4: alarm: curve table 7 is not defined"
    );
}

#[test]
fn redefining_the_coupled_table_is_an_alarm_and_an_aborted_coupling_is_released() {
    let table = table_program(1, 1);
    // Couple, then call the table program again while coupled: an aborted run.
    let aborted = format!(
        "%_N_T_MPF\nDEF INT CL_TNO\nEXTERN {TABLE}(VAR INT)\n{TABLE}(CL_TNO)\n\
         LEADON(X,C,CL_TNO)\n{TABLE}(CL_TNO)\nM30\n"
    );
    let mut control = Control::new();
    let err = run_with(&mut control, &aborted, &table).unwrap_err();
    let ctabdef_line = table
        .lines()
        .position(|l| l.starts_with("CTABDEF("))
        .unwrap()
        + 1;
    assert_eq!(
        (err.program.as_str(), err.line, &err.fault),
        (TABLE, ctabdef_line, &ControlFault::TableInUse { number: 1 })
    );
    assert!(err.fault.is_alarm());
    // The coupling is still active; the main program releases it before redefining.
    let coupled = run_with(&mut control, &main_program(), &table).unwrap();
    assert_eq!(coupled.table_number, 1);
    assert_eq!(coupled.shape, rendered_shape(&table));
    // Without the release, the same program fails at the redefinition.
    let mut control = Control::new();
    let _ = run_with(&mut control, &aborted, &table);
    let main = main_program();
    let lines: Vec<&str> = main.lines().collect();
    let at = lines.iter().position(|l| l.starts_with("IF ")).unwrap();
    assert_eq!((lines[at + 1], lines[at + 2]), ("LEADOF(X,C)", "ENDIF"));
    let skip_if: String = lines
        .iter()
        .enumerate()
        .filter(|(i, _)| !(at..at + 3).contains(i))
        .map(|(_, l)| format!("{l}\n"))
        .collect();
    let err = run_with(&mut control, &skip_if, &table).unwrap_err();
    assert_eq!(err.fault, ControlFault::TableInUse { number: 1 });
}

#[test]
fn an_unknown_statement_is_an_error_naming_program_and_line() {
    let main = "%_N_T_MPF\n;$PATH=/_N_MPF_DIR\nDEF REAL A\nM3 S1000 ; spindle on\nM30\n";
    let err = run_with(&mut Control::new(), main, "").unwrap_err();
    assert_eq!((err.program.as_str(), err.line), ("T", 4));
    assert!(!err.fault.is_alarm());
    assert_eq!(
        err.to_string(),
        "T line 4: `M3 S1000` is not in the subset camloop writes"
    );
    // A keyword out of place is a statement outside the subset, not a program to look up.
    let err = run_with(&mut Control::new(), "%_N_T_MPF\nCTABEND\nM30\n", "").unwrap_err();
    assert_eq!(
        err.to_string(),
        "T line 2: `CTABEND` is not in the subset camloop writes"
    );
    // Inside the table program, the error names the table program and its line.
    let table = table_program(1, 1).replace("G90 G71", "G91 G71");
    let err = run_with(&mut Control::new(), &main_program(), &table).unwrap_err();
    let line = table.lines().position(|l| l.starts_with("G91")).unwrap() + 1;
    assert_eq!((err.program.as_str(), err.line), (TABLE, line));
    assert!(matches!(err.fault, ControlFault::Unsupported { .. }));
}

#[test]
fn a_missing_program_or_a_table_that_goes_backwards_is_refused() {
    let err = Control::new()
        .run(&main_program(), &|_: &str| None)
        .unwrap_err();
    assert_eq!(
        err.fault,
        ControlFault::ProgramNotFound {
            name: TABLE.to_owned()
        }
    );
    let table = table_program(1, 1).replace("C=20.0000 X=", "C=5.0000 X=");
    let err = run_with(&mut Control::new(), &main_program(), &table).unwrap_err();
    assert_eq!(
        err.fault,
        ControlFault::LeadingNotIncreasing {
            number: 1,
            c_deg: 5.0
        }
    );
}
