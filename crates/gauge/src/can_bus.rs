//! The live CAN adapter: SocketCAN through socketcan's tokio socket, feeding the same DBC
//! decoder and assembler as the candump replay. The listener is generic over a
//! [`FrameSource`], so it is tested with recorded frames where the kernel has no CAN.

use std::future::Future;
use std::io;

use socketcan::id::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_RTR_FLAG, CAN_SFF_MASK};
use socketcan::{CanFilter, EmbeddedFrame, SocketOptions};

use camloop_core::measure::RawMeasurement;

use super::assemble::{Assembled, Assembler, AssemblyProblem};
use super::candump::parse_candump_line;
use super::dbc::GaugeDbc;
use super::frame::{CanId, FrameError};

/// One received classic CAN data frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReceivedFrame {
    pub id: CanId,
    data: [u8; 8],
    len: u8,
}

impl ReceivedFrame {
    /// `None` when `data` is longer than 8 bytes.
    pub fn new(id: CanId, data: &[u8]) -> Option<Self> {
        let len = u8::try_from(data.len()).ok().filter(|l| *l <= 8)?;
        let mut bytes = [0u8; 8];
        bytes[..data.len()].copy_from_slice(data);
        Some(Self {
            id,
            data: bytes,
            len,
        })
    }

    pub fn data(&self) -> &[u8] {
        &self.data[..usize::from(self.len)]
    }
}

/// Where frames come from: a bus, a replay.
pub trait FrameSource {
    /// The next data frame; `Ok(None)` when the source has ended.
    fn next_frame(&mut self) -> impl Future<Output = io::Result<Option<ReceivedFrame>>> + Send;
}

/// Why a CAN interface could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("can interface {interface} unavailable: {source}{}", hint(.source))]
pub struct CanOpenError {
    pub interface: String,
    pub source: io::Error,
}

fn hint(e: &io::Error) -> &'static str {
    const ENODEV: i32 = 19;
    const EAFNOSUPPORT: i32 = 97;
    const EPROTONOSUPPORT: i32 = 93;
    match e.raw_os_error() {
        Some(EAFNOSUPPORT | EPROTONOSUPPORT) => " (kernel has no SocketCAN support?)",
        Some(ENODEV) => " (no network interface of that name; `ip link` lists them)",
        _ => "",
    }
}

/// A SocketCAN socket bound to one interface, filtered to the gauge's three ids.
#[derive(Debug)]
pub struct CanBus {
    socket: socketcan::tokio::CanSocket,
}

impl CanBus {
    /// Opens `interface` (e.g. "can0"). Needs a tokio runtime with I/O enabled; without
    /// one, or without kernel CAN support, or without the interface, it returns an error.
    pub fn open(interface: &str, dbc: &GaugeDbc) -> Result<Self, CanOpenError> {
        let fail = |source| CanOpenError {
            interface: interface.to_owned(),
            source,
        };
        if tokio::runtime::Handle::try_current().is_err() {
            return Err(fail(io::Error::other(
                "no tokio runtime to drive the socket",
            )));
        }
        let socket = socketcan::tokio::CanSocket::open(interface).map_err(fail)?;
        let filters = [dbc.start.id, dbc.sample.id, dbc.end.id].map(|id| match id {
            CanId::Standard(id) => {
                CanFilter::new(u32::from(id), CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_SFF_MASK)
            }
            CanId::Extended(id) => CanFilter::new(
                id | CAN_EFF_FLAG,
                CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_EFF_MASK,
            ),
        });
        socket.set_filters(&filters).map_err(fail)?;
        Ok(Self { socket })
    }
}

impl FrameSource for CanBus {
    /// Remote and error frames are skipped; a bus never ends by itself.
    async fn next_frame(&mut self) -> io::Result<Option<ReceivedFrame>> {
        loop {
            let frame = self.socket.read_frame().await?;
            let socketcan::CanFrame::Data(data) = frame else {
                continue;
            };
            let id = match data.id() {
                socketcan::Id::Standard(id) => CanId::Standard(id.as_raw()),
                socketcan::Id::Extended(id) => CanId::Extended(id.as_raw()),
            };
            if let Some(frame) = ReceivedFrame::new(id, data.data()) {
                return Ok(Some(frame));
            }
        }
    }
}

/// Replays the data frames of a candump log (lines that do not parse are skipped; use
/// [`super::candump::read_candump_measurements`] to hear about them).
#[derive(Debug, Clone)]
pub struct CandumpReplay {
    frames: std::vec::IntoIter<ReceivedFrame>,
}

impl CandumpReplay {
    pub fn new(text: &str) -> Self {
        let frames: Vec<ReceivedFrame> = text
            .lines()
            .filter_map(|line| parse_candump_line(line).ok())
            .filter_map(|r| ReceivedFrame::new(r.id, r.data()))
            .collect();
        Self {
            frames: frames.into_iter(),
        }
    }
}

impl FrameSource for CandumpReplay {
    async fn next_frame(&mut self) -> io::Result<Option<ReceivedFrame>> {
        Ok(self.frames.next())
    }
}

/// What the listener heard.
#[derive(Debug, Clone, PartialEq)]
pub enum CanEvent {
    Measurement(RawMeasurement),
    Problem(AssemblyProblem),
    /// A frame with a gauge id that does not decode.
    BadFrame(FrameError),
}

/// Frames in, measurements out: decoder and assembler over a [`FrameSource`].
#[derive(Debug)]
pub struct CanGauge<S> {
    source: S,
    dbc: GaugeDbc,
    assembler: Assembler,
    ended: bool,
    /// Frames with ids that are not gauge messages (filtered out on a real bus).
    pub foreign_frames: u64,
}

impl CanGauge<CanBus> {
    /// Opens `interface`; measurements get the interface name as origin.
    pub fn open(interface: &str, dbc: GaugeDbc) -> Result<Self, CanOpenError> {
        Ok(Self::new(CanBus::open(interface, &dbc)?, dbc, interface))
    }
}

impl<S: FrameSource> CanGauge<S> {
    pub fn new(source: S, dbc: GaugeDbc, origin: &str) -> Self {
        Self {
            source,
            dbc,
            assembler: Assembler::new(origin),
            ended: false,
            foreign_frames: 0,
        }
    }

    /// Waits for the next measurement, problem or undecodable frame. `Ok(None)` once the
    /// source has ended (after reporting a measurement left open).
    pub async fn next_event(&mut self) -> io::Result<Option<CanEvent>> {
        while !self.ended {
            let Some(frame) = self.source.next_frame().await? else {
                self.ended = true;
                return Ok(self.assembler.finish().map(event));
            };
            match self.dbc.decode(frame.id, frame.data()) {
                Ok(f) => {
                    if let Some(out) = self.assembler.push(f) {
                        return Ok(Some(event(out)));
                    }
                }
                Err(FrameError::UnknownId { .. }) => self.foreign_frames += 1,
                Err(e) => return Ok(Some(CanEvent::BadFrame(e))),
            }
        }
        Ok(None)
    }
}

fn event(out: Assembled) -> CanEvent {
    match out {
        Assembled::Measurement(m) => CanEvent::Measurement(m),
        Assembled::Problem(p) => CanEvent::Problem(p),
    }
}
