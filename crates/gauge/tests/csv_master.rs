//! A `# master=<id>` metadata line marks a CSV measurement as a run on a master part: its
//! part id becomes one the service and every listing read as a master run (`MASTER…`), with
//! the identity from the metadata or the file name, and a contradicting `part=` refused.

use camloop_core::measure::is_master_part;
use camloop_gauge::parse_measurement_csv;

const ROWS: &str = "0,0,0.0\n0,90,1.5\n0,180,3\n0,270,1.5\n";

fn identity(text: &str, file_name: &str) -> Result<[String; 3], String> {
    parse_measurement_csv(text, file_name, "drop")
        .map(|m| [m.header.machine, m.header.part, m.header.lobe])
        .map_err(|e| e.to_string())
}

#[test]
fn a_master_line_names_the_part_a_master_run() {
    let cases = [
        // With the machine and lobe in the metadata, the master fills the part.
        (
            "# machine=G7 lobe=IN1\n# master=M-0417\n",
            "scan.csv",
            "M-0417",
        ),
        // On the same line as the identity, the part given equal to the master's.
        (
            "# machine=G7 part=MASTER-A lobe=IN1 master=A\n",
            "scan.csv",
            "MASTER-A",
        ),
        // With the identity from the file name, the master replaces its part field.
        ("# master=7\n", "G7_S1042_IN1.csv", "7"),
        // An id that already reads as a master run is kept as it is.
        ("# master=master_b\n", "G7_S1042_IN1.csv", "master_b"),
    ];
    for (meta, file_name, id) in cases {
        let got = identity(&format!("{meta}{ROWS}"), file_name).expect(meta);
        let part = if id.to_ascii_uppercase().starts_with("MASTER") {
            id.to_owned()
        } else {
            format!("MASTER-{id}")
        };
        assert_eq!(got, ["G7".to_owned(), part, "IN1".to_owned()], "{meta}");
        assert!(is_master_part(&got[1]), "{meta}");
    }
    // Without the line, the same file is a production part.
    let plain = identity(ROWS, "G7_S1042_IN1.csv").unwrap();
    assert!(!is_master_part(&plain[1]));
}

#[test]
fn a_bad_or_contradicted_master_line_is_refused_by_line() {
    let cases = [
        (
            "# machine=G7 part=S1042 lobe=IN1\n# master=M7\n",
            "part=\"S1042\" and master=\"MASTER-M7\" disagree: a master run's part is the master",
        ),
        (
            "# master=M7\n# master=M8\n",
            "line 2: metadata master given twice with different values",
        ),
        (
            "# master=a/b\n",
            "line 1: metadata master=\"a/b\" is invalid: 1–25 characters of A–Z a–z 0–9 . _ - \
             (a part MASTER-id)",
        ),
        (
            // 26 characters: MASTER-… would be 33, beyond the 32 a part id may have.
            "# master=abcdefghijklmnopqrstuvwxyz\n",
            "line 1: metadata master=\"abcdefghijklmnopqrstuvwxyz\" is invalid: 1–25 characters \
             of A–Z a–z 0–9 . _ - (a part MASTER-id)",
        ),
        (
            "# master=\n",
            "line 1: metadata master=\"\" is invalid: 1–25 characters of A–Z a–z 0–9 . _ - \
             (a part MASTER-id)",
        ),
    ];
    for (meta, expected) in cases {
        assert_eq!(
            identity(&format!("{meta}{ROWS}"), "G7_S1042_IN1.csv"),
            Err(expected.to_owned()),
            "{meta}"
        );
    }
}
