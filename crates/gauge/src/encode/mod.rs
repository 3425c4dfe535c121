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

use super::dbc::GaugeDbc;
use super::frame::{CanId, GaugeFrame, GaugeStart};

mod writer;

use writer::Writer;

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

#[cfg(test)]
mod tests;
