//! The gauge frame encoder: the inverse of the DBC decoder (round trips through the decoder
//! and the assembler), byte for byte the same as cantools on the committed fixture, typed
//! errors for what cannot be sent, and the simulated gauge feeding the real decoder.

use crate::fixture_support::fixture_text;
use crate::sim_support;

use camloop::core::fit::TableForm;
use camloop::core::geometry::Follower;
use camloop::core::measure::{
    AssemblyLimits, MeasurementHeader, RawMeasurement, RawSample, check_and_average,
};
use camloop::gauge::candump::parse_candump_line;
use camloop::gauge::{
    Assembled, Assembler, CanId, EncodeError, GaugeDbc, GaugeFrame, GaugeSignalNames, GaugeStart,
    candump_line, encode_measurement,
};
use camloop::sim::{GrinderConfig, PartLabels, measurement_frames};
use proptest::prelude::*;
use sim_support::{demo_sim, demo_table};

/// Half the shipped DBC's lift resolution (0.1 µm), mm, plus 1e-12 mm for the binary
/// representation of the factor 0.0001 (raw · factor is off by < 1e-16 relative).
const HALF_STEP_MM: f64 = 0.5e-4 + 1e-12;

/// Decodes every frame and feeds the assembler; returns the one measurement delivered.
fn decode_all(dbc: &GaugeDbc, frames: &[(CanId, Vec<u8>)], origin: &str) -> RawMeasurement {
    let mut assembler = Assembler::new(origin);
    let mut delivered = Vec::new();
    for (id, data) in frames {
        let frame = dbc.decode(*id, data).expect("every encoded frame decodes");
        delivered.extend(assembler.push(frame));
    }
    delivered.extend(assembler.finish());
    match delivered.as_slice() {
        [Assembled::Measurement(m)] => m.clone(),
        other => panic!("expected exactly one measurement, got {other:?}"),
    }
}

/// The lift formula of tools/encode_candump.py, mm.
fn fixture_lift_mm(revolution: u32, angle_index: u32, points_per_rev: u32) -> f64 {
    let theta = std::f64::consts::TAU * f64::from(angle_index) / f64::from(points_per_rev);
    6.2 * ((1.0 - theta.cos()) / 2.0).powi(2) + 0.0015 * (5.0 * theta + f64::from(revolution)).sin()
        - 0.0008
}

#[test]
fn a_4x360_measurement_round_trips_through_decoder_and_assembler() {
    let dbc = GaugeDbc::builtin();
    // Arrival order deliberately not sorted: revolutions interleaved, indices descending.
    let mut samples = Vec::new();
    for angle_index in (0..360).rev() {
        for revolution in [2, 0, 3, 1] {
            samples.push(RawSample {
                revolution,
                angle_index,
                // Values off the 0.1 µm grid, both signs, up to ±~9 mm.
                lift_mm: 9.123_456_7 * (f64::from(angle_index) * 0.0174 + 0.3).sin()
                    + 1.3e-5 * f64::from(revolution),
            });
        }
    }
    let raw = RawMeasurement {
        header: MeasurementHeader {
            machine: "7".into(),
            part: "4294967296".into(),
            lobe: "3".into(),
            revolutions: 4,
            points_per_rev: 360,
        },
        samples,
        origin: "roundtrip".into(),
    };
    // Part is 24 bits wide in the shipped DBC: 2^32 is refused, the largest production part
    // is sent (all ones, 16777215, is the master part of a gauge study: `MASTER`).
    let err = encode_measurement(&dbc, &raw, 0).expect_err("part beyond 24 bits");
    assert_eq!(
        err.to_string(),
        "GaugeStart.Part = 4294967296 is outside its declared range [0, 16777215]"
    );
    let raw = RawMeasurement {
        header: MeasurementHeader {
            part: "16777214".into(),
            ..raw.header
        },
        ..raw
    };

    let frames = encode_measurement(&dbc, &raw, 0).expect("encodes");
    assert_eq!(frames.len(), 4 * 360 + 2);
    assert_eq!(frames[0].0, CanId::Standard(0x5a0));
    assert!(
        frames[1..1441]
            .iter()
            .all(|(id, data)| *id == CanId::Standard(0x5a1) && data.len() == 7)
    );
    assert_eq!(frames[1441], (CanId::Standard(0x5a2), vec![0]));

    let back = decode_all(&dbc, &frames, "roundtrip");
    assert_eq!(back.header, raw.header);
    assert_eq!(back.origin, "roundtrip");
    assert_eq!(back.samples.len(), raw.samples.len());
    let mut worst_mm = 0.0f64;
    for (got, sent) in back.samples.iter().zip(&raw.samples) {
        assert_eq!(
            (got.revolution, got.angle_index),
            (sent.revolution, sent.angle_index)
        );
        worst_mm = worst_mm.max((got.lift_mm - sent.lift_mm).abs());
    }
    assert!(worst_mm <= HALF_STEP_MM, "worst lift error {worst_mm} mm");
    // The values are off-grid, so rounding must actually have happened somewhere.
    assert!(worst_mm > 1e-6, "worst lift error {worst_mm} mm");

    // A gauge status travels too: status 2 is a probe fault the assembler discards on.
    let frames = encode_measurement(&dbc, &raw, 2).expect("encodes");
    assert_eq!(frames.last(), Some(&(CanId::Standard(0x5a2), vec![2])));
}

#[test]
fn the_cantools_fixture_is_reproduced_byte_for_byte() {
    let dbc = GaugeDbc::builtin();
    let log = fixture_text("gauge_3x360.log");
    let mut counts = [0usize; 3];
    for (n, line) in log.lines().enumerate() {
        let record = parse_candump_line(line).expect("fixture line");
        let frame = dbc.decode(record.id, record.data()).expect("fixture frame");
        // Re-encoding the decoded frame gives cantools' bytes.
        let (id, data) = dbc.encode(&frame).expect("re-encodes");
        assert_eq!(
            (id, data.as_slice()),
            (record.id, record.data()),
            "line {n}"
        );
        // The log line too (python-can appends the direction flag ` R`).
        assert_eq!(
            format!("{} R", candump_line(record.timestamp_s, "can0", id, &data)),
            line,
            "line {n}"
        );
        match frame {
            GaugeFrame::Start(s) => {
                counts[0] += 1;
                assert_eq!(
                    s,
                    GaugeStart {
                        machine: 3,
                        part: 1234,
                        lobe: 2,
                        revolutions: 3,
                        points_per_rev: 360
                    }
                );
            }
            GaugeFrame::Sample(s) => {
                counts[1] += 1;
                // Independent of the decoder: the lift cantools was given, recomputed here
                // from the script's formula and rounded by our encoder, gives the same bytes
                // as cantools' rounding. A tie (exactly half a step) would be the only way
                // for f64 sin/cos ulps to matter; none of the 1080 values is within 1e-6
                // steps of one (checked).
                let exact = fixture_lift_mm(s.revolution, s.angle_index, 360);
                let steps = exact / 1e-4;
                assert!(
                    (steps.fract().abs() - 0.5).abs() > 1e-6,
                    "near a tie: {exact}"
                );
                let ours = dbc
                    .encode(&GaugeFrame::Sample(RawSample {
                        lift_mm: exact,
                        ..s
                    }))
                    .expect("in range");
                assert_eq!(
                    ours.1.as_slice(),
                    record.data(),
                    "line {n}: lift {exact} mm"
                );
            }
            GaugeFrame::End { status } => {
                counts[2] += 1;
                assert_eq!(status, 0);
            }
        }
    }
    assert_eq!(counts, [1, 1080, 1]);
}

#[test]
fn values_that_cannot_be_sent_are_typed_errors_naming_the_signal() {
    let dbc = GaugeDbc::builtin();
    let sample = |revolution, angle_index, lift_mm| {
        dbc.encode(&GaugeFrame::Sample(RawSample {
            revolution,
            angle_index,
            lift_mm,
        }))
    };
    let msg = |r: Result<(CanId, Vec<u8>), EncodeError>| r.expect_err("refused").to_string();

    // The declared [min|max] bounds hold, within the decoder's half step of slack.
    assert!(matches!(
        sample(0, 0, 200.1),
        Err(EncodeError::OutOfRange { ref signal, .. }) if signal == "Lift"
    ));
    assert_eq!(
        msg(sample(0, 0, 200.1)),
        "GaugeSample.Lift = 200.1 is outside its declared range [-200, 200]"
    );
    assert_eq!(
        msg(sample(0, 0, -200.0002)),
        "GaugeSample.Lift = -200.0002 is outside its declared range [-200, 200]"
    );
    for edge_mm in [-200.0, 200.0, 200.00004] {
        let (id, data) = sample(0, 0, edge_mm).expect("at the edge");
        let Ok(GaugeFrame::Sample(s)) = dbc.decode(id, &data) else {
            panic!("edge {edge_mm} does not decode")
        };
        assert!((s.lift_mm - edge_mm).abs() <= HALF_STEP_MM, "{edge_mm}");
    }
    assert_eq!(
        msg(sample(0, 0, f64::NAN)),
        "GaugeSample.Lift = NaN is not a finite number"
    );
    assert_eq!(
        msg(sample(63, 0, 0.0)),
        "GaugeSample.Revolution = 63 is outside its declared range [0, 62]"
    );
    assert_eq!(
        msg(sample(0, 36_000, 0.0)),
        "GaugeSample.AngleIndex = 36000 is outside its declared range [0, 35999]"
    );
    let start = |machine, revolutions, points_per_rev| {
        dbc.encode(&GaugeFrame::Start(GaugeStart {
            machine,
            part: 1,
            lobe: 1,
            revolutions,
            points_per_rev,
        }))
    };
    assert_eq!(
        msg(start(4096, 3, 360)),
        "GaugeStart.Machine = 4096 is outside its declared range [0, 4095]"
    );
    assert_eq!(
        msg(start(1, 0, 360)),
        "GaugeStart.Revolutions must be at least 1"
    );
    assert_eq!(
        msg(start(1, 3, 36_001)),
        "GaugeStart.PointsPerRev = 36001 is outside its declared range [1, 36000]"
    );
    assert_eq!(
        msg(dbc.encode(&GaugeFrame::End { status: 256 })),
        "GaugeEnd.Status = 256 is outside its declared range [0, 255]"
    );

    // Without a declared range the raw bits bound the value: 32-bit signed lift.
    let text = camloop::gauge::dbc::BUILTIN_DBC.replace("[-200|200] \"mm\"", "[0|0] \"mm\"");
    let open = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect("dbc");
    let big = open.encode(&GaugeFrame::Sample(RawSample {
        revolution: 0,
        angle_index: 0,
        lift_mm: 214_748.4,
    }));
    assert_eq!(
        msg(big),
        "GaugeSample.Lift = 214748.4 needs raw value 2147484000, beyond the 32-bit signed signal"
    );

    // In a measurement, the failing sample is named by position, revolution and index.
    let mut raw = RawMeasurement {
        header: MeasurementHeader {
            machine: "1".into(),
            part: "1".into(),
            lobe: "1".into(),
            revolutions: 3,
            points_per_rev: 4,
        },
        samples: (0..12)
            .map(|n| RawSample {
                revolution: n / 4,
                angle_index: n % 4,
                lift_mm: 0.0,
            })
            .collect(),
        origin: "t".into(),
    };
    raw.samples[6].lift_mm = 250.0;
    assert_eq!(
        encode_measurement(&dbc, &raw, 0).map_err(|e| e.to_string()),
        Err(
            "sample 6 (revolution 1, angle index 2): GaugeSample.Lift = 250 is outside its \
             declared range [-200, 200]"
                .into()
        )
    );
    raw.samples[6].lift_mm = 0.0;
    raw.header.lobe = "intake-1".into();
    assert_eq!(
        encode_measurement(&dbc, &raw, 0).map_err(|e| e.to_string()),
        Err(
            "measurement lobe \"intake-1\" cannot go on the bus: the can layout carries numeric \
             ids, so it must be a plain decimal number such as \"1\" (no sign, spaces or \
             leading zeros, at most 18446744073709551615)"
                .into()
        )
    );
}

#[test]
fn a_float_lift_site_layout_round_trips_to_single_precision() {
    // A site DBC with an extended id and an IEEE single lift in mm (SIG_VALTYPE_ 1).
    let text = camloop::gauge::dbc::BUILTIN_DBC
        .replace("BO_ 1441 GaugeSample", "BO_ 2566871553 GaugeSample")
        .replace("Lift : 24|32@1- (0.0001,0)", "Lift : 24|32@1- (1,0)")
        + "SIG_VALTYPE_ 2566871553 Lift : 1;\n";
    let dbc = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect("dbc");
    let sample = RawSample {
        revolution: 5,
        angle_index: 123,
        lift_mm: 6.123_456_789,
    };
    let (id, data) = dbc.encode(&GaugeFrame::Sample(sample)).expect("encodes");
    assert_eq!(id, CanId::Extended(0x18ff_5a01));
    assert_eq!(&data[3..7], &(sample.lift_mm as f32).to_le_bytes());
    let Ok(GaugeFrame::Sample(back)) = dbc.decode(id, &data) else {
        panic!("decodes")
    };
    // f32 near 6 mm: half an ulp is 2.4e-7 mm.
    assert!((back.lift_mm - sample.lift_mm).abs() < 2.4e-7);
    assert_eq!((back.revolution, back.angle_index), (5, 123));
}

#[test]
fn the_simulated_gauge_feeds_the_real_decoder() {
    let mut sim = demo_sim(GrinderConfig::default(), Follower::Flat, 11);
    let ground = sim
        .grind(&demo_table(Follower::Flat, 360, TableForm::Poly))
        .expect("grinds");
    let labels = PartLabels {
        machine: "1".into(),
        part: "17".into(),
        lobe: "2".into(),
    };
    let direct = sim.measure(&ground, &labels);
    assert_eq!(direct.samples.len(), 4 * 360);
    let dbc = GaugeDbc::builtin();
    let frames = measurement_frames(&dbc, &direct).expect("numeric labels encode");
    let via_can = decode_all(&dbc, &frames, "sim");
    assert_eq!(via_can.header, direct.header);

    let limits = AssemblyLimits::default();
    let a = check_and_average(&direct, &limits).expect("direct measurement is complete");
    let b = check_and_average(&via_can, &limits).expect("decoded measurement is complete");
    assert_eq!(a.revolutions_used, b.revolutions_used);
    // Each reading moves by at most half a step (0.05 µm) through the bus, so each mean
    // does too.
    let worst_um = a
        .mean_lift_mm
        .iter()
        .zip(&b.mean_lift_mm)
        .map(|(x, y)| (x - y).abs() * 1e3)
        .fold(0.0, f64::max);
    assert!(
        worst_um <= HALF_STEP_MM * 1e3,
        "worst mean difference {worst_um} µm"
    );
    assert_eq!(a.mean_lift_mm.len(), 360);

    // The sim's usual text labels cannot go on the bus, and the error says why.
    let texty = sim.measure(
        &ground,
        &PartLabels {
            machine: "SIM".into(),
            ..labels
        },
    );
    let err = measurement_frames(&dbc, &texty).expect_err("text machine label");
    assert!(
        matches!(&err, EncodeError::Label { field: "machine", value } if value == "SIM"),
        "{err}"
    );
    assert!(err.to_string().contains("numeric ids"), "{err}");
}

fn any_frame() -> impl Strategy<Value = GaugeFrame> {
    prop_oneof![
        (
            0u64..=4095,
            0u64..=16_777_215,
            0u64..=63,
            1u32..=63,
            1u32..=36_000
        )
            .prop_map(|(machine, part, lobe, revolutions, points_per_rev)| {
                GaugeFrame::Start(GaugeStart {
                    machine,
                    part,
                    lobe,
                    revolutions,
                    points_per_rev,
                })
            }),
        (0u32..=62, 0u32..=35_999, -200.0f64..=200.0).prop_map(
            |(revolution, angle_index, lift_mm)| {
                GaugeFrame::Sample(RawSample {
                    revolution,
                    angle_index,
                    lift_mm,
                })
            }
        ),
        (0u32..=255).prop_map(|status| GaugeFrame::End { status }),
    ]
}

/// Payloads of the three gauge messages. Sample fields are drawn mostly inside their
/// declared ranges and just past them (uniform bytes would almost never hold a lift within
/// ±200 mm: 0.1 % of 32-bit raw values), the rest of the time uniformly.
fn any_payload() -> impl Strategy<Value = (CanId, Vec<u8>)> {
    let sample = (
        0u64..64,
        prop_oneof![0u64..36_001, 0u64..(1 << 18)],
        prop_oneof![-2_000_001i32..=2_000_001, any::<i32>()],
    )
        .prop_map(|(rev, index, lift_raw)| {
            let word = rev | index << 6 | u64::from(lift_raw.cast_unsigned()) << 24;
            (CanId::Standard(0x5a1), word.to_le_bytes()[..7].to_vec())
        });
    prop_oneof![
        proptest::array::uniform8(any::<u8>()).prop_map(|b| (CanId::Standard(0x5a0), b.to_vec())),
        sample,
        any::<u8>().prop_map(|b| (CanId::Standard(0x5a2), vec![b])),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    /// Arbitrary in-range physical values come back: counts exactly, lift within half a
    /// step.
    #[test]
    fn in_range_frames_round_trip(frame in any_frame()) {
        let dbc = GaugeDbc::builtin();
        let (id, data) = dbc.encode(&frame).expect("in range");
        let back = dbc.decode(id, &data).expect("decodes");
        match (frame, back) {
            (GaugeFrame::Sample(sent), GaugeFrame::Sample(got)) => {
                prop_assert_eq!(
                    (got.revolution, got.angle_index),
                    (sent.revolution, sent.angle_index)
                );
                prop_assert!((got.lift_mm - sent.lift_mm).abs() <= HALF_STEP_MM);
            }
            (sent, got) => prop_assert_eq!(sent, got),
        }
    }

    /// Every payload the decoder accepts is re-encoded to the same bytes (all three
    /// messages use every bit of their payload, so nothing is left to chance).
    #[test]
    fn accepted_payloads_re_encode_identically((id, payload) in any_payload()) {
        let dbc = GaugeDbc::builtin();
        if let Ok(frame) = dbc.decode(id, &payload) {
            let (id_back, data) = dbc.encode(&frame).expect("decodable frames encode");
            prop_assert_eq!(id_back, id);
            prop_assert_eq!(data, payload);
        }
    }
}
