//! Turning a stream of gauge frames into measurements: a pure state machine (no I/O, no
//! clock) shared in spirit by every interface, with what went wrong returned as data.
//!
//! Protocol: a Start opens a measurement, Samples accumulate in arrival order, an End closes
//! it. A new Start before the End discards the open measurement (reported); samples or an End
//! with nothing open are reported and ignored. Completeness and averaging are checked later,
//! in `core`; here only what makes a measurement unusable as a whole is caught: a sample off
//! the announced grid, more samples than the grid holds, a gauge fault status.

use std::fmt;

use camloop_core::measure::{MeasurementHeader, RawMeasurement, RawSample};

use super::frame::{GaugeFrame, GaugeStart};

/// Most readings per revolution any interface accepts (0.0036° spacing).
pub const MAX_POINTS_PER_REV: u32 = 100_000;
/// Most revolutions per measurement any interface accepts.
pub const MAX_REVOLUTIONS: u32 = 1_000;
/// Most samples one measurement may hold (`revolutions · points_per_rev`); bounds memory.
pub const MAX_SAMPLES: u64 = 1_000_000;

/// Why a measurement that had begun was not delivered.
#[derive(Debug, Clone, PartialEq)]
pub enum DiscardReason {
    /// A new start arrived before the end.
    CutOffByNewStart,
    /// The stream (log, port, bus) ended before the end.
    StreamEnded,
    /// The gauge closed it with a non-zero status.
    GaugeStatus(u32),
    /// The header announces more than the limits allow.
    HeaderBeyondLimits {
        revolutions: u32,
        points_per_rev: u32,
    },
    /// A sample outside `revolution < revolutions`, `angle_index < points_per_rev`.
    SampleOffGrid { revolution: u32, angle_index: u32 },
    /// More samples than `revolutions · points_per_rev`.
    TooManySamples { capacity: u64 },
    /// Serial: the end line announced a different sample count.
    CountMismatch { announced: u64, received: u64 },
    /// Serial: the CRC-32 over the start and sample lines does not match.
    ChecksumMismatch { announced: u32, computed: u32 },
    /// Serial: a line inside the measurement did not parse.
    MalformedLine { line: usize, error: String },
}

impl fmt::Display for DiscardReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::CutOffByNewStart => write!(f, "cut off by a new start before its end"),
            Self::StreamEnded => write!(f, "stream ended before the measurement's end"),
            Self::GaugeStatus(s) => write!(f, "gauge ended it with status {s}"),
            Self::HeaderBeyondLimits {
                revolutions,
                points_per_rev,
            } => write!(
                f,
                "header announces {revolutions} revolutions × {points_per_rev} points, beyond \
                 the limits ({MAX_REVOLUTIONS} revolutions, {MAX_POINTS_PER_REV} points, \
                 {MAX_SAMPLES} samples)"
            ),
            Self::SampleOffGrid {
                revolution,
                angle_index,
            } => write!(
                f,
                "sample at revolution {revolution}, angle index {angle_index} is outside the \
                 announced grid"
            ),
            Self::TooManySamples { capacity } => {
                write!(f, "more samples than the {capacity} the header announces")
            }
            Self::CountMismatch {
                announced,
                received,
            } => write!(
                f,
                "end line announces {announced} samples, {received} were received"
            ),
            Self::ChecksumMismatch {
                announced,
                computed,
            } => write!(
                f,
                "checksum mismatch: end line says {announced:08X}, lines give {computed:08X}"
            ),
            Self::MalformedLine { line, error } => write!(f, "line {line}: {error}"),
        }
    }
}

/// Something in the stream that did not become a measurement.
#[derive(Debug, Clone, PartialEq)]
pub enum AssemblyProblem {
    /// A measurement began and was dropped.
    Discarded {
        header: MeasurementHeader,
        samples_received: usize,
        reason: DiscardReason,
    },
    /// A run of samples with no measurement open (reported once per run).
    SamplesWithoutStart { count: usize },
    /// An end with no measurement open, after `stray_samples` samples with none open.
    EndWithoutStart { stray_samples: usize },
}

impl fmt::Display for AssemblyProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Discarded {
                header: h,
                samples_received,
                reason,
            } => write!(
                f,
                "measurement of machine {} part {} lobe {} discarded after {samples_received} \
                 samples: {reason}",
                h.machine, h.part, h.lobe
            ),
            Self::SamplesWithoutStart { count } => {
                write!(f, "{count} samples arrived with no measurement started")
            }
            Self::EndWithoutStart { stray_samples } => write!(
                f,
                "end arrived with no measurement started (after {stray_samples} stray samples)"
            ),
        }
    }
}

/// What feeding one frame produced, if anything.
#[derive(Debug, Clone, PartialEq)]
pub enum Assembled {
    Measurement(RawMeasurement),
    Problem(AssemblyProblem),
}

/// The CAN part number of a master part (the 24-bit field all ones).
pub(crate) const MASTER_PART_NUMBER: u64 = 0xFF_FFFF;
/// The part id a master part's CAN run renders as.
pub const MASTER_PART: &str = "MASTER";

/// Renders the numeric ids of a CAN start frame. Decision: plain decimal numbers ("3",
/// "1234", "2"), so that the same machine/part/lobe sent over serial or in a file name as
/// digits names the same thing.
/// The one exception: part [`MASTER_PART_NUMBER`] (all ones) is a master part's run of a
/// gauge study and renders as [`MASTER_PART`].
pub(crate) fn header_from_start(start: &GaugeStart) -> MeasurementHeader {
    MeasurementHeader {
        machine: start.machine.to_string(),
        part: if start.part == MASTER_PART_NUMBER {
            MASTER_PART.to_string()
        } else {
            start.part.to_string()
        },
        lobe: start.lobe.to_string(),
        revolutions: start.revolutions,
        points_per_rev: start.points_per_rev,
    }
}

/// A measurement being received: the header, the samples so far and the first reason it is
/// unusable, if any. Shared by the CAN assembler and the serial decoder.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct OpenMeasurement {
    pub header: MeasurementHeader,
    pub samples: Vec<RawSample>,
    pub capacity: u64,
    /// Samples counted after the measurement went bad (they are not kept).
    pub dropped: usize,
    pub spoiled: Option<DiscardReason>,
}

impl OpenMeasurement {
    pub fn new(header: MeasurementHeader) -> Self {
        let capacity = u64::from(header.revolutions) * u64::from(header.points_per_rev);
        let spoiled = (header.revolutions > MAX_REVOLUTIONS
            || header.points_per_rev > MAX_POINTS_PER_REV
            || capacity > MAX_SAMPLES)
            .then_some(DiscardReason::HeaderBeyondLimits {
                revolutions: header.revolutions,
                points_per_rev: header.points_per_rev,
            });
        // Reserve for a typical measurement only: a header announcing a huge grid must not
        // cost memory before samples actually arrive.
        let reserve = if spoiled.is_some() {
            0
        } else {
            capacity.min(4096)
        };
        Self {
            header,
            samples: Vec::with_capacity(usize::try_from(reserve).unwrap_or(0)),
            capacity,
            dropped: 0,
            spoiled,
        }
    }

    /// Keeps a sample, or spoils the measurement if the sample is off the grid or one too
    /// many. Once spoiled, samples are only counted.
    pub fn add(&mut self, s: RawSample) {
        if self.spoiled.is_some() {
            self.dropped += 1;
            return;
        }
        if s.revolution >= self.header.revolutions || s.angle_index >= self.header.points_per_rev {
            self.spoil(DiscardReason::SampleOffGrid {
                revolution: s.revolution,
                angle_index: s.angle_index,
            });
            self.dropped += 1;
        } else if self.samples.len() as u64 >= self.capacity {
            self.spoil(DiscardReason::TooManySamples {
                capacity: self.capacity,
            });
            self.dropped += 1;
        } else {
            self.samples.push(s);
        }
    }

    /// Records the first reason this measurement is unusable.
    pub(crate) fn spoil(&mut self, reason: DiscardReason) {
        self.spoiled.get_or_insert(reason);
    }

    pub fn received(&self) -> usize {
        self.samples.len() + self.dropped
    }

    /// Discards it, keeping the first reason it went bad if it already had one.
    pub fn discard(self, reason: DiscardReason) -> AssemblyProblem {
        let received = self.received();
        AssemblyProblem::Discarded {
            header: self.header,
            samples_received: received,
            reason: self.spoiled.unwrap_or(reason),
        }
    }

    /// Delivers it, unless it went bad on the way.
    pub fn finish(self, origin: &str) -> Assembled {
        match self.spoiled {
            Some(reason) => Assembled::Problem(AssemblyProblem::Discarded {
                samples_received: self.samples.len() + self.dropped,
                header: self.header,
                reason,
            }),
            None => Assembled::Measurement(RawMeasurement {
                header: self.header,
                samples: self.samples,
                origin: origin.to_owned(),
            }),
        }
    }
}

/// The CAN assembler: [`GaugeFrame`]s in, measurements and problems out.
#[derive(Debug, Clone)]
pub struct Assembler {
    origin: String,
    open: Option<OpenMeasurement>,
    /// Samples seen since the last start/end while nothing was open.
    orphans: usize,
}

impl Assembler {
    /// `origin` is copied into every measurement ("can0", a log file path, …).
    pub fn new(origin: impl Into<String>) -> Self {
        Self {
            origin: origin.into(),
            open: None,
            orphans: 0,
        }
    }

    /// Whether a measurement is open.
    pub fn is_open(&self) -> bool {
        self.open.is_some()
    }

    /// Feeds one frame; at most one result per frame.
    pub fn push(&mut self, frame: GaugeFrame) -> Option<Assembled> {
        match frame {
            GaugeFrame::Start(start) => {
                let previous = self
                    .open
                    .replace(OpenMeasurement::new(header_from_start(&start)));
                match previous {
                    Some(m) => Some(Assembled::Problem(
                        m.discard(DiscardReason::CutOffByNewStart),
                    )),
                    None => self.take_orphans(),
                }
            }
            GaugeFrame::Sample(sample) => {
                match &mut self.open {
                    Some(m) => m.add(sample),
                    None => self.orphans += 1,
                }
                None
            }
            GaugeFrame::End { status } => match self.open.take() {
                Some(mut m) => {
                    if status != 0 {
                        m.spoil(DiscardReason::GaugeStatus(status));
                    }
                    Some(m.finish(&self.origin))
                }
                None => Some(Assembled::Problem(AssemblyProblem::EndWithoutStart {
                    stray_samples: std::mem::take(&mut self.orphans),
                })),
            },
        }
    }

    /// The stream ended: reports a measurement left open, or a trailing run of orphans.
    pub fn finish(&mut self) -> Option<Assembled> {
        match self.open.take() {
            Some(m) => Some(Assembled::Problem(m.discard(DiscardReason::StreamEnded))),
            None => self.take_orphans(),
        }
    }

    fn take_orphans(&mut self) -> Option<Assembled> {
        let count = std::mem::take(&mut self.orphans);
        (count > 0).then_some(Assembled::Problem(AssemblyProblem::SamplesWithoutStart {
            count,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn start(lobe: u64, revolutions: u32, points_per_rev: u32) -> GaugeFrame {
        GaugeFrame::Start(GaugeStart {
            machine: 3,
            part: 1234,
            lobe,
            revolutions,
            points_per_rev,
        })
    }

    fn sample(revolution: u32, angle_index: u32) -> GaugeFrame {
        GaugeFrame::Sample(RawSample {
            revolution,
            angle_index,
            lift_mm: f64::from(revolution * 100 + angle_index) * 1e-3,
        })
    }

    fn run(frames: &[GaugeFrame]) -> Vec<Assembled> {
        let mut a = Assembler::new("test");
        let mut out: Vec<_> = frames.iter().filter_map(|f| a.push(*f)).collect();
        out.extend(a.finish());
        out
    }

    fn discarded(out: &Assembled) -> (&str, usize, &DiscardReason) {
        match out {
            Assembled::Problem(AssemblyProblem::Discarded {
                header,
                samples_received,
                reason,
            }) => (header.lobe.as_str(), *samples_received, reason),
            other => panic!("expected a discarded measurement, got {other:?}"),
        }
    }

    #[test]
    fn a_clean_measurement_keeps_arrival_order() {
        let mut frames = vec![start(2, 2, 3)];
        // Arrival order deliberately not sorted.
        for (r, i) in [(0, 2), (0, 0), (0, 1), (1, 0), (1, 2), (1, 1)] {
            frames.push(sample(r, i));
        }
        frames.push(GaugeFrame::End { status: 0 });
        let out = run(&frames);
        assert_eq!(out.len(), 1);
        let Assembled::Measurement(m) = &out[0] else {
            panic!("{out:?}")
        };
        assert_eq!(
            (m.header.machine.as_str(), m.header.part.as_str()),
            ("3", "1234")
        );
        assert_eq!(m.header.lobe, "2");
        assert_eq!(m.origin, "test");
        let order: Vec<_> = m
            .samples
            .iter()
            .map(|s| (s.revolution, s.angle_index))
            .collect();
        assert_eq!(order, [(0, 2), (0, 0), (0, 1), (1, 0), (1, 2), (1, 1)]);
        assert_eq!(m.samples[1].lift_mm, 0.0);
        // Values pass through untouched: bit-identical to what the frame carried.
        assert_eq!(m.samples[4].lift_mm, 102.0 * 1e-3);
    }

    #[test]
    fn a_new_start_discards_the_open_measurement() {
        let out = run(&[
            start(1, 3, 4),
            sample(0, 0),
            sample(0, 1),
            start(2, 1, 2),
            sample(0, 0),
            sample(0, 1),
            GaugeFrame::End { status: 0 },
        ]);
        assert_eq!(out.len(), 2);
        assert_eq!(
            discarded(&out[0]),
            ("1", 2, &DiscardReason::CutOffByNewStart)
        );
        assert!(
            matches!(&out[1], Assembled::Measurement(m) if m.header.lobe == "2" && m.samples.len() == 2)
        );
        assert_eq!(
            out[0].clone(),
            Assembled::Problem(AssemblyProblem::Discarded {
                header: header_from_start(&GaugeStart {
                    machine: 3,
                    part: 1234,
                    lobe: 1,
                    revolutions: 3,
                    points_per_rev: 4
                }),
                samples_received: 2,
                reason: DiscardReason::CutOffByNewStart,
            })
        );
    }

    #[test]
    fn stray_samples_and_ends_are_reported_once_per_run() {
        let out = run(&[
            sample(0, 0),
            sample(0, 1),
            sample(0, 2),
            start(1, 1, 1),
            sample(0, 0),
            GaugeFrame::End { status: 0 },
            sample(0, 0),
            GaugeFrame::End { status: 0 },
            sample(0, 0),
            sample(0, 0),
        ]);
        assert_eq!(out.len(), 4, "{out:?}");
        assert_eq!(
            out[0],
            Assembled::Problem(AssemblyProblem::SamplesWithoutStart { count: 3 })
        );
        assert!(matches!(&out[1], Assembled::Measurement(m) if m.samples.len() == 1));
        assert_eq!(
            out[2],
            Assembled::Problem(AssemblyProblem::EndWithoutStart { stray_samples: 1 })
        );
        assert_eq!(
            out[3],
            Assembled::Problem(AssemblyProblem::SamplesWithoutStart { count: 2 })
        );
    }

    #[test]
    fn unusable_measurements_are_discarded_with_the_first_reason() {
        let out = run(&[start(1, 1, 2), sample(0, 0), sample(0, 2), sample(0, 1)]);
        assert_eq!(out.len(), 1);
        assert_eq!(
            discarded(&out[0]),
            (
                "1",
                3,
                &DiscardReason::SampleOffGrid {
                    revolution: 0,
                    angle_index: 2
                }
            )
        );

        let out = run(&[start(1, 1, 2), sample(0, 0), GaugeFrame::End { status: 2 }]);
        assert_eq!(discarded(&out[0]), ("1", 1, &DiscardReason::GaugeStatus(2)));

        let out = run(&[
            start(1, 1, 2),
            sample(0, 0),
            sample(0, 1),
            sample(0, 1),
            GaugeFrame::End { status: 0 },
        ]);
        assert_eq!(
            discarded(&out[0]),
            ("1", 3, &DiscardReason::TooManySamples { capacity: 2 })
        );

        let out = run(&[start(1, 2_000, 36_000), GaugeFrame::End { status: 0 }]);
        assert_eq!(
            discarded(&out[0]).2,
            &DiscardReason::HeaderBeyondLimits {
                revolutions: 2_000,
                points_per_rev: 36_000
            }
        );
        assert_eq!(
            out[0].clone(),
            Assembled::Problem(AssemblyProblem::Discarded {
                header: header_from_start(&GaugeStart {
                    machine: 3,
                    part: 1234,
                    lobe: 1,
                    revolutions: 2_000,
                    points_per_rev: 36_000
                }),
                samples_received: 0,
                reason: DiscardReason::HeaderBeyondLimits {
                    revolutions: 2_000,
                    points_per_rev: 36_000
                },
            })
        );
    }

    #[test]
    fn an_unfinished_measurement_is_reported_at_the_end_of_the_stream() {
        let out = run(&[start(5, 3, 360), sample(0, 0)]);
        assert_eq!(discarded(&out[0]), ("5", 1, &DiscardReason::StreamEnded));
        let msg = match &out[0] {
            Assembled::Problem(p) => p.to_string(),
            Assembled::Measurement(_) => String::new(),
        };
        assert_eq!(
            msg,
            "measurement of machine 3 part 1234 lobe 5 discarded after 1 samples: stream ended \
             before the measurement's end"
        );
    }
}
