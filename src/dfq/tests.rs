//! The writer's output checked against the published AQDEF field list: every line is a known
//! K-field of the right level, its value has the field's type and fits its length, and the
//! structure holds (K0100 = characteristics defined, every value names one).

use super::*;
use std::collections::{BTreeMap, BTreeSet};

/// The published fields this writer may use: (key, type, longest text).
/// Types: I integer, D number, S text, T date/time `DD.MM.YYYY/HH:MM:SS`.
const FIELDS: &[(&str, char, usize)] = &[
    ("K0100", 'I', 0),
    ("K1001", 'S', 30),
    ("K1002", 'S', 80),
    ("K2001", 'S', 40),
    ("K2002", 'S', 80),
    ("K2004", 'I', 0),
    ("K2022", 'I', 0),
    ("K2101", 'D', 0),
    ("K2110", 'D', 0),
    ("K2111", 'D', 0),
    ("K2142", 'S', 20),
    ("K0001", 'D', 0),
    ("K0002", 'I', 0),
    ("K0004", 'T', 0),
    ("K0014", 'S', 40),
];

fn is_time(v: &str) -> bool {
    let b = v.as_bytes();
    b.len() == 19
        && v.chars().enumerate().all(|(i, c)| match i {
            2 | 5 => c == '.',
            10 => c == '/',
            13 | 16 => c == ':',
            _ => c.is_ascii_digit(),
        })
}

/// Parses and checks a file; returns the fields by (key, index) in order.
fn check(text: &str) -> Vec<(String, Option<usize>, String)> {
    let known: BTreeMap<&str, (char, usize)> = FIELDS.iter().map(|f| (f.0, (f.1, f.2))).collect();
    assert!(text.ends_with("\r\n"), "lines end with CR LF");
    let mut out = Vec::new();
    for (n, line) in text.split("\r\n").filter(|l| !l.is_empty()).enumerate() {
        let (key, value) = line.split_once(' ').unwrap_or((line, ""));
        let (field, index) = match key.split_once('/') {
            Some((f, i)) => (f, Some(i.parse::<usize>().expect("index is a number"))),
            None => (key, None),
        };
        let &(kind, len) = known
            .get(field)
            .unwrap_or_else(|| panic!("line {}: {field} is not in the field list", n + 1));
        match kind {
            'I' => assert!(value.parse::<i64>().is_ok(), "line {}: {line}", n + 1),
            'D' => assert!(
                value.parse::<f64>().is_ok_and(f64::is_finite),
                "line {}: {line}",
                n + 1
            ),
            'T' => assert!(is_time(value), "line {}: {line}", n + 1),
            _ => {
                assert!(
                    value.chars().count() <= len,
                    "line {}: over {len} chars",
                    n + 1
                );
                assert!(!value.chars().any(char::is_control), "line {}", n + 1);
            }
        }
        // Part fields stand alone here (one part per file); characteristic and value
        // fields name their characteristic.
        let per_characteristic =
            field.starts_with("K2") || (field.starts_with("K00") && field != "K0100");
        assert_eq!(
            index.is_some(),
            per_characteristic,
            "line {}: {line}",
            n + 1
        );
        out.push((field.to_string(), index, value.to_string()));
    }
    out
}

fn row(id: i64, at_ms: i64, profile: f64) -> DfqRow {
    DfqRow {
        received_at: jiff::Timestamp::from_millisecond(at_ms).unwrap(),
        part_ident: id.to_string().parse().unwrap(),
        max_error_um: Some(profile + 1.0),
        profile_error_um: profile,
        size_error_um: -0.25,
        phase_error_deg: 0.0125,
    }
}

fn series(feature: &str, band: Option<(f64, f64)>, rows: Vec<DfqRow>) -> DfqSeries {
    DfqSeries {
        machine: "GR1".parse().unwrap(),
        feature: feature.parse().unwrap(),
        profile_band_um: band,
        limits: crate::dfq::DfqLimits::default(),
        rows,
    }
}

#[test]
fn a_file_holds_only_published_fields_with_consistent_structure() {
    // 2026-11-21T10:30:05Z.
    let t = 1_795_219_200_000 + 37_805_000;
    let text = write_dfq(
        "DEMO-CAM",
        "demo camshaft",
        &[
            series(
                "IN1",
                Some((-2.5, 2.5)),
                vec![row(7, t, 1.5), row(8, t + 60_000, 1.25)],
            ),
            series("EX1", None, vec![row(9, t, 0.5)]),
        ],
    )
    .unwrap();
    let fields = check(&text);
    let get = |k: &str, i: Option<usize>| -> Vec<String> {
        fields
            .iter()
            .filter(|f| f.0 == k && f.1 == i)
            .map(|f| f.2.clone())
            .collect()
    };
    assert_eq!(get("K0100", None), vec!["8"]);
    assert_eq!(get("K1001", None), vec!["DEMO-CAM"]);
    let defined: BTreeSet<usize> = fields
        .iter()
        .filter(|f| f.0 == "K2001")
        .filter_map(|f| f.1)
        .collect();
    assert_eq!(defined, (1..=8).collect());
    // Every value names a defined characteristic, and each has its time, attribute, ident.
    for k in 1..=8 {
        let n = get("K0001", Some(k)).len();
        assert_eq!(get("K0004", Some(k)).len(), n);
        assert_eq!(get("K0002", Some(k)).len(), n);
        assert_eq!(get("K0014", Some(k)).len(), n);
        assert_eq!(n, if k <= 4 { 2 } else { 1 }, "characteristic {k}");
    }
    // IN1's profile error (characteristic 2): limits from the symmetric band, values as given.
    assert_eq!(get("K2001", Some(2)), vec!["GR1.IN1.PROFILE"]);
    assert_eq!(get("K2110", Some(2)), vec!["0"]);
    assert_eq!(get("K2111", Some(2)), vec!["2.500"]);
    assert_eq!(get("K0001", Some(2)), vec!["1.500", "1.250"]);
    assert_eq!(
        get("K0004", Some(2)),
        vec!["21.11.2026/10:30:05", "21.11.2026/10:31:05"]
    );
    assert_eq!(get("K0014", Some(2)), vec!["7", "8"]);
    // EX1 has no band: no limits rather than a made-up one.
    assert!(get("K2111", Some(6)).is_empty());
    assert_eq!(get("K2142", Some(4)), vec!["°"]);
    assert_eq!(get("K0001", Some(4)), vec!["0.0125", "0.0125"]);
}

#[test]
fn texts_are_cut_to_their_field_and_lose_line_breaks() {
    let long = "P".repeat(50) + "\r\nK0001/1 9";
    let text = write_dfq(
        &long,
        "two\r\nK0001/1 9",
        &[series("IN1", None, vec![row(1, 0, 1.0)])],
    )
    .unwrap();
    let fields = check(&text);
    assert_eq!(
        fields.iter().filter(|f| f.0 == "K0001").count(),
        4,
        "{text}"
    );
    let part = fields.iter().find(|f| f.0 == "K1001").unwrap();
    assert_eq!(part.2, "P".repeat(30));
}

#[test]
fn an_unknown_max_error_is_a_placeholder_and_bad_numbers_are_refused() {
    let mut r = row(1, 0, 1.0);
    r.max_error_um = None;
    let text = write_dfq("P", "p", &[series("IN1", None, vec![r.clone()])]).unwrap();
    let fields = check(&text);
    let attr: Vec<&str> = fields
        .iter()
        .filter(|f| f.0 == "K0002")
        .map(|f| f.2.as_str())
        .collect();
    assert_eq!(attr, vec!["255", "0", "0", "0"]);
    r.phase_error_deg = f64::NAN;
    let e = write_dfq("P", "p", &[series("IN1", None, vec![r])]).unwrap_err();
    assert!(e.to_string().contains("phase error"), "{e}");
    assert_eq!(
        write_dfq("P", "p", &[series("IN1", None, vec![])]),
        Err(DfqError::Empty)
    );
}

/// The recipe's other tolerances reach the file as limits: max error 0..4 µm, size ±5 µm,
/// phase ±0.05°; characteristics without one get none.
#[test]
fn recipe_tolerances_become_the_characteristics_limits() {
    let mut s = series("IN1", None, vec![row(1, 1_795_219_200_000, 0.5)]);
    s.limits = DfqLimits {
        max_error_um: Some(4.0),
        size_um: Some(5.0),
        phase_deg: Some(0.05),
    };
    let text = write_dfq("DEMO-CAM", "demo", &[s]).unwrap();
    let fields = check(&text);
    let field = |key: &str, k: usize| {
        fields
            .iter()
            .find(|(f, i, _)| f == key && *i == Some(k))
            .map(|(_, _, v)| v.clone())
    };
    // 1 max error, 2 profile (no band given), 3 size, 4 phase.
    assert_eq!(
        (field("K2110", 1), field("K2111", 1)),
        (Some("0".into()), Some("4.000".into()))
    );
    assert_eq!((field("K2110", 2), field("K2111", 2)), (None, None));
    assert_eq!(
        (field("K2110", 3), field("K2111", 3)),
        (Some("-5.000".into()), Some("5.000".into()))
    );
    assert_eq!(
        (field("K2110", 4), field("K2111", 4)),
        (Some("-0.0500".into()), Some("0.0500".into()))
    );
}
