// The isac-mission console page: live (WebSocket updates) or replay (`isac-mission view`).
// Everything it draws is also kept in window.consoleState (positions drawn, labels placed, the
// phase shown, latencies measured), for tests and benchmarks.
"use strict";

const $ = (id) => document.getElementById(id);
const S = {
  mode: null, config: null, latest: {}, trails: {}, series: new Map(), replies: [], sent: {},
  console: {}, token: null, dirty: false, chartsDirty: true, runs: [], frame: 1, playing: null,
  trackSeries: new Map(), airborne: {},
  follow: false, insetTrack: "", rxMs: {}, priorityNotes: {},
};
const M = {  // measurements, read by the tests and bench/console.py
  loadStart: performance.timeOrigin, firstMapWallMs: null, drawn: {}, telemetryReceived: 0,
  telemetryDrawn: 0, latenciesMs: [], drawnIds: [], redrawMs: [], frames: 0,
  phase: null, phaseLog: [], map: null, inset: null, charts: {},
};
window.consoleState = { S, M };
let pendingTelemetry = [];
const TRACK_SERIES_SLOTS = 5000;
const CHARTED_TRACKS = 8;
const LEAD_VELOCITY_COLOUR = "#37474f";

// ------------------------------------------------------------------------- the mission's phase

// The phase of a live mission from what the bus says (docs/console.md, "The mission's phase"):
// the world's clock (its mission start and slot), the ground loop's health status and each
// vehicle's telemetry (armed, landed). {phase: "starting" | "take-off" | "running" | "landing" |
// "done", slot: the slot shown, 1..N, or null, stopped: the ground loop stopped before slot N}.
// Running, the slot shown is the one being flown: the clock's slot (the last one ended) + 1.
function missionPhase(c, latest) {
  const N = c && c.N > 0 ? c.N : null;
  const clock = latest.clock, health = latest.health;
  const tel = [];
  for (let m = 0; m < (c ? c.M : 0); m++) { const t = latest["telemetry/" + m]; if (t) tel.push(t); }
  const airborne = tel.some((t) => t.armed && !t.landed);
  const status = health ? health.status : null;
  const started = !!(clock && clock.mission_t0 != null && clock.slot >= 0);
  const clamp = (k) => (N ? Math.min(Math.max(k, 1), N) : Math.max(k, 1));
  if (status === "done" || status === "stopped" || (started && N && clock.slot > N)) {
    const stopped = status === "stopped";
    const slot = stopped ? (health.slot >= 1 ? clamp(health.slot) : null) : N;
    return { phase: airborne ? "landing" : "done", slot, stopped };
  }
  if (started) return { phase: "running", slot: clamp(clock.slot + 1), stopped: false };
  if (airborne || tel.some((t) => t.armed)) return { phase: "take-off", slot: null, stopped: false };
  return { phase: "starting", slot: null, stopped: false };
}

function showPhase(ph) {
  const c = S.config, e = $("phase");
  const word = ph.phase + (ph.stopped ? " (stopped)" : "");
  e.textContent = word; e.dataset.phase = ph.phase; e.className = "badge phase " + ph.phase;
  const slotText = ph.slot == null ? "-" : String(ph.slot);
  $("slot").textContent = slotText; $("slot").dataset.slot = ph.slot == null ? "" : String(ph.slot);
  $("slots-total").textContent = c && c.N ? " / " + c.N : "";
  const last = M.phaseLog[M.phaseLog.length - 1];
  if (!last || last.phase !== ph.phase || last.slot !== slotText || last.stopped !== ph.stopped) {
    M.phaseLog.push({ phase: ph.phase, slot: slotText, stopped: ph.stopped });
  }
  if (M.phaseLog.length > 5000) M.phaseLog.splice(0, 2500);
  M.phase = ph;
}

// ------------------------------------------------------------------------- scene building

// The tracker's cue before the mission starts (config x0 and P0; on a multi-target mission every
// target whose prior is known): where the target is expected, drawn dashed.
function cuesOf(c) {
  if (!c) return [];
  const ellipse = ellipse2sigma(c.P0);
  if (Array.isArray(c.targets) && c.targets.length) {
    return c.targets.map((t, i) => ({ t, i })).filter(({ t }) => t.prior_known && t.first_slot === 0)
      .map(({ t, i }) => ({ xy: t.x0, ellipse, label: "target " + (i + 1) + " cue (before the start)" }));
  }
  return c.x0 ? [{ xy: c.x0, ellipse, label: "target cue (before the start)" }] : [];
}

function targetNames(c) { return c && Array.isArray(c.targets) ? c.targets.map((t) => t.name || "") : []; }

// A vehicle on the ground: landed, or not armed; `landed` once it has flown (else on the ground).
function onGround(t) { return !!t && (t.landed || !t.armed); }

function liveScene(ph) {
  const c = S.config, plan = S.latest.plan;
  const before = ph.phase === "starting" || ph.phase === "take-off";
  const uavs = [];
  for (let m = 0; m < (c ? c.M : 0); m++) {
    const t = S.latest["telemetry/" + m];
    uavs.push({
      m, xy: t ? t.position_xy_m : null, trail: S.trails[m] || [], mode: t ? t.mode : null,
      link: t ? t.link : null, wp: plan ? plan.waypoints_xy_m[m] : null,
      eta: plan ? plan.bandwidth_share[m] : null, bs: plan ? plan.assoc[m] : null,
      landed: onGround(t) && (!!S.airborne[m] || ph.phase === "landing" || ph.phase === "done"),
    });
  }
  // Any number of targets, one way: the tracks (a single target's is track 1) and the targets
  // present at the tracks' slot (the world's next truth may already have arrived).
  const tracks = S.latest.tracks;
  const truths = tracks ? tracks.truths_of_slot || [] : S.latest.truths ? S.latest.truths.present : [];
  return {
    config: c, follow: S.follow, targetNames: targetNames(c),
    layers: [{
      label: "live", colour: colourOf(0), uavs,
      cues: before && !tracks ? cuesOf(c) : [],
      tracks: tracks ? tracks.tracks : [],
      truths,
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
    // a trace's estimate and truth, drawn as a track and a target are (named by the trace)
    // a trace's tracks and targets, drawn as the live page draws them (a single target's is
    // track 1); a frame without them (an older page's data): its estimate and truth
    const est = f && f.target_est && f.target_est[0] != null ? [{ id: 1, confirmed: true, x: f.target_est, ellipse: f.ellipse }] : [];
    return {
      label: run.label, colour: colourOf(i), uavs,
      tracks: f && f.tracks ? f.tracks : est,
      truths: f && f.truths ? f.truths : f && f.target_true ? [{ index: 0, x: f.target_true }] : [],
    };
  });
  M.replayDrawn = layers.map((L) => ({ label: L.label, uavs: L.uavs.map((u) => u.xy) }));
  return { config: S.config, follow: S.follow, replay: true, layers };
}

// What the close-up shows: the chosen track (a replay: each trace's estimate; before the start:
// the cue), its 2-sigma ellipse, the target of its slot it follows (else the nearest one), and
// the vehicles, waypoints and other tracks that fall in the window.
function insetFocus(scene, ph) {
  const L0 = scene.layers[0];
  if (!L0) return null;
  const items = [];
  let centre = null, note = "";
  const chosen = S.mode === "replay" ? null : chooseTrack(L0.tracks);
  if (S.mode === "replay") {
    scene.layers.forEach((L) => {
      const t = L.tracks[0];
      if (!t) return;
      if (!centre) centre = t.x;
      items.push({ kind: "estimate", xy: t.x, ellipse: t.ellipse, colour: scene.layers.length > 1 ? L.colour : ESTIMATE_COLOUR, label: scene.layers.length > 1 ? L.label : "" });
    });
    if (L0.truths.length) items.push({ kind: "truth", xy: L0.truths[0].x, label: "truth" });
  } else if (chosen) {
    // the chosen track, the target it follows (else the nearest present one) and the other
    // tracks where they fall in the window
    centre = chosen.x;
    items.push({ kind: "estimate", xy: chosen.x, ellipse: chosen.ellipse, label: "T" + chosen.id, dashed: !chosen.confirmed });
    for (const t of L0.tracks) if (t !== chosen) items.push({ kind: "estimate", xy: t.x, ellipse: t.ellipse, label: "T" + t.id, dashed: !t.confirmed, far: true });
    const off = (t) => Math.hypot(chosen.x[0] - t.x[0], chosen.x[1] - t.x[1]);
    const followed = L0.truths.find((t) => chosen.target != null && t.index === chosen.target);
    const target = followed || L0.truths.slice().sort((a, b) => off(a) - off(b))[0];
    if (target) items.push({ kind: "truth", xy: target.x, label: targetName(scene, target.index) });
    note = "T" + chosen.id + (!target ? ""
      : followed ? " follows " + targetName(scene, target.index) + ", " + fmtMetres(off(target)) + " off"
        : " follows no target: " + targetName(scene, target.index) + " " + fmtMetres(off(target)) + " off");
  } else if (L0.cues && L0.cues.length) {
    centre = L0.cues[0].xy;
    items.push({ kind: "estimate", xy: centre, ellipse: L0.cues[0].ellipse, label: "cue", dashed: true });
    note = ph.phase + ": the tracker's cue; tracking starts with slot 1";
  }
  if (!centre) return null;
  const e = items[0] && items[0].ellipse;
  if (e) note = "2\u03c3 " + fmtMetres(e.a_m) + " \u00d7 " + fmtMetres(e.b_m) + (note ? " \u00b7 " + note : "");
  let nearest = null;
  for (const L of scene.layers) {
    const colour = (u) => (scene.layers.length > 1 ? L.colour : colourOf(u.m));
    for (const u of L.uavs) {
      if (u.xy && u.xy[0] != null) {
        items.push({ kind: "uav", xy: u.xy, colour: colour(u), label: "U" + u.m });
        const d = Math.hypot(u.xy[0] - centre[0], u.xy[1] - centre[1]);
        if (!nearest || d < nearest.d) nearest = { m: u.m, d };
      }
      if (u.wp) items.push({ kind: "waypoint", xy: u.wp, colour: colour(u) });
    }
  }
  if (nearest) note += (note ? " \u00b7 " : "") + "nearest UAV U" + nearest.m + " " + fmtMetres(nearest.d);
  return { centre, items, note };
}

// The track the close-up follows: the one chosen in the list, else the confirmed one with the
// lowest id, else the first.
function chooseTrack(tracks) {
  if (!tracks || !tracks.length) return null;
  const id = Number(S.insetTrack);
  return tracks.find((t) => S.insetTrack !== "" && t.id === id) || tracks.filter((t) => t.confirmed).sort((a, b) => a.id - b.id)[0] || tracks[0];
}

// ------------------------------------------------------------------------- rendering

function render() {
  S.dirty = false;
  const t0 = performance.now();
  const ph = S.mode === "replay" ? { phase: "replay", slot: S.frame } : missionPhase(S.config, S.latest);
  const scene = S.mode === "replay" ? replayScene() : liveScene(ph);
  M.map = drawMap($("map"), scene);
  M.labels = M.map.labels;
  const box = $("inset-panel"), inset = $("inset");
  const width = Math.max(200, Math.min(560, box.clientWidth - 22));
  if (inset.width !== width) inset.width = width;
  const focus = insetFocus(scene, ph);
  M.inset = drawInset(inset, focus);
  $("inset-note").textContent = focus ? focus.note : "";
  $("map-scale").textContent = M.map.s ? (M.map.follow ? "following the target: " : "whole area: ") + "100 px = " + fmtMetres(100 / M.map.s) : "";
  if (S.mode !== "replay") {  // the tracks and targets, as drawn
    const L = scene.layers[0];
    M.tracksDrawn = L.tracks.map((t) => ({ id: t.id, confirmed: t.confirmed, x: t.x[0], y: t.x[1] }));
    M.truthsDrawn = L.truths.map((t) => ({ index: t.index, x: t.x[0], y: t.x[1] }));
    M.cuesDrawn = (L.cues || []).map((q) => ({ x: q.xy[0], y: q.xy[1], label: q.label }));
    showPhase(ph);
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
  if (replay || t0 - lastPanelsMs >= 250) { renderPanels(ph); lastPanelsMs = t0; } else later();
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

// A plan that is not the one being flown: the last one after the mission, or one more than a
// slot behind the slot being flown (a plan the ground loop did not publish, or one the console
// refused); "" when it is current.
function planAge(plan, ph) {
  if (!plan) return "";
  if (ph.phase === "landing" || ph.phase === "done") return "last plan, slot " + plan.slot;
  if (ph.phase === "running" && ph.slot != null && plan.slot < ph.slot - 1) return "plan of slot " + plan.slot + ", " + (ph.slot - plan.slot) + " slots old";
  return "";
}

// Vehicle m's share and association as the plan says: "no BS" for assoc -1, share 0 as "0".
function planShare(plan, m) {
  if (!plan) return "-";
  const k = plan.assoc[m], eta = plan.bandwidth_share[m];
  return (k < 0 ? "no BS" : "BS" + k) + " \u03b7 " + (eta === 0 ? "0" : fmt(eta, 3));
}

function renderPanels(ph) {
  const c = S.config;
  if (!c) return;
  $("mission").textContent = c.mission_id || "";
  if (S.mode === "replay") return renderReplayPanels();
  const clock = S.latest.clock, plan = S.latest.plan, track = S.latest.track, health = S.latest.health;
  $("method").textContent = c.method || "-";
  $("plan-status").textContent = plan ? plan.status : "-";
  showReason(plan);
  const age = planAge(plan, ph);
  const phaseText = ph.phase === "running" ? "running, slot " + ph.slot + " of " + c.N
    : ph.phase === "landing" || ph.phase === "done"
      ? ph.phase + (ph.stopped ? ", stopped after " + (ph.slot == null ? "no slot" : "slot " + ph.slot) + " of " + c.N : ", after slot " + c.N + " of " + c.N)
      : ph.phase + ", before slot 1";
  rows($("mission-table"), [
    ["phase", phaseText],
    ["plan slot", plan ? String(plan.slot) + (age ? " (" + age + ")" : "") : "-", age ? "stale" : ""],
    [leadName("tr(PCRB)"), track ? fmt(track.pcrb_trace, 4) : "-"],
    ["  position / velocity", track ? fmt(track.pcrb_pos, 4) + " / " + fmt(track.pcrb_vel, 4) : "-"],
    ["plan objective", plan ? fmt(plan.objective, 4) : "-"],
    ["solve time", plan ? fmt(plan.solve_s * 1e3, 1) + " ms" : "-"],
    ["sim time", clock ? fmt(clock.t, 1) + " s (x" + fmt(clock.speed, 1) + ")" : "-"],
    ["service", health ? health.status : "-"],
  ].concat(tracksRows(S.latest.tracks)));
  const veh = health ? health.vehicles || {} : {};
  const vrows = [];
  const nowMs = Date.now();
  for (let m = 0; m < c.M; m++) {
    const t = S.latest["telemetry/" + m];
    const ground = onGround(t);
    const landed = ground && (!!S.airborne[m] || ph.phase === "landing" || ph.phase === "done");
    let state = veh[String(m)] || "-";
    if (landed) state = state.startsWith("excluded") ? "landed \u00b7 " + state : "landed";
    let desc = "no telemetry";
    if (t) {
      const what = ground ? (landed ? "landed" : "on the ground") + (t.armed ? ", armed" : ", disarmed") : t.mode;
      desc = `${what}, link ${t.link}${t.override && !ground ? ", " + t.override : ""}`;
      const quiet = (nowMs - (S.rxMs["telemetry/" + m] || nowMs)) / 1000;
      if (quiet > 5) desc += `, no telemetry for ${quiet.toFixed(0)} s`;
    }
    const share = planShare(plan, m) + (age ? " (" + age + ")" : "");
    vrows.push(["U" + m + " " + desc, `${share} \u00b7 ${state}`, state.startsWith("excluded") || state.includes("excluded") ? "reason" : age ? "stale" : ""]);
  }
  rows($("vehicles"), vrows);
  const counters = health ? Object.entries(health.counters).sort() : [];
  const cons = S.console || {};
  const extra = [["console pages", String(cons.pages ?? "-")], ["console bus", cons.status || "-"]];
  for (const [k, v] of Object.entries(cons.rejected || {})) extra.push(["console rejected " + k, String(v)]);
  rows($("health"), counters.map(([k, v]) => [k, String(v)]).concat(extra, health && health.last_error ? [["last error", health.last_error]] : []));
  renderInsetChoice();
  renderTracksTable();
}

// The ground loop's lead track (its `track` message: tr(PCRB) and its parts) is named so when it
// is one of several tracks.
function leadName(text) {
  const tracks = S.latest.tracks;
  return tracks && tracks.tracks.length > 1 ? text + " (lead track)" : text;
}

// The tracks (how many of each kind) and, once the slot's truth is known, each present target
// (1-based, in the scenario's order) with the track that follows it (the nearest confirmed track
// within the follow gate) and its distance to the nearest confirmed track.
function tracksRows(tracks) {
  if (!tracks) return [];
  const confirmed = tracks.tracks.filter((t) => t.confirmed);
  const out = [
    ["tracks (slot " + tracks.slot + ")", confirmed.length + " confirmed, " + (tracks.tracks.length - confirmed.length) + " tentative"],
    ["  confirmed ids", confirmed.length ? confirmed.map((t) => "T" + t.id).join(" ") : "-"],
  ];
  const scene = { targetNames: targetNames(S.config) };
  for (const e of tracks.target_errors || []) {
    const follower = confirmed.find((t) => t.target === e.index);
    const value = follower ? "T" + follower.id + ", " + fmt(e.error_m, 2) + " m"
      : e.error_m == null ? "no confirmed track"
        : "no track within " + fmt(tracks.follow_gate_m, 0) + " m (nearest " + fmt(e.error_m, 1) + " m)";
    out.push([targetName(scene, e.index), value]);
  }
  return out;
}

function renderInsetChoice() {
  const sel = $("inset-track"), tracks = S.latest.tracks;
  sel.hidden = !tracks || (tracks.tracks.length < 2 && S.insetTrack === "");  // a choice of one: none
  if (!tracks) return;
  const want = ["", ...tracks.tracks.map((t) => String(t.id))];
  const have = [...sel.options].map((o) => o.value);
  if (want.join(",") === have.join(",")) return;
  const keep = S.insetTrack;
  sel.replaceChildren(...want.map((v) => {
    const o = document.createElement("option"); o.value = v;
    o.textContent = v === "" ? "close-up: lowest confirmed track" : "close-up: T" + v;
    return o;
  }));
  sel.value = want.includes(keep) ? keep : "";
}

function showReason(plan) {
  const e = $("reason");
  e.textContent = plan && plan.reason ? plan.status + ": " + plan.reason : "";
  e.className = plan && plan.status !== "ok" ? "reason" : "reason ok";
}

function renderReplayPanels() {
  const rowsOut = [];
  $("slot").textContent = String(S.frame); $("slot").dataset.slot = String(S.frame);
  $("slots-total").textContent = " / " + $("slider").max;
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
  renderTracksTable();
}

function seriesPoints(key) {
  const out = [];
  for (const [n, p] of [...S.series.entries()].sort((a, b) => a[0] - b[0])) out.push([n, p[key]]);
  return out;
}

// Per confirmed track (the CHARTED_TRACKS seen last), its `pcrb` or `error` series.
function trackSeries(kind) {
  const slots = [...S.trackSeries.keys()].sort((a, b) => a - b);
  const lastSeen = new Map();
  for (const n of slots) for (const k of Object.keys(S.trackSeries.get(n))) if (k.startsWith("pcrb/") || k.startsWith("error/")) lastSeen.set(Number(k.split("/")[1]), n);
  const ids = [...lastSeen.entries()].sort((a, b) => b[1] - a[1] || a[0] - b[0]).slice(0, CHARTED_TRACKS).map(([id]) => id).sort((a, b) => a - b);
  return ids.map((id) => ({
    label: "T" + id, colour: colourOf(id - 1),
    points: slots.map((n) => [n, S.trackSeries.get(n)[kind + "/" + id]]),
  }));
}

function renderCharts() {
  if (S.mode === "replay") {
    const per = (key) => S.runs.map((r, i) => ({ label: r.label, colour: colourOf(i), points: r.frames.map((f) => [f.slot, f[key]]) }));
    $("caption-pcrb").textContent = "tr(PCRB) per trace (m\u00b2 + m\u00b2/s\u00b2), log scale";
    $("caption-error").textContent = "per trace: position error (m)";
    M.charts.pcrb = drawChart($("chart-pcrb"), per("pcrb_trace"), { log: true, cursor: S.frame });
    M.charts.error = drawChart($("chart-error"), per("error_m"), { cursor: S.frame });
    M.charts.time = drawChart($("chart-time"), per("solve_ms"), { cursor: S.frame });
    return;
  }
  // One line per confirmed track (a single target's is T1): its position bound and its error;
  // with the lead track's velocity bound (its `track` message), dashed, when the ground sends it.
  const bounds = trackSeries("pcrb");
  const velocity = seriesPoints("pcrb_vel");
  const withVelocity = velocity.some(([, v]) => v != null && isFinite(v));
  if (withVelocity) bounds.push({ label: "lead track velocity (m\u00b2/s\u00b2)", colour: LEAD_VELOCITY_COLOUR, dashed: true, points: velocity });
  $("caption-pcrb").textContent = "position bound per confirmed track (m\u00b2)" + (withVelocity ? ", lead track's velocity bound dashed (m\u00b2/s\u00b2)" : "") + ", log scale";
  M.charts.pcrb = drawChart($("chart-pcrb"), bounds, { log: true, empty: "no confirmed track yet" });
  $("caption-error").textContent = "per confirmed track: distance to the nearest target (m)";
  M.charts.error = drawChart($("chart-error"), trackSeries("error"), { empty: S.latest.truths ? "no confirmed track yet" : "no truth from the world" });
  M.charts.time = drawChart($("chart-time"), [
    { label: "solve", colour: "#6a1b9a", points: seriesPoints("solve_ms") },
    { label: "detection to plan", colour: "#ef6c00", points: seriesPoints("det_to_plan_ms") },
  ]);
}

// ------------------------------------------------------------------------- tracks and priorities

// The tracks table: per track its id, state and priority (its weight in the planner's objective,
// 0 to 10, as the ground loop's latest `track`/`track_set` says; 1 by default). Live, each row
// has an input that sends the `priority` command and, under it, that request's fate (sent,
// accepted with what was done, refused and why). A replay shows the first trace's tracks at the
// slot shown, read-only. Rows are updated in place, so that a value being typed survives the
// updates. `M.tracksTable` lists the rows shown.
function tracksShown() {
  if (S.mode === "replay") {
    const run = S.runs[0], f = run ? run.frames[S.frame - 1] : null;
    return f && f.tracks ? f.tracks : [];
  }
  return S.latest.tracks ? S.latest.tracks.tracks : [];
}

function fmtPriority(p) { return p == null || !isFinite(p) ? "1" : String(Number(p)); }

function readOnlyPage() { return !!(S.console && S.console.secured && !S.token); }

function trackRow(id, live) {
  const tr = document.createElement("tr");
  tr.dataset.track = String(id);
  const name = document.createElement("td"); name.className = "track";
  const prio = document.createElement("td"); prio.className = "num prio";
  tr.append(name, prio);
  if (live) {
    const cell = document.createElement("td"); cell.className = "set";
    const input = document.createElement("input");
    input.type = "text"; input.inputMode = "decimal"; input.size = 4; input.className = "prio-input";
    input.placeholder = "0\u201310"; input.setAttribute("aria-label", "priority of T" + id);
    const button = document.createElement("button");
    button.type = "button"; button.className = "prio-set"; button.textContent = "set";
    const note = document.createElement("div"); note.className = "prio-note";
    button.addEventListener("click", () => setPriority(id, input));
    input.addEventListener("keydown", (ev) => { if (ev.key === "Enter") { ev.preventDefault(); setPriority(id, input); } });
    cell.append(input, button, note);
    tr.append(cell);
  }
  return tr;
}

// The fate of the latest priority request for track `id`: [text, kind] ("" when none).
function priorityNote(id) {
  const note = S.priorityNotes[id];
  if (!note) return ["", ""];
  if (!note.sentId) return [note.text, "error"];
  const r = S.replies.find((x) => x.id === note.sentId);
  if (!r) return ["sent " + note.weight + " (" + note.sentId + "), waiting for the ground loop's reply", "pending"];
  return r.accepted ? ["accepted: " + (r.effect || r.reason), "accepted"] : ["refused: " + r.reason, "refused"];
}

function renderTracksTable() {
  const table = $("tracks-table"), live = S.mode === "live";
  const tracks = tracksShown().slice().sort((a, b) => a.id - b.id);
  const ids = tracks.map((t) => String(t.id));
  for (const tr of [...table.children]) if (!tr.dataset.track || !ids.includes(tr.dataset.track) || (tr.querySelector("input") !== null) !== live) tr.remove();
  const rowsNow = new Map([...table.children].map((tr) => [tr.dataset.track, tr]));
  tracks.forEach((t, i) => {
    const id = String(t.id);
    const tr = rowsNow.get(id) || trackRow(t.id, live);
    if (table.children[i] !== tr) table.insertBefore(tr, table.children[i] || null);
    const name = "T" + t.id + (t.confirmed ? "" : " (tentative)");
    if (tr.cells[0].textContent !== name) tr.cells[0].textContent = name;
    const prio = fmtPriority(t.priority);
    if (tr.cells[1].textContent !== prio) { tr.cells[1].textContent = prio; tr.dataset.priority = prio; }
    if (live) {
      const ro = readOnlyPage();
      for (const e of tr.cells[2].querySelectorAll("input, button")) e.disabled = ro;
      const [text, kind] = priorityNote(id);
      const note = tr.querySelector(".prio-note");
      if (note.textContent !== text) note.textContent = text;
      note.className = "prio-note" + (kind ? " " + kind : "");
      tr.dataset.state = kind;
    }
  });
  const run = S.runs[0];
  $("tracks-note").textContent = !tracks.length ? "no track yet"
    : S.mode === "replay" ? "priority (read-only) of " + (run ? run.label : "the trace") + "'s tracks at slot " + S.frame
      : readOnlyPage() ? "priority, 0 to 10 (0: not planned for, still kept clear of); read-only until you log in"
        : "priority, 0 to 10 (0: not planned for, still kept clear of; 1 by default)";
  M.tracksTable = tracks.map((t) => ({ id: t.id, confirmed: t.confirmed, priority: fmtPriority(t.priority) }));
}

async function setPriority(id, input) {
  const text = input.value.trim();
  const w = Number(text);
  if (text === "" || !isFinite(w)) {
    S.priorityNotes[id] = { text: `priority of T${id}: ${JSON.stringify(text)} is not a number (nothing sent)` };
    renderTracksTable();
    return;
  }
  const r = await command({ command: "priority", track: id, params: { weight: w } });
  S.priorityNotes[id] = r.id ? { sentId: r.id, weight: w } : { text: r.error };
  if (r.id) input.value = "";
  renderTracksTable();
}

// ------------------------------------------------------------------------- live updates

function applySnapshot(d) {
  S.mode = d.mode; S.config = d.config; S.latest = d.latest || {}; S.trails = {};
  for (const [m, t] of Object.entries(d.trails || {})) S.trails[m] = t;
  S.series = new Map((d.series || []).map((p) => [p.slot, p]));
  S.replies = d.replies || []; S.console = d.console || {};
  S.trackSeries = new Map((d.track_series || []).map((p) => [p.slot, p]));
  for (const [topic, data] of Object.entries(S.latest)) {
    if (topic.startsWith("telemetry/") && data.armed && !data.landed) S.airborne[data.uav] = true;
  }
  renderReplies(); showRole();
  S.chartsDirty = true;
}

function apply(u) {
  const { topic, data } = u;
  if (topic === "snapshot") return applySnapshot(data);
  if (topic.startsWith("telemetry/")) {
    M.telemetryReceived++;
    S.rxMs[topic] = Date.now();
    if (data.armed && !data.landed) S.airborne[data.uav] = true;
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
    keepBySlot(topic, data);
  }
}

// The per-track series (the charts), from the tracks as they arrive (the snapshot brings the
// history); a slot's row replaces the one kept.
function keepBySlot(topic, data) {
  if (topic === "tracks") {
    for (const row of data.series_rows || []) bounded(S.trackSeries, row.slot, row, TRACK_SERIES_SLOTS);
    S.chartsDirty = true;
  }
}

function bounded(map, slot, value, keep) {
  map.set(slot, value);
  if (map.size > keep) for (const k of [...map.keys()].sort((a, b) => a - b).slice(0, map.size - keep)) map.delete(k);
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
  r.hidden = !live;  // a replay says so once, in the link badge
  $("phase").hidden = !live;
  if (!live) return;
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
    const what = s.request.command + (s.request.uav != null ? " U" + s.request.uav : "") + (s.request.track != null ? " T" + s.request.track : "") + (s.request.params ? " " + JSON.stringify(s.request.params) : "");
    if (r) {
      li.className = r.accepted ? "accepted" : "refused";
      li.textContent = `${what}: ${r.accepted ? "accepted" : "refused"} \u2014 ${r.reason || ""}${r.effect ? " \u2014 " + r.effect : ""}`;
    } else li.textContent = `${what}: sent (${s.id}), waiting for the ground loop's reply`;
    li.dataset.id = s.id; li.dataset.state = r ? (r.accepted ? "accepted" : "refused") : "pending";
    items.push(li);
  }
  ol.replaceChildren(...items);
  if (S.mode === "live") renderTracksTable();
}

async function post(path, body) {
  const headers = { "Content-Type": "application/json" };
  if (S.token) headers["X-Console-Token"] = S.token;
  const res = await fetch(path, { method: "POST", headers, body: JSON.stringify(body) });
  let data = {};
  try { data = await res.json(); } catch (e) { data = { error: "response: not JSON (HTTP " + res.status + ")" }; }
  return { ok: res.ok, status: res.status, data };
}

// Send a fleet command; {id} once sent, else {error: why nothing was sent}.
async function command(body) {
  if (S.console && S.console.secured && !S.token) {
    const error = "read-only: log in with the operator password to send commands (nothing sent)";
    say(error, "error");
    return { error };
  }
  const r = await post("/api/control", body);
  if (!r.ok) {
    const error = `refused (HTTP ${r.status}): ${r.data.error}; nothing sent`;
    say(error, "error");
    return { error };
  }
  S.sent[r.data.id] = r.data; renderReplies();
  say(`sent ${body.command} (${r.data.id})`, "info");
  return { id: r.data.id };
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

function wireView() {
  $("follow").addEventListener("change", () => { S.follow = $("follow").checked; S.chartsDirty = true; schedule(); });
  $("inset-track").addEventListener("change", () => { S.insetTrack = $("inset-track").value; schedule(); });
}

async function main() {
  wireControls();
  wireView();
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
