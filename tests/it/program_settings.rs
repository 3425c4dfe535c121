//! Program settings: name and axis rules, validation, configuration parsing, table
//! numbering and the main-program fragment.

use camloop::core::program::{
    AxisNameError, CDirection, MainProgramSettings, ProgramNameError, ProgramSettings,
    SettingError, TableMemory, TablePairError, check_table_pair, next_table_number,
    render_main_program, validate_axis_name, validate_program_name,
};

#[test]
fn program_name_rules() {
    use ProgramNameError as E;
    let s = |v: &str| v.to_owned();
    let cases: Vec<(&str, Result<String, ProgramNameError>)> = vec![
        ("cam_lobe1", Ok(s("CAM_LOBE1"))),
        // The notes suggest `U_` for user cycles, but the two-letter rule as quoted refuses it;
        // we keep the stricter reading (see `validate_program_name`).
        (
            "U_CAMTABLE",
            Err(E::FirstTwoNotLetters {
                name: s("U_CAMTABLE"),
            }),
        ),
        ("AB", Ok(s("AB"))),
        // 24 characters is the limit.
        (
            "ABCDEFGHIJKLMNOPQRSTUVWX",
            Ok(s("ABCDEFGHIJKLMNOPQRSTUVWX")),
        ),
        ("", Err(E::Empty)),
        (
            "ABCDEFGHIJKLMNOPQRSTUVWXY",
            Err(E::TooLong {
                name: s("ABCDEFGHIJKLMNOPQRSTUVWXY"),
                chars: 25,
            }),
        ),
        (
            "CAM-1",
            Err(E::BadCharacter {
                name: s("CAM-1"),
                ch: '-',
                position: 4,
            }),
        ),
        (
            "CAM 1",
            Err(E::BadCharacter {
                name: s("CAM 1"),
                ch: ' ',
                position: 4,
            }),
        ),
        (
            "NOCKE_Ä",
            Err(E::BadCharacter {
                name: s("NOCKE_Ä"),
                ch: 'Ä',
                position: 7,
            }),
        ),
        // `_` + letter would be a valid start, but `_` is a reserved prefix: refused.
        ("_CAM", Err(E::LeadingUnderscore { name: s("_CAM") })),
        (
            "CYCLE800X",
            Err(E::ReservedPrefix {
                name: s("CYCLE800X"),
                prefix: "CYCLE",
            }),
        ),
        (
            "cycle_cam",
            Err(E::ReservedPrefix {
                name: s("cycle_cam"),
                prefix: "CYCLE",
            }),
        ),
        (
            "CUST_CAM",
            Err(E::ReservedPrefix {
                name: s("CUST_CAM"),
                prefix: "CUST_",
            }),
        ),
        (
            "group_a",
            Err(E::ReservedPrefix {
                name: s("group_a"),
                prefix: "GROUP_",
            }),
        ),
        (
            "S_TABLE",
            Err(E::ReservedPrefix {
                name: s("S_TABLE"),
                prefix: "S_",
            }),
        ),
        (
            "e_table",
            Err(E::ReservedPrefix {
                name: s("e_table"),
                prefix: "E_",
            }),
        ),
        (
            "F_TABLE",
            Err(E::ReservedPrefix {
                name: s("F_TABLE"),
                prefix: "F_",
            }),
        ),
        ("A1CAM", Err(E::FirstTwoNotLetters { name: s("A1CAM") })),
        ("1CAM", Err(E::FirstTwoNotLetters { name: s("1CAM") })),
        ("A", Err(E::FirstTwoNotLetters { name: s("A") })),
        ("X_", Err(E::FirstTwoNotLetters { name: s("X_") })),
        // CYCLE without anything after it is still the reserved prefix.
        (
            "CYCLE",
            Err(E::ReservedPrefix {
                name: s("CYCLE"),
                prefix: "CYCLE",
            }),
        ),
        // Not a reserved prefix: CUST without `_`.
        ("CUSTOM", Ok(s("CUSTOM"))),
    ];
    for (name, expected) in cases {
        assert_eq!(validate_program_name(name), expected, "name {name:?}");
    }
}

#[test]
fn reserved_device_names_are_refused_whatever_the_case() {
    let refused = ["con", "PRN", "Aux", "NUL", "COM1", "com9", "LPT1", "lpt9"];
    for name in refused {
        assert_eq!(
            validate_program_name(name),
            Err(ProgramNameError::ReservedDeviceName {
                name: name.to_owned()
            }),
            "name {name:?}"
        );
    }
    // Only the exact device names: COM0, COM10 and longer names are ordinary names.
    for name in ["COM0", "COM10", "LPT", "CONE", "NUL_TABLE", "AUX2"] {
        assert_eq!(validate_program_name(name), Ok(name.to_owned()), "{name}");
    }
}

#[test]
fn program_name_messages_say_which_rule_failed() {
    let msg = |n: &str| validate_program_name(n).unwrap_err().to_string();
    assert_eq!(
        msg("_CAM"),
        "program name `_CAM` starts with `_`: the prefix `_` is reserved by Siemens, although `_` + letter would otherwise be a valid start"
    );
    assert_eq!(
        msg("CAM.1"),
        "program name `CAM.1` has `.` at position 4: only letters A-Z, digits and `_` are allowed"
    );
    assert_eq!(msg("A1"), "program name `A1` must start with two letters");
    assert_eq!(
        msg("lpt3"),
        "program name `lpt3` is a reserved device name (CON, PRN, AUX, NUL, COM1-COM9, LPT1-LPT9)"
    );
    assert_eq!(
        msg("ABCDEFGHIJKLMNOPQRSTUVWXYZ"),
        "program name `ABCDEFGHIJKLMNOPQRSTUVWXYZ` has 26 characters: at most 24 are allowed"
    );
}

#[test]
fn axis_name_rules() {
    use AxisNameError as E;
    let s = |v: &str| v.to_owned();
    assert_eq!(validate_axis_name("leading", "c"), Ok(s("C")));
    assert_eq!(validate_axis_name("leading", "C1"), Ok(s("C1")));
    assert_eq!(validate_axis_name("following", "XA2"), Ok(s("XA2")));
    assert_eq!(
        validate_axis_name("following", ""),
        Err(E::Empty { role: "following" })
    );
    assert_eq!(
        validate_axis_name("following", "1X"),
        Err(E::BadStart {
            role: "following",
            name: s("1X")
        })
    );
    assert_eq!(
        validate_axis_name("leading", "C_1"),
        Err(E::BadCharacter {
            role: "leading",
            name: s("C_1"),
            ch: '_',
            position: 2
        })
    );
    assert_eq!(
        validate_axis_name("leading", "f"),
        Err(E::FixedAddress {
            role: "leading",
            name: s("f")
        })
    );
    // A fixed address letter with an extension is an ordinary axis name.
    assert_eq!(validate_axis_name("leading", "S1"), Ok(s("S1")));
    // At most 8 characters.
    assert_eq!(validate_axis_name("leading", "CSPINDLE"), Ok(s("CSPINDLE")));
    assert_eq!(
        validate_axis_name("leading", "CSPINDLE1"),
        Err(E::TooLong {
            role: "leading",
            name: s("CSPINDLE1"),
            chars: 9
        })
    );
    assert_eq!(
        validate_axis_name("following", "WHEELHEAD")
            .unwrap_err()
            .to_string(),
        "following axis name `WHEELHEAD` has 9 characters: at most 8 are allowed"
    );
}

#[test]
fn defaults_are_valid_and_as_documented() {
    let s = ProgramSettings::default();
    assert_eq!(s.validate(), Ok(()));
    assert_eq!(
        (s.following_axis.as_str(), s.leading_axis.as_str()),
        ("X", "C")
    );
    assert_eq!((s.table_number, s.x_decimals, s.c_decimals), (1, 4, 4));
    assert_eq!(
        (s.x_increments_per_mm, s.c_increments_per_deg),
        (10_000, 10_000)
    );
    assert_eq!(s.provenance, None);
    assert_eq!(
        (s.c_direction, s.c_offset_deg, s.x_offset_mm),
        (CDirection::Same, 0.0, 0.0)
    );
    assert_eq!(s.memory, None);
}

/// The messages of every problem `validate` finds in `s`, which it must refuse.
fn refusals(s: &ProgramSettings) -> Vec<String> {
    let problems = s.validate().expect_err("the settings are refused");
    problems.0.iter().map(|e| e.to_string()).collect()
}

#[test]
fn validation_reports_every_problem() {
    let s = ProgramSettings {
        name: "1CAM".to_owned(),
        following_axis: "X".to_owned(),
        leading_axis: "x".to_owned(),
        table_number: 0,
        x_decimals: 10,
        c_decimals: 12,
        c_offset_deg: f64::NAN,
        x_offset_mm: f64::INFINITY,
        comment_lines: vec![
            "ok".to_owned(),
            "two\nlines".to_owned(),
            "grad °".to_owned(),
        ],
        ..ProgramSettings::default()
    };
    // Compared by message: NaN in an error makes `==` on the values useless.
    let messages = refusals(&s);
    assert_eq!(
        messages,
        [
            "program name `1CAM` must start with two letters",
            "following and leading axis are both `X`",
            "table_number is 0: curve table numbers start at 1",
            "x_decimals is 10: allowed 3 to 9",
            "c_decimals is 12: allowed 0 to 9",
            "c_offset_deg is NaN: it must be a finite number",
            "x_offset_mm is inf: it must be a finite number",
            "comment line 2 has '\\n' at column 4: only printable ASCII is written into a program",
            "comment line 3 has '°' at column 6: only printable ASCII is written into a program",
        ]
    );
}

#[test]
fn decimals_finer_than_the_control_resolution_are_refused_with_the_rest() {
    let s = ProgramSettings {
        name: "CON".to_owned(),
        following_axis: "WHEELHEAD".to_owned(),
        x_decimals: 6,
        c_decimals: 4,
        c_increments_per_deg: 1000,
        ..ProgramSettings::default()
    };
    let messages = refusals(&s);
    assert_eq!(
        messages,
        [
            "program name `CON` is a reserved device name (CON, PRN, AUX, NUL, COM1-COM9, LPT1-LPT9)",
            "following axis name `WHEELHEAD` has 9 characters: at most 8 are allowed",
            "x_decimals is 6, finer than the control's resolution (x_increments_per_mm is 10000): the control would round the written values",
            "c_decimals is 4, finer than the control's resolution (c_increments_per_deg is 1000): the control would round the written values",
        ]
    );
    assert_eq!(
        s.validate().unwrap_err().0[2],
        SettingError::FinerThanResolution {
            decimals_field: "x_decimals",
            decimals: 6,
            resolution_field: "x_increments_per_mm",
            increments: 10_000
        }
    );
    // Equal to the resolution, or coarser (also with a resolution that is not a power of
    // ten), is fine.
    let fine =
        |x_decimals, x_increments_per_mm, c_decimals, c_increments_per_deg| ProgramSettings {
            x_decimals,
            x_increments_per_mm,
            c_decimals,
            c_increments_per_deg,
            ..ProgramSettings::default()
        };
    assert_eq!(fine(6, 1_000_000, 3, 1000).validate(), Ok(()));
    assert_eq!(fine(3, 2000, 0, 1).validate(), Ok(()));
    assert!(fine(4, 2000, 0, 1).validate().is_err());
    let zero = fine(4, 0, 4, 0).validate().unwrap_err();
    assert_eq!(
        zero.0,
        [
            SettingError::ResolutionZero {
                field: "x_increments_per_mm"
            },
            SettingError::ResolutionZero {
                field: "c_increments_per_deg"
            }
        ]
    );
}

#[test]
fn settings_parse_from_toml() {
    let s: ProgramSettings = toml::from_str(
        r#"
        name = "LOBE1"
        leading_axis = "C1"
        table_number = 7
        memory = "SRAM"
        x_decimals = 5
        x_increments_per_mm = 100000
        c_increments_per_deg = 1000
        c_decimals = 3
        c_direction = -1
        c_offset_deg = 12.5
        x_offset_mm = -0.1
        comment_lines = ["part: P-1"]
        "#,
    )
    .unwrap();
    assert_eq!(
        s,
        ProgramSettings {
            name: "LOBE1".to_owned(),
            leading_axis: "C1".to_owned(),
            table_number: 7,
            memory: Some(TableMemory::Sram),
            x_decimals: 5,
            x_increments_per_mm: 100_000,
            c_increments_per_deg: 1000,
            c_decimals: 3,
            c_direction: CDirection::Reversed,
            c_offset_deg: 12.5,
            x_offset_mm: -0.1,
            comment_lines: vec!["part: P-1".to_owned()],
            ..ProgramSettings::default()
        }
    );
    let empty: ProgramSettings = toml::from_str("").unwrap();
    assert_eq!(empty, ProgramSettings::default());
    let dram: ProgramSettings = toml::from_str("memory = \"dram\"").unwrap();
    assert_eq!(dram.memory, Some(TableMemory::Dram));

    let err = toml::from_str::<ProgramSettings>("c_direction = 2").unwrap_err();
    assert!(
        err.to_string()
            .contains("c_direction is 2: it must be 1 or -1"),
        "{err}"
    );
    let err = toml::from_str::<ProgramSettings>("c_offset = 1.0").unwrap_err();
    assert!(
        err.to_string().contains("unknown field `c_offset`"),
        "{err}"
    );
    // Provenance is set per version by the caller, never read from configuration.
    let err = toml::from_str::<ProgramSettings>("provenance = \"v1\"").unwrap_err();
    assert!(
        err.to_string().contains("unknown field `provenance`"),
        "{err}"
    );
    let err = toml::from_str::<ProgramSettings>("memory = \"FLASH\"").unwrap_err();
    assert!(err.to_string().contains("FLASH"), "{err}");
}

#[test]
fn next_table_number_alternates_and_never_returns_the_one_in_use() {
    assert_eq!(next_table_number(1, (1, 2)), 2);
    assert_eq!(next_table_number(2, (1, 2)), 1);
    // First run, or a leftover table outside the pair: start with the first of the pair.
    assert_eq!(next_table_number(0, (1, 2)), 1);
    assert_eq!(next_table_number(9, (11, 12)), 11);
    let mut current = 0;
    for _ in 0..10 {
        let next = next_table_number(current, (11, 12));
        assert_ne!(next, current);
        assert!(next == 11 || next == 12);
        current = next;
    }
    assert_eq!(check_table_pair((1, 2)), Ok(()));
    assert_eq!(check_table_pair((3, 3)), Err(TablePairError::Same(3, 3)));
    assert_eq!(check_table_pair((0, 3)), Err(TablePairError::Zero(0, 3)));
}

fn table_settings() -> ProgramSettings {
    ProgramSettings {
        name: "LOBE1_TABLE".to_owned(),
        table_number: 2,
        ..ProgramSettings::default()
    }
}

#[test]
fn main_program_golden() {
    let main = MainProgramSettings {
        name: "LOBE1_GRIND".to_owned(),
        revolutions: 3.0,
        c_speed_rpm: 12.5,
        x_feed_mm_min: 50.0,
        comment_lines: vec!["part: TEST-CAM lobe 1".to_owned()],
        ..MainProgramSettings::default()
    };
    let program = render_main_program(&main, &table_settings()).unwrap();
    let lines: Vec<&str> = program.lines().collect();
    assert!(
        lines[2].starts_with("DEF REAL") && lines[3] == "DEF INT CL_TNO",
        "DEF must come first after the header"
    );
    assert_eq!(lines[4], "EXTERN LOBE1_TABLE(VAR INT)");
    insta::assert_snapshot!(program);
    // The table number is not in the program: the same text for every number (0 included,
    // since it is never read), so it is delivered once.
    for table_number in [0, 1, 7] {
        let other = ProgramSettings {
            table_number,
            ..table_settings()
        };
        assert_eq!(render_main_program(&main, &other).unwrap(), program);
    }
    for literal in ["LEADON(X,C,2)", "CTAB(CL_C,2,", "table 2"] {
        assert!(!program.contains(literal), "{literal} in\n{program}");
    }
    // Multi-letter axes flow through every command.
    let multi = ProgramSettings {
        following_axis: "X1".to_owned(),
        leading_axis: "C2".to_owned(),
        ..table_settings()
    };
    let program = render_main_program(&main, &multi).unwrap();
    for expected in [
        "$AA_IW[C2]",
        "G90 G1 X1=CL_X",
        "IF $AA_COUP_ACT[X1]<>0 ;",
        "\nLEADOF(X1,C2)\nENDIF\n",
        "LEADON(X1,C2,CL_TNO)",
        "POS[C2]=IC(",
        "FA[C2]=",
        "WAITP(C2)",
        "LEADOF(X1,C2)",
    ] {
        assert!(
            program.contains(expected),
            "{expected} missing in\n{program}"
        );
    }
}

#[test]
fn main_program_settings_are_checked() {
    let main = MainProgramSettings {
        name: "lobe1_table".to_owned(),
        revolutions: 0.0,
        c_speed_rpm: -1.0,
        x_feed_mm_min: f64::NAN,
        comment_lines: vec![],
        ..MainProgramSettings::default()
    };
    let bad_table = ProgramSettings {
        x_decimals: 5,
        ..table_settings()
    };
    let messages: Vec<String> = render_main_program(&main, &bad_table)
        .unwrap_err()
        .0
        .iter()
        .map(|e| e.to_string())
        .collect();
    assert_eq!(
        messages,
        [
            "x_decimals is 5, finer than the control's resolution (x_increments_per_mm is 10000): the control would round the written values",
            "revolutions is 0: it must be greater than 0",
            "c_speed_rpm is -1: it must be greater than 0",
            "x_feed_mm_min is NaN: it must be a finite number",
        ]
    );
    // Same name as the table subprogram (names are case-insensitive).
    let err = render_main_program(&main, &table_settings()).unwrap_err();
    assert!(
        err.0.contains(&SettingError::MainSameAsTable {
            name: "LOBE1_TABLE".to_owned()
        }),
        "{err}"
    );
}
