#!/usr/bin/env python3
"""Plant-scale load probe against the release binary: N simulated 8-lobe camshaft machines,
each grinding a shaft every 30 s, while /healthz is asked every second.

    cargo build --release && python3 tools/probe_plant.py N [SECONDS] [--replay]

Two ways to feed it:
- by default the simulator runs inside the service (`kind = "sim"` gauges): each machine's
  first shaft is ground at once, then one every 30 s;
- `--replay`: no simulator in the service, so the service's own cost is measured. First one
  simulated machine grinds as many shafts as the run needs (a recording run of the service,
  in its own folder); each shaft's averaged lift per lobe is read back through the API
  (`GET /api/v1/measurements/{id}`). Then N machines with drop-folder gauges (`kind = "drop"`)
  get those shafts, in the order they were ground, as measurement files (the averaged lift
  for each of 3 revolutions, written beside the folder and renamed into it, with the `# end`
  marker), one shaft every 30 s per machine, the machines' starts spread evenly over the
  first 30 s as a plant's would be. Each machine's learning starts where the recording's did,
  so it meets the measurements of the tables it would have made itself (up to the averaging),
  and nearly every part makes a new table. Files the service has processed are deleted by the
  probe 10 s later so the disk stays bounded.

Prints, for one run of SECONDS (default 90) after every machine is open:
- start-up: seconds from the process start to the first /healthz answer, and to the answer
  that says every machine is open (status no longer "starting");
- /healthz latency p50 / p99 / max over the whole run (start-up included), and how many
  asks went unanswered within 5 s; the same for an API read (GET /api/v1/machines) asked
  right after each;
- from a measurement received to its part done (its table durable on the share): p50 and
  p99 from the service's histogram (the bounds of the buckets they fall in);
- lobe measurements demanded (each machine's first shaft is ground at once, then one every
  30 s) against those processed (/metrics: parts + rejects) and stored (rows in the
  database);
- CPU of the process (per cent of one core) and its RSS (now and peak);
- the load average of the machine, since other work on it changes every figure.

Everything runs in a temporary folder on loopback; nothing is left behind.
"""

import json
import os
import socket
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BINARY = os.environ.get("CAMLOOP_BINARY") or os.path.join(ROOT, "target", "release", "camloop")
RECIPE = os.path.join(ROOT, "config", "parts", "demo-camshaft.toml")
LOBES = 8
PART_INTERVAL_S = 30


def free_port():
    # The service binds the port itself at start; a port free a moment ago is good enough
    # for a probe (a test would use port 0 and read the address back).
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def gauge_section(i, replay, part_interval_ms=PART_INTERVAL_S * 1000):
    if replay:
        # The folder's default poll (500 ms), as a plant would run it.
        return f"""[machines.gauge]
kind = "drop"
folder = "drop/P{i:03}"
"""
    return f"""[machines.gauge]
kind = "sim"
part_interval_ms = {part_interval_ms}
seed = {i + 1}
"""


def write_config(dir, machines, port, replay=False, part_interval_ms=PART_INTERVAL_S * 1000):
    parts = [
        f"""[service]
var_dir = "var"
[database]
url = "sqlite://{dir}/var/camloop.db?mode=rwc"
[http]
listen = "127.0.0.1:{port}"
max_connections = 64
"""
    ]
    for i in range(machines):
        parts.append(
            f"""[[machines]]
name = "P{i:03}"
recipe = "{RECIPE}"
share = "share/P{i:03}"
{gauge_section(i, replay, part_interval_ms)}"""
        )
    path = os.path.join(dir, "camloop.toml")
    with open(path, "w") as f:
        f.write("\n".join(parts))
    return path


def ask(url, timeout=5.0):
    """(latency in ms, body) or (None, None) when no answer came in time."""
    t0 = time.monotonic()
    try:
        body = urllib.request.urlopen(url, timeout=timeout).read().decode()
        return 1000 * (time.monotonic() - t0), body
    except Exception:
        return None, None


def cpu_seconds(pid):
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    ticks = os.sysconf("SC_CLK_TCK")
    return (int(fields[11]) + int(fields[12])) / ticks


def rss_mib(pid):
    now = peak = 0
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                now = int(line.split()[1]) / 1024
            elif line.startswith("VmHWM:"):
                peak = int(line.split()[1]) / 1024
    return now, peak


def metric_sum(text, name):
    return sum(float(l.split()[-1]) for l in text.splitlines() if l.startswith(name + "{"))


def metric_total(text, name):
    """A metric without labels (0 when this build does not have it)."""
    return sum(float(l.split()[-1]) for l in text.splitlines() if l.split(" ")[0] == name)


def histogram_quantile(text, name, q):
    """The upper bound of the bucket holding quantile q of histogram `name` (None: no
    observations, or a build without it)."""
    buckets = []
    for l in text.splitlines():
        if l.startswith(name + '_bucket{le="'):
            le = l.split('"')[1]
            buckets.append((float("inf") if le == "+Inf" else float(le), float(l.split()[-1])))
    total = buckets[-1][1] if buckets else 0
    if total == 0:
        return None
    return next(le for le, n in buckets if n >= q * total)


def stored_rows(dir):
    try:
        db = sqlite3.connect(f"file:{dir}/var/camloop.db?mode=ro", uri=True, timeout=10)
        (n,) = db.execute("SELECT COUNT(*) FROM measurements").fetchone()
        db.close()
        return n
    except sqlite3.Error:
        return 0


def record(dir, shafts):
    """The averaged lift of each lobe of `shafts` shafts ground by one simulated machine, in
    the order they were ground: [(part, [(lobe, [lift_mm per gauge angle])])]."""
    port = free_port()
    os.makedirs(dir)
    # One simulated machine grinding as fast as it goes.
    config = write_config(dir, 1, port, part_interval_ms=20)
    log = open(os.path.join(dir, "log.txt"), "w")
    proc = subprocess.Popen([BINARY, "run", "--config", config], cwd=dir, stdout=log, stderr=log)
    try:
        rows = []
        deadline = time.monotonic() + 600
        while len(rows) < shafts * LOBES:
            if proc.poll() is not None or time.monotonic() > deadline:
                sys.exit(f"recording: the service stopped or was too slow; see {dir}/log.txt")
            time.sleep(0.5)
            try:
                db = sqlite3.connect(f"file:{dir}/var/camloop.db?mode=ro", uri=True, timeout=10)
                rows = db.execute(
                    "SELECT id, part, lobe FROM measurements WHERE part NOT LIKE 'MASTER%' "
                    "ORDER BY id"
                ).fetchall()
                db.close()
            except sqlite3.Error:
                rows = []
        ground, by_part = [], {}
        for id, part, lobe in rows:
            if part not in by_part:
                if len(ground) == shafts:
                    continue
                by_part[part] = []
                ground.append((part, by_part[part]))
            _, body = ask(f"http://127.0.0.1:{port}/api/v1/measurements/{id}", timeout=30)
            if body is None:
                sys.exit(f"recording: measurement {id} not answered")
            by_part[part].append((lobe, json.loads(body)["averaged_lift_mm"]))
        return ground
    finally:
        proc.terminate()
        proc.wait(timeout=60)


def measurement_text(machine, part, lobe, lift_mm, revolutions=3):
    """A drop-folder CSV of `lift_mm` (one value per gauge angle) for each revolution."""
    step = 360.0 / len(lift_mm)
    rows = "".join(f"{i * step:.6f},{l:.7f}\n" for i, l in enumerate(lift_mm))
    body = "".join(
        "".join(f"{r}," + row + "\n" for row in rows.splitlines()) for r in range(revolutions)
    )
    return (
        f"# machine={machine} part={part} lobe={lobe}\n"
        f"# points_per_rev={len(lift_mm)} revolutions={revolutions}\n"
        f"rev,angle_deg,lift_mm\n{body}# end\n"
    )


class Feeder(threading.Thread):
    """Writes each machine's recorded shafts into its drop folder, one shaft every 30 s per
    machine, the machines' starts spread over the first 30 s; deletes processed files 10 s
    after they were written."""

    def __init__(self, dir, machines, ground):
        super().__init__(daemon=True)
        self.dir, self.machines, self.ground = dir, machines, ground
        self.stop = threading.Event()
        self.written = 0
        self.behind_s = 0.0

    def run(self):
        tmp = os.path.join(self.dir, "drop-tmp")
        os.makedirs(tmp, exist_ok=True)
        start = time.monotonic()
        due = sorted(
            (start + PART_INTERVAL_S * (i / self.machines + s), i, s)
            for i in range(self.machines)
            for s in range(len(self.ground))
        )
        last_clean = start
        for at, i, s in due:
            if self.stop.wait(max(0.0, at - time.monotonic())):
                break
            self.behind_s = max(self.behind_s, time.monotonic() - at)
            machine = f"P{i:03}"
            part, lobes = self.ground[s]
            for lobe, lift in lobes:
                name = f"{machine}_{part}_{lobe}.csv"
                path = os.path.join(tmp, name)
                with open(path, "w") as f:
                    f.write(measurement_text(machine, part, lobe, lift))
                os.rename(path, os.path.join(self.dir, "drop", machine, name))
                self.written += 1
            if time.monotonic() - last_clean > 10:
                last_clean = time.monotonic()
                self.clean(older_than_s=10)

    def clean(self, older_than_s):
        now = time.time()
        for machine in range(self.machines):
            folder = os.path.join(self.dir, "drop", f"P{machine:03}", "processed")
            try:
                entries = list(os.scandir(folder))
            except FileNotFoundError:
                continue
            for e in entries:
                if now - e.stat().st_mtime > older_than_s:
                    os.unlink(e.path)

    def rejected_files(self):
        return sum(
            len(os.listdir(f))
            for f in (
                os.path.join(self.dir, "drop", f"P{m:03}", "rejected") for m in range(self.machines)
            )
            if os.path.isdir(f)
        )


def percentile(values, q):
    if not values:
        return float("nan")
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))]


def plant(dir, machines, seconds, replay):
    feeder = None
    if replay:
        shafts = int(seconds // PART_INTERVAL_S) + 2
        t0 = time.monotonic()
        ground = record(os.path.join(dir, "recording"), shafts)
        print(
            f"plant {machines}: recorded {len(ground)} shafts of one simulated machine in "
            f"{time.monotonic() - t0:.0f} s"
        )
        for i in range(machines):
            os.makedirs(os.path.join(dir, "drop", f"P{i:03}"))
        feeder = Feeder(dir, machines, ground)
    port = free_port()
    config = write_config(dir, machines, port, replay)
    log = open(os.path.join(dir, "log.txt"), "w")
    started = time.monotonic()
    proc = subprocess.Popen([BINARY, "run", "--config", config], cwd=dir, stdout=log, stderr=log)
    latencies, unanswered, statuses, api = [], [0], [], []
    first_answer, all_open, opening = [None], [None], [None]
    stop = threading.Event()

    def healthz():
        while not stop.is_set() and proc.poll() is None:
            ms, body = ask(f"http://127.0.0.1:{port}/healthz")
            at = time.monotonic() - started
            if ms is None:
                # Connection refused before the listener is bound is not a slow answer.
                unanswered[0] += 1 if first_answer[0] is not None else 0
            else:
                latencies.append(ms)
                health = json.loads(body)
                statuses.append(health.get("status", "?"))
                if first_answer[0] is None:
                    first_answer[0] = at
                # Open once the machines' component is ok (a build without components: at
                # its first answer, which came only once they were open).
                machines = [c for c in health.get("components", []) if c["name"] == "machines"]
                opening[0] = next((c.get("reason") for c in machines), None) or "open"
                if all_open[0] is None and all(c["state"] == "ok" for c in machines):
                    all_open[0] = at
            # An API read beside it (anonymous on loopback): the machines and their state.
            if first_answer[0] is not None:
                api.append(ask(f"http://127.0.0.1:{port}/api/v1/machines")[0])
            stop.wait(1.0)

    prober = threading.Thread(target=healthz, daemon=True)
    prober.start()
    try:
        deadline = started + 300
        while all_open[0] is None and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        if all_open[0] is None:
            print(
                f"plant {machines}: machines not open within 300 s ({opening[0]}); /healthz over "
                f"{len(latencies) + unanswered[0]} asks: p50 {percentile(latencies, 0.5):.1f} ms, "
                f"p99 {percentile(latencies, 0.99):.1f} ms, {unanswered[0]} unanswered within 5 s; "
                f"RSS {rss_mib(proc.pid)[0]:.0f} MiB"
            )
            return False
        opened = time.monotonic()
        cpu0 = cpu_seconds(proc.pid)
        if feeder is not None:
            feeder.start()
        time.sleep(seconds)
        elapsed = time.monotonic() - opened
        if feeder is not None:
            feeder.stop.set()
            feeder.join()
        cpu = 100 * (cpu_seconds(proc.pid) - cpu0) / elapsed
        _, text = ask(f"http://127.0.0.1:{port}/metrics", timeout=30)
        rss_now, rss_peak = rss_mib(proc.pid)
        load = open("/proc/loadavg").read().split()[:3]
    finally:
        stop.set()
        proc.terminate()
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        prober.join(timeout=10)
    if feeder is None:
        demanded = machines * (int(elapsed // PART_INTERVAL_S) + 1) * LOBES
    else:
        demanded = feeder.written
        print(
            f"plant {machines}: replay: {feeder.written} files written, the feeder at most "
            f"{feeder.behind_s:.2f} s behind its schedule, {feeder.rejected_files()} files rejected"
        )
    processed = None
    if text is not None:
        processed = int(
            metric_sum(text, "camloop_parts_total")
            + metric_sum(text, "camloop_measurements_rejected_total")
        )
    stored = stored_rows(dir)
    if text is not None:
        print(
            f"plant {machines}: at the end: {metric_total(text, 'camloop_measurements_waiting'):.0f} "
            f"measurements waiting, the oldest for {metric_total(text, 'camloop_oldest_waiting_seconds'):.1f} s; "
            f"journal: {metric_total(text, 'camloop_journal_appends_total'):.0f} appends in "
            f"{metric_total(text, 'camloop_journal_syncs_total'):.0f} syncs; tables pushed "
            f"{metric_sum(text, 'camloop_tables_pushed_total'):.0f}, refused "
            f"{metric_sum(text, 'camloop_tables_refused_total'):.0f}"
        )
        p50, p99 = (histogram_quantile(text, "camloop_part_seconds", q) for q in (0.5, 0.99))
        print(
            f"plant {machines}: measurement received to part done (table durable on the share): "
            f"p50 <= {p50} s, p99 <= {p99} s over "
            f"{metric_total(text, 'camloop_part_seconds_count'):.0f} parts (bucket bounds)"
        )
    print(
        f"plant {machines}: start-up: first /healthz answer {first_answer[0]:.1f} s, "
        f"every machine open {all_open[0]:.1f} s"
    )
    print(
        f"plant {machines}: /healthz over {len(latencies) + unanswered[0]} asks: "
        f"p50 {percentile(latencies, 0.5):.1f} ms, p99 {percentile(latencies, 0.99):.1f} ms, "
        f"max {max(latencies, default=float('nan')):.1f} ms, {unanswered[0]} unanswered within 5 s; "
        f"statuses seen {sorted(set(statuses))}"
    )
    answered = [ms for ms in api if ms is not None]
    print(
        f"plant {machines}: GET /api/v1/machines over {len(api)} asks: "
        f"p50 {percentile(answered, 0.5):.1f} ms, p99 {percentile(answered, 0.99):.1f} ms, "
        f"max {max(answered, default=float('nan')):.1f} ms, {len(api) - len(answered)} unanswered within 5 s"
    )
    print(
        f"plant {machines}: {elapsed:.0f} s: lobes demanded {demanded}, processed "
        f"{processed if processed is not None else 'unknown (/metrics unanswered)'}, stored {stored} "
        f"(stored after the stop, so parts in hand count)"
    )
    print(
        f"plant {machines}: CPU {cpu:.0f} % of one core, RSS {rss_now:.0f} MiB "
        f"(peak {rss_peak:.0f} MiB), load average {' '.join(load)}"
    )
    return unanswered[0] == 0 and processed is not None and processed >= demanded * 0.95


def main():
    if len(sys.argv) < 2:
        print(__doc__)
        sys.exit(2)
    args = [a for a in sys.argv[1:] if a != "--replay"]
    replay = len(args) < len(sys.argv) - 1
    machines = int(args[0])
    seconds = float(args[1]) if len(args) > 1 else 90.0
    with tempfile.TemporaryDirectory() as dir:
        good = plant(dir, machines, seconds, replay)
    print(f"plant {machines}: {'ok' if good else 'FAILED'}")
    sys.exit(0 if good else 1)


if __name__ == "__main__":
    main()
