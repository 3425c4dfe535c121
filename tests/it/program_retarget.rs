//! Provenance in table programs, and retargeting a kept program to the other table number
//! (rollback): the result is the program the renderer would write for that number, and the
//! simulated control couples it.

use camloop::core::program::{
    MainProgramSettings, ProgramSettings, Provenance, RetargetError, parse_table_program,
    render_g1_table, render_main_program, retarget_table_program,
};
use camloop::core::table::TablePoint;
use camloop::sim::{Control, table_shape};

fn points() -> Vec<TablePoint> {
    (0..12)
        .map(|i| {
            let c_deg = 30.0 * f64::from(i);
            let x_mm = 3.0 + 2.5 * c_deg.to_radians().cos();
            TablePoint {
                c_deg,
                d_mm: 0.0,
                x_mm,
            }
        })
        .collect()
}

fn provenance(version: u64, parent: Option<u64>) -> Provenance {
    Provenance {
        camloop_version: "0.1.0".to_owned(),
        table_version: version,
        parent_version: parent,
        created_utc: "2026-11-23T14:05:00Z".to_owned(),
        recipe: "demo-cam".to_owned(),
        feature: "intake".parse().unwrap(),
        correction_sha256: "9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08"
            .parse()
            .unwrap(),
    }
}

fn settings(number: u32, provenance: Option<Provenance>) -> ProgramSettings {
    ProgramSettings {
        name: "DEMO_CAM_TABLE".to_owned(),
        table_number: number,
        c_offset_deg: 12.5,
        comment_lines: vec!["reason: learned from part 41".to_owned()],
        provenance,
        ..ProgramSettings::default()
    }
}

fn render(number: u32, provenance: Option<Provenance>) -> String {
    render_g1_table(&points(), &settings(number, provenance)).unwrap()
}

#[test]
fn provenance_golden() {
    let program = render(2, Some(provenance(7, Some(6))));
    insta::assert_snapshot!(program);
    let lines: Vec<&str> = program.lines().collect();
    assert_eq!(lines[2], "PROC DEMO_CAM_TABLE(VAR INT CL_TNO) SAVE");
    assert_eq!(lines[3], "; camloop version: 0.1.0");
    assert_eq!(lines[5], "; parent version: v6");
    // The first version has no parent.
    let first = render(1, Some(provenance(1, None)));
    assert!(first.contains("\n; parent version: none\n"), "{first}");
}

#[test]
fn provenance_text_is_made_safe_for_a_comment() {
    let mut p = provenance(3, Some(2));
    // `°` is spelled out; the line break has no spelling and becomes `?`. (The feature's
    // name is a `FeatureName`: plain by its type, it has no such characters to carry.)
    p.recipe = "Nocken; °1\nCTABDEF(X,C,9,1)".to_owned();
    let program = render(1, Some(p));
    assert!(
        program.contains("\n; recipe: Nocken;  deg1?CTABDEF(X,C,9,1)\n"),
        "{program}"
    );
    // The line break became `?`: no block was injected, and the program is plain ASCII.
    assert_eq!(
        program
            .lines()
            .filter(|l| l.starts_with("CTABDEF("))
            .count(),
        1
    );
    assert!(
        program
            .chars()
            .all(|c| c == '\n' || (' '..='~').contains(&c))
    );
    // A `;` inside a comment stays a comment, and the table reads back unchanged.
    assert_eq!(parse_table_program(&program).unwrap().table_number, 1);
}

#[test]
fn retarget_gives_the_program_the_renderer_writes_for_the_other_number() {
    let old = render(1, Some(provenance(4, Some(3))));
    // Rollback to version 4 as version 9, under table 2.
    let new = provenance(9, Some(4));
    assert_eq!(
        retarget_table_program(&old, 2, Some(&new)).unwrap(),
        render(2, Some(new))
    );
    // Without a new provenance the old block is kept.
    assert_eq!(
        retarget_table_program(&old, 2, None).unwrap(),
        render(2, Some(provenance(4, Some(3))))
    );
    // A program written without provenance gets one after PROC.
    let bare = render(1, None);
    assert_eq!(
        retarget_table_program(&bare, 2, Some(&provenance(5, Some(1)))).unwrap(),
        render(2, Some(provenance(5, Some(1))))
    );
    // Retargeting to the same number with no provenance changes nothing.
    assert_eq!(retarget_table_program(&old, 1, None).unwrap(), old);
}

#[test]
fn the_control_couples_a_retargeted_program() {
    let table = retarget_table_program(&render(1, None), 2, None).unwrap();
    let main = render_main_program(&MainProgramSettings::default(), &settings(1, None)).unwrap();
    let mut control = Control::new();
    let coupled = control
        .run(&main, &|name: &str| {
            (name == "DEMO_CAM_TABLE").then(|| table.clone())
        })
        .unwrap();
    assert_eq!(coupled.table_number, 2);
    assert_eq!(
        coupled.shape,
        table_shape(&parse_table_program(&render(2, None)).unwrap().shape)
    );
    assert_eq!(control.defined_tables(), [2]);
}

#[test]
fn retarget_refuses_programs_that_would_couple_the_wrong_table() {
    let old = render(1, None);
    let line_of = |prefix: &str| old.lines().position(|l| l.starts_with(prefix)).unwrap() + 1;
    let (assignment_line, ctabdef_line) = (line_of("CL_TNO="), line_of("CTABDEF("));
    assert_eq!(
        retarget_table_program(&old, 0, None),
        Err(RetargetError::NumberZero)
    );
    let without_assignment: String = old
        .lines()
        .filter(|l| !l.starts_with("CL_TNO="))
        .map(|l| format!("{l}\n"))
        .collect();
    assert_eq!(
        retarget_table_program(&without_assignment, 2, None),
        Err(RetargetError::NoAssignment)
    );
    let without_ctabdef = old.replace("CTABDEF(X,C,1,1)\n", "");
    assert_eq!(
        retarget_table_program(&without_ctabdef, 2, None),
        Err(RetargetError::NoCtabdef)
    );
    let disagree = old.replace("CL_TNO=1 ", "CL_TNO=3 ");
    let err = retarget_table_program(&disagree, 2, None).unwrap_err();
    assert_eq!(
        err,
        RetargetError::Disagree {
            assignment_line,
            assigned: 3,
            ctabdef_line,
            defined: 1
        }
    );
    assert_eq!(
        err.to_string(),
        format!(
            "line {assignment_line} assigns CL_TNO=3 but line {ctabdef_line} defines table 1: the caller would couple the wrong table"
        )
    );
    let twice = old.replace("CTABDEF(X,C,1,1)\n", "CTABDEF(X,C,1,1)\nCTABDEF(X,C,1,1)\n");
    assert_eq!(
        retarget_table_program(&twice, 2, None),
        Err(RetargetError::Repeated {
            what: "CTABDEF",
            line: ctabdef_line + 1,
            first_line: ctabdef_line
        })
    );
    let bad = old.replace("CL_TNO=1 ", "CL_TNO=N ");
    assert!(matches!(
        retarget_table_program(&bad, 2, None),
        Err(RetargetError::BadNumber { line, .. }) if line == assignment_line
    ));
}
