//! Bit-level extraction of one DBC signal from a classic CAN payload (≤ 8 bytes).
//!
//! A [`SignalCodec`] is compiled once from a DBC signal definition and then applied to many
//! frames. Byte order follows the DBC convention:
//! - Intel (`@1`, little endian): `start_bit` is the least significant bit, numbered
//!   `byte·8 + bit` with bit 0 the LSB of the byte; the signal grows towards higher bytes.
//! - Motorola (`@0`, big endian): `start_bit` is the most significant bit in the same
//!   "sawtooth" numbering; the signal continues at bit 7 of the next byte.
//!
//! Both are reduced to a shift of the payload read as one 64-bit integer (little-endian read
//! for Intel, big-endian read for Motorola), so decoding costs a shift, a mask and a sign
//! extension, and encoding ([`SignalCodec::write_bits`]) the same shift and mask the other way.

/// How the raw bits are turned into a number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RawKind {
    Unsigned,
    /// Two's complement over the signal's length.
    Signed,
    /// IEEE 754 single precision (signal length 32, `SIG_VALTYPE_ … : 1`).
    Float32,
    /// IEEE 754 double precision (signal length 64, `SIG_VALTYPE_ … : 2`).
    Float64,
}

/// Byte order of a signal, as written in the DBC (`@1` Intel, `@0` Motorola).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    Intel,
    Motorola,
}

/// Why a DBC signal definition cannot be compiled.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LayoutError {
    #[error("length {length} bits is outside 1..=64")]
    BadLength { length: u64 },
    #[error("start bit {start_bit} with length {length} runs past the {size_bytes}-byte message")]
    OutsideMessage {
        start_bit: u64,
        length: u64,
        size_bytes: u64,
    },
    #[error("a float signal must be 32 or 64 bits long, not {length}")]
    BadFloatLength { length: u64 },
}

/// A compiled signal: where its bits are and how to read them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalCodec {
    /// Right shift applied to the 64-bit payload word (LSB position of the signal).
    shift: u32,
    /// Mask of `length` low bits.
    mask: u64,
    length: u32,
    order: ByteOrder,
    kind: RawKind,
    /// Payload bytes that must be present: index of the highest byte touched + 1.
    pub bytes_needed: usize,
}

impl SignalCodec {
    /// Compiles a signal of `length` bits at DBC `start_bit` in a message of `size_bytes`
    /// (≤ 8) bytes.
    pub fn new(
        start_bit: u64,
        length: u64,
        order: ByteOrder,
        kind: RawKind,
        size_bytes: u64,
    ) -> Result<Self, LayoutError> {
        if !(1..=64).contains(&length) {
            return Err(LayoutError::BadLength { length });
        }
        if matches!(kind, RawKind::Float32) && length != 32
            || matches!(kind, RawKind::Float64) && length != 64
        {
            return Err(LayoutError::BadFloatLength { length });
        }
        let outside = LayoutError::OutsideMessage {
            start_bit,
            length,
            size_bytes,
        };
        let size_bits = size_bytes.min(8) * 8;
        let (shift, last_byte) = match order {
            ByteOrder::Intel => {
                let end = start_bit + length; // one past the MSB
                if end > size_bits {
                    return Err(outside);
                }
                (start_bit, (end - 1) / 8)
            }
            ByteOrder::Motorola => {
                if start_bit >= size_bits {
                    return Err(outside);
                }
                // Position of the MSB in the payload read big-endian as a u64.
                let msb = (7 - start_bit / 8) * 8 + start_bit % 8;
                let Some(lsb) = (msb + 1).checked_sub(length) else {
                    return Err(outside);
                };
                let last_byte = 7 - lsb / 8;
                if last_byte >= size_bytes {
                    return Err(outside);
                }
                (lsb, last_byte)
            }
        };
        let mask = if length == 64 {
            u64::MAX
        } else {
            (1u64 << length) - 1
        };
        Ok(Self {
            shift: u32::try_from(shift).expect("shift < 64 by the checks above"),
            mask,
            length: u32::try_from(length).expect("length ≤ 64"),
            order,
            kind,
            bytes_needed: usize::try_from(last_byte + 1).expect("≤ 8"),
        })
    }

    /// Whether the raw bits are an integer (not an IEEE float).
    pub(crate) fn is_integer(&self) -> bool {
        matches!(self.kind, RawKind::Unsigned | RawKind::Signed)
    }

    /// The signal's raw bits, right-aligned. `words` is the payload (zero-padded to 8
    /// bytes) read as `(little-endian u64, big-endian u64)`.
    #[inline]
    pub(crate) fn raw_bits(&self, words: PayloadWords) -> u64 {
        let word = match self.order {
            ByteOrder::Intel => words.le,
            ByteOrder::Motorola => words.be,
        };
        (word >> self.shift) & self.mask
    }

    /// How the raw bits are read (integer or float).
    pub fn kind(&self) -> RawKind {
        self.kind
    }

    /// The signal's length in bits (1..=64).
    pub fn length(&self) -> u32 {
        self.length
    }

    /// The smallest and largest raw integer the signal holds: `0..=2^len − 1` unsigned,
    /// `−2^(len−1)..=2^(len−1) − 1` signed; `None` for float signals.
    pub(crate) fn integer_range(&self) -> Option<(i128, i128)> {
        let len = self.length;
        match self.kind {
            RawKind::Unsigned => Some((0, (1i128 << len) - 1)),
            RawKind::Signed => Some((-(1i128 << (len - 1)), (1i128 << (len - 1)) - 1)),
            RawKind::Float32 | RawKind::Float64 => None,
        }
    }

    /// The bit pattern of `raw` for this signal, right-aligned, or `None` when it does not
    /// fit: an integer outside [`SignalCodec::integer_range`], a float for an integer
    /// signal or the other way round, or a finite value that overflows a 32-bit float.
    /// The inverse of [`SignalCodec::raw_value`].
    pub(crate) fn bits_of(&self, raw: RawValue) -> Option<u64> {
        match (self.kind, raw) {
            (RawKind::Unsigned | RawKind::Signed, RawValue::Unsigned(v)) => {
                let (_, hi) = self.integer_range()?;
                (i128::from(v) <= hi).then_some(v)
            }
            (RawKind::Unsigned | RawKind::Signed, RawValue::Signed(v)) => {
                let (lo, hi) = self.integer_range()?;
                // Two's complement, cut to the signal's length: the cast keeps the bits.
                #[allow(clippy::cast_sign_loss)]
                let bits = (v as u64) & self.mask;
                (lo..=hi).contains(&i128::from(v)).then_some(bits)
            }
            (RawKind::Float32, RawValue::Float(v)) => {
                // Rounding to single precision is the point of a 32-bit float signal.
                #[allow(clippy::cast_possible_truncation)]
                let single = v as f32;
                (single.is_finite() || !v.is_finite()).then_some(u64::from(single.to_bits()))
            }
            (RawKind::Float64, RawValue::Float(v)) => Some(v.to_bits()),
            _ => None,
        }
    }

    /// Writes the signal's raw bits (right-aligned; bits above the length are ignored) into
    /// an 8-byte payload buffer, leaving every other bit as it was. The inverse of
    /// [`SignalCodec::raw_bits`]: reading back gives `bits` masked to the length.
    #[inline]
    pub(crate) fn write_bits(&self, data: &mut [u8; 8], bits: u64) {
        let field = self.mask << self.shift;
        let placed = (bits & self.mask) << self.shift;
        match self.order {
            ByteOrder::Intel => {
                let word = u64::from_le_bytes(*data);
                *data = ((word & !field) | placed).to_le_bytes();
            }
            ByteOrder::Motorola => {
                let word = u64::from_be_bytes(*data);
                *data = ((word & !field) | placed).to_be_bytes();
            }
        }
    }

    /// The raw value as a number, before factor and offset.
    #[inline]
    pub(crate) fn raw_value(&self, words: PayloadWords) -> RawValue {
        let bits = self.raw_bits(words);
        match self.kind {
            RawKind::Unsigned => RawValue::Unsigned(bits),
            RawKind::Signed => {
                let unused = 64 - self.length;
                // Two's complement sign extension: move the sign bit to bit 63, shift back
                // arithmetically. The cast reinterprets the bits on purpose.
                #[allow(clippy::cast_possible_wrap)]
                let v = ((bits << unused) as i64) >> unused;
                RawValue::Signed(v)
            }
            RawKind::Float32 => {
                let bits32 = u32::try_from(bits).expect("a 32-bit mask was applied");
                RawValue::Float(f64::from(f32::from_bits(bits32)))
            }
            RawKind::Float64 => RawValue::Float(f64::from_bits(bits)),
        }
    }
}

/// The payload of one frame read as two 64-bit words (zero-padded to 8 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct PayloadWords {
    pub le: u64,
    pub be: u64,
}

impl PayloadWords {
    /// Reads up to 8 bytes; shorter payloads are zero-padded (callers check `bytes_needed`).
    #[inline]
    pub fn new(data: &[u8]) -> Self {
        let mut bytes = [0u8; 8];
        let n = data.len().min(8);
        bytes[..n].copy_from_slice(&data[..n]);
        Self {
            le: u64::from_le_bytes(bytes),
            be: u64::from_be_bytes(bytes),
        }
    }
}

/// A raw signal value before scaling.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum RawValue {
    Unsigned(u64),
    Signed(i64),
    Float(f64),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn codec(start: u64, len: u64, order: ByteOrder, kind: RawKind) -> SignalCodec {
        SignalCodec::new(start, len, order, kind, 8).expect("valid layout")
    }

    /// Independent reference: walk the bits one at a time exactly as the DBC definition
    /// describes them (Intel: start = LSB, going up; Motorola: start = MSB, going down
    /// within a byte and on to bit 7 of the next byte).
    fn reference_bits(data: [u8; 8], start: u64, len: u64, order: ByteOrder) -> u64 {
        let bit = |pos: u64| u64::from(data[(pos / 8) as usize] >> (pos % 8) & 1);
        let mut value = 0u64;
        match order {
            ByteOrder::Intel => {
                for i in 0..len {
                    value |= bit(start + i) << i;
                }
            }
            ByteOrder::Motorola => {
                let mut pos = start;
                for _ in 0..len {
                    value = (value << 1) | bit(pos);
                    pos = if pos.is_multiple_of(8) {
                        pos + 15
                    } else {
                        pos - 1
                    };
                }
            }
        }
        value
    }

    #[test]
    fn motorola_vector_encoded_by_cantools() {
        // cantools 45.1 encoded GaugeStart{Machine=0xABC, Lobe=0x2D, Revolutions=3,
        // Part=0x123456, PointsPerRev=360} from config/gauge.dbc as ab cb 43 12 34 56 01 68.
        let words = PayloadWords::new(&[0xab, 0xcb, 0x43, 0x12, 0x34, 0x56, 0x01, 0x68]);
        let m = ByteOrder::Motorola;
        let u = RawKind::Unsigned;
        assert_eq!(codec(7, 12, m, u).raw_bits(words), 0xABC);
        assert_eq!(codec(11, 6, m, u).raw_bits(words), 0x2D);
        assert_eq!(codec(21, 6, m, u).raw_bits(words), 3);
        assert_eq!(codec(31, 24, m, u).raw_bits(words), 0x12_3456);
        assert_eq!(codec(55, 16, m, u).raw_bits(words), 360);
    }

    #[test]
    fn every_layout_matches_the_bitwise_reference() {
        // Exhaustive over start bit, length and byte order on three payloads.
        let payloads = [
            [0x01, 0x23, 0x45, 0x67, 0x89, 0xab, 0xcd, 0xef],
            [0xff, 0x00, 0xa5, 0x5a, 0x81, 0x7e, 0x3c, 0xc3],
            [0x80, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01],
        ];
        let mut checked = 0;
        for data in payloads {
            let words = PayloadWords::new(&data);
            for order in [ByteOrder::Intel, ByteOrder::Motorola] {
                for start in 0..64 {
                    for len in 1..=64 {
                        let Ok(c) = SignalCodec::new(start, len, order, RawKind::Unsigned, 8)
                        else {
                            continue;
                        };
                        assert_eq!(
                            c.raw_bits(words),
                            reference_bits(data, start, len, order),
                            "{order:?} start {start} len {len}"
                        );
                        checked += 1;
                    }
                }
            }
        }
        // Intel: 64·65/2 valid layouts; Motorola the same count.
        assert_eq!(checked, 3 * 2 * 2080);
    }

    /// Independent reference writer: sets the bits one at a time in the DBC numbering.
    fn reference_write(data: &mut [u8; 8], start: u64, len: u64, order: ByteOrder, value: u64) {
        let mut set = |pos: u64, bit: u64| {
            let (byte, shift) = ((pos / 8) as usize, pos % 8);
            data[byte] = (data[byte] & !(1 << shift)) | ((bit as u8) << shift);
        };
        match order {
            ByteOrder::Intel => {
                for i in 0..len {
                    set(start + i, value >> i & 1);
                }
            }
            ByteOrder::Motorola => {
                let mut pos = start;
                for i in (0..len).rev() {
                    set(pos, value >> i & 1);
                    pos = if pos.is_multiple_of(8) {
                        pos + 15
                    } else {
                        pos - 1
                    };
                }
            }
        }
    }

    #[test]
    fn writing_matches_the_bitwise_reference_and_leaves_other_bits_alone() {
        // Every valid layout, written over two backgrounds with a value that sets bits
        // above the length (which must be ignored).
        let backgrounds = [[0u8; 8], [0xff, 0x00, 0xa5, 0x5a, 0x81, 0x7e, 0x3c, 0xc3]];
        let value = 0x9e37_79b9_7f4a_7c15u64;
        let mut checked = 0;
        for background in backgrounds {
            for order in [ByteOrder::Intel, ByteOrder::Motorola] {
                for start in 0..64 {
                    for len in 1..=64 {
                        let Ok(c) = SignalCodec::new(start, len, order, RawKind::Unsigned, 8)
                        else {
                            continue;
                        };
                        let mut ours = background;
                        c.write_bits(&mut ours, value);
                        let mut reference = background;
                        let masked = if len == 64 {
                            value
                        } else {
                            value & ((1 << len) - 1)
                        };
                        reference_write(&mut reference, start, len, order, masked);
                        assert_eq!(ours, reference, "{order:?} start {start} len {len}");
                        assert_eq!(c.raw_bits(PayloadWords::new(&ours)), masked);
                        checked += 1;
                    }
                }
            }
        }
        assert_eq!(checked, 2 * 2 * 2080);
    }

    #[test]
    fn bits_of_is_the_inverse_of_raw_value() {
        let s4 = codec(0, 4, ByteOrder::Intel, RawKind::Signed);
        assert_eq!(s4.integer_range(), Some((-8, 7)));
        for v in -8..=7 {
            let bits = s4.bits_of(RawValue::Signed(v)).expect("fits");
            let mut data = [0u8; 8];
            s4.write_bits(&mut data, bits);
            assert_eq!(s4.raw_value(PayloadWords::new(&data)), RawValue::Signed(v));
        }
        assert_eq!(s4.bits_of(RawValue::Signed(8)), None);
        assert_eq!(s4.bits_of(RawValue::Signed(-9)), None);
        assert_eq!(s4.bits_of(RawValue::Unsigned(7)), Some(7));
        assert_eq!(s4.bits_of(RawValue::Unsigned(8)), None);
        assert_eq!(s4.bits_of(RawValue::Float(1.0)), None);
        let u64_sig = codec(0, 64, ByteOrder::Intel, RawKind::Unsigned);
        assert_eq!(
            u64_sig.bits_of(RawValue::Unsigned(u64::MAX)),
            Some(u64::MAX)
        );
        assert_eq!(u64_sig.bits_of(RawValue::Signed(-1)), None);
        let f32_sig = codec(0, 32, ByteOrder::Intel, RawKind::Float32);
        assert_eq!(
            f32_sig.bits_of(RawValue::Float(1.25)),
            Some(u64::from(1.25f32.to_bits()))
        );
        // 1e300 overflows single precision; an infinity asked for stays one.
        assert_eq!(f32_sig.bits_of(RawValue::Float(1e300)), None);
        assert_eq!(
            f32_sig.bits_of(RawValue::Float(f64::INFINITY)),
            Some(u64::from(f32::INFINITY.to_bits()))
        );
        assert_eq!(f32_sig.bits_of(RawValue::Signed(1)), None);
    }

    #[test]
    fn signed_values_sign_extend() {
        let c = codec(24, 32, ByteOrder::Intel, RawKind::Signed);
        let words = PayloadWords::new(&[0, 0, 0, 0xf8, 0xff, 0xff, 0xff]);
        assert_eq!(c.raw_value(words), RawValue::Signed(-8));
        let c4 = codec(0, 4, ByteOrder::Intel, RawKind::Signed);
        assert_eq!(
            c4.raw_value(PayloadWords::new(&[0x0f])),
            RawValue::Signed(-1)
        );
        assert_eq!(
            c4.raw_value(PayloadWords::new(&[0x07])),
            RawValue::Signed(7)
        );
        assert_eq!(
            c4.raw_value(PayloadWords::new(&[0x08])),
            RawValue::Signed(-8)
        );
    }

    #[test]
    fn floats_decode_from_their_bits() {
        let c = codec(0, 32, ByteOrder::Intel, RawKind::Float32);
        let bytes = 1.25f32.to_le_bytes();
        assert_eq!(
            c.raw_value(PayloadWords::new(&bytes)),
            RawValue::Float(1.25)
        );
        let c = codec(7, 64, ByteOrder::Motorola, RawKind::Float64);
        let bytes = (-3.5f64).to_be_bytes();
        assert_eq!(
            c.raw_value(PayloadWords::new(&bytes)),
            RawValue::Float(-3.5)
        );
    }

    #[test]
    fn layouts_outside_the_message_are_rejected() {
        let intel = SignalCodec::new(60, 8, ByteOrder::Intel, RawKind::Unsigned, 8);
        assert!(matches!(intel, Err(LayoutError::OutsideMessage { .. })));
        // Motorola MSB at bit 3 of byte 0 with 8 bits needs byte 1: absent in a 1-byte message.
        let moto = SignalCodec::new(3, 8, ByteOrder::Motorola, RawKind::Unsigned, 1);
        assert!(matches!(moto, Err(LayoutError::OutsideMessage { .. })));
        // …and present in a 2-byte one.
        let moto = SignalCodec::new(3, 8, ByteOrder::Motorola, RawKind::Unsigned, 2);
        assert_eq!(moto.map(|c| c.bytes_needed), Ok(2));
        // Motorola that runs off the last byte.
        let moto = SignalCodec::new(58, 8, ByteOrder::Motorola, RawKind::Unsigned, 8);
        assert!(matches!(moto, Err(LayoutError::OutsideMessage { .. })));
        let zero = SignalCodec::new(0, 0, ByteOrder::Intel, RawKind::Unsigned, 8);
        assert_eq!(zero, Err(LayoutError::BadLength { length: 0 }));
        let float = SignalCodec::new(0, 16, ByteOrder::Intel, RawKind::Float32, 8);
        assert_eq!(float, Err(LayoutError::BadFloatLength { length: 16 }));
    }
}
