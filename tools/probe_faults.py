#!/usr/bin/env python3
"""Fault probes against the release binary, as an operator's bad day would bring them.

    cargo build --release && python3 tools/probe_faults.py [kills|outage|dropmem|readers|all]

- kills:   one simulated machine at 100 ms parts, killed with SIGKILL at 20 random moments
           and restarted each time; afterwards the parts the loop counted, the measurement
           rows in the database and their distinct identities must agree.
- outage:  the share made immutable (chattr +i) for 10 s while parts go on; prints the max
           error per part before, during and after, and whether learning froze. Needs root.
- dropmem: a drop-folder machine; resident memory before and after a 100 MB file is dropped.
- readers: parts made in 20 s at 100 ms parts, alone and with 200 clients reading history
           over HTTP as fast as they can.

Everything runs in a temporary folder on loopback; nothing is left behind.
"""

import json
import math
import os
import random
import re
import signal
import sqlite3
import struct
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BINARY = os.path.join(ROOT, "target", "release", "camloop")
RECIPE = os.path.join(ROOT, "config", "parts", "demo-camshaft.toml")


def write_config(dir, gauge):
    text = f"""
[service]
var_dir = "var"
[database]
url = "sqlite://{dir}/var/camloop.db?mode=rwc"
[http]
listen = "127.0.0.1:0"
[[machines]]
name = "M1"
recipe = "{RECIPE}"
lobe = "IN1"
share = "share/M1"
[machines.gauge]
{gauge}
"""
    path = os.path.join(dir, "camloop.toml")
    with open(path, "w") as f:
        f.write(text)
    return path


def start(dir, config):
    log = open(os.path.join(dir, "log.txt"), "a")
    return subprocess.Popen([BINARY, "run", "--config", config], cwd=dir, stdout=log, stderr=log)


def zstd_frame(frame, dictionary=b""):
    """One zstd frame, with `dictionary` as raw content, by the zstd tool."""
    with tempfile.NamedTemporaryFile() as d:
        d.write(dictionary)
        d.flush()
        args = ["zstd", "-d", "-c", "-q"] + (["-D", d.name] if dictionary else [])
        return subprocess.run(args, input=frame, capture_output=True, check=True).stdout


def unzstd(blob, dictionary=b""):
    """A packed blob (see src/store/pack.rs): format 1 is zstd against the parent text,
    format 2 the numbers against the parent's (src/store/pack_numbers.rs), decoded here
    from its description, apart from the Rust code."""
    if blob[0] == 1:
        return zstd_frame(blob[1:], dictionary)
    assert blob[0] == 2, "unknown packed format"
    return unpack_numbers(blob, dictionary)


NUMBER = re.compile(rb"(?<![A-Za-z0-9_.])-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?![A-Za-z0-9_.])")


def tokenise(text):
    """(template, [(mantissa, decimals)]): numbers of at most 18 digits become marker bytes
    (2 for a negative zero); `None` when the text holds a marker byte."""
    if b"\x01" in text or b"\x02" in text:
        return None
    template, numbers, pos = bytearray(), [], 0
    for m in NUMBER.finditer(text):
        word = m.group(0)
        body = word.lstrip(b"-")
        whole, _, frac = body.partition(b".")
        if len(whole) + len(frac) > 18:
            continue
        mantissa = int(whole + frac) * (-1 if word.startswith(b"-") else 1)
        template += text[pos:m.start()]
        template.append(2 if word.startswith(b"-") and mantissa == 0 else 1)
        numbers.append((mantissa, len(frac) if b"." in body else -1))
        pos = m.end()
    template += text[pos:]
    return bytes(template), numbers


def units(template):
    """(unit template, index of its first number) per unit: up to and with each , or \n."""
    out, start, first = [], 0, 0
    for i, b in enumerate(template):
        if b in b",\n" or i + 1 == len(template):
            unit = template[start:i + 1]
            out.append((unit, first))
            first += unit.count(1) + unit.count(2)
            start = i + 1
    return out


def predict(parent, decimals):
    mantissa, before = parent
    shift = max(decimals, 0) - max(before, 0)
    if shift >= 0:
        return mantissa * 10**shift
    q = 10**-shift
    return int(math.copysign((abs(mantissa) + q // 2) // q, mantissa))


def varint(data, pos):
    """The LEB128 varint at `pos` and the position after it."""
    value, shift = 0, 0
    while True:
        b = data[pos]
        pos += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if b < 0x80:
            return value, pos


def unpack_numbers(blob, parent_text):
    parent = tokenise(parent_text) or (b"", [])
    length, pos = varint(blob, 1)
    template = zstd_frame(blob[pos:pos + length], parent[0])
    stream = zstd_frame(blob[pos + length:])
    parent_units = units(parent[0])
    bases = []
    for k, (unit, _) in enumerate(units(template)):
        same = k < len(parent_units) and parent_units[k][0] == unit
        for n in range(unit.count(1) + unit.count(2)):
            bases.append(parent[1][parent_units[k][1] + n] if same else None)
    values, pos = [], 0
    while pos < len(stream):
        v, pos = varint(stream, pos)
        values.append((v >> 1) ^ -(v & 1))
    assert len(values) == 2 * len(bases), "numbers pack does not match its template"
    out, k = bytearray(), 0
    for b in template:
        if b not in (1, 2):
            out.append(b)
            continue
        base = bases[k]
        decimals = values[len(bases) + k] + (base[1] if base else -1)
        mantissa = values[k] + (predict(base, decimals) if base else 0)
        digits = str(abs(mantissa))
        if decimals >= 0:
            digits = digits.rjust(decimals + 1, "0")
            digits = digits[:len(digits) - decimals] + "." + digits[len(digits) - decimals:]
        out += (b"-" if mantissa < 0 or b == 2 else b"") + digits.encode()
        k += 1
    return bytes(out)


def unpack_report(blob):
    """The analysis report of a packed row (src/store/pack_report.rs), as a Python value."""
    data, pos = unzstd(blob), 0

    def u():
        nonlocal pos
        value, pos = varint(data, pos)
        return value

    def i():
        v = u()
        return (v >> 1) ^ -(v & 1)

    def text():
        nonlocal pos
        n = u()
        pos += n
        return data[pos - n:pos].decode()

    def value():
        nonlocal pos
        tag = data[pos]
        pos += 1
        if tag in (0, 1, 2):
            return [None, False, True][tag]
        if tag == 3:
            return i()
        if tag == 4:
            return u()
        if tag == 5:
            return i() / 100.0
        if tag == 6:
            pos += 8
            return struct.unpack("<d", data[pos - 8:pos])[0]
        if tag == 7:
            return text()
        if tag == 8:
            return [value() for _ in range(u())]
        if tag == 10:
            out, prev = [], 0
            for _ in range(u()):
                prev += i()
                out.append(prev / 100.0)
            return out
        if tag == 9:
            return {text(): value() for _ in range(u())}
        raise ValueError(f"unknown tag {tag}")

    return value()


def report(codec, text, packed):
    return json.loads(text) if codec == 0 else unpack_report(packed)


def newest_state(db):
    """The newest learning state, unpacked along its chain (src/store/chain.rs)."""
    row = db.execute("SELECT id FROM learning_states ORDER BY id DESC LIMIT 1").fetchone()
    if row is None:
        return None

    def plain(id):
        codec, base, text, packed = db.execute(
            "SELECT codec, base_id, state_json, state_packed FROM learning_states WHERE id = ?", (id,)
        ).fetchone()
        if codec == 0:
            return text.encode()
        return unzstd(packed, plain(base) if base is not None else b"")

    return json.loads(plain(row[0]))


def rows(dir):
    db = sqlite3.connect(os.path.join(dir, "var", "camloop.db"))
    n, distinct = db.execute("SELECT COUNT(*), COUNT(DISTINCT sha256) FROM measurements").fetchone()
    errors = [
        max(abs(e) for e in report(codec, text, packed)["error_um"])
        for (codec, text, packed) in db.execute(
            "SELECT d.codec, d.analysis_json, d.analysis_packed FROM measurements m "
            "JOIN measurement_data d ON d.measurement_id = m.id ORDER BY m.id"
        )
    ]
    state = newest_state(db)
    db.close()
    return n, distinct, errors, state


def stop(proc):
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=60)


def kills(dir):
    config = write_config(dir, 'kind = "sim"\npart_interval_ms = 100\nseed = 7')
    random.seed(20261123)
    for _ in range(20):
        proc = start(dir, config)
        time.sleep(random.uniform(0.5, 3.0))
        proc.kill()
        proc.wait()
    proc = start(dir, config)
    time.sleep(5)  # a last stretch, then a clean stop so the journal drains
    stop(proc)
    n, distinct, _, state = rows(dir)
    parts = state["parts"] if state else 0
    print(f"kills: 20 SIGKILLs; loop counted {parts} parts; {n} measurement rows, {distinct} distinct")
    return parts == n == distinct


def outage(dir):
    config = write_config(dir, 'kind = "sim"\npart_interval_ms = 100\nseed = 7')
    share = os.path.join(dir, "share", "M1")
    proc = start(dir, config)
    time.sleep(4)
    subprocess.run(["chattr", "+i", share], check=True)
    made_read_only_ms = time.time() * 1000
    time.sleep(10)
    subprocess.run(["chattr", "-i", share], check=True)
    restored_ms = time.time() * 1000
    time.sleep(5)
    stop(proc)
    _, _, errors, state = rows(dir)
    # Parts are placed by when they were received, not by how many rows the database held
    # at the moment: the journal may lag behind the parts during the outage, so a row
    # count taken then can put parts ground during the outage on the "after" side.
    received = received_ms(dir)
    before = sum(1 for t in received if t < made_read_only_ms)
    during = sum(1 for t in received if t < restored_ms)
    show = lambda v: " ".join(f"{e:.2f}" for e in v)
    print(f"outage: before {show(errors[:before])}")
    print(f"outage: during {show(errors[before:during])}")
    print(f"outage: after  {show(errors[during:])}")
    frozen = state["learning"].get("frozen") if state else None
    print(f"outage: learning frozen: {frozen}")
    # The first part received after the restore was ground before any new table reached
    # the share; the next one with a table learned from it. Without a dressing in the
    # outage the second part ground with a new table is back under 1.3 µm; a dressing late
    # in the outage overshoots by up to 1.5 µm for a few parts. So: learning never froze,
    # and the 10th to 20th parts after the restore are all under 1.3 µm.
    settled = errors[during + 10 : during + 20]
    print(f"outage: 10th to 20th part after the restore {show(settled)}")
    return frozen is None and len(settled) == 10 and max(settled) < 1.3


def received_ms(dir):
    db = sqlite3.connect(os.path.join(dir, "var", "camloop.db"))
    times = [t for (t,) in db.execute("SELECT received_at_ms FROM measurements ORDER BY id")]
    db.close()
    return times


def rows_now(dir):
    db = sqlite3.connect(os.path.join(dir, "var", "camloop.db"))
    (n,) = db.execute("SELECT COUNT(*) FROM measurements").fetchone()
    db.close()
    return n


def rss_kib(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


def dropmem(dir):
    config = write_config(dir, 'kind = "drop"\nfolder = "inbox"\npoll_ms = 50')
    proc = start(dir, config)
    time.sleep(2)
    before = rss_kib(proc.pid)
    with open(os.path.join(dir, "inbox", "huge.csv"), "wb") as f:
        f.write(b"rev,angle_deg,lift_mm\n")
        f.write(b"0,0,0.0\n" * (100 * 1024 * 1024 // 8))
    deadline = time.time() + 60
    while not os.path.exists(os.path.join(dir, "inbox", "rejected", "huge.csv")):
        if time.time() > deadline:
            break
        time.sleep(0.2)
    peak = rss_kib(proc.pid)
    stop(proc)
    moved = os.path.exists(os.path.join(dir, "inbox", "rejected", "huge.csv"))
    print(f"dropmem: RSS {before / 1024:.1f} MiB before, {peak / 1024:.1f} MiB after a 100 MB file; rejected: {moved}")
    return moved and peak - before < 16 * 1024


def processing(port):
    import urllib.request

    text = urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=30).read().decode()
    value = lambda name: float(
        next(l.split()[-1] for l in text.splitlines() if l.startswith(name + "{"))
    )
    return value("camloop_part_processing_seconds_sum"), value("camloop_part_processing_seconds_count")


def parts_in(dir, seconds, port):
    before, (s0, n0) = rows_now(dir), processing(port)
    time.sleep(seconds)
    (s1, n1) = processing(port)
    mean_ms = 1000 * (s1 - s0) / max(n1 - n0, 1)
    return rows_now(dir) - before, mean_ms


def readers(dir):
    import threading
    import urllib.request

    config = write_config(dir, 'kind = "sim"\npart_interval_ms = 100\nseed = 7')
    with open(config) as f:
        text = f.read().replace('listen = "127.0.0.1:0"', 'listen = "127.0.0.1:18931"')
    with open(config, "w") as f:
        f.write(text)
    proc = start(dir, config)
    time.sleep(3)
    alone, alone_ms = parts_in(dir, 20, 18931)
    stop_flag = threading.Event()
    served = [0]

    def client():
        url = "http://127.0.0.1:18931/api/v1/machines/M1/measurements?limit=100"
        while not stop_flag.is_set():
            try:
                with urllib.request.urlopen(url, timeout=10) as r:
                    r.read()
                served[0] += 1
            except Exception:
                time.sleep(0.05)

    threads = [threading.Thread(target=client, daemon=True) for _ in range(200)]
    for t in threads:
        t.start()
    time.sleep(2)
    loaded, loaded_ms = parts_in(dir, 20, 18931)
    stop_flag.set()
    for t in threads:
        t.join(timeout=15)
    stop(proc)
    print(
        f"readers: {alone} parts in 20 s alone (mean processing {alone_ms:.1f} ms), "
        f"{loaded} with 200 readers (mean processing {loaded_ms:.1f} ms; {served[0]} reads served)"
    )
    # The load generator shares the machine's cores, so the part rate falls with it; what
    # must not happen is a part waiting behind readers (the campaign saw 41 → 416 ms).
    return loaded_ms < 50


def main():
    which = sys.argv[1] if len(sys.argv) > 1 else "all"
    probes = {"kills": kills, "outage": outage, "dropmem": dropmem, "readers": readers}
    ok = True
    for name, probe in probes.items():
        if which in (name, "all"):
            with tempfile.TemporaryDirectory() as dir:
                try:
                    good = probe(dir)
                finally:
                    subprocess.run(["chattr", "-R", "-i", dir], stderr=subprocess.DEVNULL)
                print(f"{name}: {'ok' if good else 'FAILED'}")
                ok &= good
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
