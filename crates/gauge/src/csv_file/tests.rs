//! The CSV measurement file's tests: identity and grid, errors that name the line, revolution
//! labels, completeness.

use super::*;

fn parse(text: &str, name: &str) -> Result<RawMeasurement, String> {
    parse_measurement_csv(text, name, "drop").map_err(|e| e.to_string())
}

/// Machine, part and lobe as the file named them.
fn identity(m: &RawMeasurement) -> (&str, &str, &str) {
    let h = &m.header;
    (h.machine.as_str(), h.part.as_str(), h.lobe.as_str())
}

#[test]
fn identity_from_the_file_name_and_grid_from_the_angles() {
    let m = parse(
        "\u{feff}rev, Angle_deg ,LIFT_MM\r\n0,0,0.0\r\n0,90,1.5\r\n0,180.0000004,3\r\n\
         0,270,1.5\r\n1,0,0.01\r\n",
        "M3_P1234_L2_20240501.csv",
    )
    .expect("valid");
    assert_eq!(identity(&m), ("M3", "P1234", "L2"));
    assert_eq!((m.header.revolutions, m.header.points_per_rev), (2, 4));
    let got: Vec<(u32, u32, f64)> = m
        .samples
        .iter()
        .map(|s| (s.revolution, s.angle_index, s.lift_mm))
        .collect();
    assert_eq!(
        got,
        [
            (0, 0, 0.0),
            (0, 1, 1.5),
            (0, 2, 3.0),
            (0, 3, 1.5),
            (1, 0, 0.01)
        ]
    );
    assert_eq!(m.origin, "drop");
}

#[test]
fn metadata_comments_override_the_file_name() {
    let m = parse(
        "# machine=G7 part=X-9 lobe=pin.1\n# free text comment\n#points_per_rev=8 revolutions=3\n\
         0,45,0.5\n1,315,-0.001\n",
        "scan.csv",
    )
    .expect("valid");
    assert_eq!(identity(&m), ("G7", "X-9", "pin.1"));
    assert_eq!((m.header.revolutions, m.header.points_per_rev), (3, 8));
    assert_eq!(m.samples[1].angle_index, 7);
}

/// Each `(text, expected error)` parses to exactly that error.
fn assert_errors(cases: &[(&str, &str)]) {
    for (text, expected) in cases {
        let got = parse(text, "M3_P1_L1.csv");
        assert_eq!(got, Err((*expected).to_owned()), "{text:?}");
    }
}

#[test]
fn row_errors_name_the_line() {
    assert_errors(&[
        (
            "0,0,0\n0,1\n",
            "line 2: expected 3 fields rev,angle_deg,lift_mm, found 2",
        ),
        (
            "revolution,angle,lift\n0,0,0\n",
            "line 1: expected the header rev,angle_deg,lift_mm or a data row, found \
             \"revolution,angle,lift\"",
        ),
        (
            "0,0,0\n-1,1,0\n",
            "line 2: rev \"-1\" is not a whole number ≥ 0",
        ),
        (
            "0,360,0\n",
            "line 1: angle \"360\" is not a number in [0, 360) degrees",
        ),
        (
            "0,NaN,0\n",
            "line 1: angle \"NaN\" is not a number in [0, 360) degrees",
        ),
        (
            "0,0,inf\n",
            "line 1: lift \"inf\" is not a finite number of mm within ±1000",
        ),
        (
            "# points_per_rev=360\n0,0,0\n\n0,1.5,0\n",
            "line 4: angle 1.5° is not on the 1° grid of 360 points per revolution \
             (tolerance 0.000001°)",
        ),
        (
            "0,0,0\n0,120,0\n0,200,0\n",
            "line 3: angle 200° is not on the 120° grid of 3 points per revolution \
             (tolerance 0.000001°)",
        ),
    ]);
}

#[test]
fn revolution_marker_and_metadata_errors_name_the_line() {
    assert_errors(&[
        (
            "# revolutions=2\n5,0,0\n6,0,0\n7,0,0\n",
            "line 4: rev 7 is revolution 3 counting from rev 5, more than the 2 \
             revolutions announced",
        ),
        (
            "1,0,0\n2,0,0\n4,0,0\n",
            "revolutions jump from 2 to 4: revolution 3 is missing",
        ),
        (
            "0,0,0\n3,0,0\n",
            "revolutions jump from 0 to 3: revolutions 1 to 2 are missing",
        ),
        (
            "0,0,0\n# END\n\n0,1,0\n",
            "line 4: found \"0,1,0\" after the `# end` marker on line 2",
        ),
        (
            "# machine=M3 shift=night\n0,0,0\n",
            "line 1: metadata token \"shift=night\" is not key=value with a key among \
             machine, part, lobe, points_per_rev, revolutions, master",
        ),
        (
            "# points_per_rev=0\n",
            "line 1: metadata points_per_rev=\"0\" is invalid: a whole number in 1..=100000",
        ),
        (
            "# lobe=L1\n# lobe=L2\n",
            "line 2: metadata lobe given twice with different values",
        ),
        ("# only comments\n\n", "no data rows"),
        (
            "# machine=M3\n0,0,0\n",
            "metadata names machine but not part, lobe: give machine, part and lobe \
             together",
        ),
    ]);
    assert_eq!(
        parse("0,0,0\n", "lobe scan.csv"),
        Err(
            "machine, part and lobe unknown: add a `# machine=… part=… lobe=…` comment \
             line or name the file MACHINE_PART_LOBE[_…].csv (file name \"lobe scan.csv\")"
                .to_owned()
        )
    );
}

/// Revolution numbers are labels: a file numbered from 1 is the same measurement as one
/// numbered from 0.
#[test]
fn revolutions_numbered_from_any_start_map_to_zero_based() {
    let from_zero = parse("0,0,1\n0,180,2\n1,0,3\n1,180,4\n", "M_P_L.csv").expect("ok");
    for first in [1, 7] {
        let text = format!(
            "{a},0,1\n{a},180,2\n{b},0,3\n{b},180,4\n",
            a = first,
            b = first + 1
        );
        let m = parse(&text, "M_P_L.csv").expect("consecutive labels");
        assert_eq!(m, from_zero, "numbered from {first}");
    }
    let m = parse("# revolutions=3\n1,0,1\n2,0,2\n", "M_P_L.csv").expect("ok");
    assert_eq!(m.header.revolutions, 3);
    let revs: Vec<u32> = m.samples.iter().map(|s| s.revolution).collect();
    assert_eq!(revs, [0, 1]);
}

fn completeness(text: &str) -> Completeness {
    let mut parser = CsvParser::new();
    for line in text.split_inclusive('\n') {
        parser.push_line(line).expect("valid line");
    }
    parser.finish("M_P_L.csv", "t").expect("valid").completeness
}

#[test]
fn completeness_from_the_end_marker_or_the_declared_count() {
    let two_of_three = "# revolutions=3 points_per_rev=2\n1,0,0\n1,180,0\n2,0,0\n2,180,0\n";
    let c = completeness(two_of_three);
    assert_eq!(
        (c.revolutions_found, c.readings_found, c.readings_expected),
        (2, 4, 6)
    );
    assert!(!c.is_complete());
    let c = completeness(&format!("{two_of_three}3,0,0\n"));
    assert!(!c.is_complete(), "one angle of the last revolution missing");
    let c = completeness(&format!("{two_of_three}3,180,0\n3,0,0\n"));
    assert!(c.declared_count_met() && c.is_complete());
    // The last line may be cut short while the writer is at work.
    let c = completeness(&format!("{two_of_three}3,180,0\n3,0,0.12"));
    assert!(c.declared_count_met() && !c.last_line_ended && !c.is_complete());
    // A repeated reading does not stand in for a missing one.
    let c = completeness(&format!("{two_of_three}3,0,0\n3,0,0.1\n"));
    assert_eq!((c.readings_found, c.is_complete()), (5, false));
    let c = completeness("0,0,0\n0,180,0\n");
    assert_eq!((c.end_marker, c.is_complete()), (false, false));
    let c = completeness("0,0,0\n0,180,0\n #  End \n\n");
    assert_eq!((c.end_marker, c.is_complete()), (true, true));
}
