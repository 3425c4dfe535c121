//! CAN decoding proved against an independent encoder: the candump fixtures were written by
//! tools/encode_candump.py (cantools + python-can, from config/gauge.dbc); here they are
//! decoded by camloop and compared with the script's lift formula re-computed in Rust.

use crate::fixture_support::{encoder_lift_mm, fixture_text};
use std::path::PathBuf;

use camloop::core::measure::RawMeasurement;
use camloop::gauge::{
    AssemblyProblem, CandumpIssue, DiscardReason, GaugeDbc, GaugeSignalNames,
    read_candump_measurements,
};

/// cantools rounds to the DBC resolution (0.0001 mm), so a right decoder is within half of
/// it; 1e-12 mm covers the binary representation of the factor and libm differences.
const TOLERANCE_MM: f64 = 0.0001 / 2.0 + 1e-12;

fn assert_matches_formula(m: &RawMeasurement) {
    let ppr = m.header.points_per_rev;
    let order: Vec<(u32, u32)> = m
        .samples
        .iter()
        .map(|s| (s.revolution, s.angle_index))
        .collect();
    let expected: Vec<(u32, u32)> = (0..3).flat_map(|r| (0..ppr).map(move |i| (r, i))).collect();
    assert_eq!(order, expected, "samples in arrival order");
    let mut worst = 0.0f64;
    for s in &m.samples {
        let err = (s.lift_mm - encoder_lift_mm(s.revolution, s.angle_index, ppr)).abs();
        assert!(
            err <= TOLERANCE_MM,
            "rev {} index {}: decoded {} mm, formula {} mm",
            s.revolution,
            s.angle_index,
            s.lift_mm,
            encoder_lift_mm(s.revolution, s.angle_index, ppr)
        );
        worst = worst.max(err);
    }
    // A decoder that truncated instead of reading cantools' rounding would still pass the
    // bound above only by luck; the worst error must use most of the half step.
    assert!(worst > 0.0001 * 0.4, "worst error {worst} mm");
    // Negative lift near the base circle survived the signed decoding.
    assert!(m.samples.iter().any(|s| s.lift_mm < -0.001));
}

#[test]
fn a_cantools_encoded_measurement_decodes_to_the_formula() {
    let report = read_candump_measurements(
        &fixture_text("gauge_3x360.log"),
        &GaugeDbc::builtin(),
        "gauge_3x360.log",
    );
    assert_eq!(report.issues, []);
    assert_eq!(report.foreign_frames, 0);
    assert_eq!(report.measurements.len(), 1);
    let m = &report.measurements[0];
    assert_eq!(m.origin, "gauge_3x360.log");
    assert_eq!(
        (
            m.header.machine.as_str(),
            m.header.part.as_str(),
            m.header.lobe.as_str()
        ),
        ("3", "1234", "2")
    );
    assert_eq!((m.header.revolutions, m.header.points_per_rev), (3, 360));
    assert_eq!(m.samples.len(), 1080);
    assert_matches_formula(m);
}

#[test]
fn a_cut_off_measurement_is_reported_and_the_next_one_kept() {
    let report = read_candump_measurements(
        &fixture_text("gauge_cutoff.log"),
        &GaugeDbc::builtin(),
        "cutoff",
    );
    assert_eq!(report.measurements.len(), 1);
    assert_eq!(report.measurements[0].header.lobe, "2");
    assert_matches_formula(&report.measurements[0]);
    // One standard 0x123 frame plus ten extended 0x18FEF100 frames.
    assert_eq!(report.foreign_frames, 11);

    let summary: Vec<(usize, String, usize, Option<DiscardReason>)> = report
        .issues
        .iter()
        .map(|issue| match issue {
            CandumpIssue::Assembly {
                line,
                problem:
                    AssemblyProblem::Discarded {
                        header,
                        samples_received,
                        reason,
                    },
            } => (
                *line,
                header.lobe.clone(),
                *samples_received,
                Some(reason.clone()),
            ),
            CandumpIssue::Assembly {
                line,
                problem: AssemblyProblem::SamplesWithoutStart { count },
            } => (*line, String::new(), *count, None),
            other => panic!("unexpected issue {other}"),
        })
        .collect();
    // Lines: 1–2 stray samples, 3 foreign, 4 start lobe 1, 5–504 its samples, 505 start
    // lobe 2, 1080 samples + 10 foreign frames, end at 1596, start lobe 3 at 1597, 10
    // samples, end at 1608.
    assert_eq!(
        summary,
        [
            (4, String::new(), 2, None),
            (505, "1".into(), 500, Some(DiscardReason::CutOffByNewStart)),
            (1608, "3".into(), 10, Some(DiscardReason::GaugeStatus(2))),
        ]
    );
}

#[test]
fn the_shipped_dbc_file_is_the_builtin_one() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/gauge.dbc");
    let loaded = GaugeDbc::load(&path, &GaugeSignalNames::default()).expect("loads");
    assert_eq!(loaded, GaugeDbc::builtin());
    let missing = GaugeDbc::load(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/none.dbc"),
        &GaugeSignalNames::default(),
    )
    .expect_err("no such file");
    assert!(
        missing.to_string().starts_with("cannot read dbc file ")
            && missing.to_string().contains("none.dbc"),
        "{missing}"
    );
}
