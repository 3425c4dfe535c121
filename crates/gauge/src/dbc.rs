//! The gauge's CAN layout: which DBC messages and signals carry a measurement, compiled once
//! from a DBC file into a decoder ([`GaugeDbc`]).
//!
//! Nothing about bit positions is hard-coded: start bit, length, byte order, signedness,
//! factor, offset, `[min|max]` and simple multiplexing all come from the DBC, and the message
//! and signal names come from [`GaugeSignalNames`], so a site can drop in its own gauge's
//! DBC and rename the signals in config.

use std::path::Path;
use std::sync::LazyLock;

use can_dbc::{Dbc, MessageId, MultiplexIndicator, NumericValue, SignalExtendedValueType};

use super::frame::CanId;
use super::signal::{ByteOrder, LayoutError, RawKind, SignalCodec};

/// The DBC shipped with camloop (`config/gauge.dbc`), compiled into the binary so tests,
/// benches and a default install need no file.
pub const BUILTIN_DBC: &str = include_str!("../../../config/gauge.dbc");

/// Names of the three gauge messages and their signals in the DBC. The defaults match
/// `config/gauge.dbc`; a site with its own gauge DBC overrides them in config.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GaugeSignalNames {
    pub start_message: String,
    /// Signal names (DBC identifiers), not the values they carry.
    pub machine: String,
    pub part: String,
    pub lobe: String,
    pub revolutions: String,
    pub points_per_rev: String,
    pub sample_message: String,
    pub revolution: String,
    pub angle_index: String,
    /// Physical unit must be mm (factor and offset in the DBC make it so).
    pub lift_mm: String,
    pub end_message: String,
    pub status: String,
}

impl Default for GaugeSignalNames {
    fn default() -> Self {
        Self {
            start_message: "GaugeStart".into(),
            machine: "Machine".into(),
            part: "Part".into(),
            lobe: "Lobe".into(),
            revolutions: "Revolutions".into(),
            points_per_rev: "PointsPerRev".into(),
            sample_message: "GaugeSample".into(),
            revolution: "Revolution".into(),
            angle_index: "AngleIndex".into(),
            lift_mm: "Lift".into(),
            end_message: "GaugeEnd".into(),
            status: "Status".into(),
        }
    }
}

/// Why a DBC cannot serve as the gauge layout.
#[derive(Debug, thiserror::Error)]
pub enum DbcLoadError {
    #[error("cannot read dbc file {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("dbc does not parse: {0}")]
    Parse(String),
    #[error("message {message} not found in the dbc")]
    MissingMessage { message: String },
    #[error("signal {signal} not found in message {message}")]
    MissingSignal { message: String, signal: String },
    #[error("message {message} is {size_bytes} bytes; only classic CAN (at most 8) is supported")]
    MessageTooLong { message: String, size_bytes: u64 },
    #[error("message {message} has standard id {id:#x} beyond 11 bits")]
    BadStandardId { message: String, id: u16 },
    #[error("messages {first} and {second} share CAN id {id}")]
    SharedId {
        first: String,
        second: String,
        id: CanId,
    },
    #[error("signal {message}.{signal}: {source}")]
    Layout {
        message: String,
        signal: String,
        source: LayoutError,
    },
    #[error("signal {message}.{signal}: factor {factor} must be finite and non-zero")]
    BadFactor {
        message: String,
        signal: String,
        factor: f64,
    },
    #[error(
        "signal {message}.{signal} is multiplexed but message {message} has no plain multiplexor (extended multiplexing is not supported)"
    )]
    Multiplexing { message: String, signal: String },
}

/// A compiled signal with its scaling and declared range.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalSpec {
    /// The signal's name in the DBC, for error messages.
    pub name: String,
    pub codec: SignalCodec,
    pub factor: f64,
    pub offset: f64,
    /// Declared `[min|max]` in physical units; `None` when the DBC says `[0|0]`.
    pub range: Option<(f64, f64)>,
    /// Present only when the multiplexor signal has this value.
    pub multiplexed: Option<(SignalCodec, u64)>,
    /// `(factor, offset)` as integers when the signal is an integer and both are whole
    /// numbers below 2^53: counters are then scaled exactly.
    pub integer_scale: Option<(i64, i64)>,
}

/// One gauge message: its id, declared size and signals in a fixed order.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageSpec<const N: usize> {
    pub name: String,
    pub id: CanId,
    /// Payload bytes the frame must carry (the DBC message size).
    pub size_bytes: usize,
    pub signals: [SignalSpec; N],
}

/// The gauge layout compiled from a DBC: the decoder for `(can id, payload) → GaugeFrame`
/// (see [`GaugeDbc::decode`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GaugeDbc {
    /// Signals: machine, part, lobe, revolutions, points_per_rev.
    pub start: MessageSpec<5>,
    /// Signals: revolution, angle_index, lift_mm.
    pub sample: MessageSpec<3>,
    /// Signals: status.
    pub end: MessageSpec<1>,
}

impl GaugeDbc {
    /// The layout of `config/gauge.dbc` with the default names (compiled once per process).
    pub fn builtin() -> Self {
        static BUILTIN: LazyLock<GaugeDbc> = LazyLock::new(|| {
            GaugeDbc::from_dbc_text(BUILTIN_DBC, &GaugeSignalNames::default())
                .expect("the shipped config/gauge.dbc compiles (checked by tests)")
        });
        BUILTIN.clone()
    }

    /// Reads and compiles a DBC file.
    pub fn load(path: &Path, names: &GaugeSignalNames) -> Result<Self, DbcLoadError> {
        let text = std::fs::read_to_string(path).map_err(|source| DbcLoadError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_dbc_text(&text, names)
    }

    /// Compiles DBC text; every named message and signal must exist and fit classic CAN.
    pub fn from_dbc_text(text: &str, names: &GaugeSignalNames) -> Result<Self, DbcLoadError> {
        let dbc = Dbc::try_from(text).map_err(|e| DbcLoadError::Parse(e.to_string()))?;
        let n = names;
        let start = compile_message(
            &dbc,
            &n.start_message,
            [
                &n.machine,
                &n.part,
                &n.lobe,
                &n.revolutions,
                &n.points_per_rev,
            ],
        )?;
        let sample = compile_message(
            &dbc,
            &n.sample_message,
            [&n.revolution, &n.angle_index, &n.lift_mm],
        )?;
        let end = compile_message(&dbc, &n.end_message, [&n.status])?;
        let ids = [
            (&start.name, start.id),
            (&sample.name, sample.id),
            (&end.name, end.id),
        ];
        for (i, (first, id)) in ids.iter().enumerate() {
            if let Some((second, _)) = ids[i + 1..].iter().find(|(_, other)| other == id) {
                return Err(DbcLoadError::SharedId {
                    first: (*first).clone(),
                    second: (*second).clone(),
                    id: *id,
                });
            }
        }
        Ok(Self { start, sample, end })
    }
}

fn compile_message<const N: usize>(
    dbc: &Dbc,
    message_name: &str,
    signal_names: [&String; N],
) -> Result<MessageSpec<N>, DbcLoadError> {
    let message = dbc
        .messages
        .iter()
        .find(|m| m.name == message_name)
        .ok_or_else(|| DbcLoadError::MissingMessage {
            message: message_name.to_owned(),
        })?;
    let id = frame_id(message)?;
    let has_extended_mux = dbc
        .extended_multiplex
        .iter()
        .any(|e| e.message_id == message.id);
    let multiplexor = message
        .signals
        .iter()
        .find(|s| s.multiplexer_indicator == MultiplexIndicator::Multiplexor);

    let mut specs = Vec::with_capacity(N);
    for wanted in signal_names {
        specs.push(compile_signal(
            dbc,
            message,
            wanted,
            multiplexor,
            has_extended_mux,
        )?);
    }
    let signals: [SignalSpec; N] = specs
        .try_into()
        .expect("exactly N signals were pushed above");
    Ok(MessageSpec {
        name: message.name.clone(),
        id,
        size_bytes: usize::try_from(message.size).expect("size ≤ 8 checked above"),
        signals,
    })
}

/// The message's CAN id, once its size fits a classic frame and a standard id fits 11 bits.
fn frame_id(message: &can_dbc::Message) -> Result<CanId, DbcLoadError> {
    if message.size > 8 {
        return Err(DbcLoadError::MessageTooLong {
            message: message.name.clone(),
            size_bytes: message.size,
        });
    }
    match message.id {
        MessageId::Standard(id) if id > 0x7ff => Err(DbcLoadError::BadStandardId {
            message: message.name.clone(),
            id,
        }),
        MessageId::Standard(id) => Ok(CanId::Standard(id)),
        MessageId::Extended(id) => Ok(CanId::Extended(id)),
    }
}

/// One wanted signal: found, its scaling sound, its multiplexing one the decoder handles.
fn compile_signal(
    dbc: &Dbc,
    message: &can_dbc::Message,
    wanted: &str,
    multiplexor: Option<&can_dbc::Signal>,
    has_extended_mux: bool,
) -> Result<SignalSpec, DbcLoadError> {
    let signal = message
        .signals
        .iter()
        .find(|s| s.name == wanted)
        .ok_or_else(|| DbcLoadError::MissingSignal {
            message: message.name.clone(),
            signal: wanted.to_owned(),
        })?;
    if !signal.factor.is_finite() || signal.factor == 0.0 || !signal.offset.is_finite() {
        return Err(DbcLoadError::BadFactor {
            message: message.name.clone(),
            signal: signal.name.clone(),
            factor: signal.factor,
        });
    }
    let multiplexed = match signal.multiplexer_indicator {
        MultiplexIndicator::Plain | MultiplexIndicator::Multiplexor => None,
        MultiplexIndicator::MultiplexedSignal(value)
        | MultiplexIndicator::MultiplexorAndMultiplexedSignal(value) => {
            match (multiplexor, has_extended_mux) {
                (Some(mux), false) => Some((compile_codec(dbc, message, mux)?, value)),
                _ => {
                    return Err(DbcLoadError::Multiplexing {
                        message: message.name.clone(),
                        signal: signal.name.clone(),
                    });
                }
            }
        }
    };
    let (min, max) = (numeric(signal.min), numeric(signal.max));
    let codec = compile_codec(dbc, message, signal)?;
    let whole = |x: f64| x.fract() == 0.0 && x.abs() < 9.0e15;
    // Whole and below 2^53 in magnitude, so the casts are exact.
    #[allow(clippy::cast_possible_truncation)]
    let integer_scale = (codec.is_integer() && whole(signal.factor) && whole(signal.offset))
        .then_some((signal.factor as i64, signal.offset as i64));
    Ok(SignalSpec {
        name: signal.name.clone(),
        codec,
        factor: signal.factor,
        offset: signal.offset,
        range: (min != 0.0 || max != 0.0).then_some((min, max)),
        multiplexed,
        integer_scale,
    })
}

/// A signal's bit layout and raw type (an extended value type overrides the sign).
fn compile_codec(
    dbc: &Dbc,
    message: &can_dbc::Message,
    signal: &can_dbc::Signal,
) -> Result<SignalCodec, DbcLoadError> {
    let order = match signal.byte_order {
        can_dbc::ByteOrder::LittleEndian => ByteOrder::Intel,
        can_dbc::ByteOrder::BigEndian => ByteOrder::Motorola,
    };
    let kind = match dbc.extended_value_type_for_signal(message.id, &signal.name) {
        Some(SignalExtendedValueType::IEEEfloat32Bit) => RawKind::Float32,
        Some(SignalExtendedValueType::IEEEdouble64bit) => RawKind::Float64,
        Some(SignalExtendedValueType::SignedOrUnsignedInteger) | None => match signal.value_type {
            can_dbc::ValueType::Signed => RawKind::Signed,
            can_dbc::ValueType::Unsigned => RawKind::Unsigned,
        },
    };
    SignalCodec::new(signal.start_bit, signal.size, order, kind, message.size).map_err(|source| {
        DbcLoadError::Layout {
            message: message.name.clone(),
            signal: signal.name.clone(),
            source,
        }
    })
}

// Declared ranges only bound physical values, so f64 is precise enough for them.
#[allow(clippy::cast_precision_loss)]
fn numeric(value: NumericValue) -> f64 {
    match value {
        NumericValue::Uint(v) => v as f64,
        NumericValue::Int(v) => v as f64,
        NumericValue::Double(v) => v,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_dbc_compiles_with_the_documented_ids() {
        let dbc = GaugeDbc::builtin();
        assert_eq!(dbc.start.id, CanId::Standard(0x5a0));
        assert_eq!(dbc.sample.id, CanId::Standard(0x5a1));
        assert_eq!(dbc.end.id, CanId::Standard(0x5a2));
        assert_eq!(
            (
                dbc.start.size_bytes,
                dbc.sample.size_bytes,
                dbc.end.size_bytes
            ),
            (8, 7, 1)
        );
        let lift = &dbc.sample.signals[2];
        assert_eq!(lift.name, "Lift");
        assert_eq!(lift.factor, 0.0001);
        assert_eq!(lift.range, Some((-200.0, 200.0)));
    }

    #[test]
    fn renamed_signals_are_found_and_missing_ones_named() {
        let text = BUILTIN_DBC.replace("Lift", "Hub");
        let err =
            GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect_err("Lift is gone");
        assert_eq!(
            err.to_string(),
            "signal Lift not found in message GaugeSample"
        );
        let names = GaugeSignalNames {
            lift_mm: "Hub".into(),
            ..GaugeSignalNames::default()
        };
        let dbc = GaugeDbc::from_dbc_text(&text, &names).expect("renamed signal");
        assert_eq!(dbc.sample.signals[2].name, "Hub");
    }

    #[test]
    fn missing_message_and_shared_ids_are_reported() {
        let text = BUILTIN_DBC.replace("GaugeEnd", "Other");
        let err = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect_err("");
        assert_eq!(err.to_string(), "message GaugeEnd not found in the dbc");

        let text = BUILTIN_DBC.replace("BO_ 1442 GaugeEnd", "BO_ 1441 GaugeEnd");
        let err = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect_err("");
        assert_eq!(
            err.to_string(),
            "messages GaugeSample and GaugeEnd share CAN id 0x5A1"
        );
    }

    #[test]
    fn garbage_and_can_fd_sizes_are_rejected() {
        let err = GaugeDbc::from_dbc_text("BO_ nonsense", &GaugeSignalNames::default())
            .expect_err("not a dbc");
        assert!(err.to_string().starts_with("dbc does not parse"), "{err}");
        let text = BUILTIN_DBC.replace("GaugeEnd: 1 Gauge", "GaugeEnd: 12 Gauge");
        let err = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect_err("");
        assert_eq!(
            err.to_string(),
            "message GaugeEnd is 12 bytes; only classic CAN (at most 8) is supported"
        );
    }

    #[test]
    fn a_signal_past_the_message_end_is_a_layout_error() {
        let text = BUILTIN_DBC.replace("GaugeSample: 7 Gauge", "GaugeSample: 6 Gauge");
        let err = GaugeDbc::from_dbc_text(&text, &GaugeSignalNames::default()).expect_err("");
        assert_eq!(
            err.to_string(),
            "signal GaugeSample.Lift: start bit 24 with length 32 runs past the 6-byte message"
        );
    }
}
