//! The serial gauge adapter: reads the line protocol (see `serial`) from any `AsyncRead` —
//! a real port opened with tokio-serial, a pseudo-terminal, a pipe — with bounded line
//! length, and feeds the pure [`SerialDecoder`].

use std::io;

use tokio::io::{AsyncBufReadExt, AsyncRead, BufReader};
use tokio_serial::{SerialPortBuilderExt, SerialStream};

use super::serial::{MAX_LINE_BYTES, SerialDecoder, SerialEvent, SerialLineError};

/// Why a serial port could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("serial port {path} unavailable: {source}")]
pub struct SerialOpenError {
    pub path: String,
    #[source]
    pub source: tokio_serial::Error,
}

/// Opens a serial port at `baud_rate`, 8 data bits, no parity, 1 stop bit, no flow control.
/// Must be called inside a tokio runtime with I/O enabled.
pub fn open_serial_port(path: &str, baud_rate: u32) -> Result<SerialStream, SerialOpenError> {
    tokio_serial::new(path, baud_rate)
        .data_bits(tokio_serial::DataBits::Eight)
        .parity(tokio_serial::Parity::None)
        .stop_bits(tokio_serial::StopBits::One)
        .flow_control(tokio_serial::FlowControl::None)
        .open_native_async()
        .map_err(|source| SerialOpenError {
            path: path.to_owned(),
            source,
        })
}

/// A gauge speaking the line protocol over `R`.
#[derive(Debug)]
pub struct SerialGauge<R> {
    reader: BufReader<R>,
    decoder: SerialDecoder,
    line: usize,
    buf: Vec<u8>,
    ended: bool,
}

impl SerialGauge<SerialStream> {
    /// Opens the port at `path`; measurements get `path` as their origin.
    pub fn open(path: &str, baud_rate: u32) -> Result<Self, SerialOpenError> {
        Ok(Self::new(open_serial_port(path, baud_rate)?, path))
    }
}

impl<R: AsyncRead + Unpin> SerialGauge<R> {
    pub fn new(reader: R, origin: &str) -> Self {
        Self {
            reader: BufReader::new(reader),
            decoder: SerialDecoder::new(origin),
            line: 0,
            buf: Vec::with_capacity(MAX_LINE_BYTES + 2),
            ended: false,
        }
    }

    /// Waits for the next measurement or problem. `Ok(None)` once the stream has ended
    /// (after reporting a measurement left open); read errors are passed on.
    pub async fn next_event(&mut self) -> io::Result<Option<SerialEvent>> {
        while !self.ended {
            match self.read_line().await? {
                None => {
                    self.ended = true;
                    return Ok(self.decoder.finish(self.line));
                }
                Some(Err(error)) => {
                    if let Some(event) = self.decoder.push_unreadable_line(self.line, error) {
                        return Ok(Some(event));
                    }
                }
                Some(Ok(())) => {
                    let text = std::str::from_utf8(&self.buf).expect("read_line checked the bytes");
                    if let Some(event) = self.decoder.push_line(self.line, text) {
                        return Ok(Some(event));
                    }
                }
            }
        }
        Ok(None)
    }

    /// Reads one line into `buf` without its terminator, keeping at most
    /// `MAX_LINE_BYTES + 1` bytes of it. `None` at end of stream.
    async fn read_line(&mut self) -> io::Result<Option<Result<(), SerialLineError>>> {
        self.buf.clear();
        let mut overflow = false;
        loop {
            let available = self.reader.fill_buf().await?;
            if available.is_empty() {
                if self.buf.is_empty() && !overflow {
                    return Ok(None);
                }
                break;
            }
            let (chunk, used, done) = match available.iter().position(|&b| b == b'\n') {
                Some(pos) => (&available[..pos], pos + 1, true),
                None => (available, available.len(), false),
            };
            let room = (MAX_LINE_BYTES + 1).saturating_sub(self.buf.len());
            overflow |= chunk.len() > room;
            self.buf.extend_from_slice(&chunk[..chunk.len().min(room)]);
            self.reader.consume(used);
            if done {
                break;
            }
        }
        self.line += 1;
        if self.buf.last() == Some(&b'\r') {
            self.buf.pop();
        }
        Ok(Some(if overflow || self.buf.len() > MAX_LINE_BYTES {
            Err(SerialLineError::TooLong)
        } else if std::str::from_utf8(&self.buf).is_err() {
            Err(SerialLineError::NotAscii)
        } else {
            Ok(())
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serial::SerialProblem;

    async fn events(input: &[u8]) -> Vec<SerialEvent> {
        let mut gauge = SerialGauge::new(input, "pipe");
        let mut out = Vec::new();
        while let Some(e) = gauge
            .next_event()
            .await
            .expect("reading a slice cannot fail")
        {
            out.push(e);
        }
        out
    }

    #[tokio::test]
    async fn overlong_and_binary_lines_are_bounded_and_reported() {
        let mut input = b"hello\n".to_vec();
        input.extend(std::iter::repeat_n(b'7', 100_000));
        input.extend(b"\n\xff\xfe\nS 0 0 0.1");
        let out = events(&input).await;
        let lines: Vec<String> = out
            .iter()
            .map(|e| match e {
                SerialEvent::Problem(p) => p.to_string(),
                SerialEvent::Measurement(_) => "measurement".into(),
            })
            .collect();
        assert_eq!(
            lines,
            [
                "line 1: unknown record \"hello\" (expected START, S or END)",
                "line 2: line is longer than 256 bytes",
                "line 3: line is not ascii text",
                "line 4: 1 samples arrived with no measurement started",
            ]
        );
    }

    #[tokio::test]
    async fn a_bad_line_inside_a_measurement_spoils_it() {
        let mut input = b"START M1 P1 L1 1 2\nS 0 0 0.1\n".to_vec();
        input.extend(std::iter::repeat_n(b'x', 1000));
        input.extend(b"\nS 0 1 0.2\nEND 2 00000000\n");
        let out = events(&input).await;
        assert_eq!(out.len(), 1);
        let SerialEvent::Problem(SerialProblem::Assembly { line, problem }) = &out[0] else {
            panic!("{out:?}")
        };
        assert_eq!(*line, 5);
        assert!(
            problem
                .to_string()
                .ends_with("line 3: line is longer than 256 bytes"),
            "{problem}"
        );
    }
}
