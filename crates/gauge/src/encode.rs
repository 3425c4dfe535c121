//! Encoding gauge frames: the exact inverse of [`GaugeDbc::decode`], driven by the same
//! compiled DBC, plus a whole measurement as a frame sequence and the `candump -l` line
//! format. Pure: bytes and strings out, no bus.
//!
//! Contract, checked by tests against the decoder and against cantools:
//! - every frame [`GaugeDbc::encode`] returns decodes to the frame it was given, with
//!   physical values rounded to the nearest raw step (ties to even, as cantools rounds) and
//!   counts exact;
//! - every payload the decoder accepts re-encodes to the same bytes (bits that no gauge
//!   signal covers are written as zero);
//! - what the decoder would reject is refused here with a typed error naming the message
//!   and the signal, never silently clamped or wrapped.

use std::fmt::Write as _;

use camloop_core::measure::RawMeasurement;

use super::dbc::{GaugeDbc, MessageSpec, SignalSpec};
use super::frame::{CanId, GaugeFrame, GaugeStart};
use super::signal::{RawKind, RawValue, SignalCodec};

/// Why a frame or a measurement cannot be put on the bus with this DBC.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EncodeError {
    /// The value lies outside the DBC's `[min|max]` (with the decoder's half-step slack).
    #[error("{message}.{signal} = {value} is outside its declared range [{min}, {max}]")]
    OutOfRange {
        message: String,
        signal: String,
        value: f64,
        min: f64,
        max: f64,
    },
    /// The raw value `(value − offset) / factor` does not fit the signal's bits.
    #[error(
        "{message}.{signal} = {value} needs raw value {raw}, beyond the {length}-bit {kind} signal"
    )]
    RawOverflow {
        message: String,
        signal: String,
        value: f64,
        raw: f64,
        length: u32,
        kind: &'static str,
    },
    #[error("{message}.{signal} = {value} is not a finite number")]
    NotFinite {
        message: String,
        signal: String,
        value: f64,
    },
    /// A count that no raw value encodes exactly (factor/offset step past it).
    #[error(
        "{message}.{signal} = {value} is not a whole number of steps of {factor} from {offset}, so it cannot be sent exactly"
    )]
    NotRepresentable {
        message: String,
        signal: String,
        value: u64,
        factor: f64,
        offset: f64,
    },
    #[error("{message}.{signal} must be at least 1")]
    Zero { message: String, signal: String },
    /// Two gauge signals of one message live on different multiplexor pages: no single
    /// frame can carry them.
    #[error(
        "{message}.{signal} needs multiplexor value {wanted}, but the frame already carries {carried}"
    )]
    MultiplexorClash {
        message: String,
        signal: String,
        wanted: u64,
        carried: u64,
    },
    /// The DBC puts a signal on a page number its multiplexor's bits cannot hold.
    #[error(
        "{message}.{signal} needs multiplexor value {wanted}, beyond its {length}-bit multiplexor"
    )]
    MultiplexorTooShort {
        message: String,
        signal: String,
        wanted: u64,
        length: u32,
    },
    /// A measurement header label is not the decimal number the CAN layout carries.
    #[error(
        "measurement {field} {value:?} cannot go on the bus: the can layout carries numeric ids, so it must be a plain decimal number such as \"1\" (no sign, spaces or leading zeros, at most {max})",
        max = u64::MAX
    )]
    Label { field: &'static str, value: String },
    /// A sample of a measurement could not be encoded.
    #[error("sample {index} (revolution {revolution}, angle index {angle_index}): {source}")]
    Sample {
        index: usize,
        revolution: u32,
        angle_index: u32,
        source: Box<EncodeError>,
    },
}

impl GaugeDbc {
    /// Encodes one gauge frame as `(can id, payload)`; the payload is the DBC message size
    /// long. The inverse of [`GaugeDbc::decode`] (see the module docs for the contract).
    pub fn encode(&self, frame: &GaugeFrame) -> Result<(CanId, Vec<u8>), EncodeError> {
        match frame {
            GaugeFrame::Start(start) => {
                let GaugeStart {
                    machine,
                    part,
                    lobe,
                    revolutions,
                    points_per_rev,
                } = *start;
                let m = &self.start;
                let [s_machine, s_part, s_lobe, s_revs, s_ppr] = &m.signals;
                let mut w = Writer::new(m);
                w.count(s_machine, machine)?;
                w.count(s_part, part)?;
                w.count(s_lobe, lobe)?;
                w.positive(s_revs, revolutions)?;
                w.positive(s_ppr, points_per_rev)?;
                w.finish()
            }
            GaugeFrame::Sample(sample) => {
                let m = &self.sample;
                let [s_rev, s_index, s_lift] = &m.signals;
                let mut w = Writer::new(m);
                w.count(s_rev, u64::from(sample.revolution))?;
                w.count(s_index, u64::from(sample.angle_index))?;
                w.physical(s_lift, sample.lift_mm)?;
                w.finish()
            }
            GaugeFrame::End { status } => {
                let m = &self.end;
                let [s_status] = &m.signals;
                let mut w = Writer::new(m);
                w.count(s_status, u64::from(*status))?;
                w.finish()
            }
        }
    }
}

/// A whole measurement as the gauge sends it: GaugeStart, every sample in the order held,
/// then GaugeEnd with `status` (0 = complete). The header's machine, part and lobe must be
/// plain decimal numbers (`"3"`, `"1234"`), exactly as the decoder renders the ids it
/// receives, so that decoding gives back the same strings (part `MASTER` is sent as the
/// master's number, see [`super::assemble::MASTER_PART_NUMBER`]); anything else is
/// [`EncodeError::Label`]. Samples are encoded as given, even off the announced grid (the
/// assembler on the other side judges those). A failing sample is named by its position.
pub fn encode_measurement(
    dbc: &GaugeDbc,
    m: &RawMeasurement,
    status: u8,
) -> Result<Vec<(CanId, Vec<u8>)>, EncodeError> {
    let h = &m.header;
    let start = GaugeStart {
        machine: numeric_label("machine", &h.machine)?,
        part: if h.part == super::assemble::MASTER_PART {
            super::assemble::MASTER_PART_NUMBER
        } else {
            numeric_label("part", &h.part)?
        },
        lobe: numeric_label("lobe", &h.lobe)?,
        revolutions: h.revolutions,
        points_per_rev: h.points_per_rev,
    };
    let mut frames = Vec::with_capacity(m.samples.len() + 2);
    frames.push(dbc.encode(&GaugeFrame::Start(start))?);
    for (index, sample) in m.samples.iter().enumerate() {
        let frame =
            dbc.encode(&GaugeFrame::Sample(*sample))
                .map_err(|source| EncodeError::Sample {
                    index,
                    revolution: sample.revolution,
                    angle_index: sample.angle_index,
                    source: Box::new(source),
                })?;
        frames.push(frame);
    }
    frames.push(dbc.encode(&GaugeFrame::End {
        status: u32::from(status),
    })?);
    Ok(frames)
}

/// One `candump -l` log line, `(seconds.micros) iface ID#DATA`: 3 upper-case hex digits for
/// a standard id, 8 for an extended one, data as upper-case hex bytes with no separators,
/// no trailing newline. [`super::candump::parse_candump_line`] reads it back when `ts_s` is
/// finite and non-negative, `iface` has no whitespace and `data` is at most 8 bytes; the
/// timestamp is written to the microsecond, as candump does.
pub fn candump_line(ts_s: f64, iface: &str, id: CanId, data: &[u8]) -> String {
    let mut line = String::with_capacity(32 + iface.len() + 2 * data.len());
    // Writing to a String cannot fail.
    let _ = write!(line, "({ts_s:.6}) {iface} ");
    let _ = match id {
        CanId::Standard(id) => write!(line, "{id:03X}#"),
        CanId::Extended(id) => write!(line, "{id:08X}#"),
    };
    for byte in data {
        let _ = write!(line, "{byte:02X}");
    }
    line
}

/// A label as the CAN id it stands for: canonical decimal only, so the round trip through
/// the decoder (which renders `u64::to_string`) gives back the same text.
fn numeric_label(field: &'static str, value: &str) -> Result<u64, EncodeError> {
    let canonical = !value.is_empty()
        && value.bytes().all(|b| b.is_ascii_digit())
        && (value == "0" || !value.starts_with('0'));
    canonical
        .then(|| value.parse::<u64>().ok())
        .flatten()
        .ok_or_else(|| EncodeError::Label {
            field,
            value: value.to_owned(),
        })
}

/// A frame being packed: the 8-byte buffer and the multiplexor page its signals need.
struct Writer<'a, const N: usize> {
    message: &'a MessageSpec<N>,
    data: [u8; 8],
    page: Option<(SignalCodec, u64)>,
}

impl<'a, const N: usize> Writer<'a, N> {
    fn new(message: &'a MessageSpec<N>) -> Self {
        Self {
            message,
            data: [0; 8],
            page: None,
        }
    }

    fn finish(mut self) -> Result<(CanId, Vec<u8>), EncodeError> {
        if let Some((mux, value)) = self.page {
            mux.write_bits(&mut self.data, value);
        }
        let len = self.message.size_bytes.min(8);
        Ok((self.message.id, self.data[..len].to_vec()))
    }

    fn name(&self, s: &SignalSpec) -> (String, String) {
        (self.message.name.clone(), s.name.clone())
    }

    /// Records the multiplexor page `s` needs; the decoder checks it on every signal.
    fn select_page(&mut self, s: &SignalSpec) -> Result<(), EncodeError> {
        let Some((mux, wanted)) = s.multiplexed else {
            return Ok(());
        };
        let (message, signal) = self.name(s);
        match self.page {
            Some((_, carried)) if carried != wanted => Err(EncodeError::MultiplexorClash {
                message,
                signal,
                wanted,
                carried,
            }),
            _ if mux.bits_of(RawValue::Unsigned(wanted)) != Some(wanted) => {
                Err(EncodeError::MultiplexorTooShort {
                    message,
                    signal,
                    wanted,
                    length: mux.length(),
                })
            }
            _ => {
                self.page = Some((mux, wanted));
                Ok(())
            }
        }
    }

    /// The decoder's range check, with the same half-step slack, so that whatever the
    /// decoder accepts the encoder accepts too.
    fn check_range(&self, s: &SignalSpec, checked: f64, shown: f64) -> Result<(), EncodeError> {
        if let Some((min, max)) = s.range {
            let slack = 0.5 * s.factor.abs();
            if !(min - slack..=max + slack).contains(&checked) {
                let (message, signal) = self.name(s);
                return Err(EncodeError::OutOfRange {
                    message,
                    signal,
                    value: shown,
                    min,
                    max,
                });
            }
        }
        Ok(())
    }

    /// A count at least 1 (revolutions, points per revolution).
    fn positive(&mut self, s: &SignalSpec, value: u32) -> Result<(), EncodeError> {
        if value == 0 {
            let (message, signal) = self.name(s);
            return Err(EncodeError::Zero { message, signal });
        }
        self.count(s, u64::from(value))
    }

    /// A whole non-negative number that must decode back exactly.
    fn count(&mut self, s: &SignalSpec, value: u64) -> Result<(), EncodeError> {
        let not_representable = |w: &Self| {
            let (message, signal) = w.name(s);
            EncodeError::NotRepresentable {
                message,
                signal,
                value,
                factor: s.factor,
                offset: s.offset,
            }
        };
        // Display only: counts beyond 2^53 show rounded in messages.
        #[allow(clippy::cast_precision_loss)]
        let shown = value as f64;
        if let Some((factor, offset)) = s.integer_scale {
            // The decoder's exact path: value = raw · factor + offset in integers.
            self.check_range(s, shown, shown)?;
            let steps = i128::from(value) - i128::from(offset);
            let factor = i128::from(factor);
            if steps % factor != 0 {
                return Err(not_representable(self));
            }
            let raw = steps / factor;
            let bits = match (i64::try_from(raw), u64::try_from(raw)) {
                (Ok(v), _) => s.codec.bits_of(RawValue::Signed(v)),
                (_, Ok(v)) => s.codec.bits_of(RawValue::Unsigned(v)),
                _ => None,
            };
            let Some(bits) = bits else {
                #[allow(clippy::cast_precision_loss)]
                return Err(self.overflow(s, shown, raw as f64));
            };
            self.select_page(s)?;
            s.codec.write_bits(&mut self.data, bits);
            return Ok(());
        }
        // Fractional scaling (or a float signal): the value must land on a raw step exactly
        // and survive f64, as the decoder's `count` requires.
        let decoded = self.physical(s, shown)?;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let exact = decoded == shown && decoded.fract() == 0.0 && decoded as u64 == value;
        if exact {
            Ok(())
        } else {
            Err(not_representable(self))
        }
    }

    /// A physical value: raw = (value − offset) / factor, rounded to the nearest integer
    /// (ties to even, as cantools) for integer signals. Returns the value the decoder will
    /// read back.
    fn physical(&mut self, s: &SignalSpec, value: f64) -> Result<f64, EncodeError> {
        let not_finite = |w: &Self| {
            let (message, signal) = w.name(s);
            EncodeError::NotFinite {
                message,
                signal,
                value,
            }
        };
        if !value.is_finite() {
            return Err(not_finite(self));
        }
        self.check_range(s, value, value)?;
        let raw = (value - s.offset) / s.factor;
        let (bits, raw_back) = match s.codec.kind() {
            RawKind::Unsigned | RawKind::Signed => {
                let rounded = raw.round_ties_even();
                let (lo, hi) = s
                    .codec
                    .integer_range()
                    .expect("integer kinds have an integer range");
                // Powers of two and their negatives are exact in f64, so this bounds the
                // cast below without rounding trouble.
                #[allow(clippy::cast_precision_loss)]
                let (lo_f, hi_excl) = (lo as f64, (hi + 1) as f64);
                if !(rounded >= lo_f && rounded < hi_excl) {
                    return Err(self.overflow(s, value, rounded));
                }
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let raw_value = if rounded < 0.0 {
                    RawValue::Signed(rounded as i64)
                } else {
                    RawValue::Unsigned(rounded as u64)
                };
                let bits = s
                    .codec
                    .bits_of(raw_value)
                    .ok_or_else(|| self.overflow(s, value, rounded))?;
                (bits, rounded)
            }
            RawKind::Float32 => {
                let bits = s
                    .codec
                    .bits_of(RawValue::Float(raw))
                    .ok_or_else(|| self.overflow(s, value, raw))?;
                let single = u32::try_from(bits).expect("32-bit pattern");
                (bits, f64::from(f32::from_bits(single)))
            }
            RawKind::Float64 => (raw.to_bits(), raw),
        };
        // What the decoder will compute, checked as the decoder checks it.
        let decoded = raw_back * s.factor + s.offset;
        if !decoded.is_finite() {
            return Err(not_finite(self));
        }
        self.check_range(s, decoded, value)?;
        self.select_page(s)?;
        s.codec.write_bits(&mut self.data, bits);
        Ok(decoded)
    }

    fn overflow(&self, s: &SignalSpec, value: f64, raw: f64) -> EncodeError {
        let (message, signal) = self.name(s);
        EncodeError::RawOverflow {
            message,
            signal,
            value,
            raw,
            length: s.codec.length(),
            kind: match s.codec.kind() {
                RawKind::Unsigned => "unsigned",
                RawKind::Signed => "signed",
                RawKind::Float32 => "32-bit float",
                RawKind::Float64 => "64-bit float",
            },
        }
    }
}

#[cfg(test)]
mod tests {
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
            Err(
                "GaugeSample.Lift needs multiplexor value 1, but the frame already carries 2"
                    .into()
            )
        );
        let high = text.replace("SG_ Lift m1 :", "SG_ Lift m300 :");
        let dbc = GaugeDbc::from_dbc_text(&high, &GaugeSignalNames::default()).expect("dbc");
        assert_eq!(
            dbc.encode(&sample).map_err(|e| e.to_string()),
            Err(
                "GaugeSample.Lift needs multiplexor value 300, beyond its 8-bit multiplexor".into()
            )
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
}
