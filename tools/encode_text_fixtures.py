#!/usr/bin/env python3
"""Write the serial-protocol and CSV gauge fixtures, independently of camloop's Rust code.

Uses only the standard library: the checksum comes from zlib.crc32, the lifts from the
formula documented in encode_candump.py (imported from there, so both share one formula).

    python3 tools/encode_text_fixtures.py     # rewrites the fixtures listed below

Fixtures written (tests/fixtures/):
  gauge_serial_3x360.txt             serial line protocol, machine M3, part P1234, lobe L2,
                                     3 revolutions x 360 points, lifts with 6 decimals.
  M3_P1234_L2_20240501T101500.csv    drop-folder CSV, identity from the file name, header row,
                                     360 points per revolution inferred from the angles.
  lobe_scan_720.csv                  drop-folder CSV, identity and points per revolution from
                                     a `# machine=... part=... lobe=...` comment, 0.5 deg grid,
                                     no header row, CRLF line ends.
"""

import pathlib
import sys
import zlib

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from encode_candump import lift_mm  # noqa: E402  (one formula for every fixture)

ROOT = pathlib.Path(__file__).resolve().parent.parent
FIXTURES = ROOT / "tests" / "fixtures"


def serial_text(machine, part, lobe, revolutions, ppr):
    lines = [f"START {machine} {part} {lobe} {revolutions} {ppr}"]
    for r in range(revolutions):
        for i in range(ppr):
            lines.append(f"S {r} {i} {lift_mm(r, i, ppr):.6f}")
    crc = zlib.crc32("".join(line + "\n" for line in lines).encode("ascii"))
    lines.append(f"END {len(lines) - 1} {crc:08X}")
    return "".join(line + "\n" for line in lines)


def csv_rows(revolutions, ppr):
    for r in range(revolutions):
        for i in range(ppr):
            yield f"{r},{i * 360.0 / ppr:.6f},{lift_mm(r, i, ppr):.6f}"


if __name__ == "__main__":
    FIXTURES.mkdir(parents=True, exist_ok=True)
    (FIXTURES / "gauge_serial_3x360.txt").write_text(
        "# camloop gauge line protocol fixture\n" + serial_text("M3", "P1234", "L2", 3, 360)
    )
    with open(FIXTURES / "M3_P1234_L2_20240501T101500.csv", "w", newline="\n") as f:
        f.write("# written by tools/encode_text_fixtures.py\n")
        f.write("rev,angle_deg,lift_mm\n")
        for row in csv_rows(3, 360):
            f.write(row + "\n")
    with open(FIXTURES / "lobe_scan_720.csv", "w", newline="\r\n") as f:
        f.write("# machine=M3 part=P1234 lobe=L2\n")
        f.write("# points_per_rev=720 revolutions=3\n")
        for row in csv_rows(3, 720):
            f.write(row + "\n")
