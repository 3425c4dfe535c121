//! `read_measurement_file`: one measurement from a `.csv` or candump `.log`, errors naming
//! the file. Fixtures come from tools/encode_candump.py and tools/encode_text_fixtures.py.

use crate::fixture_support::{encoder_lift_mm, fixture_path};
use std::path::Path;

use camloop::gauge::file::MAX_FILE_BYTES;
use camloop::gauge::{GaugeDbc, read_measurement_file};

fn read(path: &Path) -> Result<camloop::core::measure::RawMeasurement, String> {
    read_measurement_file(path, &GaugeDbc::builtin()).map_err(|e| e.to_string())
}

#[test]
fn csv_fixtures_read_with_identity_and_grid() {
    for (name, ppr) in [
        ("M3_P1234_L2_20240501T101500.csv", 360),
        ("lobe_scan_720.csv", 720),
    ] {
        let m = read(&fixture_path(name)).expect("valid fixture");
        assert_eq!(
            (
                m.header.machine.as_str(),
                m.header.part.as_str(),
                m.header.lobe.as_str()
            ),
            ("M3", "P1234", "L2"),
            "{name}"
        );
        assert_eq!((m.header.revolutions, m.header.points_per_rev), (3, ppr));
        assert_eq!(m.samples.len(), 3 * ppr as usize);
        assert_eq!(m.origin, fixture_path(name).display().to_string());
        for (n, s) in m.samples.iter().enumerate() {
            let n = u32::try_from(n).expect("small");
            assert_eq!((s.revolution, s.angle_index), (n / ppr, n % ppr));
            // Written with 6 decimals: within half a nm (+1e-12 for binary parsing).
            let expected = encoder_lift_mm(s.revolution, s.angle_index, ppr);
            assert!(
                (s.lift_mm - expected).abs() <= 0.5e-6 + 1e-12,
                "{name} sample {n}"
            );
        }
    }
}

#[test]
fn a_candump_log_with_one_measurement_reads() {
    let m = read(&fixture_path("gauge_3x360.log")).expect("one clean measurement");
    assert_eq!(m.header.lobe, "2");
    assert_eq!(m.samples.len(), 1080);
    // cantools rounding to 0.0001 mm: within half a step.
    let worst = m
        .samples
        .iter()
        .map(|s| (s.lift_mm - encoder_lift_mm(s.revolution, s.angle_index, 360)).abs())
        .fold(0.0, f64::max);
    assert!(worst <= 0.00005 + 1e-12, "{worst}");
}

#[test]
fn errors_name_the_file() {
    let cutoff = fixture_path("gauge_cutoff.log");
    assert_eq!(
        read(&cutoff),
        Err(format!(
            "candump log {}: line 4: 2 samples arrived with no measurement started",
            cutoff.display()
        ))
    );
    let dir = tempfile::tempdir().expect("tempdir");
    let two = dir.path().join("two.log");
    let one = std::fs::read_to_string(fixture_path("gauge_3x360.log")).expect("read");
    std::fs::write(&two, format!("{one}{one}")).expect("write");
    assert_eq!(
        read(&two),
        Err(format!(
            "candump log {} holds 2 complete measurements; exactly one was expected",
            two.display()
        ))
    );
    let empty = dir.path().join("empty.log");
    std::fs::write(&empty, "").expect("write");
    assert_eq!(
        read(&empty),
        Err(format!(
            "candump log {} holds 0 complete measurements; exactly one was expected",
            empty.display()
        ))
    );
    let missing = dir.path().join("M1_P1_L1.csv");
    let err = read(&missing).expect_err("missing");
    assert!(
        err.starts_with(&format!(
            "cannot read measurement file {}: ",
            missing.display()
        )),
        "{err}"
    );
    let txt = dir.path().join("m.txt");
    assert_eq!(
        read(&txt),
        Err(format!(
            "measurement file {} has no .csv or .log extension",
            txt.display()
        ))
    );
    let anonymous = dir.path().join("scan.CSV");
    std::fs::write(&anonymous, "0,0,0\n").expect("write");
    let err = read(&anonymous).expect_err("no identity");
    assert!(
        err.starts_with(&format!(
            "measurement file {}: machine, part and lobe unknown",
            anonymous.display()
        )),
        "{err}"
    );
}

/// `rev,angle_deg,lift_mm` rows for the revolution labels given, 360 points each, lift by
/// the fixture formula of the revolution's position (so labels do not change the values).
fn csv_rows(labels: &[u32]) -> String {
    let mut text = String::from("rev,angle_deg,lift_mm\n");
    for (n, label) in labels.iter().enumerate() {
        let n = u32::try_from(n).expect("few");
        for k in 0..360 {
            text.push_str(&format!("{label},{k},{:.6}\n", encoder_lift_mm(n, k, 360)));
        }
    }
    text
}

/// Revolution numbers are labels: a file numbered from 1 reads as revolutions 0, 1, 2 and
/// passes the completeness checks (it was refused as "revolution 0 missing").
#[test]
fn a_csv_numbered_from_one_reads_and_passes_the_checks() {
    use camloop::core::measure::{AssemblyLimits, check_and_average};
    let dir = tempfile::tempdir().expect("tempdir");
    let from_zero = dir.path().join("M3_P1_L1.csv");
    let from_one = dir.path().join("M3_P1_L2.csv");
    std::fs::write(&from_zero, csv_rows(&[0, 1, 2])).expect("write");
    std::fs::write(&from_one, csv_rows(&[1, 2, 3])).expect("write");
    let zero = read_measurement_file(&from_zero, &GaugeDbc::builtin()).expect("from 0");
    let one = read_measurement_file(&from_one, &GaugeDbc::builtin()).expect("from 1");
    assert_eq!(
        (one.header.revolutions, one.header.points_per_rev),
        (3, 360)
    );
    assert_eq!(one.samples, zero.samples);
    let averaged = check_and_average(&one, &AssemblyLimits::default()).expect("complete");
    assert_eq!(averaged.revolutions_used, [0, 1, 2]);
}

#[test]
fn a_gap_in_the_revolution_numbers_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("M3_P1_L1.csv");
    std::fs::write(&path, csv_rows(&[1, 2, 4])).expect("write");
    assert_eq!(
        read(&path),
        Err(format!(
            "measurement file {}: revolutions jump from 2 to 4: revolution 3 is missing",
            path.display()
        ))
    );
}

/// The size comes from the metadata (a sparse file: reading it would be slow and large), and
/// a line is read through a bounded buffer.
#[test]
fn oversized_files_and_lines_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let big = dir.path().join("M3_P1_L1.csv");
    std::fs::File::create(&big)
        .expect("create")
        .set_len(MAX_FILE_BYTES + 1)
        .expect("set_len");
    assert_eq!(
        read(&big),
        Err(format!(
            "measurement file {} is 16777217 bytes, over the limit of 16777216 bytes",
            big.display()
        ))
    );
    let long = dir.path().join("M3_P1_L2.csv");
    std::fs::write(&long, format!("0,0,0\n# {}\n0,1,0\n", "x".repeat(5000))).expect("write");
    assert_eq!(
        read(&long),
        Err(format!(
            "measurement file {} line 2 is longer than 4096 bytes",
            long.display()
        ))
    );
}
