#!/usr/bin/env python3
"""Encode gauge measurements as candump logs, independently of camloop's Rust decoder.

Frames are encoded from config/gauge.dbc by cantools (not by camloop) and written with
python-can's candump log writer, so the Rust test that decodes these logs checks camloop's
DBC decoding (bit positions, Intel and Motorola byte order, signedness, scale) against a
second implementation.

    pip install cantools python-can
    python3 tools/encode_candump.py            # rewrites tests/fixtures/gauge_*.log

The lift of every sample follows one formula, re-computed by the Rust tests:

    theta  = 2*pi * angle_index / points_per_rev              (radians)
    lift_mm = 6.2 * ((1 - cos theta) / 2)**2
              + 0.0015 * sin(5*theta + revolution)
              - 0.0008

so it runs from about -0.0023 mm (slightly negative, as a real gauge reads near the base
circle) to about 6.2 mm, and differs from revolution to revolution. cantools rounds each
lift to the DBC resolution (0.0001 mm), so a correct decoder is within 0.00005 mm of it.

Fixtures written:
  gauge_3x360.log  machine 3, part 1234, lobe 2: 3 revolutions x 360 points, status 0.
  gauge_cutoff.log two stray samples, a foreign frame (0x123), lobe 1 cut off after 500
                   samples by the start of lobe 2 (complete, 3 x 360, with a foreign extended
                   frame 0x18FEF100 after every 100th sample), then lobe 3 ended by the gauge
                   with status 2 (probe fault) after 10 samples.
"""

import math
import pathlib

import can
import cantools

ROOT = pathlib.Path(__file__).resolve().parent.parent
DBC = cantools.database.load_file(str(ROOT / "config" / "gauge.dbc"))
START = DBC.get_message_by_name("GaugeStart")
SAMPLE = DBC.get_message_by_name("GaugeSample")
END = DBC.get_message_by_name("GaugeEnd")

T0 = 1_700_000_000.0
# C turning at 60 rpm with 360 readings per revolution: one frame every 1/360 s.
DT = 1.0 / 360.0


def lift_mm(revolution: int, angle_index: int, points_per_rev: int) -> float:
    theta = 2.0 * math.pi * angle_index / points_per_rev
    return (
        6.2 * ((1.0 - math.cos(theta)) / 2.0) ** 2
        + 0.0015 * math.sin(5.0 * theta + revolution)
        - 0.0008
    )


class Log:
    def __init__(self, path: pathlib.Path):
        self.writer = can.CanutilsLogWriter(str(path), channel="can0")
        self.t = T0

    def send(self, message, signals):
        self.raw(message.frame_id, message.encode(signals), extended=False)

    def raw(self, frame_id: int, data: bytes, extended: bool):
        self.writer.on_message_received(
            can.Message(
                timestamp=self.t,
                arbitration_id=frame_id,
                is_extended_id=extended,
                data=data,
                channel="can0",
            )
        )
        self.t += DT

    def start(self, machine, part, lobe, revolutions, points_per_rev):
        self.send(
            START,
            {
                "Machine": machine,
                "Part": part,
                "Lobe": lobe,
                "Revolutions": revolutions,
                "PointsPerRev": points_per_rev,
            },
        )

    def sample(self, revolution, angle_index, points_per_rev):
        self.send(
            SAMPLE,
            {
                "Revolution": revolution,
                "AngleIndex": angle_index,
                "Lift": lift_mm(revolution, angle_index, points_per_rev),
            },
        )

    def end(self, status):
        self.send(END, {"Status": status})

    def close(self):
        self.writer.stop()


def write_full(path):
    log = Log(path)
    log.start(3, 1234, 2, 3, 360)
    for r in range(3):
        for i in range(360):
            log.sample(r, i, 360)
    log.end(0)
    log.close()


def write_cutoff(path):
    log = Log(path)
    log.sample(0, 0, 360)
    log.sample(0, 1, 360)
    log.raw(0x123, bytes([1, 2, 3]), extended=False)
    log.start(3, 1234, 1, 3, 360)
    for n in range(500):
        log.sample(n // 360, n % 360, 360)
    log.start(3, 1234, 2, 3, 360)
    for n in range(3 * 360):
        log.sample(n // 360, n % 360, 360)
        if n % 100 == 99:
            log.raw(0x18FEF100, bytes(8), extended=True)
    log.end(0)
    log.start(3, 1234, 3, 3, 360)
    for n in range(10):
        log.sample(0, n, 360)
    log.end(2)
    log.close()


if __name__ == "__main__":
    fixtures = ROOT / "tests" / "fixtures"
    fixtures.mkdir(parents=True, exist_ok=True)
    write_full(fixtures / "gauge_3x360.log")
    write_cutoff(fixtures / "gauge_cutoff.log")
