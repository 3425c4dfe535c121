"""What a client holds across a restart of camloop's OPC UA server, with Python's `asyncua`,
as the integration test `opcua_restart` runs it:

    python3 restart_checks.py before PARAMS.json OUT.json BOUND_S   # a rollback; its EventId
    python3 restart_checks.py after PARAMS.json OUT.json BOUND_S    # after the restart

BOUND_S: past it the script prints where it waits and fails.

`before` rolls a feature back as the admin and keeps the EventId of the rollback's event.
`after` (the service restarted, no part since) reads every feature's result variables, which
must be the newest stored result with its own time as SourceTimestamp (a feature with no
stored result: BadWaitingForInitialData), and acknowledges the event by the EventId kept
from before the restart.
"""

import asyncio
import json
import sys
import time
from pathlib import Path

from asyncua import ua

from client_checks import Changes, acknowledge, connected, fail, http_json, ok, rollback, watched


async def before(p, out):
    admin = ("admin", p["admin_password"])
    c = await connected(p, admin)
    try:
        ns = await c.get_namespace_index("urn:camloop:ua")
        machine = await c.nodes.objects.get_child([f"{ns}:Machines", f"{ns}:{p['machine']}"])
        h = Changes()
        sub = await c.create_subscription(100, h)
        await sub.subscribe_events(machine, queuesize=100)
        new_version, message = await rollback(p, admin, ns)
        deadline = time.time() + 30
        found = None
        while time.time() < deadline and found is None:
            found = next((e for _, e in h.events if str(e.Message.Text).startswith("rollback:")), None)
            await asyncio.sleep(0.05)
        if found is None:
            fail("no rollback event on the machine within 30 s")
        await sub.delete()
    finally:
        await c.disconnect()
    ok(f"rolled back to v{new_version} ({message}); its event's EventId {found.EventId.hex()}")
    Path(out).write_text(json.dumps({"event_id": found.EventId.hex()}))


def newest(p, feature):
    page = http_json(p["http"], f"/api/v1/machines/{p['machine']}/measurements?lobe={feature}&limit=1")
    items = page["items"]
    return items[0] if items else None


async def read_result(c, ns, feature_node):
    names = ["PartId", "Time", "Verdict", "MaxError", "ProfileError", "SizeError", "PhaseError",
             "LatestResult"]
    nodes = [await feature_node.get_child([f"{ns}:{n}"]) for n in names]
    # One Read of every value: what a client sees at one instant.
    values = await c.read_attributes(nodes, ua.AttributeIds.Value)
    return dict(zip(names, values))


def opc_ms(dt):
    """A DataValue's timestamp (asyncua gives an aware or naive UTC datetime) as Unix ms."""
    if dt.tzinfo is None:
        import datetime
        dt = dt.replace(tzinfo=datetime.timezone.utc)
    return round(dt.timestamp() * 1000)


async def seeded(c, p, ns):
    features = await c.nodes.objects.get_child(
        [f"{ns}:Machines", f"{ns}:{p['machine']}", f"{ns}:Features"])
    for f in p["features"]:
        obj = await features.get_child([f"{ns}:{f}"])
        row = newest(p, f)
        # The server reads the history on a task of its own at start: a client connecting
        # at once may be quicker. Waited for (bounded), then every value checked.
        deadline = time.time() + 30
        while True:
            dv = await read_result(c, ns, obj)
            waiting = any(v.StatusCode.value == ua.StatusCodes.BadWaitingForInitialData for v in dv.values())
            if row is None or not waiting or time.time() > deadline:
                break
            await asyncio.sleep(0.2)
        if row is None:
            bad = [n for n, v in dv.items() if v.StatusCode.value != ua.StatusCodes.BadWaitingForInitialData]
            if bad:
                fail(f"{f} has no stored result but {bad} are not BadWaitingForInitialData")
            ok(f"{f}: no stored result, every result variable BadWaitingForInitialData")
            continue
        for name, v in dv.items():
            if not v.StatusCode.is_good():
                fail(f"{f}'s {name} after the restart: {v.StatusCode} (stored part {row['part']})")
            if opc_ms(v.SourceTimestamp) != row["received_at_ms"]:
                fail(f"{f}'s {name} SourceTimestamp {v.SourceTimestamp} is not the part's time {row['received_at_ms']}")
        value = {n: v.Value.Value for n, v in dv.items()}
        pairs = [("PartId", "part"), ("Verdict", "verdict"), ("ProfileError", "max_profile_error_um"),
                 ("SizeError", "base_radius_error_um"), ("PhaseError", "phase_error_deg")]
        # The same f64 the history holds: equal to the last bit.
        for a, b in pairs:
            if value[a] != row[b]:
                fail(f"{f}'s {a} after the restart {value[a]!r} != the history's {b} {row[b]!r}")
        if opc_ms(value["Time"]) != row["received_at_ms"]:
            fail(f"{f}'s Time {value['Time']} != the history's {row['received_at_ms']}")
        # MaxError is the loop's max |error| over the angles: from the stored report's
        # error_um, which the API gives back as stored.
        detail = http_json(p["http"], f"/api/v1/measurements/{row['id']}")
        errors = detail["analysis"]["error_um"]
        if value["MaxError"] != max(abs(e) for e in errors):
            fail(f"{f}'s MaxError {value['MaxError']} != max |error_um| of the stored report")
        latest = json.loads(value["LatestResult"])
        if latest["part"] != row["part"] or latest["time_ms"] != row["received_at_ms"]:
            fail(f"{f}'s LatestResult names {latest['part']} at {latest['time_ms']}, not the stored {row['part']}")
        ok(f"{f}: part {row['part']} of the history, every value Good with its time {row['received_at_ms']}")


async def after(p, out):
    kept = json.loads(Path(out).read_text())
    admin = ("admin", p["admin_password"])
    c = await connected(p, admin)
    try:
        ns = await c.get_namespace_index("urn:camloop:ua")
        await seeded(c, p, ns)
    finally:
        await c.disconnect()
    event_id = bytes.fromhex(kept["event_id"])
    answer = await acknowledge(p, admin, ns, event_id, ua.VariantType.ByteString)
    words = answer.split()
    if len(words) != 3 or words[0] != "event" or words[2] != "acknowledged":
        fail(f"AcknowledgeEvent by the EventId from before the restart answered {answer!r}")
    listed = http_json(p["http"], f"/api/v1/machines/{p['machine']}/events?limit=100")["items"]
    row = next((e for e in listed if e.get("id") == int(words[1])), None)
    if row is None or row["kind"] != "rollback":
        fail(f"the EventId from before the restart acknowledged event {words[1]}, not the rollback's: {row}")
    ok(f"AcknowledgeEvent by the EventId from before the restart: {answer!r} ({row['kind']})")
    try:
        await acknowledge(p, admin, ns, event_id[:-1] + bytes([event_id[-1] ^ 1]), ua.VariantType.ByteString)
        fail("an EventId of no event was acknowledged")
    except ua.uaerrors.BadNotFound:
        ok("an EventId naming no stored event: BadNotFound")


if __name__ == "__main__":
    params = json.loads(Path(sys.argv[2]).read_text())
    step = {"before": before, "after": after}[sys.argv[1]](params, sys.argv[3])
    asyncio.run(watched(step, float(sys.argv[4])))
    print(f"{sys.argv[1]}: restart checks passed", flush=True)
