"""Watches camloop's OPC UA server with Python's `asyncua` as a plant client would, at any
number of machines, as the integration test `opcua_asyncua_watch` runs it (the asyncua
counterpart of tools/opcua-node/checks.js):

    python3 watch_checks.py PARAMS.json

Signed in as the admin over Basic256Sha256 SignAndEncrypt, it watches events on `Server`,
`Machines` and the first machine (one subscription, queues of 10,000) and `PartId`, `Time`
and `LatestResult` of every feature (another) for `duration_s`. It prints a JSON summary
last and exits 1 when an event came twice to an item, when an event of the first machine
is missing on `Server` or `Machines` (or one of `Machines` on `Server`, or the other way
round), or when a part's values are torn: `PartId`, `Time` and `LatestResult` of one
SourceTimestamp that name different parts or times.
"""

import asyncio
import json
import sys
from collections import defaultdict
from pathlib import Path

from asyncua import ua

from client_checks import connected


class Watch:
    def __init__(self):
        self.events = defaultdict(list)  # notifier -> [EventId]
        self.values = defaultdict(dict)  # (feature node path, SourceTimestamp ms) -> {name: value}

    def datachange_notification(self, node, val, data):
        path = node.nodeid.Identifier
        feature, name = path.rsplit("/", 1)
        dv = data.monitored_item.Value
        if dv.StatusCode is not None and not dv.StatusCode.is_good():
            return
        at = dv.SourceTimestamp
        key = (feature, round(at.timestamp() * 1000) if at else None)
        self.values[key][name] = val


class Notifier:
    """Tags each event with the notifier its item watches (asyncua gives the event only)."""

    def __init__(self, watch, name):
        self.watch = watch
        self.name = name

    def event_notification(self, event):
        self.watch.events[self.name].append(bytes(event.EventId))


def ms_of(dt):
    import datetime
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=datetime.timezone.utc)
    return round(dt.timestamp() * 1000)


async def run(p):
    c = await connected(p, ("admin", p["admin_password"]))
    watch = Watch()
    try:
        ns = await c.get_namespace_index("urn:camloop:ua")
        machines = await c.nodes.objects.get_child([f"{ns}:Machines"])
        first = await machines.get_child([f"{ns}:{p['machines'][0]}"])
        subs = []
        for name, node in (("Server", c.nodes.server), ("Machines", machines), ("machine", first)):
            sub = await c.create_subscription(100, Notifier(watch, name))
            await sub.subscribe_events(node, queuesize=10_000)
            subs.append(sub)
        values = await c.create_subscription(100, watch)
        nodes = [c.get_node(ua.NodeId(f"Machines/{m}/Features/{f}/{v}", ns))
                 for m in p["machines"] for f in p["features"] for v in ("PartId", "Time", "LatestResult")]
        for i in range(0, len(nodes), 500):
            await values.subscribe_data_change(nodes[i:i + 500], queuesize=100)
        await asyncio.sleep(p["duration_s"])
        # The machine's item first, Server's last: every event the machine's item got was
        # raised while the other two items existed.
        for sub in [values] + subs[::-1]:
            await sub.delete()
    finally:
        await c.disconnect()
    return summarise(watch, p)


def summarise(watch, p):
    problems = []
    events = {}
    for name in ("Server", "Machines", "machine"):
        ids = watch.events[name]
        dup = len(ids) - len(set(ids))
        events[name] = {"received": len(ids), "duplicates": dup}
        if dup:
            problems.append(f"{dup} events came twice to the item on {name}")
    server, folder, machine = (set(watch.events[n]) for n in ("Server", "Machines", "machine"))
    # Events raised while the three items existed: the machine's must be on both others.
    missing_server = len(machine - server)
    missing_folder = len(machine - folder)
    events["machine"]["missing_on_Server"] = missing_server
    events["machine"]["missing_on_Machines"] = missing_folder
    events["Machines"]["differs_from_Server"] = len(folder ^ server)
    if missing_server or missing_folder:
        problems.append(f"events of the machine missing: {missing_server} on Server, {missing_folder} on Machines")
    checked = torn = 0
    for (feature, at), vals in watch.values.items():
        if at is None or "PartId" not in vals:
            continue
        checked += 1
        latest = json.loads(vals["LatestResult"]) if "LatestResult" in vals else None
        time_ms = ms_of(vals["Time"]) if "Time" in vals else None
        if latest is None or time_ms is None or latest["part"] != vals["PartId"] \
                or latest["time_ms"] != at or time_ms != at:
            torn += 1
    if checked == 0:
        problems.append("no result seen")
    if torn:
        problems.append(f"{torn} of {checked} results torn")
    summary = {"events": events, "results": {"checked": checked, "torn": torn}, "problems": problems}
    print(json.dumps(summary), flush=True)
    return not problems


if __name__ == "__main__":
    params = json.loads(Path(sys.argv[1]).read_text())
    sys.exit(0 if asyncio.run(run(params)) else 1)
