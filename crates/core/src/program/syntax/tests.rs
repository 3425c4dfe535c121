//! The reader against the statements camloop writes, and its errors' lines and columns.

use super::*;

fn one(code: &str) -> Statement<'_> {
    Line::new(1, code).statement().unwrap().unwrap()
}

fn error(code: &str) -> String {
    Line::new(3, code).statement().unwrap_err().to_string()
}

#[test]
fn the_main_programs_statements_are_read() {
    assert_eq!(
        one("%_N_CAMLOOP_GRIND_MPF"),
        Statement::Header {
            name: "CAMLOOP_GRIND",
            kind: "MPF"
        }
    );
    assert_eq!(
        one("DEF REAL CL_C, CL_X"),
        Statement::Def {
            kind: "REAL",
            names: vec!["CL_C", "CL_X"]
        }
    );
    let var_int = Param {
        by_reference: true,
        kind: "INT",
        name: None,
    };
    assert_eq!(
        one("EXTERN T(VAR INT, VAR INT)"),
        Statement::Extern {
            name: "T",
            params: vec![var_int.clone(), var_int]
        }
    );
    assert_eq!(
        one("PROC T(VAR INT CL_TNO) SAVE"),
        Statement::Proc {
            name: "T",
            params: vec![Param {
                by_reference: true,
                kind: "INT",
                name: Some("CL_TNO")
            }],
            save: true
        }
    );
    let Statement::If { cond, goto: None } = one("IF $AA_COUP_ACT[X]<>0 ; aborted") else {
        panic!("IF")
    };
    assert_eq!(
        (cond.left, cond.op, cond.right),
        (Expr::Indexed("$AA_COUP_ACT", "X"), "<>", Expr::Num(0.0))
    );
    assert_eq!(
        one("CL_X=CTAB(CL_C,CL_TNO,CL_SLOPE)"),
        Statement::Assign {
            target: "CL_X",
            value: Expr::Call(
                "CTAB",
                vec![
                    Expr::Var("CL_C"),
                    Expr::Var("CL_TNO"),
                    Expr::Var("CL_SLOPE")
                ]
            )
        }
    );
    assert_eq!(
        one("LEADOF(X,C)"),
        Statement::Call {
            name: "LEADOF",
            args: vec![Expr::Var("X"), Expr::Var("C")]
        }
    );
    assert_eq!(one("STOPRE"), Statement::Keyword("STOPRE"));
    assert_eq!(one("G90"), Statement::Block(vec![Word::Code("G90")]));
    assert_eq!(one("LOOP_1:"), Statement::Label("LOOP_1"));
}

#[test]
fn blocks_are_read_word_by_word() {
    let Statement::Block(words) = one("POS[C]=IC(1080.0000) FA[C]=10800.000") else {
        panic!("block")
    };
    assert_eq!(
        words,
        [
            Word::Set {
                address: "POS",
                index: Some("C"),
                value: Expr::Call("IC", vec![Expr::Num(1080.0)])
            },
            Word::Set {
                address: "FA",
                index: Some("C"),
                value: Expr::Num(10800.0)
            }
        ]
    );
    let Statement::Block(words) = one("PO[C]=(20.0) PO[X]=(1.5,-0.25,0.125)") else {
        panic!("block")
    };
    let lists: Vec<Vec<f64>> = words
        .iter()
        .map(|w| match w {
            Word::Set { value, .. } => value.numbers().unwrap(),
            Word::Code(_) => Vec::new(),
        })
        .collect();
    assert_eq!(lists, [vec![20.0], vec![1.5, -0.25, 0.125]]);
    let Statement::Block(words) = one("G41 G1 X=CL_U*2+(-1) F100.0") else {
        panic!("block")
    };
    assert!(words[0].is_g_code() && words[1].is_g_code());
    assert_eq!(words[3], Word::Code("F100.0"));
    let Word::Set { value, .. } = &words[2] else {
        panic!("X=")
    };
    // `*` binds tighter than `+`.
    assert!(matches!(value, Expr::Binary('+', l, _) if matches!(**l, Expr::Binary('*', ..))));
}

#[test]
fn loops_and_ctabdef_are_read() {
    let Statement::If {
        cond,
        goto: Some(goto),
    } = one("IF CL_U<3 GOTOB LOOP_1")
    else {
        panic!("IF … GOTOB")
    };
    assert_eq!((cond.op, goto), ("<", ("GOTOB", "LOOP_1")));
    assert!(cond.holds(2.0, 3.0) && !cond.holds(3.0, 3.0));
    assert_eq!(
        parse_ctabdef("CTABDEF(X,C,17,1,\"DRAM\") ; memory", 9).unwrap(),
        CtabDef {
            following: "X".into(),
            leading: "C".into(),
            number: 17,
            periodicity: "1".into()
        }
    );
}

#[test]
fn errors_name_line_and_column() {
    assert_eq!(
        error("CTABDEF(X,C,1.5,1)"),
        "line 3, column 13: the table number is not a whole number"
    );
    assert_eq!(
        error("  LEADON(X,C"),
        "line 3, column 13: expected `,` or `)`"
    );
    assert_eq!(error("G1 X=1 POS[C]"), "line 3, column 14: expected `=`");
    assert_eq!(
        error("IF CL_U GOTOB L"),
        "line 3, column 9: expected a comparison"
    );
    assert_eq!(error("X=(1,"), "line 3, column 6: expected a value");
    assert_eq!(
        parse_ctabdef("LEADOF(X,C)", 4).unwrap_err().to_string(),
        "line 4, column 1: `LEADOF(X,C)` is not CTABDEF(…)"
    );
}
