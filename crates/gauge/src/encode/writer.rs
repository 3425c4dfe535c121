//! Packing one frame: the 8-byte buffer, the multiplexor page its signals need, and each
//! signal's value checked against its range and step before it is written.

use super::EncodeError;
use crate::dbc::{MessageSpec, SignalSpec};
use crate::frame::CanId;
use crate::signal::{RawKind, RawValue, SignalCodec};

/// A frame being packed: the 8-byte buffer and the multiplexor page its signals need.
pub(super) struct Writer<'a, const N: usize> {
    message: &'a MessageSpec<N>,
    data: [u8; 8],
    page: Option<(SignalCodec, u64)>,
}

impl<'a, const N: usize> Writer<'a, N> {
    pub(super) fn new(message: &'a MessageSpec<N>) -> Self {
        Self {
            message,
            data: [0; 8],
            page: None,
        }
    }

    pub(super) fn finish(mut self) -> Result<(CanId, Vec<u8>), EncodeError> {
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
    pub(super) fn positive(&mut self, s: &SignalSpec, value: u32) -> Result<(), EncodeError> {
        if value == 0 {
            let (message, signal) = self.name(s);
            return Err(EncodeError::Zero { message, signal });
        }
        self.count(s, u64::from(value))
    }

    /// A whole non-negative number that must decode back exactly.
    pub(super) fn count(&mut self, s: &SignalSpec, value: u64) -> Result<(), EncodeError> {
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
    pub(super) fn physical(&mut self, s: &SignalSpec, value: f64) -> Result<f64, EncodeError> {
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
