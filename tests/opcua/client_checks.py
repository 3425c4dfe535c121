"""Drives camloop's OPC UA server with the Python `asyncua` client (a client nobody on the
project wrote), as the integration test `opcua_asyncua` runs it.

    python3 client_checks.py certs DIR        # makes trusted.der/.pem and stranger.der/.pem
    python3 client_checks.py check PARAMS.json
    python3 client_checks.py clear-password PARAMS.json   # a Basic256Sha256+None server

`check` prints one line per check passed and exits 1 at the first one failing.
"""

import asyncio
import json
import os
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID

APP_URI = "urn:camloop:test-client"
# How long a value or event may take to reach the subscriber after the part is stored: the
# issue's bound. Parts arrive every `part_interval_ms` (set by the test), so a wait for the
# next part is bounded by that interval plus this.
FRESH_S = 1.0


def ok(what):
    print(f"ok: {what}", flush=True)


def fail(what):
    print(f"FAILED: {what}", flush=True)
    sys.exit(1)


async def watched(main, bound_s):
    """Awaits `main`; past `bound_s` prints where each of its tasks waits, and fails (a hang
    then says where it hung instead of being killed silently)."""
    async def dog():
        await asyncio.sleep(bound_s)
        print(f"FAILED: still running after {bound_s} s; its tasks:", flush=True)
        for task in asyncio.all_tasks():
            task.print_stack(file=sys.stdout)
        sys.stdout.flush()
        os._exit(1)

    watchdog = asyncio.create_task(dog())
    try:
        return await main
    finally:
        watchdog.cancel()


async def make_certs(folder):
    folder = Path(folder)
    for name in ("trusted", "stranger"):
        await setup_self_signed_certificate(
            folder / f"{name}.pem",
            folder / f"{name}.der",
            APP_URI,
            "localhost",
            [ExtendedKeyUsageOID.CLIENT_AUTH],
            {"commonName": f"camloop test client ({name})"},
        )


def http_json(base, path):
    with urllib.request.urlopen(base + path, timeout=10) as r:
        return json.loads(r.read())


async def client(p, user=None, cert="trusted", secure=True):
    c = Client(p["endpoint"], timeout=10)
    c.application_uri = APP_URI
    if user is not None:
        c.set_user(user[0])
        c.set_password(user[1])
    if secure:
        d = Path(p["cert_dir"])
        await c.set_security(
            SecurityPolicyBasic256Sha256,
            str(d / f"{cert}.der"),
            str(d / f"{cert}.pem"),
            mode=ua.MessageSecurityMode.SignAndEncrypt,
        )
    return c


async def connected(p, user, bound_s=240.0):
    """A session once the server answers: on a loaded machine a server that accepts the TCP
    connection may leave a Hello unanswered within the client's timeout (a service of many
    machines, or one just started). What the checks assert is what it then answers."""
    deadline = time.monotonic() + bound_s
    while True:
        try:
            c = await client(p, user)
            await c.connect()
            return c
        except (asyncio.TimeoutError, OSError) as e:
            print(f"no session yet ({e!r}); trying again", file=sys.stderr, flush=True)
            if time.monotonic() > deadline:
                fail(f"no session within {bound_s} s: {e!r}")
            await asyncio.sleep(1.0)


async def refused(make, what):
    c = await make()
    try:
        await c.connect()
    except Exception as e:  # any refusal will do; what matters is that no session opens
        ok(f"{what} refused ({type(e).__name__})")
        return
    await c.disconnect()
    fail(f"{what} was accepted")


class Changes:
    """Data-change and event handler: what arrived, with the wall clock on arrival."""

    def __init__(self):
        self.values = []
        self.events = []

    def datachange_notification(self, node, val, data):
        self.values.append((time.time(), val))

    def event_notification(self, event):
        self.events.append((time.time(), event))


async def browse(c, p):
    ns = await c.get_namespace_index("urn:camloop:ua")
    machines = await c.nodes.objects.get_child([f"{ns}:Machines"])
    names = {(await m.read_browse_name()).Name: m for m in await machines.get_children()}
    if sorted(names) != sorted(p["machines"]):
        fail(f"machines browsed {sorted(names)} != configured {p['machines']}")
    m = p["machine"]
    features = await names[m].get_child([f"{ns}:Features"])
    found = [(await f.read_browse_name()).Name for f in await features.get_children()]
    if sorted(found) != sorted(p["features"]):
        fail(f"features browsed {found} != configured {p['features']}")
    order = await (await names[m].get_child([f"{ns}:GrindingOrder"])).read_value()
    if sorted(order) != sorted(p["features"]):
        fail(f"GrindingOrder {order} != configured {p['features']}")
    # The browse gives the features in grinding order.
    if found != order:
        fail(f"features browsed in the order {found}, not the grinding order {order}")
    ok(f"browsed Machines {sorted(names)} and {m}'s features {found}, in GrindingOrder")
    return ns, features


async def wait_for_part(node, bound_s):
    """The PartId value once there is one (the first part may still be on its way)."""
    deadline = time.time() + bound_s
    while time.time() < deadline:
        v = await node.read_value()
        if v:
            return v
        await asyncio.sleep(0.1)
    fail(f"no part within {bound_s} s")


async def latest_matches_http(c, p, ns, features):
    f = p["feature"]
    obj = await features.get_child([f"{ns}:{f}"])
    part = await wait_for_part(await obj.get_child([f"{ns}:PartId"]), 60)
    # A newer part may land between the two reads: read both again until they agree.
    for _ in range(20):
        values = {}
        for name in ("PartId", "ProfileError", "SizeError", "PhaseError", "Verdict"):
            values[name] = await (await obj.get_child([f"{ns}:{name}"])).read_value()
        reply = http_json(p["http"], f"/api/v1/machines/{p['machine']}/parts/{values['PartId']}")
        row = next((x["measurement"] for x in reply["features"] if x["lobe"] == f), None)
        if row is None:
            await asyncio.sleep(0.2)
            continue
        pairs = [
            ("ProfileError", "max_profile_error_um"),
            ("SizeError", "base_radius_error_um"),
            ("PhaseError", "phase_error_deg"),
        ]
        # Both are the same f64 from one analysis: equal to the last bit.
        same = all(values[a] == row[b] for a, b in pairs) and values["Verdict"] == row["verdict"]
        if same:
            eu = await (await obj.get_child([f"{ns}:ProfileError", "0:EngineeringUnits"])).read_value()
            if eu.DisplayName.Text != "µm":
                fail(f"ProfileError's unit is {eu.DisplayName.Text!r}")
            ok(f"latest result of {f} (part {values['PartId']}) equals the API's, unit µm")
            return
        await asyncio.sleep(0.2)
    fail(f"latest result of {f} never matched the API ({part})")


async def next_part_and_event(c, p, ns, features):
    f = p["feature"]
    obj = await features.get_child([f"{ns}:{f}"])
    node = await obj.get_child([f"{ns}:PartId"])
    h = Changes()
    sub = await c.create_subscription(100, h)
    await sub.subscribe_data_change(node)
    await sub.subscribe_events()  # the Server object, BaseEventType and every subtype
    first = await node.read_value()
    bound = p["part_interval_s"] * 3 + 10
    deadline = time.time() + bound
    while time.time() < deadline:
        new = [(t, v) for t, v in h.values if v and v != first]
        if new:
            break
        await asyncio.sleep(0.05)
    else:
        fail(f"no new part of {f} within {bound} s")
    seen_s, part = new[0]
    # The part's event is sent once the store has written its row (the database is up
    # here): asked once, at the event, the history must have it.
    reply = http_json(p["http"], f"/api/v1/machines/{p['machine']}/parts/{part}")
    row = next(x["measurement"] for x in reply["features"] if x["lobe"] == f)
    if row is None:
        fail(f"part {part} of {f} announced before its history row")
    # Stored after it was received: arriving within FRESH_S of receipt is within FRESH_S
    # of storage. Same host, same clock.
    lag_s = seen_s - row["received_at_ms"] / 1000.0
    if lag_s > FRESH_S:
        fail(f"part {part} seen {lag_s:.3f} s after it was received (bound {FRESH_S} s)")
    ok(f"subscribed: part {part} of {f} seen {lag_s * 1000:.0f} ms after receipt (bound {FRESH_S * 1000:.0f} ms)")
    deadline = time.time() + 10
    while time.time() < deadline and not h.events:
        await asyncio.sleep(0.05)
    if not h.events:
        fail("no event within 10 s of a part")
    e = h.events[0][1]
    ok(f"event received: {e.EventType} from {e.SourceName}: {str(e.Message.Text)[:60]}")
    await sub.delete()


async def rollback(p, user, ns):
    c = await client(p, user)
    async with c:
        machine = await c.nodes.objects.get_child([f"{ns}:Machines", f"{ns}:{p['machine']}"])
        method = await machine.get_child([f"{ns}:Rollback"])
        # Back to the version before the one on the control (its text is surely kept).
        in_force = await (await machine.get_child(
            [f"{ns}:Features", f"{ns}:{p['feature']}", f"{ns}:TableVersionInForce"])).read_value()
        back_to = max(1, in_force - 1)
        return await machine.call_method(method, ua.Variant(p["feature"], ua.VariantType.String),
                                         ua.Variant(back_to, ua.VariantType.Int64))


async def acknowledge(p, user, ns, event_id, variant_type=ua.VariantType.Int64):
    c = await client(p, user)
    async with c:
        machine = await c.nodes.objects.get_child([f"{ns}:Machines", f"{ns}:{p['machine']}"])
        method = await machine.get_child([f"{ns}:AcknowledgeEvent"])
        return await machine.call_method(method, ua.Variant(event_id, variant_type))


async def acknowledgements(p, ns, rollback_event_id):
    """The HTTP ack handler answers for the method: an operator role is needed, and an
    event the history lacks is not found. The rollback's event is acknowledged by the
    EventId the subscriber got, then by the id the events API lists for it: the second
    answer says it was acknowledged before, as the audit row does."""
    try:
        await acknowledge(p, (p["viewer"], p["viewer_password"]), ns, 1)
        fail("AcknowledgeEvent by a viewer was carried out")
    except ua.uaerrors.BadUserAccessDenied:
        ok("AcknowledgeEvent by a viewer refused: BadUserAccessDenied")
    admin = ("admin", p["admin_password"])
    try:
        await acknowledge(p, admin, ns, 987654321)
        fail("AcknowledgeEvent of an event the history lacks succeeded")
    except ua.uaerrors.BadNotFound:
        ok("AcknowledgeEvent of an unknown event: BadNotFound")
    try:
        await acknowledge(p, admin, ns, 1.5, ua.VariantType.Double)
        fail("AcknowledgeEvent with a Double id was carried out")
    except ua.uaerrors.BadInvalidArgument:
        ok("AcknowledgeEvent with a Double: BadInvalidArgument (its argument BadTypeMismatch)")
    first = await acknowledge(p, admin, ns, rollback_event_id, ua.VariantType.ByteString)
    words = first.split()
    if len(words) != 3 or words[0] != "event" or words[2] != "acknowledged":
        fail(f"AcknowledgeEvent by EventId answered {first!r}")
    event_id = int(words[1])
    listed = http_json(p["http"], f"/api/v1/machines/{p['machine']}/events?limit=100")["items"]
    row = next((e for e in listed if e.get("id") == event_id), None)
    if row is None or row["kind"] != "rollback":
        fail(f"the events API lists no rollback event {event_id}: {listed[:3]}")
    ok(f"AcknowledgeEvent by the OPC UA EventId: {first!r}, the API's event {event_id} ({row['kind']})")
    again = await acknowledge(p, admin, ns, event_id)
    if again != f"event {event_id} acknowledged before":
        fail(f"a repeated AcknowledgeEvent answered {again!r}")
    ok(f"a repeated AcknowledgeEvent by the API's id: {again!r}")


async def rollbacks(p, ns):
    try:
        await rollback(p, (p["viewer"], p["viewer_password"]), ns)
        fail("Rollback by a viewer was carried out")
    except ua.uaerrors.BadUserAccessDenied:
        ok("Rollback by a viewer refused: BadUserAccessDenied")
    watcher = await client(p, ("admin", p["admin_password"]))
    async with watcher:
        machine = await watcher.nodes.objects.get_child([f"{ns}:Machines", f"{ns}:{p['machine']}"])
        h = Changes()
        sub = await watcher.create_subscription(100, h)
        await sub.subscribe_events(machine, queuesize=100)
        out = await rollback(p, ("admin", p["admin_password"]), ns)
        new_version, message = out
        # The table program on the share names its version and feature in its provenance lines;
        # read at once, before the next part (seconds away) can deliver a newer one.
        share = Path(p["share"])
        wanted = (f"table version: v{new_version}", f"feature: {p['feature']}")
        texts = [x.read_text(errors="replace") for x in share.rglob("*") if x.is_file()]
        if not any(all(w in t for w in wanted) for t in texts):
            fail(f"Rollback said {message!r} but no program on the share is v{new_version} of {p['feature']}")
        tables = http_json(p["http"], f"/api/v1/machines/{p['machine']}/lobes/{p['feature']}/tables")
        items = tables["items"]
        row = next((t for t in items if t.get("version") == new_version), None)
        if row is None or row.get("status") != "pushed":
            fail(f"Rollback said {message!r} but version {new_version} is not pushed: {row}")
        deadline = time.time() + 10
        found = None
        while time.time() < deadline and found is None:
            found = next((e for _, e in h.events if str(e.Message.Text).startswith("rollback:")), None)
            await asyncio.sleep(0.05)
        if found is None:
            fail("no rollback event on the machine within 10 s")
        await sub.delete()
    ok(f"Rollback by admin delivered and on the share as v{new_version}: {message}")
    return found.EventId


async def none_refused_by_server(p):
    """A client that goes ahead over `None` anyway (its endpoint check bypassed) is refused
    by the server when it activates the session. Anonymous, so no password travels."""
    real = Client.find_endpoint
    Client.find_endpoint = staticmethod(lambda endpoints, mode, uri: endpoints[0])
    # On a loaded machine a Hello can go unanswered within the client's timeout: asked again
    # (bounded), since what is asserted is the server's refusal, not how soon it comes.
    deadline = time.monotonic() + 90.0
    try:
        while True:
            c = Client(p["endpoint"], timeout=10)
            c.application_uri = APP_URI
            try:
                await c.connect()
                await c.disconnect()
                fail("a session over None was activated")
            except (ua.uaerrors.BadTcpEndpointUrlInvalid, ua.uaerrors.BadSecurityPolicyRejected) as e:
                ok(f"a session over None refused by the server ({type(e).__name__})")
                return
            except asyncio.TimeoutError:
                if time.monotonic() > deadline:
                    fail("the server answered no Hello within 90 s")
                await asyncio.sleep(0.5)
    finally:
        Client.find_endpoint = real


async def endpoints_once_answering(endpoint, bound_s=90.0):
    """The server's endpoints, asked until it answers: a listener that accepts the TCP
    connection may still be starting (a first start makes the admin and the tables), and on
    a loaded machine the first Hello can go unanswered within the client's timeout. What the
    checks assert is the endpoints' content, not how soon they come."""
    deadline = time.monotonic() + bound_s
    while True:
        c = Client(endpoint, timeout=10)
        c.application_uri = APP_URI
        try:
            return await c.connect_and_get_server_endpoints()
        except (asyncio.TimeoutError, OSError) as e:
            if time.monotonic() > deadline:
                fail(f"no endpoints from {endpoint} within {bound_s} s: {e!r}")
            await asyncio.sleep(0.5)


async def clear_password_refused(p):
    """On a `Basic256Sha256+None` server: the None endpoint offers no user-name policy, and
    a client that sends a user name and password over None anyway (in clear: the channel
    neither signs nor encrypts, and the policy names no security policy for the password)
    is refused. The same user over the secure endpoint signs in."""
    endpoints = await endpoints_once_answering(p["endpoint"])
    none = [e for e in endpoints if e.SecurityMode == ua.MessageSecurityMode.None_]
    if not none:
        fail("the server offers no None endpoint to check")
    kinds = [t.TokenType for e in none for t in e.UserIdentityTokens]
    if ua.UserTokenType.UserName in kinds:
        fail(f"the None endpoint offers a user-name policy: {kinds}")
    ok(f"the None endpoint offers no user-name policy ({kinds})")
    # A client that ignores the policies: asyncua sends the password as the policy id
    # says, with no security policy URI that is in clear.
    real = Client.find_endpoint
    Client.find_endpoint = staticmethod(lambda endpoints, mode, uri: none[0])
    c = Client(p["endpoint"], timeout=10)
    c.application_uri = APP_URI
    c.set_user("admin")
    c.set_password(p["admin_password"])
    try:
        await c.connect()
        await c.disconnect()
        fail("a user name with its password in clear was accepted over None")
    except Exception as e:  # any refusal: what matters is that no session opens
        ok(f"a clear-text password over None refused ({type(e).__name__}: {e})")
    finally:
        Client.find_endpoint = real
    c = await client(p, ("admin", p["admin_password"]))
    async with c:
        ok("the same user signs in over Basic256Sha256 SignAndEncrypt")


async def disabled_user_stopped(p):
    """A user's open session reads the machine's GrindingOrder; once the user is disabled with
    `camloop user disable` beside the running service, the same session's reads are refused
    within the service's recheck (every 2 s; the bound is 20 s, for a loaded machine)."""
    # A listener that accepts may still be starting: wait until it answers.
    await endpoints_once_answering(p["endpoint"])
    c = await client(p, (p["user"], p["password"]))
    async with c:
        ns = await c.get_namespace_index("urn:camloop:ua")
        machines = await c.nodes.objects.get_child([f"{ns}:Machines"])
        order = await (await machines.get_child([f"{ns}:{p['machine']}"])).get_child(
            [f"{ns}:GrindingOrder"]
        )
        await order.read_value()
        ok(f"{p['user']}'s session reads GrindingOrder")
        done = subprocess.run(
            [p["camloop"], "user", "disable", p["user"], "--database", p["database"]],
            cwd=p["dir"],
            capture_output=True,
            text=True,
        )
        if done.returncode != 0:
            fail(f"camloop user disable: {done.stderr}")
        disabled_at = time.monotonic()
        while True:
            try:
                await order.read_value()
            except ua.UaStatusCodeError as e:
                waited = time.monotonic() - disabled_at
                ok(f"refused {waited:.1f} s after the user was disabled ({type(e).__name__})")
                break
            except ConnectionError as e:
                # The session is gone (its channel dropped under load): it reads nothing more
                # either, which is what is asserted; said so in the output.
                waited = time.monotonic() - disabled_at
                ok(f"session ended {waited:.1f} s after the user was disabled ({e})")
                break
            if time.monotonic() - disabled_at > 20.0:
                fail("the disabled user's session still reads 20 s later")
            await asyncio.sleep(0.2)


async def opcua_lockout(p):
    """Five wrong passwords for a user over OPC UA lock that user's OPC UA sign-in: the
    right password is refused there afterwards (the caller checks HTTP is untouched)."""
    await endpoints_once_answering(p["endpoint"])
    for i in range(5):
        await refused(lambda: client(p, (p["user"], "wrong-password-guess")), f"wrong password {i + 1}")
    await refused(lambda: client(p, (p["user"], p["password"])), "the right password once locked")


def trust(p):
    """What an operator does: moves the refused client's certificate from the server's
    rejected folder to its trusted folder."""
    pki = Path(p["pki"])
    ours = (Path(p["cert_dir"]) / "trusted.der").read_bytes()
    found = [f for f in (pki / "rejected").glob("*.der") if f.read_bytes() == ours]
    if len(found) != 1:
        fail(f"the refused certificate is not in {pki / 'rejected'} once: {found}")
    found[0].rename(pki / "trusted" / found[0].name)
    ok(f"moved {found[0].name} from rejected/ to trusted/")


async def check(params_file):
    p = json.loads(Path(params_file).read_text())
    admin = ("admin", p["admin_password"])
    await refused(lambda: client(p, None, secure=False), "a None connection (by the client: no None endpoint)")
    await none_refused_by_server(p)
    await refused(lambda: client(p, admin), "a client certificate not yet trusted")
    trust(p)
    await refused(lambda: client(p, admin, cert="stranger"), "another untrusted certificate")
    await refused(lambda: client(p, None), "an anonymous session (trusted certificate)")
    c = await client(p, ("admin", p["admin_password"]))
    async with c:
        ok("connected with Basic256Sha256 SignAndEncrypt as admin")
        ns, features = await browse(c, p)
        await latest_matches_http(c, p, ns, features)
        await next_part_and_event(c, p, ns, features)
    rollback_event_id = await rollbacks(p, ns)
    await acknowledgements(p, ns, rollback_event_id)
    print("all OPC UA checks passed", flush=True)


if __name__ == "__main__":
    if sys.argv[1] == "certs":
        asyncio.run(make_certs(sys.argv[2]))
    elif sys.argv[1] == "disabled":
        asyncio.run(disabled_user_stopped(json.loads(Path(sys.argv[2]).read_text())))
        print("disabled user checks passed", flush=True)
    elif sys.argv[1] == "lockout":
        asyncio.run(opcua_lockout(json.loads(Path(sys.argv[2]).read_text())))
        print("OPC UA lockout checks passed", flush=True)
    elif sys.argv[1] == "clear-password":
        asyncio.run(clear_password_refused(json.loads(Path(sys.argv[2]).read_text())))
        print("clear-text password checks passed", flush=True)
    else:
        asyncio.run(check(sys.argv[2]))
