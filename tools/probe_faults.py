#!/usr/bin/env python3
"""Fault probes against the release binary, as an operator's bad day would bring them.

    cargo build --release && python3 tools/probe_faults.py [kills|outage|dropmem|all]

- kills:   one simulated machine at 100 ms parts, killed with SIGKILL at 20 random moments
           and restarted each time; afterwards the parts the loop counted, the measurement
           rows in the database and their distinct identities must agree.
- outage:  the share made immutable (chattr +i) for 10 s while parts go on; prints the max
           error per part before, during and after, and whether learning froze. Needs root.
- dropmem: a drop-folder machine; resident memory before and after a 100 MB file is dropped.

Everything runs in a temporary folder on loopback; nothing is left behind.
"""

import json
import os
import random
import signal
import sqlite3
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


def rows(dir):
    db = sqlite3.connect(os.path.join(dir, "var", "camloop.db"))
    n, distinct = db.execute("SELECT COUNT(*), COUNT(DISTINCT sha256) FROM measurements").fetchone()
    errors = [
        max(abs(e) for e in json.loads(a)["error_um"])
        for (a,) in db.execute(
            "SELECT d.analysis_json FROM measurements m JOIN measurement_data d "
            "ON d.measurement_id = m.id ORDER BY m.id"
        )
    ]
    state = db.execute("SELECT state_json FROM learning_states ORDER BY id DESC LIMIT 1").fetchone()
    db.close()
    return n, distinct, errors, json.loads(state[0]) if state else None


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
    before = rows_now(dir)
    time.sleep(10)
    subprocess.run(["chattr", "-i", share], check=True)
    during = rows_now(dir)
    time.sleep(5)
    stop(proc)
    _, _, errors, state = rows(dir)
    show = lambda v: " ".join(f"{e:.2f}" for e in v)
    print(f"outage: before {show(errors[:before])}")
    print(f"outage: during {show(errors[before:during])}")
    print(f"outage: after  {show(errors[during:])}")
    frozen = state["learning"].get("frozen") if state else None
    print(f"outage: learning frozen: {frozen}")
    # The first part after the restore was ground before any new table reached the share;
    # the next one with a table learned from it; the one after that is the second part
    # ground with a new table and must be back under 1.3 µm. (Later dressings bring their
    # own spike of the dressing's size error; they are not the outage's.)
    return frozen is None and errors[during + 2] < 1.3


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


def main():
    which = sys.argv[1] if len(sys.argv) > 1 else "all"
    probes = {"kills": kills, "outage": outage, "dropmem": dropmem}
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
