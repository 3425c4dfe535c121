//! Pure decoding of one CAN frame `(id, payload)` into a typed [`GaugeFrame`], driven by
//! the compiled [`GaugeDbc`]. Garbage never panics: it comes back as a [`FrameError`].

use std::fmt;

use camloop_core::measure::RawSample;

use super::dbc::{GaugeDbc, MessageSpec, SignalSpec};
use super::signal::{PayloadWords, RawValue};

/// A CAN identifier: 11-bit standard or 29-bit extended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CanId {
    Standard(u16),
    Extended(u32),
}

impl fmt::Display for CanId {
    /// candump's convention: 3 hex digits for standard ids, 8 for extended ones.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Standard(id) => write!(f, "0x{id:03X}"),
            Self::Extended(id) => write!(f, "0x{id:08X}"),
        }
    }
}

/// The announcement that opens a measurement, with the numeric ids as sent on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GaugeStart {
    pub machine: u64,
    pub part: u64,
    pub lobe: u64,
    pub revolutions: u32,
    pub points_per_rev: u32,
}

/// One decoded gauge frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GaugeFrame {
    Start(GaugeStart),
    Sample(RawSample),
    /// Closes the measurement; status 0 = complete, anything else = aborted by the gauge.
    End {
        status: u32,
    },
}

/// Why a frame is not a valid gauge frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    #[error("can id {id} is not a gauge message")]
    UnknownId { id: CanId },
    #[error("{message} frame has {got} data bytes, needs {needed}")]
    TooShort {
        message: String,
        needed: usize,
        got: usize,
    },
    #[error("{message} frame has {got} data bytes; classic CAN carries at most 8")]
    TooLong { message: String, got: usize },
    #[error("{message}.{signal} = {value} is outside its declared range [{min}, {max}]")]
    OutOfRange {
        message: String,
        signal: String,
        value: f64,
        min: f64,
        max: f64,
    },
    #[error("{message}.{signal} = {value} is not a whole number in 0..={max}")]
    NotACount {
        message: String,
        signal: String,
        value: f64,
        max: u64,
    },
    #[error("{message}.{signal} = {value} is not a finite number")]
    NotFinite {
        message: String,
        signal: String,
        value: f64,
    },
    #[error("{message}.{signal} must be at least 1")]
    Zero { message: String, signal: String },
    #[error(
        "{message}.{signal} is not in this frame (multiplexor is {found}, signal needs {expected})"
    )]
    Multiplexed {
        message: String,
        signal: String,
        expected: u64,
        found: u64,
    },
}

impl GaugeDbc {
    /// Decodes one classic CAN data frame. The payload must carry at least the DBC message
    /// size and at most 8 bytes; every signal must lie in its declared `[min|max]`, and the
    /// counting signals (ids, revolutions, indices, status) must be whole non-negative numbers.
    pub fn decode(&self, id: CanId, data: &[u8]) -> Result<GaugeFrame, FrameError> {
        if id == self.sample.id {
            let words = payload(&self.sample, data)?;
            let [rev, index, lift] = &self.sample.signals;
            Ok(GaugeFrame::Sample(RawSample {
                revolution: count_u32(&self.sample, rev, words)?,
                angle_index: count_u32(&self.sample, index, words)?,
                lift_mm: physical(&self.sample, lift, words)?,
            }))
        } else if id == self.start.id {
            let m = &self.start;
            let words = payload(m, data)?;
            let [machine, part, lobe, revs, ppr] = &m.signals;
            let start = GaugeStart {
                machine: count(m, machine, words, u64::MAX)?,
                part: count(m, part, words, u64::MAX)?,
                lobe: count(m, lobe, words, u64::MAX)?,
                revolutions: positive_u32(m, revs, words)?,
                points_per_rev: positive_u32(m, ppr, words)?,
            };
            Ok(GaugeFrame::Start(start))
        } else if id == self.end.id {
            let words = payload(&self.end, data)?;
            let [status] = &self.end.signals;
            Ok(GaugeFrame::End {
                status: count_u32(&self.end, status, words)?,
            })
        } else {
            Err(FrameError::UnknownId { id })
        }
    }
}

fn payload<const N: usize>(m: &MessageSpec<N>, data: &[u8]) -> Result<PayloadWords, FrameError> {
    if data.len() > 8 {
        return Err(FrameError::TooLong {
            message: m.name.clone(),
            got: data.len(),
        });
    }
    if data.len() < m.size_bytes {
        return Err(FrameError::TooShort {
            message: m.name.clone(),
            needed: m.size_bytes,
            got: data.len(),
        });
    }
    Ok(PayloadWords::new(data))
}

/// The physical value `raw · factor + offset`, checked against the declared range.
#[inline]
fn physical<const N: usize>(
    m: &MessageSpec<N>,
    s: &SignalSpec,
    words: PayloadWords,
) -> Result<f64, FrameError> {
    check_multiplexor(m, s, words)?;
    // Precision: raw values above 2^53 lose their last bits here; the counting signals take
    // the exact path in `count` instead.
    #[allow(clippy::cast_precision_loss)]
    let raw = match s.codec.raw_value(words) {
        RawValue::Unsigned(v) => v as f64,
        RawValue::Signed(v) => v as f64,
        RawValue::Float(v) => v,
    };
    let value = raw * s.factor + s.offset;
    if !value.is_finite() {
        return Err(FrameError::NotFinite {
            message: m.name.clone(),
            signal: s.name.clone(),
            value,
        });
    }
    check_range(m, s, value)?;
    Ok(value)
}

#[inline]
fn check_multiplexor<const N: usize>(
    m: &MessageSpec<N>,
    s: &SignalSpec,
    words: PayloadWords,
) -> Result<(), FrameError> {
    match s.multiplexed {
        Some((mux, expected)) if mux.raw_bits(words) != expected => Err(FrameError::Multiplexed {
            message: m.name.clone(),
            signal: s.name.clone(),
            expected,
            found: mux.raw_bits(words),
        }),
        _ => Ok(()),
    }
}

#[inline]
fn check_range<const N: usize>(
    m: &MessageSpec<N>,
    s: &SignalSpec,
    value: f64,
) -> Result<(), FrameError> {
    if let Some((min, max)) = s.range {
        // Half a raw step of slack so a bound that is not a multiple of the factor in binary
        // (0.0001 · 2 000 000 vs 200) does not reject the raw value that encodes it.
        let slack = 0.5 * s.factor.abs();
        if value < min - slack || value > max + slack {
            return Err(FrameError::OutOfRange {
                message: m.name.clone(),
                signal: s.name.clone(),
                value,
                min,
                max,
            });
        }
    }
    Ok(())
}

/// A whole, non-negative physical value in `0..=max`. Integer signals with whole factor and
/// offset (the usual case for counters) are scaled exactly in integers; otherwise the value
/// must land on a whole number.
#[inline]
fn count<const N: usize>(
    m: &MessageSpec<N>,
    s: &SignalSpec,
    words: PayloadWords,
    max: u64,
) -> Result<u64, FrameError> {
    let not_a_count = |value: f64| FrameError::NotACount {
        message: m.name.clone(),
        signal: s.name.clone(),
        value,
        max,
    };
    if let Some((factor, offset)) = s.integer_scale {
        let raw = match s.codec.raw_value(words) {
            RawValue::Unsigned(v) => Some(i128::from(v)),
            RawValue::Signed(v) => Some(i128::from(v)),
            RawValue::Float(_) => None, // integer_scale is only set for integer signals
        };
        if let Some(raw) = raw {
            check_multiplexor(m, s, words)?;
            // |raw| < 2^64 and |factor|, |offset| < 2^54: no overflow in i128.
            let value = raw * i128::from(factor) + i128::from(offset);
            #[allow(clippy::cast_precision_loss)]
            let shown = value as f64;
            check_range(m, s, shown)?;
            return match u64::try_from(value) {
                Ok(v) if v <= max => Ok(v),
                _ => Err(not_a_count(shown)),
            };
        }
    }
    let value = physical(m, s, words)?;
    if value.fract() == 0.0 && (0.0..18_446_744_073_709_551_616.0).contains(&value) {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let v = value as u64;
        if v <= max {
            return Ok(v);
        }
    }
    Err(not_a_count(value))
}

fn count_u32<const N: usize>(
    m: &MessageSpec<N>,
    s: &SignalSpec,
    words: PayloadWords,
) -> Result<u32, FrameError> {
    let v = count(m, s, words, u64::from(u32::MAX))?;
    Ok(u32::try_from(v).expect("bounded by u32::MAX in count"))
}

fn positive_u32<const N: usize>(
    m: &MessageSpec<N>,
    s: &SignalSpec,
    words: PayloadWords,
) -> Result<u32, FrameError> {
    match count_u32(m, s, words)? {
        0 => Err(FrameError::Zero {
            message: m.name.clone(),
            signal: s.name.clone(),
        }),
        v => Ok(v),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dbc::{BUILTIN_DBC, GaugeSignalNames};

    const START: CanId = CanId::Standard(0x5a0);
    const SAMPLE: CanId = CanId::Standard(0x5a1);
    const END: CanId = CanId::Standard(0x5a2);

    /// Hand encoding of GaugeSample (Intel): bits 0..6 revolution, 6..24 angle index,
    /// 24..56 lift in 0.1 µm, two's complement.
    fn sample_bytes(rev: u32, index: u32, lift_raw: i32) -> [u8; 7] {
        let word = u64::from(rev) | u64::from(index) << 6 | u64::from(lift_raw as u32) << 24;
        let b = word.to_le_bytes();
        [b[0], b[1], b[2], b[3], b[4], b[5], b[6]]
    }

    #[test]
    fn decodes_samples_with_negative_lift() {
        let dbc = GaugeDbc::builtin();
        let frame = dbc
            .decode(SAMPLE, &sample_bytes(2, 359, -12))
            .expect("valid");
        let GaugeFrame::Sample(s) = frame else {
            panic!("expected a sample, got {frame:?}")
        };
        assert_eq!((s.revolution, s.angle_index), (2, 359));
        // -12 raw × 0.0001 mm; f64 rounding of the factor is far below 1e-12 mm.
        assert!((s.lift_mm - -0.0012).abs() < 1e-12, "{}", s.lift_mm);
        // An 8-byte payload (padded by the gauge) is accepted too.
        let mut padded = [0u8; 8];
        padded[..7].copy_from_slice(&sample_bytes(0, 1, 5));
        assert!(matches!(
            dbc.decode(SAMPLE, &padded),
            Ok(GaugeFrame::Sample(RawSample { angle_index: 1, .. }))
        ));
    }

    #[test]
    fn decodes_start_and_end() {
        let dbc = GaugeDbc::builtin();
        // The cantools vector from signal.rs.
        let data = [0xab, 0xcb, 0x43, 0x12, 0x34, 0x56, 0x01, 0x68];
        assert_eq!(
            dbc.decode(START, &data),
            Ok(GaugeFrame::Start(GaugeStart {
                machine: 0xabc,
                part: 0x12_3456,
                lobe: 0x2d,
                revolutions: 3,
                points_per_rev: 360,
            }))
        );
        assert_eq!(dbc.decode(END, &[2]), Ok(GaugeFrame::End { status: 2 }));
    }

    #[test]
    fn garbage_comes_back_as_typed_errors() {
        let dbc = GaugeDbc::builtin();
        let e = |id, data: &[u8]| {
            dbc.decode(id, data)
                .expect_err("must be rejected")
                .to_string()
        };
        assert_eq!(
            e(CanId::Standard(0x123), &[]),
            "can id 0x123 is not a gauge message"
        );
        assert_eq!(
            e(CanId::Extended(0x5a1), &[0; 8]),
            "can id 0x000005A1 is not a gauge message"
        );
        assert_eq!(
            e(SAMPLE, &[0; 6]),
            "GaugeSample frame has 6 data bytes, needs 7"
        );
        assert_eq!(e(END, &[]), "GaugeEnd frame has 0 data bytes, needs 1");
        assert_eq!(
            e(SAMPLE, &[0; 12]),
            "GaugeSample frame has 12 data bytes; classic CAN carries at most 8"
        );
        // Revolution 63 is beyond the declared [0|62].
        assert_eq!(
            e(SAMPLE, &sample_bytes(63, 0, 0)),
            "GaugeSample.Revolution = 63 is outside its declared range [0, 62]"
        );
        // Angle index 36000 is beyond [0|35999].
        assert_eq!(
            e(SAMPLE, &sample_bytes(0, 36_000, 0)),
            "GaugeSample.AngleIndex = 36000 is outside its declared range [0, 35999]"
        );
        // Lift 200.0001 mm is beyond [-200|200].
        let msg = e(SAMPLE, &sample_bytes(0, 0, 2_000_001));
        assert!(msg.starts_with("GaugeSample.Lift = 200.000"), "{msg}");
        // Revolutions 0 in a start frame (declared [1|63]).
        let mut start = [0xab, 0xcb, 0x40, 0x12, 0x34, 0x56, 0x01, 0x68];
        assert_eq!(
            e(START, &start),
            "GaugeStart.Revolutions = 0 is outside its declared range [1, 63]"
        );
        start[2] = 0x43;
        start[6] = 0;
        start[7] = 0;
        assert_eq!(
            e(START, &start),
            "GaugeStart.PointsPerRev = 0 is outside its declared range [1, 36000]"
        );
    }

    #[test]
    fn zero_counts_are_rejected_even_without_a_declared_range() {
        let text = BUILTIN_DBC.replace("[1|36000]", "[0|0]");
        let dbc = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect("dbc");
        let start = [0xab, 0xcb, 0x43, 0x12, 0x34, 0x56, 0, 0];
        assert_eq!(
            dbc.decode(START, &start).map_err(|e| e.to_string()),
            Err("GaugeStart.PointsPerRev must be at least 1".to_owned())
        );
    }

    #[test]
    fn fractional_scaling_of_a_counter_must_land_on_whole_numbers() {
        // AngleIndex scaled by 0.5: raw 720 → 360 is whole, raw 721 → 360.5 is not.
        let text = BUILTIN_DBC.replace(
            "AngleIndex : 6|18@1+ (1,0) [0|35999]",
            "AngleIndex : 6|18@1+ (0.5,0) [0|0]",
        );
        let dbc = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect("dbc");
        let ok = dbc.decode(SAMPLE, &sample_bytes(0, 720, 0));
        assert!(matches!(
            ok,
            Ok(GaugeFrame::Sample(RawSample {
                angle_index: 360,
                ..
            }))
        ));
        let bad = dbc.decode(SAMPLE, &sample_bytes(0, 721, 0));
        assert_eq!(
            bad.map_err(|e| e.to_string()),
            Err("GaugeSample.AngleIndex = 360.5 is not a whole number in 0..=4294967295".into())
        );
    }

    #[test]
    fn multiplexed_signals_are_checked_against_their_multiplexor() {
        // A site layout where the sample frame carries a page multiplexor in byte 7 and the
        // lift only on page 1.
        let text = BUILTIN_DBC
            .replace(
                "GaugeSample: 7 Gauge",
                "GaugeSample: 8 Gauge\n SG_ Page M : 56|8@1+ (1,0) [0|0] \"\" Camloop",
            )
            .replace("SG_ Lift : ", "SG_ Lift m1 : ");
        let dbc = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect("dbc");
        let mut data = [0u8; 8];
        data[..7].copy_from_slice(&sample_bytes(1, 2, 30));
        data[7] = 1;
        assert!(matches!(
            dbc.decode(SAMPLE, &data),
            Ok(GaugeFrame::Sample(RawSample { revolution: 1, .. }))
        ));
        data[7] = 4;
        assert_eq!(
            dbc.decode(SAMPLE, &data).map_err(|e| e.to_string()),
            Err("GaugeSample.Lift is not in this frame (multiplexor is 4, signal needs 1)".into())
        );
    }

    #[test]
    fn extended_ids_and_float_lift_from_a_site_dbc() {
        // Extended ids are written in DBC with bit 31 set: 0x80000000 | 0x18FF5A01.
        let text = BUILTIN_DBC
            .replace("BO_ 1441 GaugeSample", "BO_ 2566871553 GaugeSample")
            .replace("Lift : 24|32@1- (0.0001,0)", "Lift : 24|32@1- (1,0)")
            + "SIG_VALTYPE_ 2566871553 Lift : 1;\n";
        let dbc = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect("dbc");
        assert_eq!(dbc.sample.id, CanId::Extended(0x18ff_5a01));
        let mut data = [0u8; 7];
        data[3..7].copy_from_slice(&(-0.0025f32).to_le_bytes());
        let GaugeFrame::Sample(s) = dbc
            .decode(CanId::Extended(0x18ff_5a01), &data)
            .expect("valid")
        else {
            panic!("not a sample")
        };
        // f32 carries -0.0025 to within 1.2e-10 (half an ulp at that magnitude).
        assert!((s.lift_mm - -0.0025).abs() < 1e-9, "{}", s.lift_mm);
    }
}
