//! The serial line protocol codec (pure): line parser, decoder state machine and encoder.
//! Checksums in the expected texts were computed with Python's zlib.crc32, independently of
//! the crc32fast crate the codec uses.

use camloop::core::measure::{MeasurementHeader, RawMeasurement, RawSample};
use camloop::gauge::serial::{
    SerialEvent, SerialLine, decode_serial_text, encode_serial_measurement, parse_serial_line,
};

fn err(line: &str) -> String {
    parse_serial_line(line)
        .expect_err("must be rejected")
        .to_string()
}

#[test]
fn parses_each_record() {
    assert_eq!(
        parse_serial_line("START M3 P1234 L2 3 360\r"),
        Ok(SerialLine::Start(MeasurementHeader {
            machine: "M3".into(),
            part: "P1234".into(),
            lobe: "L2".into(),
            revolutions: 3,
            points_per_rev: 360,
        }))
    );
    assert_eq!(
        parse_serial_line("S\t2  359 -0.000800"),
        Ok(SerialLine::Sample(RawSample {
            revolution: 2,
            angle_index: 359,
            lift_mm: -0.0008,
        }))
    );
    assert_eq!(
        parse_serial_line("END 1080 cbf43926"),
        Ok(SerialLine::End {
            sample_count: 1080,
            crc32: 0xcbf4_3926
        })
    );
    assert_eq!(parse_serial_line("   "), Ok(SerialLine::Ignored));
    assert_eq!(parse_serial_line("# gauge 7 v2.1"), Ok(SerialLine::Ignored));
}

#[test]
fn rejects_malformed_lines_with_the_field_named() {
    assert_eq!(
        err("START M3 P1234 L2 3"),
        "START needs 5 fields after the keyword, found 4"
    );
    assert_eq!(
        err("START M3 P/1 L2 3 360"),
        "part \"P/1\" must be 1–32 characters of A–Z a–z 0–9 . _ -"
    );
    assert_eq!(
        err("START M3 P1 L2 0 360"),
        "revolutions \"0\" is not a whole number in 1..=1000"
    );
    assert_eq!(
        err("START M3 P1 L2 3 +360"),
        "points_per_rev \"+360\" is not a whole number in 1..=100000"
    );
    assert_eq!(
        err("S 0 -1 0.1"),
        "angle_index \"-1\" is not a whole number in 0..=4294967295"
    );
    for bad in ["nan", "inf", "1e3", "1.", ".5", "--1", "1000.5", "0x10", ""] {
        let line = format!("S 0 1 {bad}");
        if bad.is_empty() {
            assert_eq!(err(&line), "S needs 3 fields after the keyword, found 2");
        } else {
            assert_eq!(
                err(&line),
                format!("lift \"{bad}\" is not a plain decimal number of mm within ±1000")
            );
        }
    }
    assert_eq!(
        err("END 10 12345"),
        "checksum \"12345\" is not 8 hex digits"
    );
    assert_eq!(
        err("END 10 +2345678"),
        "checksum \"+2345678\" is not 8 hex digits"
    );
    assert_eq!(
        err("SAMPLE 0 1 2"),
        "unknown record \"SAMPLE\" (expected START, S or END)"
    );
    assert_eq!(err("S 0 1 0.5µ"), "line is not ascii text");
    assert_eq!(
        err(&format!("S 0 1 {}", "1".repeat(300))),
        "line is longer than 256 bytes"
    );
}

fn measurement(samples: &[(u32, u32, f64)]) -> RawMeasurement {
    RawMeasurement {
        header: MeasurementHeader {
            machine: "M3".into(),
            part: "P1234".into(),
            lobe: "L2".into(),
            revolutions: 2,
            points_per_rev: 2,
        },
        samples: samples
            .iter()
            .map(|&(revolution, angle_index, lift_mm)| RawSample {
                revolution,
                angle_index,
                lift_mm,
            })
            .collect(),
        origin: "pty".into(),
    }
}

#[test]
fn encoding_matches_an_independent_crc() {
    let m = measurement(&[(0, 0, -0.0008), (0, 1, 1.25), (1, 1, 1.2501), (1, 0, 0.0)]);
    let text = encode_serial_measurement(&m).expect("encodable");
    // CRC-32 of these exact bytes by Python's zlib.crc32:
    // zlib.crc32(b"START M3 P1234 L2 2 2\nS 0 0 -0.000800\nS 0 1 1.250000\n"
    //            b"S 1 1 1.250100\nS 1 0 0.000000\n") == 0xDE24A4C8
    assert_eq!(
        text,
        "START M3 P1234 L2 2 2\nS 0 0 -0.000800\nS 0 1 1.250000\nS 1 1 1.250100\n\
         S 1 0 0.000000\nEND 4 DE24A4C8\n"
    );
    assert_eq!(
        decode_serial_text(&text, "pty"),
        [SerialEvent::Measurement(m)]
    );
}

fn problems(text: &str) -> Vec<String> {
    decode_serial_text(text, "pty")
        .iter()
        .map(|e| match e {
            SerialEvent::Measurement(m) => format!("measurement lobe {}", m.header.lobe),
            SerialEvent::Problem(p) => p.to_string(),
        })
        .collect()
}

#[test]
fn damaged_measurements_are_discarded_with_the_reason() {
    let good =
        encode_serial_measurement(&measurement(&[(0, 0, 0.1), (0, 1, 0.2)])).expect("encodable");
    // One digit changed in a sample: same count, wrong checksum.
    let flipped = good.replace("0.200000", "0.300000");
    assert_eq!(
        problems(&flipped),
        [
            "line 4: measurement of machine M3 part P1234 lobe L2 discarded after 2 samples: \
          checksum mismatch: end line says 114A8CA3, lines give B73D8717"
        ]
    );
    // A lost sample line.
    let lost = good.replace("S 0 1 0.200000\n", "");
    assert_eq!(
        problems(&lost),
        [
            "line 3: measurement of machine M3 part P1234 lobe L2 discarded after 1 samples: \
          end line announces 2 samples, 1 were received"
        ]
    );
    // A garbled line inside: the first reason is kept.
    let garbled = good.replace("S 0 1 0.200000", "S 0 1 0.2x0000");
    assert_eq!(
        problems(&garbled),
        [
            "line 4: measurement of machine M3 part P1234 lobe L2 discarded after 1 samples: \
          line 3: lift \"0.2x0000\" is not a plain decimal number of mm within ±1000"
        ]
    );
    // A sample off the announced 2 × 2 grid.
    let off = good.replace("S 0 1 0.200000", "S 0 2 0.200000");
    assert!(
        problems(&off)[0]
            .ends_with("sample at revolution 0, angle index 2 is outside the announced grid")
    );
}

#[test]
fn stream_structure_problems_are_reported_with_lines() {
    let good = encode_serial_measurement(&measurement(&[(0, 0, 0.1)])).expect("encodable");
    let text = format!(
        "S 0 0 0.1\nS 0 1 0.1\nhello\n{good}END 0 00000000\nSTART M3 P1234 L3 2 2\nS 0 0 0\n\
         START M3 P1234 L4 2 2\n"
    );
    assert_eq!(
        problems(&text),
        [
            "line 3: unknown record \"hello\" (expected START, S or END)",
            "line 4: 2 samples arrived with no measurement started",
            "measurement lobe L2",
            "line 7: end arrived with no measurement started (after 0 stray samples)",
            "line 10: measurement of machine M3 part P1234 lobe L3 discarded after 1 \
             samples: cut off by a new start before its end",
            "line 10: measurement of machine M3 part P1234 lobe L4 discarded after 0 \
             samples: stream ended before the measurement's end",
        ]
    );
}

#[test]
fn crlf_line_ends_and_comments_do_not_change_the_checksum() {
    let good =
        encode_serial_measurement(&measurement(&[(0, 0, 0.1), (1, 1, -0.1)])).expect("encodable");
    let crlf = good
        .replace('\n', "\r\n")
        .replacen("\r\nS", "\r\n# note\r\n\r\nS", 1);
    assert!(matches!(
        decode_serial_text(&crlf, "pty").as_slice(),
        [SerialEvent::Measurement(m)] if m.samples.len() == 2
    ));
}
