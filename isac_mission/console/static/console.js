// The isac-mission console page: live (WebSocket updates) or replay (`isac-mission view`).
// Everything it draws is also kept in window.consoleState (positions drawn, latencies measured),
// for tests and benchmarks.
"use strict";

const $ = (id) => document.getElementById(id);
const S = {
  mode: null, config: null, latest: {}, trails: {}, series: new Map(), replies: [], sent: {},
  console: {}, token: null, dirty: false, chartsDirty: true, runs: [], frame: 1, playing: null,
};
const M = {  // measurements, read by the tests and bench/console.py
  loadStart: performance.timeOrigin, firstMapWallMs: null, drawn: {}, telemetryReceived: 0,
  telemetryDrawn: 0, latenciesMs: [], drawnIds: [], redrawMs: [], frames: 0,
};
window.consoleState = { S, M };
let pendingTelemetry = [];

// ------------------------------------------------------------------------- scene building

function liveScene() {
  const c = S.config, plan = S.latest.plan, track = S.latest.track, truth = S.latest.truth;
  const uavs = [];
  for (let m = 0; m < (c ? c.M : 0); m++) {
    const t = S.latest["telemetry/" + m];
    uavs.push({
      m, xy: t ? t.position_xy_m : null, trail: S.trails[m] || [], mode: t ? t.mode : null,
      link: t ? t.link : null, wp: plan ? plan.waypoints_xy_m[m] : null,
      eta: plan ? plan.bandwidth_share[m] : null, bs: plan ? plan.assoc[m] : null,
    });
  }
  return {
    config: c,
    layers: [{
      label: "live", colour: colourOf(0), uavs,
      target: track ? { xy: track.x, ellipse: track.ellipse } : null,
      truth: truth ? truth.target_x : null,
      tracks: S.latest.tracks ? S.latest.tracks.tracks : undefined,
      truths: S.latest.truths ? S.latest.truths.present : undefined,
    }],
  };
}

function replayScene() {
  const layers = S.runs.map((run, i) => {
    const k = Math.min(S.frame, run.frames.length) - 1;
    const f = k >= 0 ? run.frames[k] : null;
    const uavs = [];
    for (let m = 0; f && m < run.config.M; m++) {
      const trail = [];
      for (let j = 0; j <= k; j++) trail.push(run.frames[j].uav_xy[m]);
      uavs.push({ m, xy: f.uav_xy[m], trail, wp: f.plan_xy ? f.plan_xy[m] : null, eta: f.eta[m], bs: f.assoc[m], mode: null, link: null });
    }
    return {
      label: run.label, colour: colourOf(i), uavs,
      target: f ? { xy: f.target_est, ellipse: f.ellipse } : null, truth: f ? f.target_true : null,
    };
  });
  M.replayDrawn = layers.map((L) => ({ label: L.label, uavs: L.uavs.map((u) => u.xy) }));
  return { config: S.config, layers };
}

// ------------------------------------------------------------------------- rendering

function render() {
  S.dirty = false;
  const t0 = performance.now();
  const scene = S.mode === "replay" ? replayScene() : liveScene();
  drawMap($("map"), scene);
  if (S.mode !== "replay") {  // a multi-target mission's tracks and targets, as drawn
    const L = scene.layers[0];
    M.tracksDrawn = (L.tracks || []).map((t) => ({ id: t.id, confirmed: t.confirmed, x: t.x[0], y: t.x[1] }));
    M.truthsDrawn = (L.truths || []).map((t) => ({ index: t.index, x: t.x[0], y: t.x[1] }));
  }
  const now = Date.now();
  if (M.firstMapWallMs === null && S.config) M.firstMapWallMs = now;
  for (const t of pendingTelemetry) {
    M.drawn[t.uav] = { x: t.position_xy_m[0], y: t.position_xy_m[1], slot: t.slot, t: t.t, published_wall_s: t.published_wall_s, drawn_wall_ms: now };
    if (t.superseded) continue;
    M.telemetryDrawn++;
    if (t.published_wall_s != null) {
      M.latenciesMs.push(now - 1000 * t.published_wall_s);
      M.drawnIds.push([t.uav, t.published_wall_s]);
      if (M.latenciesMs.length > 20000) { M.latenciesMs.splice(0, 10000); M.drawnIds.splice(0, 10000); }
    }
  }
  pendingTelemetry = [];
  // The map every frame; the tables at most 4 times and the charts once a second (live), so
  // that a busy mission costs the browser little; a trailing frame shows the final state.
  const replay = S.mode === "replay";
  if (replay || t0 - lastPanelsMs >= 250) { renderPanels(); lastPanelsMs = t0; } else later();
  if (S.chartsDirty) {
    if (replay || t0 - lastChartsMs >= 1000) { renderCharts(); S.chartsDirty = false; lastChartsMs = t0; } else later();
  }
  M.frames++;
  return performance.now() - t0;
}

let lastPanelsMs = -1e9, lastChartsMs = -1e9, tail = null;
function later() {
  if (tail === null) tail = setTimeout(() => { tail = null; lastPanelsMs = -1e9; schedule(); }, 300);
}

function schedule() {
  if (S.dirty) return;
  S.dirty = true;
  requestAnimationFrame(render);
}

function fmt(v, d) { return v == null || !isFinite(v) ? "-" : Number(v).toFixed(d); }

function rows(table, pairs) {
  table.replaceChildren(...pairs.map(([k, v, cls]) => {
    const tr = document.createElement("tr");
    const a = document.createElement("td"); a.textContent = k;
    const b = document.createElement("td"); b.textContent = v; b.className = "num" + (cls ? " " + cls : "");
    tr.append(a, b); return tr;
  }));
}

function renderPanels() {
  const c = S.config;
  if (!c) return;
  $("mission").textContent = c.mission_id || "";
  if (S.mode === "replay") return renderReplayPanels();
  const clock = S.latest.clock, plan = S.latest.plan, track = S.latest.track, health = S.latest.health;
  const slot = clock ? clock.slot : health ? health.slot : null;
  $("slot").textContent = slot == null ? "-" : String(slot);
  $("slot").dataset.slot = slot == null ? "" : String(slot);
  $("slots-total").textContent = c.N ? " / " + c.N : "";
  $("method").textContent = c.method || "-";
  $("plan-status").textContent = plan ? plan.status : "-";
  showReason(plan);
  rows($("mission-table"), [
    ["plan slot", plan ? String(plan.slot) : "-"],
    ["tr(PCRB)", track ? fmt(track.pcrb_trace, 4) : "-"],
    ["  position / velocity", track ? fmt(track.pcrb_pos, 4) + " / " + fmt(track.pcrb_vel, 4) : "-"],
    ["plan objective", plan ? fmt(plan.objective, 4) : "-"],
    ["solve time", plan ? fmt(plan.solve_s * 1e3, 1) + " ms" : "-"],
    ["sim time", clock ? fmt(clock.t, 1) + " s (x" + fmt(clock.speed, 1) + ")" : "-"],
    ["service", health ? health.status : "-"],
  ].concat(severalTargetsRows(S.latest.tracks)));
  const veh = health ? health.vehicles || {} : {};
  const vrows = [];
  for (let m = 0; m < c.M; m++) {
    const t = S.latest["telemetry/" + m];
    const state = veh[String(m)] || "-";
    const share = plan ? fmt(plan.bandwidth_share[m], 3) : "-";
    const bs = plan ? (plan.assoc[m] < 0 ? "none" : "BS" + plan.assoc[m]) : "-";
    const desc = t ? `${t.mode}, link ${t.link}${t.override ? ", " + t.override : ""}` : "no telemetry";
    vrows.push(["U" + m + " " + desc, `${bs} \u03b7 ${share} \u00b7 ${state}`, state.startsWith("excluded") ? "reason" : ""]);
  }
  rows($("vehicles"), vrows);
  const counters = health ? Object.entries(health.counters).sort() : [];
  const cons = S.console || {};
  const extra = [["console pages", String(cons.pages ?? "-")], ["console bus", cons.status || "-"]];
  for (const [k, v] of Object.entries(cons.rejected || {})) extra.push(["console rejected " + k, String(v)]);
  rows($("health"), counters.map(([k, v]) => [k, String(v)]).concat(extra, health && health.last_error ? [["last error", health.last_error]] : []));
}

// A multi-target mission's tracks (how many of each kind) and, once the slot's truth is known,
// each present target's distance to the nearest confirmed track; nothing on a single-target one.
function severalTargetsRows(tracks) {
  if (!tracks) return [];
  const confirmed = tracks.tracks.filter((t) => t.confirmed);
  const out = [
    ["tracks (slot " + tracks.slot + ")", confirmed.length + " confirmed, " + (tracks.tracks.length - confirmed.length) + " tentative"],
    ["  confirmed ids", confirmed.length ? confirmed.map((t) => "T" + t.id).join(" ") : "-"],
  ];
  for (const e of tracks.target_errors || []) {
    out.push(["target t" + e.index + " error", e.error_m == null ? "no confirmed track" : fmt(e.error_m, 2) + " m"]);
  }
  return out;
}

function showReason(plan) {
  const e = $("reason");
  e.textContent = plan && plan.reason ? plan.status + ": " + plan.reason : "";
  e.className = plan && plan.status !== "ok" ? "reason" : "reason ok";
}

function renderReplayPanels() {
  const rowsOut = [];
  $("slot").textContent = String(S.frame); $("slot").dataset.slot = String(S.frame);
  $("replay-slot").textContent = "slot " + S.frame + " / " + $("slider").max;
  $("method").textContent = S.runs.map((r) => r.label).join(", ");
  const first = S.runs[0] && S.runs[0].frames[S.frame - 1];
  $("plan-status").textContent = first ? first.status : "-";
  showReason(first);
  for (const panel of ["vehicles", "health"]) $(panel).closest(".panel").hidden = true;
  for (const run of S.runs) {
    const f = run.frames[S.frame - 1];
    if (!f) continue;
    rowsOut.push([run.label + " tr(PCRB)", fmt(f.pcrb_trace, 4)]);
    rowsOut.push([run.label + " error", fmt(f.error_m, 2) + " m"]);
    rowsOut.push([run.label + " status", f.status + (f.excluded && f.excluded.length ? ", excluded " + f.excluded.join(",") : "")]);
    rowsOut.push([run.label + " shares", f.eta.map((e) => e.toFixed(2)).join(" ")]);
  }
  rows($("mission-table"), rowsOut);
}

function seriesPoints(key) {
  const out = [];
  for (const [n, p] of [...S.series.entries()].sort((a, b) => a[0] - b[0])) out.push([n, p[key]]);
  return out;
}

function renderCharts() {
  if (S.mode === "replay") {
    const per = (key) => S.runs.map((r, i) => ({ label: r.label, colour: colourOf(i), points: r.frames.map((f) => [f.slot, f[key]]) }));
    drawChart($("chart-pcrb"), per("pcrb_trace"), { log: true, cursor: S.frame });
    drawChart($("chart-error"), per("error_m"), { cursor: S.frame });
    drawChart($("chart-time"), per("solve_ms"), { cursor: S.frame });
    return;
  }
  drawChart($("chart-pcrb"), [
    { label: "position", colour: "#1565c0", points: seriesPoints("pcrb_pos") },
    { label: "velocity", colour: "#c62828", points: seriesPoints("pcrb_vel") },
  ], { log: true });
  drawChart($("chart-error"), [{ label: "|estimate - truth|", colour: "#2e7d32", points: seriesPoints("error_m") }]);
  drawChart($("chart-time"), [
    { label: "solve", colour: "#6a1b9a", points: seriesPoints("solve_ms") },
    { label: "detection to plan", colour: "#ef6c00", points: seriesPoints("det_to_plan_ms") },
  ]);
}

// ------------------------------------------------------------------------- live updates

function applySnapshot(d) {
  S.mode = d.mode; S.config = d.config; S.latest = d.latest || {}; S.trails = {};
  for (const [m, t] of Object.entries(d.trails || {})) S.trails[m] = t;
  S.series = new Map((d.series || []).map((p) => [p.slot, p]));
  S.replies = d.replies || []; S.console = d.console || {};
  renderReplies(); showRole();
  S.chartsDirty = true;
}

function apply(u) {
  const { topic, data } = u;
  if (topic === "snapshot") return applySnapshot(data);
  if (topic.startsWith("telemetry/")) {
    M.telemetryReceived++;
    for (const p of pendingTelemetry) if (p.uav === data.uav) p.superseded = true;
    pendingTelemetry.push(data);
    S.latest[topic] = data;
    const tr = (S.trails[data.uav] = S.trails[data.uav] || []);
    const last = tr[tr.length - 1], xy = data.position_xy_m;
    if (!last || Math.abs(last[0] - xy[0]) + Math.abs(last[1] - xy[1]) >= 0.5) tr.push(xy);
    if (tr.length > 3000) tr.splice(0, tr.length - 3000);
  } else if (topic === "series") {
    S.series.set(data.slot, Object.assign(S.series.get(data.slot) || {}, data));
    S.chartsDirty = true;
  } else if (topic === "reply") {
    S.replies.push(data); renderReplies();
  } else if (topic === "notice") {
    if (data.sent) S.sent[data.sent.id] = data.sent;
    renderReplies();
  } else if (topic === "console") {
    S.console = data; showRole();
  } else {
    S.latest[topic] = data;
  }
}

function connect() {
  const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws");
  ws.onopen = () => { $("link").textContent = "live"; $("link").className = "badge ok"; };
  ws.onmessage = (ev) => { for (const u of JSON.parse(ev.data)) apply(u); schedule(); };
  ws.onclose = () => {
    $("link").textContent = "disconnected: retrying"; $("link").className = "badge bad";
    setTimeout(connect, 1000);
  };
}

// ------------------------------------------------------------------------- operator controls

function say(text, kind) { const e = $("control-msg"); e.textContent = text; e.className = "msg " + kind; }

function showRole() {
  const secured = !!(S.console && S.console.secured);
  const live = S.mode === "live";
  $("controls").hidden = !live;
  $("login-form").hidden = !secured || !!S.token;
  const r = $("role");
  if (!live) { r.textContent = "replay"; r.className = "badge"; return; }
  if (!secured) { r.textContent = "operator (security off)"; r.className = "badge ok"; }
  else if (S.token) { r.textContent = "operator"; r.className = "badge ok"; }
  else { r.textContent = "read-only"; r.className = "badge ro"; }
}

function renderReplies() {
  const ol = $("replies");
  const byId = new Map(S.replies.map((r) => [r.id, r]));
  const items = [];
  for (const s of Object.values(S.sent).slice(-20).reverse()) {
    const li = document.createElement("li");
    const r = byId.get(s.id);
    const what = s.request.command + (s.request.uav != null ? " U" + s.request.uav : "") + (s.request.params ? " " + JSON.stringify(s.request.params) : "");
    if (r) {
      li.className = r.accepted ? "accepted" : "refused";
      li.textContent = `${what}: ${r.accepted ? "accepted" : "refused"} \u2014 ${r.reason || ""}${r.effect ? " \u2014 " + r.effect : ""}`;
    } else li.textContent = `${what}: sent (${s.id}), waiting for the ground loop's reply`;
    li.dataset.id = s.id; li.dataset.state = r ? (r.accepted ? "accepted" : "refused") : "pending";
    items.push(li);
  }
  ol.replaceChildren(...items);
}

async function post(path, body) {
  const headers = { "Content-Type": "application/json" };
  if (S.token) headers["X-Console-Token"] = S.token;
  const res = await fetch(path, { method: "POST", headers, body: JSON.stringify(body) });
  let data = {};
  try { data = await res.json(); } catch (e) { data = { error: "response: not JSON (HTTP " + res.status + ")" }; }
  return { ok: res.ok, status: res.status, data };
}

async function command(body) {
  if (S.console && S.console.secured && !S.token) {
    say("read-only: log in with the operator password to send commands (nothing sent)", "error");
    return;
  }
  const r = await post("/api/control", body);
  if (!r.ok) { say(`refused (HTTP ${r.status}): ${r.data.error}; nothing sent`, "error"); return; }
  S.sent[r.data.id] = r.data; renderReplies();
  say(`sent ${body.command} (${r.data.id})`, "info");
}

function wireControls() {
  $("rth-form").addEventListener("submit", (ev) => {
    ev.preventDefault();
    const text = $("rth").value.trim();
    const v = Number(text);
    if (text === "" || !isFinite(v)) { say(`R_th: ${JSON.stringify(text)} is not a number (nothing sent)`, "error"); return; }
    command({ command: "set", params: { rate_min_mbps: v } });
  });
  for (const b of document.querySelectorAll("button[data-command]")) {
    b.addEventListener("click", () => {
      const sel = $("uav-select").value;
      const body = { command: b.dataset.command };
      if (sel !== "") body.uav = Number(sel);
      command(body);
    });
  }
  $("login-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const r = await post("/api/login", { password: $("password").value });
    $("password").value = "";
    if (!r.ok) { say(`login refused (HTTP ${r.status}): ${r.data.error}`, "error"); return; }
    S.token = r.data.token; showRole(); say("logged in as operator", "info");
  });
}

// ------------------------------------------------------------------------- replay

function showFrame(n) {
  const t0 = performance.now();
  S.frame = n; $("slider").value = String(n);
  S.chartsDirty = true;
  render();
  M.redrawMs.push(performance.now() - t0);
}

function startReplay(data) {
  S.runs = data.runs; S.config = data.runs[0].config;
  const n = Math.max(...data.runs.map((r) => r.frames.length));
  $("replay-bar").hidden = false; $("slider").max = String(Math.max(n, 1));
  $("legend").replaceChildren(...data.runs.map((r, i) => {
    const s = document.createElement("span");
    s.innerHTML = `<span class="swatch" style="background:${colourOf(i)}"></span>`;
    s.append(r.label); return s;
  }));
  $("slider").addEventListener("input", () => showFrame(Number($("slider").value)));
  $("play").addEventListener("click", () => {
    if (S.playing) { clearInterval(S.playing); S.playing = null; $("play").textContent = "play"; return; }
    $("play").textContent = "pause";
    S.playing = setInterval(() => {
      if (S.frame >= n) { clearInterval(S.playing); S.playing = null; $("play").textContent = "play"; return; }
      showFrame(S.frame + 1);
    }, 250);
  });
  showFrame(1);
}

async function main() {
  wireControls();
  const snap = await (await fetch("/api/snapshot")).json();
  applySnapshot(snap);
  if (snap.mode === "replay") {
    $("link").textContent = "replay"; $("link").className = "badge";
    startReplay(await (await fetch("/api/replay")).json());
    return;
  }
  for (let m = 0; m < S.config.M; m++) {
    const o = document.createElement("option"); o.value = String(m); o.textContent = "U" + m; $("uav-select").append(o);
  }
  render();
  connect();
}

main();
