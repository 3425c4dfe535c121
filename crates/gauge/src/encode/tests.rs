//! The encoder against cantools' vector, the decoder and its own refusals.

use super::*;
use crate::candump::parse_candump_line;
use crate::dbc::{BUILTIN_DBC, GaugeSignalNames};
use camloop_core::measure::RawSample;

#[test]
fn the_cantools_start_vector_is_reproduced() {
    // The vector in signal.rs: cantools 45.1 encoded this start frame.
    let dbc = GaugeDbc::builtin();
    let frame = GaugeFrame::Start(GaugeStart {
        machine: 0xabc,
        part: 0x12_3456,
        lobe: 0x2d,
        revolutions: 3,
        points_per_rev: 360,
    });
    assert_eq!(
        dbc.encode(&frame),
        Ok((
            CanId::Standard(0x5a0),
            vec![0xab, 0xcb, 0x43, 0x12, 0x34, 0x56, 0x01, 0x68]
        ))
    );
}

#[test]
fn lift_rounds_to_the_nearest_step_with_ties_to_even() {
    let dbc = GaugeDbc::builtin();
    let lift_raw = |lift_mm: f64| {
        let (_, data) = dbc
            .encode(&GaugeFrame::Sample(RawSample {
                revolution: 0,
                angle_index: 0,
                lift_mm,
            }))
            .expect("in range");
        i32::from_le_bytes([data[3], data[4], data[5], data[6]])
    };
    // 0.00012 mm = 1.2 steps → 1; 0.00018 → 2; −0.00018 → −2.
    assert_eq!(lift_raw(0.00012), 1);
    assert_eq!(lift_raw(0.00018), 2);
    assert_eq!(lift_raw(-0.00018), -2);
    // 2.5 steps: 0.00025 / 0.0001 is exactly 2.5 in f64 (checked here), so the tie
    // goes to the even raw value 2, as Python's round() does in cantools.
    assert_eq!(0.00025f64 / 0.0001, 2.5);
    assert_eq!(lift_raw(0.00025), 2);
}

#[test]
fn multiplexed_signals_get_their_page_and_conflicts_are_named() {
    let text = BUILTIN_DBC
        .replace(
            "GaugeSample: 7 Gauge",
            "GaugeSample: 8 Gauge\n SG_ Page M : 56|8@1+ (1,0) [0|0] \"\" Camloop",
        )
        .replace("SG_ Lift :", "SG_ Lift m1 :");
    let dbc = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect("dbc");
    let sample = GaugeFrame::Sample(RawSample {
        revolution: 1,
        angle_index: 2,
        lift_mm: 0.5,
    });
    let (_, data) = dbc.encode(&sample).expect("one page");
    assert_eq!(data.len(), 8);
    assert_eq!(data[7], 1, "page 1 written to the multiplexor byte");
    assert_eq!(dbc.decode(CanId::Standard(0x5a1), &data), Ok(sample));

    let clash = text.replace("SG_ Revolution :", "SG_ Revolution m2 :");
    let dbc = GaugeDbc::from_dbc_text(&clash, &GaugeSignalNames::default()).expect("dbc");
    assert_eq!(
        dbc.encode(&sample).map_err(|e| e.to_string()),
        Err("GaugeSample.Lift needs multiplexor value 1, but the frame already carries 2".into())
    );
    let high = text.replace("SG_ Lift m1 :", "SG_ Lift m300 :");
    let dbc = GaugeDbc::from_dbc_text(&high, &GaugeSignalNames::default()).expect("dbc");
    assert_eq!(
        dbc.encode(&sample).map_err(|e| e.to_string()),
        Err("GaugeSample.Lift needs multiplexor value 300, beyond its 8-bit multiplexor".into())
    );
}

#[test]
fn fractional_count_scaling_must_land_on_a_step() {
    let text = BUILTIN_DBC.replace(
        "AngleIndex : 6|18@1+ (1,0) [0|35999]",
        "AngleIndex : 6|18@1+ (0.5,0) [0|0]",
    );
    let dbc = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect("dbc");
    let sample = GaugeFrame::Sample(RawSample {
        revolution: 0,
        angle_index: 360,
        lift_mm: 0.0,
    });
    let (id, data) = dbc.encode(&sample).expect("raw 720");
    assert_eq!(dbc.decode(id, &data), Ok(sample));
    // Factor 2: odd indices have no raw value.
    let text = BUILTIN_DBC.replace(
        "AngleIndex : 6|18@1+ (1,0) [0|35999]",
        "AngleIndex : 6|18@1+ (2,0) [0|0]",
    );
    let dbc = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect("dbc");
    let odd = GaugeFrame::Sample(RawSample {
        revolution: 0,
        angle_index: 361,
        lift_mm: 0.0,
    });
    assert_eq!(
        dbc.encode(&odd).map_err(|e| e.to_string()),
        Err(
            "GaugeSample.AngleIndex = 361 is not a whole number of steps of 2 from 0, \
             so it cannot be sent exactly"
                .into()
        )
    );
}

#[test]
fn a_count_past_the_signal_bits_without_a_declared_range_overflows() {
    let text = BUILTIN_DBC.replace("[0|4095]", "[0|0]");
    let dbc = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect("dbc");
    let start = GaugeFrame::Start(GaugeStart {
        machine: 4096,
        part: 1,
        lobe: 1,
        revolutions: 3,
        points_per_rev: 360,
    });
    assert_eq!(
        dbc.encode(&start).map_err(|e| e.to_string()),
        Err(
            "GaugeStart.Machine = 4096 needs raw value 4096, beyond the 12-bit unsigned \
             signal"
                .into()
        )
    );
}

#[test]
fn labels_must_be_canonical_decimals() {
    assert_eq!(numeric_label("part", "1234"), Ok(1234));
    assert_eq!(numeric_label("part", "0"), Ok(0));
    for bad in ["", "SIM", "007", "+1", " 1", "1.0", "18446744073709551616"] {
        assert!(
            matches!(numeric_label("part", bad), Err(EncodeError::Label { .. })),
            "{bad:?}"
        );
    }
}

#[test]
fn candump_lines_parse_back() {
    let line = candump_line(
        1_700_000_000.002_778,
        "can0",
        CanId::Standard(0x5a1),
        &[0, 0xab, 0x0f],
    );
    assert_eq!(line, "(1700000000.002778) can0 5A1#00AB0F");
    let ext = candump_line(0.5, "vcan1", CanId::Extended(0x18fe_f100), &[]);
    assert_eq!(ext, "(0.500000) vcan1 18FEF100#");
    let r = parse_candump_line(&line).expect("parses");
    assert_eq!(
        (r.id, r.data(), r.interface),
        (CanId::Standard(0x5a1), &[0, 0xab, 0x0f][..], "can0")
    );
    // 1e-7 s tolerance: the line keeps microseconds.
    assert!((r.timestamp_s - 1_700_000_000.002_778).abs() < 1e-6);
}
