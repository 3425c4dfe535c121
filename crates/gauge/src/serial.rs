//! The serial gauge line protocol: a pure line parser, a decoder from lines to measurements
//! and an encoder (for simulators and tests). No I/O here; see `serial_port` for the port.
//!
//! ```text
//! START <machine> <part> <lobe> <revolutions> <points_per_rev>
//! S <revolution> <angle_index> <lift_mm>
//! …
//! END <sample_count> <crc32>
//! ```
//! - ASCII lines ended by LF or CRLF, at most [`MAX_LINE_BYTES`] bytes; fields separated by
//!   spaces or tabs. Empty lines and lines starting with `#` are ignored anywhere.
//! - `machine`, `part`, `lobe`: 1–32 characters of `A–Z a–z 0–9 . _ -`.
//! - `revolutions` 1..=1000, `points_per_rev` 1..=100000, `revolution` and `angle_index`
//!   0-based decimal integers on that grid (angle = index · 360° / points_per_rev).
//! - `lift_mm`: plain decimal `[+-]digits[.digits]` (no exponent, no inf/nan), |lift| ≤ 1000.
//! - `sample_count`: the number of `S` lines sent; `crc32`: 8 hex digits, the CRC-32
//!   (IEEE 802.3, the one of zlib and PNG) over the START line and every S line, each taken
//!   without its line terminator and followed by a single LF.
//!
//! A measurement with any malformed line, a sample off the announced grid, a wrong count or a
//! wrong checksum is discarded as a whole and reported with the reason.

use crc32fast::Hasher;

use camloop_core::measure::{MeasurementHeader, RawMeasurement, RawSample};

use super::assemble::{
    Assembled, AssemblyProblem, DiscardReason, MAX_POINTS_PER_REV, MAX_REVOLUTIONS, OpenMeasurement,
};

/// Longest accepted line, terminator excluded.
pub(crate) const MAX_LINE_BYTES: usize = 256;
/// Largest accepted |lift| in mm.
pub const MAX_ABS_LIFT_MM: f64 = 1000.0;
const MAX_ID_CHARS: usize = 32;

/// One parsed protocol line.
#[derive(Debug, Clone, PartialEq)]
pub enum SerialLine {
    Start(MeasurementHeader),
    Sample(RawSample),
    End {
        sample_count: u64,
        crc32: u32,
    },
    /// Empty or `#` comment.
    Ignored,
}

/// Why one line is not a protocol line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SerialLineError {
    #[error("line is longer than {MAX_LINE_BYTES} bytes")]
    TooLong,
    #[error("line is not ascii text")]
    NotAscii,
    #[error("unknown record {found:?} (expected START, S or END)")]
    UnknownRecord { found: String },
    #[error("{record} needs {expected} fields after the keyword, found {found}")]
    FieldCount {
        record: &'static str,
        expected: usize,
        found: usize,
    },
    #[error("{field} {found:?} must be 1–{MAX_ID_CHARS} characters of A–Z a–z 0–9 . _ -")]
    BadId { field: &'static str, found: String },
    #[error("{field} {found:?} is not a whole number in {min}..={max}")]
    BadCount {
        field: &'static str,
        found: String,
        min: u64,
        max: u64,
    },
    #[error("lift {found:?} is not a plain decimal number of mm within ±{MAX_ABS_LIFT_MM}")]
    BadLift { found: String },
    #[error("checksum {found:?} is not 8 hex digits")]
    BadChecksum { found: String },
}

/// Parses one line (terminator already removed; a trailing CR is tolerated).
pub fn parse_serial_line(line: &str) -> Result<SerialLine, SerialLineError> {
    let line = line.strip_suffix('\r').unwrap_or(line);
    if line.len() > MAX_LINE_BYTES {
        return Err(SerialLineError::TooLong);
    }
    if !line.is_ascii() {
        return Err(SerialLineError::NotAscii);
    }
    let mut fields = line.split([' ', '\t']).filter(|f| !f.is_empty());
    let Some(keyword) = fields.next() else {
        return Ok(SerialLine::Ignored);
    };
    if keyword.starts_with('#') {
        return Ok(SerialLine::Ignored);
    }
    let rest: Vec<&str> = fields.collect();
    let expect = |record, expected| {
        if rest.len() == expected {
            Ok(())
        } else {
            Err(SerialLineError::FieldCount {
                record,
                expected,
                found: rest.len(),
            })
        }
    };
    match keyword {
        "START" => {
            expect("START", 5)?;
            Ok(SerialLine::Start(MeasurementHeader {
                machine: id("machine", rest[0])?,
                part: id("part", rest[1])?,
                lobe: id("lobe", rest[2])?,
                revolutions: count_u32("revolutions", rest[3], 1, MAX_REVOLUTIONS)?,
                points_per_rev: count_u32("points_per_rev", rest[4], 1, MAX_POINTS_PER_REV)?,
            }))
        }
        "S" => {
            expect("S", 3)?;
            Ok(SerialLine::Sample(RawSample {
                revolution: count_u32("revolution", rest[0], 0, u32::MAX)?,
                angle_index: count_u32("angle_index", rest[1], 0, u32::MAX)?,
                lift_mm: lift(rest[2])?,
            }))
        }
        "END" => {
            expect("END", 2)?;
            let sample_count = count("sample_count", rest[0], 0, u64::from(u32::MAX))?;
            let crc = rest[1];
            let crc32 = (crc.len() == 8 && crc.bytes().all(|b| b.is_ascii_hexdigit()))
                .then(|| u32::from_str_radix(crc, 16).ok())
                .flatten()
                .ok_or_else(|| SerialLineError::BadChecksum {
                    found: crc.to_owned(),
                })?;
            Ok(SerialLine::End {
                sample_count,
                crc32,
            })
        }
        other => Err(SerialLineError::UnknownRecord {
            found: other.to_owned(),
        }),
    }
}

fn id(field: &'static str, text: &str) -> Result<String, SerialLineError> {
    let ok = (1..=MAX_ID_CHARS).contains(&text.len())
        && text
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-'));
    if ok {
        Ok(text.to_owned())
    } else {
        Err(SerialLineError::BadId {
            field,
            found: text.to_owned(),
        })
    }
}

fn count(field: &'static str, text: &str, min: u64, max: u64) -> Result<u64, SerialLineError> {
    let parsed = text
        .bytes()
        .all(|b| b.is_ascii_digit())
        .then(|| text.parse::<u64>().ok())
        .flatten()
        .filter(|v| (min..=max).contains(v));
    parsed.ok_or_else(|| SerialLineError::BadCount {
        field,
        found: text.to_owned(),
        min,
        max,
    })
}

fn count_u32(field: &'static str, text: &str, min: u32, max: u32) -> Result<u32, SerialLineError> {
    let v = count(field, text, u64::from(min), u64::from(max))?;
    Ok(u32::try_from(v).expect("bounded by a u32 max"))
}

fn lift(text: &str) -> Result<f64, SerialLineError> {
    let digits = text.strip_prefix(['+', '-']).unwrap_or(text);
    let (int, frac) = digits.split_once('.').unwrap_or((digits, "0"));
    let all_digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let value = (all_digits(int) && all_digits(frac))
        .then(|| text.parse::<f64>().ok())
        .flatten()
        .filter(|v| v.abs() <= MAX_ABS_LIFT_MM);
    value.ok_or_else(|| SerialLineError::BadLift {
        found: text.to_owned(),
    })
}

/// Something in the line stream that did not become a measurement, and where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SerialProblem {
    /// A malformed line outside any measurement.
    #[error("line {line}: {error}")]
    Line { line: usize, error: SerialLineError },
    /// `line` is where the problem became known.
    #[error("line {line}: {problem}")]
    Assembly {
        line: usize,
        problem: AssemblyProblem,
    },
}

/// What one line (or the end of the stream) produced.
#[derive(Debug, Clone, PartialEq)]
pub enum SerialEvent {
    Measurement(RawMeasurement),
    Problem(SerialProblem),
}

#[derive(Debug)]
enum State {
    Idle { stray_samples: usize },
    Open { m: OpenMeasurement, crc: Hasher },
}

/// The protocol state machine: lines in, measurements and problems out.
#[derive(Debug)]
pub struct SerialDecoder {
    origin: String,
    state: State,
}

impl SerialDecoder {
    /// `origin` is copied into every measurement (the port path).
    pub fn new(origin: impl Into<String>) -> Self {
        Self {
            origin: origin.into(),
            state: State::Idle { stray_samples: 0 },
        }
    }

    /// Feeds line number `line` (1-based, counting every line received).
    pub fn push_line(&mut self, line: usize, text: &str) -> Option<SerialEvent> {
        let parsed = parse_serial_line(text);
        self.push_parsed(line, text.strip_suffix('\r').unwrap_or(text), parsed)
    }

    /// Feeds a line that could not even be read as text (too long, not UTF-8).
    pub fn push_unreadable_line(
        &mut self,
        line: usize,
        error: SerialLineError,
    ) -> Option<SerialEvent> {
        self.push_parsed(line, "", Err(error))
    }

    /// `text` is the line without terminator, used for the checksum of good lines.
    fn push_parsed(
        &mut self,
        line: usize,
        text: &str,
        parsed: Result<SerialLine, SerialLineError>,
    ) -> Option<SerialEvent> {
        match (parsed, &mut self.state) {
            (Ok(SerialLine::Ignored), _) => None,
            (Err(error), State::Idle { .. }) => {
                Some(SerialEvent::Problem(SerialProblem::Line { line, error }))
            }
            (Err(error), State::Open { m, .. }) => {
                m.spoil(DiscardReason::MalformedLine {
                    line,
                    error: error.to_string(),
                });
                None
            }
            (Ok(SerialLine::Start(header)), _) => self.start(line, text, header),
            (Ok(SerialLine::Sample(s)), State::Open { m, crc }) => {
                crc_line(crc, text);
                m.add(s);
                None
            }
            (Ok(SerialLine::Sample(_)), State::Idle { stray_samples }) => {
                *stray_samples += 1;
                None
            }
            (Ok(SerialLine::End { .. }), State::Idle { stray_samples }) => {
                let stray_samples = std::mem::take(stray_samples);
                problem(line, AssemblyProblem::EndWithoutStart { stray_samples })
            }
            (
                Ok(SerialLine::End {
                    sample_count,
                    crc32,
                }),
                State::Open { .. },
            ) => {
                let State::Open { m, crc } =
                    std::mem::replace(&mut self.state, State::Idle { stray_samples: 0 })
                else {
                    unreachable!("matched State::Open above")
                };
                self.end(line, m, crc, (sample_count, crc32))
            }
        }
    }

    /// A start line opens a measurement; one still open is cut off, stray samples reported.
    fn start(&mut self, line: usize, text: &str, header: MeasurementHeader) -> Option<SerialEvent> {
        let mut crc = Hasher::new();
        crc_line(&mut crc, text);
        let previous = std::mem::replace(
            &mut self.state,
            State::Open {
                m: OpenMeasurement::new(header),
                crc,
            },
        );
        match previous {
            State::Open { m, .. } => problem(line, m.discard(DiscardReason::CutOffByNewStart)),
            State::Idle { stray_samples: 0 } => None,
            State::Idle { stray_samples } => problem(
                line,
                AssemblyProblem::SamplesWithoutStart {
                    count: stray_samples,
                },
            ),
        }
    }

    /// The end line of the measurement `m` (taken out of the open state): its announced
    /// count and CRC checked, then finished.
    fn end(
        &self,
        line: usize,
        mut m: OpenMeasurement,
        crc: Hasher,
        (sample_count, crc32): (u64, u32),
    ) -> Option<SerialEvent> {
        let received = m.received() as u64;
        if received != sample_count {
            m.spoil(DiscardReason::CountMismatch {
                announced: sample_count,
                received,
            });
        }
        let computed = crc.finalize();
        if computed != crc32 {
            m.spoil(DiscardReason::ChecksumMismatch {
                announced: crc32,
                computed,
            });
        }
        match m.finish(&self.origin) {
            Assembled::Measurement(m) => Some(SerialEvent::Measurement(m)),
            Assembled::Problem(p) => problem(line, p),
        }
    }

    /// The stream ended after line `last_line`: reports what was left open.
    pub fn finish(&mut self, last_line: usize) -> Option<SerialEvent> {
        match std::mem::replace(&mut self.state, State::Idle { stray_samples: 0 }) {
            State::Open { m, .. } => problem(last_line, m.discard(DiscardReason::StreamEnded)),
            State::Idle { stray_samples: 0 } => None,
            State::Idle { stray_samples } => problem(
                last_line,
                AssemblyProblem::SamplesWithoutStart {
                    count: stray_samples,
                },
            ),
        }
    }
}

fn crc_line(crc: &mut Hasher, text: &str) {
    crc.update(text.as_bytes());
    crc.update(b"\n");
}

fn problem(line: usize, problem: AssemblyProblem) -> Option<SerialEvent> {
    Some(SerialEvent::Problem(SerialProblem::Assembly {
        line,
        problem,
    }))
}

/// Decodes a whole text (a capture of the line stream).
pub fn decode_serial_text(text: &str, origin: &str) -> Vec<SerialEvent> {
    let mut decoder = SerialDecoder::new(origin);
    let mut events = Vec::new();
    let mut last = 0;
    for (index, line) in text.lines().enumerate() {
        last = index + 1;
        events.extend(decoder.push_line(last, line));
    }
    events.extend(decoder.finish(last));
    events
}

/// Why a measurement cannot be written in the line protocol.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SerialEncodeError {
    #[error("{field} {found:?} must be 1–{MAX_ID_CHARS} characters of A–Z a–z 0–9 . _ -")]
    BadId { field: &'static str, found: String },
    #[error(
        "lift {lift_mm} mm at revolution {revolution}, index {angle_index} is not finite or beyond ±{MAX_ABS_LIFT_MM} mm"
    )]
    BadLift {
        revolution: u32,
        angle_index: u32,
        lift_mm: f64,
    },
}

/// Writes a measurement in the line protocol (LF line ends, lifts with 6 decimals, i.e.
/// rounded to 1 nm), with its sample count and CRC-32.
pub fn encode_serial_measurement(m: &RawMeasurement) -> Result<String, SerialEncodeError> {
    let h = &m.header;
    for (field, value) in [
        ("machine", &h.machine),
        ("part", &h.part),
        ("lobe", &h.lobe),
    ] {
        id(field, value).map_err(|_| SerialEncodeError::BadId {
            field,
            found: value.clone(),
        })?;
    }
    let mut out = String::with_capacity(32 + m.samples.len() * 24);
    let mut crc = Hasher::new();
    let mut emit = |line: String, out: &mut String| {
        crc_line(&mut crc, &line);
        out.push_str(&line);
        out.push('\n');
    };
    emit(
        format!(
            "START {} {} {} {} {}",
            h.machine, h.part, h.lobe, h.revolutions, h.points_per_rev
        ),
        &mut out,
    );
    for s in &m.samples {
        if !s.lift_mm.is_finite() || s.lift_mm.abs() > MAX_ABS_LIFT_MM {
            return Err(SerialEncodeError::BadLift {
                revolution: s.revolution,
                angle_index: s.angle_index,
                lift_mm: s.lift_mm,
            });
        }
        emit(
            format!("S {} {} {:.6}", s.revolution, s.angle_index, s.lift_mm),
            &mut out,
        );
    }
    let checksum = crc.finalize();
    out.push_str(&format!("END {} {checksum:08X}\n", m.samples.len()));
    Ok(out)
}
