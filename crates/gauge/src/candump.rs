//! Recorded CAN traffic: a pure parser for `candump -l` log lines and a replay of a whole log
//! through the DBC decoder and the assembler.
//!
//! Line format: `(1700000000.000000) can0 5A1#0011223344556677`, the id as exactly 3 hex
//! digits (standard) or 8 (extended, at most 29 bits), 0–8 data bytes as hex pairs (a `.`
//! between bytes is tolerated), optionally followed by a direction flag `R` (received) or
//! `T` (transmitted) as newer can-utils and python-can write it. CAN FD lines (`ID##F…`) and remote requests (`ID#R`) are
//! rejected explicitly: the gauge protocol is classic CAN data frames.

use camloop_core::measure::RawMeasurement;

use super::assemble::{Assembled, Assembler, AssemblyProblem};
use super::dbc::GaugeDbc;
use super::frame::{CanId, FrameError};

/// One parsed log line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CandumpRecord<'a> {
    /// Seconds since the epoch, as logged.
    pub timestamp_s: f64,
    pub interface: &'a str,
    pub id: CanId,
    data: [u8; 8],
    len: u8,
}

impl CandumpRecord<'_> {
    /// The frame's data bytes (0–8).
    pub fn data(&self) -> &[u8] {
        &self.data[..usize::from(self.len)]
    }
}

/// Why a log line is not a classic CAN frame record.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CandumpLineError {
    #[error("expected `(timestamp) interface id#data`, found {found:?}")]
    Shape { found: String },
    #[error("timestamp {found:?} is not `(seconds.fraction)`")]
    Timestamp { found: String },
    #[error("can id {found:?} must be 3 hex digits (standard) or 8 (extended)")]
    IdLength { found: String },
    #[error("can id {found:?} is not hexadecimal")]
    IdHex { found: String },
    #[error("standard can id {found:?} exceeds 0x7FF")]
    StandardIdRange { found: String },
    #[error("extended can id {found:?} exceeds 29 bits (error frame flags?)")]
    ExtendedIdRange { found: String },
    #[error("can fd frame (`##`) not supported: the gauge protocol is classic CAN")]
    CanFd,
    #[error("remote request frame carries no data")]
    Remote,
    #[error("data {found:?} is not whole hex bytes")]
    DataHex { found: String },
    #[error("data has {bytes} bytes; classic CAN carries at most 8")]
    DataTooLong { bytes: usize },
}

/// Parses one `candump -l` line. Blank lines are the caller's business.
pub fn parse_candump_line(line: &str) -> Result<CandumpRecord<'_>, CandumpLineError> {
    let shape = || CandumpLineError::Shape { found: clip(line) };
    let mut fields = line.split_ascii_whitespace();
    let (Some(stamp), Some(interface), Some(frame), None | Some("R" | "T"), None) = (
        fields.next(),
        fields.next(),
        fields.next(),
        fields.next(),
        fields.next(),
    ) else {
        return Err(shape());
    };
    let timestamp_s =
        parse_timestamp(stamp).ok_or_else(|| CandumpLineError::Timestamp { found: clip(stamp) })?;
    let (id_text, data_text) = frame.split_once('#').ok_or_else(shape)?;
    let id = parse_id(id_text)?;
    if data_text.starts_with('#') {
        return Err(CandumpLineError::CanFd);
    }
    if data_text.starts_with(['R', 'r']) {
        return Err(CandumpLineError::Remote);
    }
    let (data, len) = parse_data(data_text)?;
    Ok(CandumpRecord {
        timestamp_s,
        interface,
        id,
        data,
        len,
    })
}

fn parse_timestamp(stamp: &str) -> Option<f64> {
    let inner = stamp.strip_prefix('(')?.strip_suffix(')')?;
    let (secs, frac) = inner.split_once('.')?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if !digits(secs) || !digits(frac) {
        return None;
    }
    inner.parse().ok()
}

fn parse_id(text: &str) -> Result<CanId, CandumpLineError> {
    let hex = u32::from_str_radix(text, 16);
    let found = || clip(text);
    if !text.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(CandumpLineError::IdHex { found: found() });
    }
    match (text.len(), hex) {
        (3, Ok(id)) if id <= 0x7ff => Ok(CanId::Standard(u16::try_from(id).expect("≤ 0x7FF"))),
        (3, _) => Err(CandumpLineError::StandardIdRange { found: found() }),
        (8, Ok(id)) if id <= 0x1fff_ffff => Ok(CanId::Extended(id)),
        (8, _) => Err(CandumpLineError::ExtendedIdRange { found: found() }),
        _ => Err(CandumpLineError::IdLength { found: found() }),
    }
}

fn parse_data(text: &str) -> Result<([u8; 8], u8), CandumpLineError> {
    let bad = || CandumpLineError::DataHex { found: clip(text) };
    // The first 16 digits (8 bytes) on the stack; beyond them only the count matters.
    let (mut head, mut digits) = ([0u8; 16], 0usize);
    for b in text.bytes().filter(|&b| b != b'.') {
        if let Some(slot) = head.get_mut(digits) {
            *slot = b;
        }
        digits += 1;
    }
    let head = &head[..digits.min(16)];
    let mut data = [0u8; 8];
    if head.len() % 2 != 0 || digits == 17 {
        return Err(bad());
    }
    let len = base16ct::mixed::decode(head, &mut data)
        .map_err(|_| bad())?
        .len();
    if digits > 16 {
        return Err(CandumpLineError::DataTooLong { bytes: digits / 2 });
    }
    Ok((data, u8::try_from(len).expect("≤ 8")))
}

/// Error messages quote at most this many characters of the offending text.
fn clip(text: &str) -> String {
    const MAX: usize = 80;
    match text.char_indices().nth(MAX) {
        Some((cut, _)) => format!("{}…", &text[..cut]),
        None => text.to_owned(),
    }
}

/// What went wrong at one line of a log.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CandumpIssue {
    #[error("line {line}: {error}")]
    Line {
        line: usize,
        error: CandumpLineError,
    },
    #[error("line {line}: {error}")]
    Frame { line: usize, error: FrameError },
    /// `line` is where the problem became known (the cutting start, the stray end, the
    /// last line for an unfinished measurement).
    #[error("line {line}: {problem}")]
    Assembly {
        line: usize,
        problem: AssemblyProblem,
    },
}

/// The result of replaying a log.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CandumpReport {
    /// Complete measurements in log order.
    pub measurements: Vec<RawMeasurement>,
    /// Everything else worth telling, in log order.
    pub issues: Vec<CandumpIssue>,
    /// Well-formed frames with ids that are not gauge messages (other traffic on a shared
    /// bus); counted, not reported one by one.
    pub foreign_frames: usize,
}

/// Replays a `candump -l` log through the DBC decoder and the assembler. Every measurement
/// gets `origin`. Never fails as a whole: bad lines and frames become issues naming the line.
pub fn read_candump_measurements(text: &str, dbc: &GaugeDbc, origin: &str) -> CandumpReport {
    let mut report = CandumpReport::default();
    let mut assembler = Assembler::new(origin);
    let mut last_line = 0;
    let deliver = |report: &mut CandumpReport, line: usize, out: Option<Assembled>| match out {
        Some(Assembled::Measurement(m)) => report.measurements.push(m),
        Some(Assembled::Problem(problem)) => {
            report.issues.push(CandumpIssue::Assembly { line, problem })
        }
        None => {}
    };
    for (index, raw_line) in text.lines().enumerate() {
        let line = index + 1;
        last_line = line;
        if raw_line.trim().is_empty() {
            continue;
        }
        let record = match parse_candump_line(raw_line) {
            Ok(r) => r,
            Err(error) => {
                report.issues.push(CandumpIssue::Line { line, error });
                continue;
            }
        };
        match dbc.decode(record.id, record.data()) {
            Ok(frame) => deliver(&mut report, line, assembler.push(frame)),
            Err(FrameError::UnknownId { .. }) => report.foreign_frames += 1,
            Err(error) => report.issues.push(CandumpIssue::Frame { line, error }),
        }
    }
    deliver(&mut report, last_line, assembler.finish());
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(line: &str) -> String {
        parse_candump_line(line)
            .expect_err("must be rejected")
            .to_string()
    }

    #[test]
    fn parses_standard_and_extended_frames() {
        let r = parse_candump_line("(1700000000.000000) can0 1A0#0011223344556677").expect("valid");
        assert_eq!(r.timestamp_s, 1_700_000_000.0);
        assert_eq!(r.interface, "can0");
        assert_eq!(r.id, CanId::Standard(0x1a0));
        assert_eq!(r.data(), [0x00, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77]);

        let r = parse_candump_line("(1700000000.250000) vcan1 18FF5A01#dead.BEEF R").expect("ok");
        assert_eq!(r.id, CanId::Extended(0x18ff_5a01));
        assert_eq!(r.data(), [0xde, 0xad, 0xbe, 0xef]);
        assert_eq!(r.timestamp_s, 1_700_000_000.25);

        let r = parse_candump_line("(0.1) can0 5A2# T").expect("empty payload, tx flag");
        assert!(r.data().is_empty());
    }

    #[test]
    fn rejects_what_is_not_a_classic_data_frame() {
        assert_eq!(
            err("(1.0) can0 5A1##1001122"),
            "can fd frame (`##`) not supported: the gauge protocol is classic CAN"
        );
        assert_eq!(
            err("(1.0) can0 5A1#R"),
            "remote request frame carries no data"
        );
        assert_eq!(
            err("(1.0) can0 5A1#001122334455667788"),
            "data has 9 bytes; classic CAN carries at most 8"
        );
        assert_eq!(
            err("(1.0) can0 5A1#001"),
            "data \"001\" is not whole hex bytes"
        );
        assert_eq!(
            err("(1.0) can0 5A1#0g"),
            "data \"0g\" is not whole hex bytes"
        );
        assert_eq!(
            err("(1.0) can0 5A#00"),
            "can id \"5A\" must be 3 hex digits (standard) or 8 (extended)"
        );
        assert_eq!(
            err("(1.0) can0 5Z1#00"),
            "can id \"5Z1\" is not hexadecimal"
        );
        assert_eq!(
            err("(1.0) can0 800#00"),
            "standard can id \"800\" exceeds 0x7FF"
        );
        assert_eq!(
            err("(1.0) can0 20000001#00"),
            "extended can id \"20000001\" exceeds 29 bits (error frame flags?)"
        );
        assert_eq!(
            err("1.0 can0 5A1#00"),
            "timestamp \"1.0\" is not `(seconds.fraction)`"
        );
        assert_eq!(
            err("(1.0) can0"),
            "expected `(timestamp) interface id#data`, found \"(1.0) can0\""
        );
        assert_eq!(
            err("(1.0) can0 5A1#00 extra"),
            "expected `(timestamp) interface id#data`, found \"(1.0) can0 5A1#00 extra\""
        );
        // Multi-byte characters never split when clipped.
        let long = format!("(1.0) can0 {}", "é".repeat(200));
        // 80 quoted characters plus the message around them.
        assert!(err(&long).chars().count() < 140, "{}", err(&long));
    }

    #[test]
    fn a_log_replays_into_measurements_and_line_numbered_issues() {
        let dbc = GaugeDbc::builtin();
        // Start: machine 3, part 1234 (0x0004D2), lobe 2, 3 revs… but only 1 rev × 2 points
        // used here: revolutions 1 → byte 2 = lobe low bits 10 << 6 | 1 = 0x81.
        // Machine 3 → 12 bits 0x003 in byte 0 and the top nibble of byte 1; lobe 2 = 0b000010
        // → low nibble of byte 1 = 0b0000, bits 7..6 of byte 2 = 0b10.
        let log = "\
(1.000000) can0 5A0#0030810004D20002
(1.001000) can0 123#00
(1.002000) can0 5A1#000000E8030000
(1.003000) can0 5A1#40000018FCFFFF

(1.004000) can0 5A1#400000
(1.005000) can0 5A2#00
(1.006000) can0 5A2#00
garbage
(1.007000) can0 5A0#0030810004D20002
(1.008000) can0 5A1#00000000000000
";
        let report = read_candump_measurements(log, &dbc, "bench.log");
        assert_eq!(report.foreign_frames, 1);
        assert_eq!(report.measurements.len(), 1);
        let m = &report.measurements[0];
        assert_eq!(m.origin, "bench.log");
        assert_eq!(
            (
                m.header.machine.as_str(),
                m.header.part.as_str(),
                m.header.lobe.as_str()
            ),
            ("3", "1234", "2")
        );
        assert_eq!((m.header.revolutions, m.header.points_per_rev), (1, 2));
        assert_eq!(m.samples.len(), 2);
        // 0x000003E8 = 1000 raw = 0.1 mm; 0xFFFFFC18 = -1000 raw = -0.1 mm (±1e-12 for the
        // binary factor).
        assert!((m.samples[0].lift_mm - 0.1).abs() < 1e-12);
        assert_eq!(m.samples[1].angle_index, 1);
        assert!((m.samples[1].lift_mm + 0.1).abs() < 1e-12);
        let issues: Vec<String> = report.issues.iter().map(ToString::to_string).collect();
        assert_eq!(
            issues,
            [
                "line 6: GaugeSample frame has 3 data bytes, needs 7",
                "line 8: end arrived with no measurement started (after 0 stray samples)",
                "line 9: expected `(timestamp) interface id#data`, found \"garbage\"",
                "line 11: measurement of machine 3 part 1234 lobe 2 discarded after 1 samples: \
                 stream ended before the measurement's end",
            ]
        );
    }
}
