//! Property tests: arbitrary input into every gauge parser never panics, and what is
//! accepted obeys the protocol's invariants; encoders and decoders agree.

use camloop::core::measure::{MeasurementHeader, RawMeasurement, RawSample};
use camloop::gauge::candump::parse_candump_line;
use camloop::gauge::serial::{encode_serial_measurement, parse_serial_line};
use camloop::gauge::{
    Assembled, Assembler, CanId, GaugeDbc, GaugeFrame, GaugeSignalNames, GaugeStart, SerialEvent,
    decode_serial_text, parse_measurement_csv, read_candump_measurements,
};
use proptest::prelude::*;

fn can_id() -> impl Strategy<Value = CanId> {
    prop_oneof![
        (0u16..=0x7ff).prop_map(CanId::Standard),
        (0x5a0u16..=0x5a2).prop_map(CanId::Standard),
        (0u32..=0x1fff_ffff).prop_map(CanId::Extended),
    ]
}

fn text() -> impl Strategy<Value = String> {
    // Arbitrary bytes read lossily, and arbitrary strings of characters the formats use.
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..400)
            .prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
        "[ -~\t\r\n#=,.()#]{0,400}",
        "((START|S|END|#|[0-9]{1,4}|-?[0-9]{1,3}\\.[0-9]{1,7}|[A-F0-9]{8}|M3|,)[ \n]){0,60}",
    ]
}

// Byte-level properties are cheap: many cases. Text properties spend most of their time
// generating strings in a debug build: fewer cases here, the cargo-fuzz targets in fuzz/
// search the same parsers far longer.
proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    #[test]
    fn frame_decoding_never_panics(id in can_id(), data in proptest::collection::vec(any::<u8>(), 0..16)) {
        let dbc = GaugeDbc::builtin();
        if let Ok(GaugeFrame::Sample(s)) = dbc.decode(id, &data) {
            // Whatever decodes lies within the DBC's declared ranges.
            prop_assert!(s.revolution <= 62 && s.angle_index <= 35_999);
            prop_assert!(s.lift_mm.abs() <= 200.0 + 0.00005);
        }
    }

    #[test]
    fn hand_encoded_samples_decode_exactly(rev in 0u32..=62, index in 0u32..36_000, lift_raw in -2_000_000i32..=2_000_000) {
        // Independent encoder: the GaugeSample layout of config/gauge.dbc written by hand
        // (Intel: 6 bits revolution, 18 bits angle index, 32 bits signed lift in 0.1 µm).
        let word = u64::from(rev) | u64::from(index) << 6 | u64::from(lift_raw.cast_unsigned()) << 24;
        let data = &word.to_le_bytes()[..7];
        let frame = GaugeDbc::builtin().decode(CanId::Standard(0x5a1), data);
        let Ok(GaugeFrame::Sample(s)) = frame else {
            return Err(TestCaseError::fail(format!("{frame:?}")));
        };
        prop_assert_eq!((s.revolution, s.angle_index), (rev, index));
        // raw × 0.0001 in binary: relative error of one f64 rounding.
        prop_assert!((s.lift_mm - f64::from(lift_raw) / 10_000.0).abs() <= 1e-15 * 200.0);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn candump_parsing_never_panics(t in text()) {
        for line in t.lines() {
            if let Ok(r) = parse_candump_line(line) {
                prop_assert!(r.data().len() <= 8);
            }
        }
        let report = read_candump_measurements(&t, &GaugeDbc::builtin(), "prop");
        prop_assert!(report.measurements.len() <= t.lines().count());
    }

    #[test]
    fn serial_parsing_never_panics(t in text()) {
        for line in t.lines() {
            let _ = parse_serial_line(line);
        }
        for event in decode_serial_text(&t, "prop") {
            if let SerialEvent::Measurement(m) = event {
                prop_assert!(on_grid(&m));
            }
        }
    }

    #[test]
    fn csv_parsing_never_panics(t in text(), name in "[A-Za-z0-9_.]{0,30}") {
        if let Ok(m) = parse_measurement_csv(&t, &name, "prop") {
            prop_assert!(on_grid(&m));
            prop_assert!(!m.samples.is_empty());
        }
    }

    #[test]
    fn dbc_compilation_never_panics(t in text()) {
        let _ = GaugeDbc::from_dbc_text(&t, &GaugeSignalNames::default());
    }

    #[test]
    fn assembled_measurements_stay_on_their_grid(frames in proptest::collection::vec(frame(), 0..200)) {
        let mut a = Assembler::new("prop");
        let mut out: Vec<Assembled> = frames.into_iter().filter_map(|f| a.push(f)).collect();
        out.extend(a.finish());
        prop_assert!(!a.is_open());
        for o in out {
            if let Assembled::Measurement(m) = o {
                prop_assert!(on_grid(&m));
            }
        }
    }

    #[test]
    fn serial_encoding_round_trips(m in measurement()) {
        let text = encode_serial_measurement(&m).expect("valid ids and lifts");
        let events = decode_serial_text(&text, "prop");
        prop_assert_eq!(events.len(), 1);
        let SerialEvent::Measurement(back) = &events[0] else {
            return Err(TestCaseError::fail(format!("{events:?}")));
        };
        prop_assert_eq!(&back.header, &m.header);
        prop_assert_eq!(back.samples.len(), m.samples.len());
        for (a, b) in back.samples.iter().zip(&m.samples) {
            prop_assert_eq!((a.revolution, a.angle_index), (b.revolution, b.angle_index));
            // Written with 6 decimals: half a nm, plus binary parsing slack.
            prop_assert!((a.lift_mm - b.lift_mm).abs() <= 0.5e-6 + 1e-9);
        }
    }
}

fn on_grid(m: &RawMeasurement) -> bool {
    m.samples.len() as u64 <= u64::from(m.header.revolutions) * u64::from(m.header.points_per_rev)
        && m.samples.iter().all(|s| {
            s.revolution < m.header.revolutions
                && s.angle_index < m.header.points_per_rev
                && s.lift_mm.is_finite()
        })
}

fn frame() -> impl Strategy<Value = GaugeFrame> {
    prop_oneof![
        1 => (0u64..3, 1u32..4, 1u32..5).prop_map(|(lobe, revolutions, points_per_rev)| {
            GaugeFrame::Start(GaugeStart { machine: 1, part: 2, lobe, revolutions, points_per_rev })
        }),
        8 => (0u32..5, 0u32..6, -1.0f64..10.0).prop_map(|(revolution, angle_index, lift_mm)| {
            GaugeFrame::Sample(RawSample { revolution, angle_index, lift_mm })
        }),
        1 => (0u32..2).prop_map(|status| GaugeFrame::End { status }),
    ]
}

fn measurement() -> impl Strategy<Value = RawMeasurement> {
    (
        "[A-Za-z0-9._-]{1,32}",
        "[A-Za-z0-9._-]{1,32}",
        "[A-Za-z0-9._-]{1,32}",
        1u32..5,
        1u32..50,
    )
        .prop_flat_map(|(machine, part, lobe, revolutions, points_per_rev)| {
            let header = MeasurementHeader {
                machine,
                part,
                lobe,
                revolutions,
                points_per_rev,
            };
            let sample = (0..revolutions, 0..points_per_rev, -1000.0f64..=1000.0).prop_map(
                |(revolution, angle_index, lift_mm)| RawSample {
                    revolution,
                    angle_index,
                    lift_mm,
                },
            );
            let cap = (revolutions * points_per_rev) as usize;
            proptest::collection::vec(sample, 0..=cap).prop_map(move |samples| RawMeasurement {
                header: header.clone(),
                samples,
                origin: "prop".into(),
            })
        })
}
