// camloop dashboard: live refresh over Server-Sent Events, who is signed in, and the writes
// (rollback, acknowledgement, dressing) through the API with the session's CSRF token.
"use strict";

// Every script error and failed request is kept here and shown, so a broken page says so.
const seen = { errors: [], failed: [] };
window.camloopSeen = seen;
window.addEventListener("error", (e) => seen.errors.push(String(e.message || e)));
window.addEventListener("unhandledrejection", (e) => seen.errors.push(String(e.reason)));
if (window.PerformanceObserver) {
  new PerformanceObserver((list) => {
    for (const r of list.getEntries()) {
      if (r.responseStatus >= 400) seen.failed.push(r.responseStatus + " " + r.name);
    }
  }).observe({ type: "resource", buffered: true });
}

const $ = (sel) => document.querySelector(sel);

function notice(text) {
  const n = $("#notice");
  n.textContent = text;
  n.hidden = !text;
}

// The signed-in session: {user, role, csrf}; user null when nobody is signed in.
let session = { user: null, role: null, csrf: null };

async function whoami() {
  try {
    const r = await fetch("/session", { cache: "no-store" });
    if (r.ok) session = await r.json();
  } catch (e) {
    seen.failed.push(String(e));
  }
  const who = $("#who");
  if (!who) return;
  who.textContent = "";
  if (session.user) {
    const form = document.createElement("form");
    form.method = "post";
    form.action = "/signout";
    form.id = "signout";
    const csrf = document.createElement("input");
    csrf.type = "hidden";
    csrf.name = "csrf";
    csrf.value = session.csrf;
    const button = document.createElement("button");
    button.type = "submit";
    button.textContent = "Sign out";
    const name = document.createElement("span");
    name.id = "user";
    name.textContent = session.user + " (" + session.role + ") ";
    form.append(name, csrf, button);
    who.append(form);
    if (session.role === "engineer" || session.role === "admin") {
      const audit = document.createElement("a");
      audit.href = "/audit";
      audit.textContent = "Audit trail";
      who.append(" ", audit);
    }
  } else {
    const a = document.createElement("a");
    a.href = "/signin?next=" + encodeURIComponent(location.pathname);
    a.textContent = "Sign in";
    a.id = "signin-link";
    who.append(a);
  }
}

// Refreshes the live region from its address with fragment=1; one request at a time. A
// refresh that failed says so until one succeeds (a busy store answers 503 now and then).
let busy = false;
let again = false;
let refreshFailed = false;
async function refresh() {
  const live = $("#live");
  if (!live) return;
  if (busy) { again = true; return; }
  busy = true;
  try {
    const url = live.dataset.url + (live.dataset.url.includes("?") ? "&" : "?") + "fragment=1";
    const r = await fetch(url, { cache: "no-store" });
    if (r.ok) {
      live.innerHTML = await r.text();
      if (refreshFailed) { refreshFailed = false; notice(""); }
    } else {
      seen.failed.push(r.status + " " + url);
      refreshFailed = true;
      notice("refresh failed: HTTP " + r.status);
    }
  } catch (e) {
    seen.failed.push(String(e));
  } finally {
    busy = false;
    if (again) { again = false; refresh(); }
  }
}

function listen() {
  const live = $("#live");
  const status = $("#live-status");
  if (!live || !window.EventSource) return;
  const source = new EventSource("/dashboard/events");
  // Parts stored between the page's rendering and the stream's start come with a refresh.
  source.addEventListener("open", () => { status.textContent = "live: connected"; refresh(); });
  source.addEventListener("error", () => { status.textContent = "live: reconnecting"; });
  source.addEventListener("part", (e) => {
    const part = JSON.parse(e.data);
    status.textContent = "live: part #" + part.id + " on " + part.machine + " " + part.lobe;
    const m = live.dataset.machine;
    const l = live.dataset.lobe;
    if (!m || (m === part.machine && l === part.lobe)) refresh();
  });
  window.addEventListener("pagehide", () => source.close());
}

// A write through the API as the signed-in user; answers {ok, message}.
async function write(url, body, what) {
  if (!session.user) {
    return { ok: false, message: what + " refused: sign in first" };
  }
  const r = await fetch(url, {
    method: "POST",
    headers: { "Content-Type": "application/json", "X-CSRF-Token": session.csrf },
    body: JSON.stringify(body),
  });
  let reply = {};
  try { reply = await r.json(); } catch (e) { reply = {}; }
  const message = reply.message || ("HTTP " + r.status);
  return { ok: r.ok, message: r.ok ? message : what + " refused: " + message };
}

function show(id, result) {
  const out = document.getElementById(id);
  const text = result.message;
  if (out) {
    out.textContent = text;
    out.className = result.ok ? "ok" : "refused";
  }
  notice(result.ok ? "" : text);
}

document.addEventListener("click", async (e) => {
  const b = e.target.closest("button.rollback, button.ack");
  if (!b) return;
  b.disabled = true;
  try {
    if (b.classList.contains("rollback")) {
      const v = Number(b.dataset.version);
      show("rollback-result", await write(b.dataset.url, { version: v }, "rollback to v" + v));
    } else {
      show("notice", await write(b.dataset.url, {}, "acknowledgement"));
    }
    await refresh();
  } finally {
    b.disabled = false;
  }
});

document.addEventListener("submit", async (e) => {
  const f = e.target;
  if (f.id !== "dressing") return;
  e.preventDefault();
  const r = Number(f.elements.wheel_radius_mm.value);
  show("dressing-result", await write(f.dataset.url, { wheel_radius_mm: r }, "dressing"));
  await refresh();
});

whoami();
listen();
