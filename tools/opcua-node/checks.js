// camloop's OPC UA server driven by node-opcua, a second client library nobody on the project
// wrote (the first is Python's asyncua, tests/opcua/client_checks.py). Run by the integration
// test opcua_node: `node checks.js PARAMS.json`. It signs in as the admin over Basic256Sha256
// SignAndEncrypt, reads MaxNodesPerRead nodes in one Read, watches events on Server, Machines
// and the first machine in one subscription, and PartId, Time and LatestResult of every
// feature in another, for `duration_s`; then it prints a JSON summary and exits 1 when an
// event came twice or missed a notifier, when a publish carried part of a result, when a
// value's times disagree, or when a part's Time is not its time in the history.
"use strict";

const fs = require("fs");
const path = require("path");
const http = require("http");
const {
  OPCUAClient,
  MessageSecurityMode,
  SecurityPolicy,
  UserTokenType,
  AttributeIds,
  TimestampsToReturn,
  ClientSubscription,
  ClientMonitoredItem,
  ClientMonitoredItemGroup,
  constructEventFilter,
} = require("node-opcua-client");
const { OPCUACertificateManager } = require("node-opcua-certificate-manager");

function httpJson(base, p) {
  return new Promise((resolve, reject) => {
    http
      .get(base + p, (res) => {
        let body = "";
        res.on("data", (c) => (body += c));
        res.on("end", () => {
          try {
            resolve(JSON.parse(body));
          } catch (e) {
            reject(new Error(`${p}: ${e} (${body.slice(0, 200)})`));
          }
        });
      })
      .on("error", reject);
  });
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
const ms = (date) => (date instanceof Date ? date.getTime() : null);

async function connect(p) {
  const certificateManager = new OPCUACertificateManager({
    rootFolder: p.client_pki,
    automaticallyAcceptUnknownCertificate: true,
  });
  const client = OPCUAClient.create({
    applicationName: "camloop node-opcua check",
    applicationUri: "urn:camloop:node-check",
    securityMode: MessageSecurityMode.SignAndEncrypt,
    securityPolicy: SecurityPolicy.Basic256Sha256,
    endpointMustExist: false,
    clientCertificateManager: certificateManager,
    // A service of many machines may take minutes to start serving on a loaded machine.
    connectionStrategy: { maxRetry: 120, initialDelay: 500, maxDelay: 2000 },
  });
  await client.connect(p.endpoint);
  const session = await client.createSession({
    type: UserTokenType.UserName,
    userName: "admin",
    password: p.admin_password,
  });
  return { client, session };
}

async function readAtTheLimit(session, values) {
  const max = (await session.read({ nodeId: "ns=0;i=11705", attributeId: AttributeIds.Value })).value.value;
  const nodes = [];
  for (let i = 0; nodes.length < max; i++) {
    nodes.push({ nodeId: values[i % values.length], attributeId: AttributeIds.Value });
  }
  const read = await session.read(nodes);
  const refused = read.filter((dv) => dv.statusCode.name === "BadDecodingError").length;
  return { max_nodes_per_read: max, read: read.length, refused };
}

async function watchEvents(session, ns, firstMachine, seen) {
  const sub = ClientSubscription.create(session, {
    requestedPublishingInterval: 100,
    requestedLifetimeCount: 600,
    requestedMaxKeepAliveCount: 10,
    maxNotificationsPerPublish: 0,
    publishingEnabled: true,
    priority: 10,
  });
  const filter = constructEventFilter(["EventId", "SourceName", "Message", "Time"]);
  const notifiers = {
    Server: "ns=0;i=2253",
    Machines: `ns=${ns};s=Machines`,
    [firstMachine]: `ns=${ns};s=Machines/${firstMachine}`,
  };
  for (const [name, nodeId] of Object.entries(notifiers)) {
    seen[name] = [];
    const item = ClientMonitoredItem.create(
      sub,
      { nodeId, attributeId: AttributeIds.EventNotifier },
      { samplingInterval: 0, filter, queueSize: 10000, discardOldest: true },
      TimestampsToReturn.Both,
    );
    item.on("changed", (fields) => {
      seen[name].push({
        id: Buffer.from(fields[0].value).toString("hex"),
        source: String(fields[1].value),
        message: fields[2].value ? String(fields[2].value.text) : "",
        at: ms(fields[3].value),
      });
    });
    // One item at a time (each its own call): an event raised before the last exists
    // reaches only the earlier ones, so the comparison starts once all are there.
    await new Promise((resolve) => item.on("initialized", resolve));
  }
  seen.since = Date.now() + 1000;
  return sub;
}

async function watchResults(session, ns, p, publishes) {
  const sub = ClientSubscription.create(session, {
    requestedPublishingInterval: 100,
    requestedLifetimeCount: 600,
    requestedMaxKeepAliveCount: 10,
    maxNotificationsPerPublish: 0,
    publishingEnabled: true,
    priority: 10,
  });
  const names = [];
  for (const m of p.machines) {
    for (const f of p.features) {
      for (const v of ["PartId", "Time", "LatestResult"]) {
        names.push({ m, f, v, nodeId: `ns=${ns};s=Machines/${m}/Features/${f}/${v}` });
      }
    }
  }
  const byHandle = new Map();
  // Each item's first notification is its value when subscribed (read, not published
  // with a part): left out.
  const first = new Set();
  sub.on("raw_notification", (message) => {
    const publish = [];
    for (const data of message.notificationData || []) {
      for (const n of data.monitoredItems || []) {
        const name = byHandle.get(n.clientHandle);
        if (!name) continue;
        if (!first.has(n.clientHandle)) {
          first.add(n.clientHandle);
          continue;
        }
        publish.push({ ...name, value: n.value });
      }
    }
    if (publish.length) publishes.push(publish);
  });
  // As many items a call as the server advertises (MaxMonitoredItemsPerCall): node-opcua
  // sends a group in one call.
  // A feature's three values in the same call (a multiple of 3 a call).
  const limit = (await session.read({ nodeId: "ns=0;i=11714", attributeId: AttributeIds.Value })).value.value;
  const perCall = Math.max(3, limit - (limit % 3));
  for (let start = 0; start < names.length; start += perCall) {
    const chunk = names.slice(start, start + perCall);
    const group = ClientMonitoredItemGroup.create(
      sub,
      chunk.map((n) => ({ nodeId: n.nodeId, attributeId: AttributeIds.Value })),
      { samplingInterval: 0, queueSize: 100, discardOldest: true },
      TimestampsToReturn.Both,
    );
    await new Promise((resolve, reject) => {
      group.on("initialized", resolve);
      group.on("err", (e) => reject(new Error(`monitored items: ${e}`)));
    });
    group.monitoredItems.forEach((item, i) => byHandle.set(item.monitoringParameters.clientHandle, chunk[i]));
  }
  return sub;
}

// Each publish's results, feature by feature: all three values or none, one SourceTimestamp,
// Time's value that timestamp, LatestResult's part the PartId.
function results(publishes) {
  let consistent = 0;
  const torn = [];
  const parts = [];
  for (const publish of publishes) {
    const byFeature = new Map();
    for (const n of publish) {
      if (!n.value.statusCode || n.value.statusCode.name !== "Good") continue;
      const key = `${n.m}/${n.f}`;
      if (!byFeature.has(key)) byFeature.set(key, {});
      byFeature.get(key)[n.v] = n.value;
    }
    for (const [key, r] of byFeature) {
      const [m, f] = key.split("/");
      const complete = r.PartId && r.Time && r.LatestResult;
      const at = complete ? ms(r.PartId.sourceTimestamp) : null;
      const ok =
        complete &&
        ms(r.Time.sourceTimestamp) === at &&
        ms(r.LatestResult.sourceTimestamp) === at &&
        ms(r.Time.value.value) === at &&
        JSON.parse(r.LatestResult.value.value).part === r.PartId.value.value;
      if (ok) {
        consistent += 1;
        parts.push({ m, f, part: r.PartId.value.value, at });
      } else {
        torn.push({ key, values: Object.keys(r) });
      }
    }
  }
  return { consistent, torn, parts };
}

async function inTheHistory(base, parts, sample) {
  let checked = 0;
  const mismatched = [];
  for (const x of parts.slice(-sample)) {
    const reply = await httpJson(base, `/api/v1/machines/${x.m}/parts/${encodeURIComponent(x.part)}`);
    const row = (reply.features || []).find((y) => y.lobe === x.f);
    checked += 1;
    if (!row || row.measurement.received_at_ms !== x.at) mismatched.push({ ...x, history: row && row.measurement.received_at_ms });
  }
  return { checked, mismatched };
}

function events(all, firstMachine) {
  const out = {};
  // Events raised once every item existed (a second's margin: same host, same clock).
  const seen = {};
  for (const [name, list] of Object.entries(all)) {
    if (Array.isArray(list)) seen[name] = list.filter((e) => e.at !== null && e.at > all.since);
  }
  for (const [name, list] of Object.entries(seen)) {
    const ids = new Set(list.map((e) => e.id));
    out[name] = { received: list.length, distinct: ids.size, duplicates: list.length - ids.size };
  }
  const ids = (name) => new Set(seen[name].map((e) => e.id));
  const server = ids("Server");
  const machines = ids("Machines");
  const mine = ids(firstMachine);
  const onServerOfMine = seen.Server.filter((e) => e.source.startsWith(`${firstMachine}/`)).map((e) => e.id);
  out.missing = {
    machine_on_server: [...mine].filter((id) => !server.has(id)).length,
    server_on_machines: [...server].filter((id) => !machines.has(id)).length,
    machines_on_server: [...machines].filter((id) => !server.has(id)).length,
    server_on_machine: onServerOfMine.filter((id) => !mine.has(id)).length,
  };
  out.result_ready_on_server = seen.Server.filter((e) => e.message.startsWith("{")).length;
  return out;
}

async function main() {
  const p = JSON.parse(fs.readFileSync(process.argv[2], "utf8"));
  const { client, session } = await connect(p);
  const ns = (await session.readNamespaceArray()).indexOf("urn:camloop:ua");
  if (ns < 0) throw new Error("no urn:camloop:ua in the namespace array");
  const values = [];
  for (const m of p.machines) for (const f of p.features) values.push(`ns=${ns};s=Machines/${m}/Features/${f}/PartId`);
  const limits = await readAtTheLimit(session, values);
  const seen = {};
  const publishes = [];
  const eventsSub = await watchEvents(session, ns, p.machines[0], seen);
  const resultsSub = await watchResults(session, ns, p, publishes);
  // At least `duration_s`, and then until `min_results` results came (a loaded machine
  // grinds slowly: what is checked is their consistency, not the pace), within `bound_s`.
  const started = Date.now();
  await sleep(p.duration_s * 1000);
  while (results(publishes).consistent < p.min_results && Date.now() - started < p.bound_s * 1000) {
    await sleep(500);
  }
  await resultsSub.terminate();
  await eventsSub.terminate();
  const r = results(publishes);
  const history = await inTheHistory(p.http, r.parts, p.history_sample);
  const summary = {
    machines: p.machines.length,
    features: p.features.length,
    duration_s: p.duration_s,
    limits,
    events: events(seen, p.machines[0]),
    results: { publishes: publishes.length, consistent: r.consistent, torn: r.torn.length, torn_examples: r.torn.slice(0, 3) },
    history,
  };
  await session.close();
  await client.disconnect();
  console.log(JSON.stringify(summary));
  const e = summary.events;
  const failed =
    limits.refused > 0 ||
    limits.read !== limits.max_nodes_per_read ||
    Object.values(e).some((x) => x && x.duplicates > 0) ||
    Object.values(e.missing).some((n) => n > 0) ||
    e.result_ready_on_server === 0 ||
    r.torn.length > 0 ||
    r.consistent === 0 ||
    history.mismatched.length > 0;
  process.exit(failed ? 1 : 0);
}

main().catch((e) => {
  console.error(`FAILED: ${e && e.stack ? e.stack : e}`);
  process.exit(2);
});
