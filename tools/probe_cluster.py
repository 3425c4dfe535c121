#!/usr/bin/env python3
"""Cluster probe against the release binary: INSTANCES `camloop run` processes with
`[cluster]` on one throwaway PostgreSQL (initdb, fsync on), sharing MACHINES simulated
8-lobe camshaft machines (each grinds a shaft every INTERVAL s), /healthz of every instance
asked every second; after a steady period one instance is killed with SIGKILL.

    cargo build --release && python3 tools/probe_cluster.py [options]

    --machines N      simulated machines (default 1500)
    --instances N     camloop processes (default 3; 1 with --no-cluster)
    --seconds S       steady run before the kill (default 60)
    --after S         run after the kill (default 30)
    --interval S      seconds between two shafts of one machine (default 30)
    --lease-ms MS     the cluster's lease (default 6000, the service's default)
    --no-cluster      one instance on the same PostgreSQL without [cluster] (no kill)

Prints:
- start-up: seconds from the launch to every instance's first /healthz answer, to every
  machine owned exactly once (the lease table, live leases), and to every machine having a
  part stored;
- ownership every second: machines owned by no live lease, and leases lost (`lease lost`
  lines in the logs), over the whole run;
- /healthz latency p50 / p99 / max and unanswered asks (5 s timeout), per instance;
- lobe measurements demanded against processed (/metrics, every instance) and stored
  (rows in the database), and each instance's CPU and peak RSS;
- the kill: when the dead instance's machines were all owned by the survivors, and when
  each had a new part stored again (p50 / max over them), against the lease;
- the load average.

PostgreSQL 15 binaries are looked for under /usr/lib/postgresql/*/bin (as root they run as
the `postgres` user). Everything runs in a temporary folder on loopback; nothing is left
behind.
"""

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from probe_plant import (  # noqa: E402  (the same helpers as the one-instance probe)
    BINARY,
    LOBES,
    RECIPE,
    ask,
    cpu_seconds,
    free_port,
    metric_sum,
    percentile,
    rss_mib,
)


def pg_bin():
    root = "/usr/lib/postgresql"
    versions = sorted(
        (int(v), os.path.join(root, v, "bin"))
        for v in os.listdir(root)
        if v.isdigit() and os.path.isfile(os.path.join(root, v, "bin", "initdb"))
    )
    if not versions:
        sys.exit("no PostgreSQL server binaries under /usr/lib/postgresql")
    return versions[-1][1]


class Postgres:
    """A throwaway server in `dir`: initdb, pg_ctl start on a free port, database camloop."""

    def __init__(self, dir):
        self.bin = pg_bin()
        self.dir = dir
        self.data = os.path.join(dir, "data")
        self.as_postgres = os.getuid() == 0
        self.port = free_port()
        os.makedirs(dir, exist_ok=True)
        if self.as_postgres:
            subprocess.run(["chown", "-R", "postgres:", dir], check=True)
        self.run("initdb", "-D", self.data, "-A", "trust", "-U", "postgres", "-E", "UTF8")
        opts = f"-p {self.port} -h 127.0.0.1 -k {dir} -c max_connections=200"
        self.run("pg_ctl", "start", "-w", "-D", self.data, "-l", os.path.join(dir, "server.log"), "-o", opts)
        self.run("createdb", "-h", "127.0.0.1", "-p", str(self.port), "-U", "postgres", "camloop")

    def run(self, name, *args, capture=False):
        cmd = [os.path.join(self.bin, name), *args]
        if self.as_postgres:
            cmd = ["runuser", "-u", "postgres", "--", *cmd]
        out = subprocess.run(cmd, check=True, capture_output=True, text=True)
        return out.stdout

    def url(self):
        return f"postgres://postgres@127.0.0.1:{self.port}/camloop"

    def query(self, sql):
        """Rows as lists of text; none when the query fails (a table not made yet)."""
        try:
            out = self.run("psql", "-h", "127.0.0.1", "-p", str(self.port), "-U", "postgres",
                           "-d", "camloop", "-At", "-F", "\t", "-c", sql)
        except subprocess.CalledProcessError:
            return []
        return [line.split("\t") for line in out.splitlines() if line]

    def stop(self):
        try:
            self.run("pg_ctl", "stop", "-m", "immediate", "-w", "-D", self.data)
        except subprocess.CalledProcessError:
            pass


def write_config(dir, instance, machines, port, url, args):
    parts = [
        f"""[service]
var_dir = "var-{instance}"
[database]
url = "{url}"
[http]
listen = "127.0.0.1:{port}"
max_connections = 64
"""
    ]
    if not args.no_cluster:
        parts.append(
            f"""[cluster]
enabled = true
instance = "{instance}"
lease_ms = {args.lease_ms}
state_dir = "state"
"""
        )
    for i in range(machines):
        parts.append(
            f"""[[machines]]
name = "C{i:04}"
recipe = "{RECIPE}"
share = "share/C{i:04}"
[machines.gauge]
kind = "sim"
part_interval_ms = {int(args.interval * 1000)}
seed = {i + 1}
"""
        )
    path = os.path.join(dir, f"{instance}.toml")
    with open(path, "w") as f:
        f.write("\n".join(parts))
    return path


class Instance:
    def __init__(self, dir, name, machines, url, args):
        self.name = name
        self.port = free_port()
        self.config = write_config(dir, name, machines, self.port, url, args)
        self.log_path = os.path.join(dir, f"{name}.log")
        self.log = open(self.log_path, "w")
        self.started = time.monotonic()
        self.proc = subprocess.Popen([BINARY, "run", "--config", self.config], cwd=dir,
                                     stdout=self.log, stderr=self.log)
        self.latencies, self.unanswered, self.first_answer = [], 0, None
        self.metrics, self.cpu0, self.rss_peak = None, None, 0.0

    def alive(self):
        return self.proc.poll() is None

    def probe(self, stop):
        while not stop.is_set() and self.alive():
            ms, _ = ask(f"http://127.0.0.1:{self.port}/healthz")
            if ms is None:
                # Connection refused before the listener is bound is not a slow answer.
                self.unanswered += 1 if self.first_answer is not None else 0
            else:
                self.latencies.append(ms)
                if self.first_answer is None:
                    self.first_answer = time.monotonic() - self.started
            if self.alive():
                self.rss_peak = max(self.rss_peak, rss_mib(self.proc.pid)[1])
            stop.wait(1.0)

    def lease_lost_lines(self):
        with open(self.log_path, errors="replace") as f:
            return sum(1 for line in f if "lease lost" in line or "lease not renewed in time" in line)

    def stop(self):
        if self.alive():
            self.proc.terminate()
            try:
                self.proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def owners(db):
    """Live leases: machine -> owner."""
    return dict(db.query("SELECT machine, owner FROM camloop_leases WHERE expires_at > now()"))


def newest_ids(db):
    """Each machine's newest measurement id."""
    return {m: int(i) for m, i in db.query("SELECT machine, max(id) FROM measurements GROUP BY machine")}


def wait_until(what, limit_s, check, step=0.2):
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit_s:
        if check():
            return time.monotonic() - t0
        time.sleep(step)
    print(f"  {what}: not within {limit_s:.0f} s", flush=True)
    return None


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--machines", type=int, default=1500)
    p.add_argument("--instances", type=int, default=3)
    p.add_argument("--seconds", type=float, default=60)
    p.add_argument("--after", type=float, default=30)
    p.add_argument("--interval", type=float, default=30)
    p.add_argument("--lease-ms", type=int, default=6000)
    p.add_argument("--no-cluster", action="store_true")
    args = p.parse_args()
    if args.no_cluster:
        args.instances = 1
    with tempfile.TemporaryDirectory() as dir:
        os.chmod(dir, 0o755)
        db = Postgres(os.path.join(dir, "pg"))
        try:
            good = run(dir, db, args)
        finally:
            db.stop()
    print(f"cluster probe: {'ok' if good else 'FAILED'}")
    sys.exit(0 if good else 1)


def run(dir, db, args):
    n = args.machines
    label = f"{args.instances} instance(s), {n} machines, a shaft every {args.interval:.0f} s"
    launched = time.monotonic()
    names = [chr(ord("a") + k) for k in range(args.instances)]
    instances = [Instance(dir, name, n, db.url(), args) for name in names]
    stop = threading.Event()
    probers = [threading.Thread(target=i.probe, args=(stop,), daemon=True) for i in instances]
    for t in probers:
        t.start()
    unowned_seen, double = [], [0]
    try:
        good = True
        answered = wait_until("every instance answering /healthz", 120,
                              lambda: all(i.first_answer is not None for i in instances))
        if args.no_cluster:
            owned = 0.0
        else:
            owned = wait_until("every machine owned once", 300, lambda: len(owners(db)) == n, step=0.5)
        grinding = wait_until("every machine with a part stored", 600,
                              lambda: len(newest_ids(db)) == n, step=1.0)
        print(f"{label}: start-up: every /healthz answering {answered and answered:.1f} s; "
              f"every machine owned {owned if owned is None else round(owned, 1)} s; "
              f"every machine with a part stored "
              f"{grinding if grinding is None else round(time.monotonic() - launched, 1)} s after the launch")
        if owned is None or grinding is None:
            good = False
        steady = time.monotonic()
        for i in instances:
            i.cpu0 = cpu_seconds(i.proc.pid)
        while time.monotonic() - steady < args.seconds:
            if not args.no_cluster:
                o = owners(db)
                unowned_seen.append(n - len(o))
            time.sleep(1.0)
        elapsed = time.monotonic() - steady
        for i in instances:
            i.cpu = 100 * (cpu_seconds(i.proc.pid) - i.cpu0) / elapsed
            _, i.metrics = ask(f"http://127.0.0.1:{i.port}/metrics", timeout=30)
        report_steady(label, db, instances, unowned_seen, elapsed, args, launched)
        if not args.no_cluster and args.instances > 1:
            good &= kill_one(label, db, instances, args)
    finally:
        stop.set()
        for i in instances:
            i.stop()
        for t in probers:
            t.join(timeout=10)
    for i in instances:
        lat = i.latencies
        print(f"{label}: instance {i.name}: /healthz over {len(lat) + i.unanswered} asks: "
              f"p50 {percentile(lat, 0.5):.1f} ms, p99 {percentile(lat, 0.99):.1f} ms, "
              f"max {max(lat, default=float('nan')):.1f} ms, {i.unanswered} unanswered within 5 s; "
              f"peak RSS {i.rss_peak:.0f} MiB; 'lease lost' lines {i.lease_lost_lines()}")
        good &= i.unanswered == 0
    print(f"{label}: load average {' '.join(open('/proc/loadavg').read().split()[:3])}")
    return good


def report_steady(label, db, instances, unowned_seen, elapsed, args, launched):
    n = args.machines
    shafts = n * (int((time.monotonic() - launched) // args.interval) + 1)
    processed = 0
    for i in instances:
        if i.metrics is not None:
            processed += int(metric_sum(i.metrics, "camloop_parts_total")
                             + metric_sum(i.metrics, "camloop_measurements_rejected_total"))
    (stored,) = db.query("SELECT count(*) FROM measurements")[0] or ["0"]
    per = {o: c for o, c in db.query(
        "SELECT owner, count(*) FROM camloop_leases WHERE expires_at > now() GROUP BY owner")}
    print(f"{label}: steady {elapsed:.0f} s: leases per instance {per}; machines unowned at a "
          f"1 s look: max {max(unowned_seen, default=0)}")
    print(f"{label}: lobes demanded since the launch {shafts * LOBES}, processed {processed}, "
          f"stored {stored}")
    for i in instances:
        print(f"{label}: instance {i.name}: CPU {i.cpu:.0f} % of one core, RSS "
              f"{rss_mib(i.proc.pid)[0]:.0f} MiB")


def kill_one(label, db, instances, args):
    victim = instances[-1]
    mine = [m for m, o in owners(db).items() if o == victim.name]
    before = newest_ids(db)
    os.kill(victim.proc.pid, signal.SIGKILL)
    killed = time.monotonic()
    victim.proc.wait()
    lease_s = args.lease_ms / 1000
    taken, back = None, {}
    while time.monotonic() - killed < max(args.after, 10 * lease_s):
        o = owners(db)
        if taken is None and all(o.get(m) not in (None, victim.name) for m in mine):
            taken = time.monotonic() - killed
        ids = newest_ids(db)
        now = time.monotonic() - killed
        for m in mine:
            if m not in back and ids.get(m, 0) > before.get(m, 0):
                back[m] = now
        if taken is not None and len(back) == len(mine) and now >= args.after:
            break
        time.sleep(0.2)
    times = sorted(back.values())
    print(f"{label}: SIGKILL of instance {victim.name} holding {len(mine)} machines: all owned by "
          f"the survivors after {taken if taken is None else round(taken, 1)} s (lease {lease_s:.1f} s); "
          f"a new part stored for {len(back)} of them, p50 {percentile(times, 0.5):.1f} s, "
          f"max {max(times, default=float('nan')):.1f} s after the kill")
    per = {o: c for o, c in db.query(
        "SELECT owner, count(*) FROM camloop_leases WHERE expires_at > now() GROUP BY owner")}
    print(f"{label}: after the kill: leases per instance {per}")
    return taken is not None and taken <= lease_s * 1.25 + 1.0


if __name__ == "__main__":
    main()
