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

use crate::core::measure::{MeasurementHeader, RawMeasurement, RawSample};

use super::assemble::{
    Assembled, AssemblyProblem, DiscardReason, MAX_POINTS_PER_REV, MAX_REVOLUTIONS, OpenMeasurement,
};

/// Longest accepted line, terminator excluded.
pub const MAX_LINE_BYTES: usize = 256;
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
            (Ok(SerialLine::Start(header)), _) => {
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
                    State::Open { m, .. } => {
                        problem(line, m.discard(DiscardReason::CutOffByNewStart))
                    }
                    State::Idle { stray_samples: 0 } => None,
                    State::Idle { stray_samples } => problem(
                        line,
                        AssemblyProblem::SamplesWithoutStart {
                            count: stray_samples,
                        },
                    ),
                }
            }
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
                let State::Open { mut m, crc } =
                    std::mem::replace(&mut self.state, State::Idle { stray_samples: 0 })
                else {
                    unreachable!("matched State::Open above")
                };
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

#[cfg(test)]
mod tests {
    use super::*;

    fn err(line: &str) -> String {
        parse_serial_line(line)
            .expect_err("must be rejected")
            .to_string()
    }

    #[test]
    fn parses_each_record() {
        assert_eq!(
            parse_serial_line("START M3 P1234 L2 3 360\r"),
            Ok(SerialLine::Start(MeasurementHeader {
                machine: "M3".into(),
                part: "P1234".into(),
                lobe: "L2".into(),
                revolutions: 3,
                points_per_rev: 360,
            }))
        );
        assert_eq!(
            parse_serial_line("S\t2  359 -0.000800"),
            Ok(SerialLine::Sample(RawSample {
                revolution: 2,
                angle_index: 359,
                lift_mm: -0.0008,
            }))
        );
        assert_eq!(
            parse_serial_line("END 1080 cbf43926"),
            Ok(SerialLine::End {
                sample_count: 1080,
                crc32: 0xcbf4_3926
            })
        );
        assert_eq!(parse_serial_line("   "), Ok(SerialLine::Ignored));
        assert_eq!(parse_serial_line("# gauge 7 v2.1"), Ok(SerialLine::Ignored));
    }

    #[test]
    fn rejects_malformed_lines_with_the_field_named() {
        assert_eq!(
            err("START M3 P1234 L2 3"),
            "START needs 5 fields after the keyword, found 4"
        );
        assert_eq!(
            err("START M3 P/1 L2 3 360"),
            "part \"P/1\" must be 1–32 characters of A–Z a–z 0–9 . _ -"
        );
        assert_eq!(
            err("START M3 P1 L2 0 360"),
            "revolutions \"0\" is not a whole number in 1..=1000"
        );
        assert_eq!(
            err("START M3 P1 L2 3 +360"),
            "points_per_rev \"+360\" is not a whole number in 1..=100000"
        );
        assert_eq!(
            err("S 0 -1 0.1"),
            "angle_index \"-1\" is not a whole number in 0..=4294967295"
        );
        for bad in ["nan", "inf", "1e3", "1.", ".5", "--1", "1000.5", "0x10", ""] {
            let line = format!("S 0 1 {bad}");
            if bad.is_empty() {
                assert_eq!(err(&line), "S needs 3 fields after the keyword, found 2");
            } else {
                assert_eq!(
                    err(&line),
                    format!("lift \"{bad}\" is not a plain decimal number of mm within ±1000")
                );
            }
        }
        assert_eq!(
            err("END 10 12345"),
            "checksum \"12345\" is not 8 hex digits"
        );
        assert_eq!(
            err("END 10 +2345678"),
            "checksum \"+2345678\" is not 8 hex digits"
        );
        assert_eq!(
            err("SAMPLE 0 1 2"),
            "unknown record \"SAMPLE\" (expected START, S or END)"
        );
        assert_eq!(err("S 0 1 0.5µ"), "line is not ascii text");
        assert_eq!(
            err(&format!("S 0 1 {}", "1".repeat(300))),
            "line is longer than 256 bytes"
        );
    }

    fn measurement(samples: &[(u32, u32, f64)]) -> RawMeasurement {
        RawMeasurement {
            header: MeasurementHeader {
                machine: "M3".into(),
                part: "P1234".into(),
                lobe: "L2".into(),
                revolutions: 2,
                points_per_rev: 2,
            },
            samples: samples
                .iter()
                .map(|&(revolution, angle_index, lift_mm)| RawSample {
                    revolution,
                    angle_index,
                    lift_mm,
                })
                .collect(),
            origin: "pty".into(),
        }
    }

    #[test]
    fn encoding_matches_an_independent_crc() {
        let m = measurement(&[(0, 0, -0.0008), (0, 1, 1.25), (1, 1, 1.2501), (1, 0, 0.0)]);
        let text = encode_serial_measurement(&m).expect("encodable");
        // CRC-32 of these exact bytes by Python's zlib.crc32:
        // zlib.crc32(b"START M3 P1234 L2 2 2\nS 0 0 -0.000800\nS 0 1 1.250000\n"
        //            b"S 1 1 1.250100\nS 1 0 0.000000\n") == 0xDE24A4C8
        assert_eq!(
            text,
            "START M3 P1234 L2 2 2\nS 0 0 -0.000800\nS 0 1 1.250000\nS 1 1 1.250100\n\
             S 1 0 0.000000\nEND 4 DE24A4C8\n"
        );
        assert_eq!(
            decode_serial_text(&text, "pty"),
            [SerialEvent::Measurement(m)]
        );
    }

    fn problems(text: &str) -> Vec<String> {
        decode_serial_text(text, "pty")
            .iter()
            .map(|e| match e {
                SerialEvent::Measurement(m) => format!("measurement lobe {}", m.header.lobe),
                SerialEvent::Problem(p) => p.to_string(),
            })
            .collect()
    }

    #[test]
    fn damaged_measurements_are_discarded_with_the_reason() {
        let good = encode_serial_measurement(&measurement(&[(0, 0, 0.1), (0, 1, 0.2)]))
            .expect("encodable");
        // One digit changed in a sample: same count, wrong checksum.
        let flipped = good.replace("0.200000", "0.300000");
        assert_eq!(
            problems(&flipped),
            [
                "line 4: measurement of machine M3 part P1234 lobe L2 discarded after 2 samples: \
              checksum mismatch: end line says 114A8CA3, lines give B73D8717"
            ]
        );
        // A lost sample line.
        let lost = good.replace("S 0 1 0.200000\n", "");
        assert_eq!(
            problems(&lost),
            [
                "line 3: measurement of machine M3 part P1234 lobe L2 discarded after 1 samples: \
              end line announces 2 samples, 1 were received"
            ]
        );
        // A garbled line inside: the first reason is kept.
        let garbled = good.replace("S 0 1 0.200000", "S 0 1 0.2x0000");
        assert_eq!(
            problems(&garbled),
            [
                "line 4: measurement of machine M3 part P1234 lobe L2 discarded after 1 samples: \
              line 3: lift \"0.2x0000\" is not a plain decimal number of mm within ±1000"
            ]
        );
        // A sample off the announced 2 × 2 grid.
        let off = good.replace("S 0 1 0.200000", "S 0 2 0.200000");
        assert!(
            problems(&off)[0]
                .ends_with("sample at revolution 0, angle index 2 is outside the announced grid")
        );
    }

    #[test]
    fn stream_structure_problems_are_reported_with_lines() {
        let good = encode_serial_measurement(&measurement(&[(0, 0, 0.1)])).expect("encodable");
        let text = format!(
            "S 0 0 0.1\nS 0 1 0.1\nhello\n{good}END 0 00000000\nSTART M3 P1234 L3 2 2\nS 0 0 0\n\
             START M3 P1234 L4 2 2\n"
        );
        assert_eq!(
            problems(&text),
            [
                "line 3: unknown record \"hello\" (expected START, S or END)",
                "line 4: 2 samples arrived with no measurement started",
                "measurement lobe L2",
                "line 7: end arrived with no measurement started (after 0 stray samples)",
                "line 10: measurement of machine M3 part P1234 lobe L3 discarded after 1 \
                 samples: cut off by a new start before its end",
                "line 10: measurement of machine M3 part P1234 lobe L4 discarded after 0 \
                 samples: stream ended before the measurement's end",
            ]
        );
    }

    #[test]
    fn crlf_line_ends_and_comments_do_not_change_the_checksum() {
        let good = encode_serial_measurement(&measurement(&[(0, 0, 0.1), (1, 1, -0.1)]))
            .expect("encodable");
        let crlf = good
            .replace('\n', "\r\n")
            .replacen("\r\nS", "\r\n# note\r\n\r\nS", 1);
        assert!(matches!(
            decode_serial_text(&crlf, "pty").as_slice(),
            [SerialEvent::Measurement(m)] if m.samples.len() == 2
        ));
    }
}
