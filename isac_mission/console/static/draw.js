// Drawing for the isac-mission console: the map of the operating area, the target close-up
// (inset) and the time-series charts, on plain 2-D canvases (no library). Scenario plane: x east,
// y north, metres; canvas: pixels, y down.
"use strict";

const PALETTE = ["#1565c0", "#c62828", "#2e7d32", "#6a1b9a", "#ef6c00", "#00838f", "#4e342e", "#ad1457"];
const ESTIMATE_COLOUR = "#d84315";
const LABEL_FONT = "11px system-ui";

function colourOf(i) { return PALETTE[((i % PALETTE.length) + PALETTE.length) % PALETTE.length]; }

// ------------------------------------------------------------------------- geometry

// The 2-sigma ellipse of the position block of a 4 x 4 covariance (m^2): semi-axes a_m >= b_m
// (m) and the major axis's angle from +x toward +y (rad); null when not finite / not PSD.
function ellipse2sigma(P) {
  if (!P) return null;
  const a = P[0][0], b = 0.5 * (P[0][1] + P[1][0]), d = P[1][1];
  if (![a, b, d].every(isFinite)) return null;
  const mid = 0.5 * (a + d), rad = Math.hypot(0.5 * (a - d), b);
  const hi = mid + rad, lo = mid - rad;
  if (lo < -1e-9 * Math.max(1, Math.abs(hi))) return null;
  return { a_m: 2 * Math.sqrt(Math.max(hi, 0)), b_m: 2 * Math.sqrt(Math.max(lo, 0)), angle_rad: 0.5 * Math.atan2(2 * b, a - d) };
}

// A box [x0, x1] x [y0, y1] (m) holding every point, padded by `padFrac` of its span and at
// least `minSpan` m across in each direction.
function fitBox(points, padFrac, minSpan) {
  const xs = [], ys = [];
  for (const p of points) if (p && Number.isFinite(p[0]) && Number.isFinite(p[1])) { xs.push(p[0]); ys.push(p[1]); }
  if (!xs.length) return null;
  let x0 = Math.min(...xs), x1 = Math.max(...xs), y0 = Math.min(...ys), y1 = Math.max(...ys);
  const pad = padFrac * Math.max(x1 - x0, y1 - y0, 1);
  x0 -= pad; x1 += pad; y0 -= pad; y1 += pad;
  if (x1 - x0 < minSpan) { const c = 0.5 * (x0 + x1); x0 = c - minSpan / 2; x1 = c + minSpan / 2; }
  if (y1 - y0 < minSpan) { const c = 0.5 * (y0 + y1); y0 = c - minSpan / 2; y1 = c + minSpan / 2; }
  return { x0, x1, y0, y1 };
}

// The operating area [0, W] x [0, H] plus every base station and start point, with a margin.
function areaBox(config) {
  const pts = [[0, 0], [config.area[0], config.area[1]]].concat(config.bs_xy || [], config.uav_start_xy || []);
  return fitBox(pts, 0.06, 1);
}

// The world-to-canvas transform fitting `box` into the canvas's top `height` px with equal
// scales (s px/m), y up.
function boxTransform(canvas, box, height) {
  const W = canvas.width, H = height;
  const s = Math.min(W / (box.x1 - box.x0), H / (box.y1 - box.y0));
  const ox = (W - s * (box.x1 - box.x0)) / 2, oy = (H - s * (box.y1 - box.y0)) / 2;
  return { s, box, px: (x) => ox + s * (x - box.x0), py: (y) => H - oy - s * (y - box.y0) };
}

// 1, 2 or 5 times a power of ten, the largest at most v (v > 0).
function niceFloor(v) {
  const e = Math.pow(10, Math.floor(Math.log10(v)));
  for (const k of [5, 2, 1]) if (k * e <= v * (1 + 1e-12)) return k * e;
  return e;
}

function fmtMetres(m) { return m >= 1000 ? (m / 1000).toPrecision(3) + " km" : m >= 10 ? m.toFixed(0) + " m" : m >= 1 ? m.toFixed(1) + " m" : m.toFixed(2) + " m"; }

// ------------------------------------------------------------------------- labels

// Text labels placed so that none overlaps another and each stays inside `bounds` (canvas px):
// each label tries positions around its anchor, nearest first, and takes the first that is
// inside and free (labels added first have the first choice); marks (markers) are avoided when
// possible. A label pushed away from its anchor gets a leader line. `placed` lists the boxes.
class LabelLayer {
  constructor(ctx, bounds) { this.ctx = ctx; this.bounds = bounds; this.placed = []; this.keepOut = []; this.marks = []; }

  block(x, y, w, h) { this.keepOut.push({ x, y, w, h }); }
  mark(x, y, r) { this.marks.push({ x: x - r, y: y - r, w: 2 * r, h: 2 * r }); }

  fit(text, font) {
    const ctx = this.ctx; ctx.font = font;
    const maxW = this.bounds.w - 4;
    let t = text, w = ctx.measureText(t).width;
    while (w > maxW && t.length > 1) { t = t.slice(0, -2) + "\u2026"; w = ctx.measureText(t).width; }
    return { t, w: Math.ceil(w) + 4 };
  }

  add(text, ax, ay, opts) {
    const b0 = this.bounds;  // nothing of an anchor off the map is shown, nor its label
    if (!(ax >= b0.x && ax <= b0.x + b0.w && ay >= b0.y && ay <= b0.y + b0.h)) return null;
    const o = Object.assign({ font: LABEL_FONT, colour: "#1d2330", r: 8, size: 11 }, opts || {});
    const { t, w } = this.fit(text, o.font);
    const h = o.size + 4, r = o.r, b = this.bounds;
    // Lexicographic: off the canvas or over another label only when nothing else is left;
    // then covering markers; then distance from the anchor.
    let best = null;
    search: for (const dist of [0, 10, 22, 38, 60, 90]) {
      const d = r + 2 + dist;
      const cands = [[d, -h / 2], [d * 0.8, -h - d * 0.5], [d * 0.8, d * 0.5], [-d - w, -h / 2],
        [-d * 0.8 - w, -h - d * 0.5], [-d * 0.8 - w, d * 0.5], [-w / 2, -d - h], [-w / 2, d]];
      for (const [dx, dy] of cands) {
        const box = { x: ax + dx, y: ay + dy, w, h };
        const bad = 1000 * this.outside(box) + 10 * (this.overlap(box, this.placed) + this.overlap(box, this.keepOut));
        const covered = this.overlap(box, this.marks);
        const score = (bad > 0 ? 1e9 + bad : 0) + covered + dist;
        if (!best || score < best.score) best = { box, score, dist };
        if (bad === 0 && covered === 0) break search;
      }
    }
    const box = best.box;  // clamped inside: never off the canvas, whatever else
    box.x = Math.min(Math.max(box.x, b.x), b.x + b.w - box.w);
    box.y = Math.min(Math.max(box.y, b.y), b.y + b.h - box.h);
    this.placed.push(Object.assign(box, { text: t, ax, ay, leader: best.dist > 0, font: o.font, colour: o.colour, size: o.size }));
    return box;
  }

  outside(box) {
    const b = this.bounds;
    const ix = Math.max(0, Math.min(box.x + box.w, b.x + b.w) - Math.max(box.x, b.x));
    const iy = Math.max(0, Math.min(box.y + box.h, b.y + b.h) - Math.max(box.y, b.y));
    return box.w * box.h - ix * iy;
  }

  overlap(box, boxes) {
    let sum = 0;
    for (const o of boxes) {
      const ix = Math.min(box.x + box.w, o.x + o.w) - Math.max(box.x, o.x);
      const iy = Math.min(box.y + box.h, o.y + o.h) - Math.max(box.y, o.y);
      if (ix > 0 && iy > 0) sum += ix * iy;
    }
    return sum;
  }

  draw() {
    const ctx = this.ctx;
    ctx.save();
    ctx.setLineDash([]);
    for (const L of this.placed) {
      if (L.leader) {
        const cx = Math.min(Math.max(L.ax, L.x), L.x + L.w), cy = Math.min(Math.max(L.ay, L.y), L.y + L.h);
        ctx.strokeStyle = "rgba(60,70,90,0.6)"; ctx.lineWidth = 0.8;
        ctx.beginPath(); ctx.moveTo(L.ax, L.ay); ctx.lineTo(cx, cy); ctx.stroke();
      }
      ctx.fillStyle = "rgba(255,255,255,0.8)"; ctx.fillRect(L.x, L.y, L.w, L.h);
      ctx.fillStyle = L.colour; ctx.font = L.font; ctx.textBaseline = "middle";
      ctx.fillText(L.text, L.x + 2, L.y + L.h / 2 + 0.5);
    }
    ctx.restore();
  }
}

// Legend items wrapped into lines of at most `width` px; [[text, ...], ...].
function wrapLegend(ctx, items, width) {
  ctx.font = LABEL_FONT;
  const lines = [[]];
  let used = 0;
  for (const item of items) {
    const w = ctx.measureText(item + "   ").width;
    if (used + w > width && lines[lines.length - 1].length) { lines.push([]); used = 0; }
    lines[lines.length - 1].push(item); used += w;
  }
  return lines;
}

// ------------------------------------------------------------------------- markers

function drawCross(ctx, x, y, size, colour, width) {
  ctx.strokeStyle = colour; ctx.lineWidth = width || 2;
  ctx.beginPath(); ctx.moveTo(x - size, y); ctx.lineTo(x + size, y); ctx.moveTo(x, y - size); ctx.lineTo(x, y + size); ctx.stroke();
  ctx.lineWidth = 1;
}

function drawDiamond(ctx, x, y, colour) {
  ctx.fillStyle = colour || "#000"; ctx.beginPath();
  ctx.moveTo(x, y - 6); ctx.lineTo(x + 5, y); ctx.lineTo(x, y + 6); ctx.lineTo(x - 5, y); ctx.closePath(); ctx.fill();
}

function drawWaypoint(ctx, x, y, colour) {
  ctx.save();
  ctx.strokeStyle = "#fff"; ctx.lineWidth = 4;  // a halo: the cross stays visible over a marker
  ctx.beginPath(); ctx.moveTo(x - 5, y - 5); ctx.lineTo(x + 5, y + 5); ctx.moveTo(x - 5, y + 5); ctx.lineTo(x + 5, y - 5); ctx.stroke();
  ctx.strokeStyle = colour; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(x - 5, y - 5); ctx.lineTo(x + 5, y + 5); ctx.moveTo(x - 5, y + 5); ctx.lineTo(x + 5, y - 5); ctx.stroke();
  ctx.restore();
}

// An estimate's 2-sigma ellipse (m, at scale s px/m; at least 1 px) and its cross.
function drawEstimate(ctx, x, y, ellipse, s, colour, opts) {
  const o = opts || {};
  ctx.save();
  if (o.dashed) ctx.setLineDash([4, 3]);
  if (o.alpha != null) ctx.globalAlpha = o.alpha;
  const alpha = ctx.globalAlpha;
  ctx.strokeStyle = colour;
  let px = null;
  if (ellipse) {
    px = { a: Math.max(s * ellipse.a_m, 1), b: Math.max(s * ellipse.b_m, 1) };
    ctx.beginPath(); ctx.ellipse(x, y, px.a, px.b, -ellipse.angle_rad, 0, 2 * Math.PI);
    ctx.globalAlpha = alpha * (o.fillAlpha != null ? o.fillAlpha : 0.15); ctx.fillStyle = colour; ctx.fill();
    ctx.globalAlpha = alpha; ctx.lineWidth = 1.5; ctx.stroke();
  }
  ctx.setLineDash([]);
  drawCross(ctx, x, y, 7, colour, o.width || 2);
  ctx.restore();
  return px;
}

// ------------------------------------------------------------------------- the map

// scene: {config, follow, targetNames, replay, layers: [{label, colour,
//          uavs: [{m, xy, trail, wp, mode, link, eta, bs, landed}], cues: [{xy, ellipse, label}],
//          tracks: [{id, confirmed, x, ellipse, target}] (any number of targets; a single
//          target's is track 1; a replay: each trace's estimate),
//          truths: [{index, x}] (the targets present at the tracks' slot)}]}
// Live, tracks are labelled T<id> and targets "target k <name> (T<id>)"; a replay labels its
// estimates by trace (several traces) or "target" (one).
// Returns what it drew: {s (px/m), follow, box, labels, uavs, waypoints, estimates, truths,
// ellipses} in canvas px.
function drawMap(canvas, scene) {
  const ctx = canvas.getContext("2d");
  const c = scene.config;
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  const info = { s: null, follow: false, box: null, labels: [], uavs: [], waypoints: [], estimates: [], truths: [], ellipses: [] };
  if (!c) return info;
  const multi = scene.layers.length > 1;
  const several = !scene.replay && scene.layers.some((L) => L.tracks.length || L.truths.length);
  const cueing = scene.layers.some((L) => L.cues && L.cues.length);
  // legend first: its lines set the height left for the map
  const legendItems = ["\u25a0 BS", "\u25cf UAV (hollow: link lost)", "\u00d7 waypoint", "+ estimate (2\u03c3 ellipse)", "\u25c6 truth"];
  if (several) legendItems.push("T<id> track (dashed: tentative)", "target k (T<id>: the track following it)");
  if (cueing) legendItems.push("dashed +: the tracker's cue before the start");
  const legend = wrapLegend(ctx, legendItems, canvas.width - 16);
  const legendH = 14 * legend.length + 6;
  const mapH = canvas.height - legendH;
  // the view: the whole area, or (follow) the target, the vehicles and their waypoints
  let box = null;
  if (scene.follow) {
    const pts = [];
    for (const L of scene.layers) {
      for (const t of L.tracks) if (t.confirmed) pts.push(t.x);
      for (const t of L.truths) pts.push(t.x);
      for (const q of L.cues || []) pts.push(q.xy);
      for (const u of L.uavs) { if (u.xy) pts.push(u.xy); if (u.wp) pts.push(u.wp); }
    }
    box = fitBox(pts, 0.12, Math.max(4 * (c.d_safe || 30), 60));
  }
  info.follow = !!box;
  const T = boxTransform(canvas, box || areaBox(c), mapH);
  info.s = T.s; info.box = T.box;
  const labels = new LabelLayer(ctx, { x: 0, y: 0, w: canvas.width, h: mapH });
  ctx.save();
  ctx.beginPath(); ctx.rect(0, 0, canvas.width, mapH); ctx.clip();
  // operating area
  ctx.fillStyle = "#fbfcfd"; ctx.strokeStyle = "#9aa3b0"; ctx.lineWidth = 1;
  ctx.fillRect(T.px(0), T.py(c.area[1]), T.s * c.area[0], T.s * c.area[1]);
  ctx.strokeRect(T.px(0), T.py(c.area[1]), T.s * c.area[0], T.s * c.area[1]);
  // control-range circles (only where they fall on the map)
  const bs = c.bs_xy || [];
  ctx.setLineDash([5, 4]); ctx.strokeStyle = "rgba(90,100,120,0.45)";
  for (const b of bs) {
    if (!(c.d_th > 0)) break;
    ctx.beginPath(); ctx.arc(T.px(b[0]), T.py(b[1]), T.s * c.d_th, 0, 2 * Math.PI); ctx.stroke();
  }
  // serving links BS -> UAV
  for (const L of scene.layers) {
    for (const u of L.uavs) {
      if (u.bs == null || u.bs < 0 || !bs[u.bs] || !u.xy) continue;
      ctx.strokeStyle = multi ? L.colour : "rgba(60,70,90,0.35)"; ctx.setLineDash([2, 3]);
      ctx.beginPath(); ctx.moveTo(T.px(bs[u.bs][0]), T.py(bs[u.bs][1]));
      ctx.lineTo(T.px(u.xy[0]), T.py(u.xy[1])); ctx.stroke();
    }
  }
  ctx.setLineDash([]);
  // trails
  for (const L of scene.layers) {
    for (const u of L.uavs) {
      if (!u.trail || u.trail.length < 2) continue;
      const col = multi ? L.colour : colourOf(u.m);
      ctx.strokeStyle = col; ctx.globalAlpha = 0.55; ctx.lineWidth = 1.5;
      ctx.beginPath();
      let started = false;
      for (const p of u.trail) {
        if (!p || p[0] == null || p[1] == null) { started = false; continue; }
        if (!started) { ctx.moveTo(T.px(p[0]), T.py(p[1])); started = true; } else ctx.lineTo(T.px(p[0]), T.py(p[1]));
      }
      ctx.stroke(); ctx.globalAlpha = 1; ctx.lineWidth = 1;
    }
  }
  // base stations
  bs.forEach((b) => {
    const x = T.px(b[0]), y = T.py(b[1]);
    ctx.fillStyle = "#37474f"; ctx.fillRect(x - 6, y - 6, 12, 12);
    labels.mark(x, y, 6);
  });
  // the tracker's cue before the start, the tracks (a cross and its 2-sigma ellipse; a
  // tentative one fainter and dashed), the targets (diamonds)
  for (const L of scene.layers) {
    const col = multi ? L.colour : ESTIMATE_COLOUR;
    for (const q of L.cues || []) {
      const x = T.px(q.xy[0]), y = T.py(q.xy[1]);
      drawEstimate(ctx, x, y, q.ellipse, T.s, col, { dashed: true, alpha: 0.6, fillAlpha: 0.05, width: 1.5 });
      labels.mark(x, y, 7);
    }
    for (const tr of L.tracks) {
      const x = T.px(tr.x[0]), y = T.py(tr.x[1]);
      const px = drawEstimate(ctx, x, y, tr.ellipse, T.s, col, tr.confirmed ? {} : { dashed: true, alpha: 0.45, fillAlpha: 0.08, width: 1.5 });
      info.estimates.push([x, y]); info.ellipses.push(px);
      labels.mark(x, y, 7);
    }
    for (const t of L.truths) {
      const x = T.px(t.x[0]), y = T.py(t.x[1]);
      drawDiamond(ctx, x, y); info.truths.push([x, y]); labels.mark(x, y, 6);
    }
  }
  // vehicles, then their waypoints on top (a waypoint a few metres ahead stays visible)
  for (const L of scene.layers) {
    for (const u of L.uavs) {
      if (!u.xy) continue;
      const col = multi ? L.colour : colourOf(u.m);
      const x = T.px(u.xy[0]), y = T.py(u.xy[1]);
      if (u.wp) {
        ctx.strokeStyle = col; ctx.setLineDash([3, 3]);
        ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(T.px(u.wp[0]), T.py(u.wp[1])); ctx.stroke(); ctx.setLineDash([]);
      }
      ctx.fillStyle = u.link === "lost" ? "#fff" : col; ctx.strokeStyle = col; ctx.lineWidth = 2;
      ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI); ctx.fill(); ctx.stroke(); ctx.lineWidth = 1;
      if (u.landed) { ctx.fillStyle = "#fff"; ctx.fillRect(x - 3, y - 1, 6, 2); }
      labels.mark(x, y, 7);
      info.uavs.push({ layer: L.label, m: u.m, x, y });
    }
  }
  for (const L of scene.layers) {
    for (const u of L.uavs) {
      if (!u.xy || !u.wp) continue;
      const col = multi ? L.colour : colourOf(u.m);
      const wx = T.px(u.wp[0]), wy = T.py(u.wp[1]);
      drawWaypoint(ctx, wx, wy, col);
      info.waypoints.push({ layer: L.label, m: u.m, x: wx, y: wy });
    }
  }
  ctx.restore();
  // labels, most important first: vehicles, tracks, targets, cues, base stations, the area
  for (const L of scene.layers) {
    for (const u of L.uavs) {
      if (!u.xy) continue;
      const parts = [(multi ? L.label + " " : "") + "U" + u.m];
      if (u.landed) parts.push("landed");
      else if (u.mode) parts.push(u.mode);
      if (u.link && u.link !== "ok") parts.push("LINK " + u.link.toUpperCase());
      if (u.bs != null && u.bs < 0) parts.push("no BS");
      if (u.eta != null) parts.push("\u03b7 " + (u.eta === 0 ? "0" : u.eta.toFixed(2)));
      labels.add(parts.join(" \u00b7 "), T.px(u.xy[0]), T.py(u.xy[1]));
    }
  }
  for (const L of scene.layers) {
    const col = multi ? L.colour : ESTIMATE_COLOUR;
    if (scene.replay) continue;  // a trace's estimate: below
    for (const tr of L.tracks) {
      labels.add("T" + tr.id, T.px(tr.x[0]), T.py(tr.x[1]), { colour: col, font: (tr.confirmed ? "bold " : "") + LABEL_FONT });
    }
    const follower = new Map();
    for (const tr of L.tracks) if (tr.confirmed && tr.target != null) follower.set(tr.target, tr.id);
    for (const t of L.truths) {
      const id = follower.get(t.index);
      labels.add(targetName(scene, t.index) + (id != null ? " (T" + id + ")" : " (no track)"), T.px(t.x[0]), T.py(t.x[1]), { colour: "#333" });
    }
    for (const q of L.cues || []) labels.add(q.label, T.px(q.xy[0]), T.py(q.xy[1]), { colour: col });
  }
  bs.forEach((b, k) => {
    const served = [];
    for (const L of scene.layers) for (const u of L.uavs) if (u.bs === k) served.push((multi ? L.label + ":" : "") + "U" + u.m);
    labels.add(`BS${k}` + (served.length ? " \u2192 " + served.join(", ") : ""), T.px(b[0]), T.py(b[1]), { font: "12px system-ui", size: 12, colour: "#263238" });
  });
  if (scene.replay && !multi) {  // one trace: its estimate reads "target"; beside others, nothing
    for (const tr of scene.layers[0].tracks) labels.add("target", T.px(tr.x[0]), T.py(tr.x[1]), { colour: ESTIMATE_COLOUR });
  }
  if (!info.follow) labels.add(`${c.area[0]} m x ${c.area[1]} m`, T.px(0), T.py(0), { colour: "#8a93a0", r: 2 });
  // scale bar, bottom right: the longest 1-2-5 length within 120 px
  const bar = niceFloor(120 / T.s), barPx = bar * T.s;
  const bx = canvas.width - 12 - barPx, by = mapH - 8;
  labels.block(bx - 4, by - 18, barPx + 8, 22);
  labels.draw();
  ctx.strokeStyle = "#1d2330"; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(bx, by); ctx.lineTo(bx + barPx, by); ctx.stroke(); ctx.lineWidth = 1;
  ctx.fillStyle = "#1d2330"; ctx.font = LABEL_FONT; ctx.textBaseline = "alphabetic";
  ctx.fillText(fmtMetres(bar), bx, by - 5);
  info.bar_m = bar;
  info.labels = labels.placed.map((L) => ({ text: L.text, x: L.x, y: L.y, w: L.w, h: L.h }));
  // legend, below the map
  ctx.font = LABEL_FONT; ctx.fillStyle = "#556"; ctx.textBaseline = "alphabetic";
  legend.forEach((line, i) => ctx.fillText(line.join("   "), 8, mapH + 14 * (i + 1)));
  return info;
}

// Target k's name for a person: 1-based, in the scenario's `targets:` order, with its name.
function targetName(scene, index) {
  const name = scene.targetNames && scene.targetNames[index];
  return "target " + (index + 1) + (name ? " " + name : "");
}

// ------------------------------------------------------------------------- the close-up

// The target close-up: a window around focus.centre sized to hold the estimate's 2-sigma
// ellipse, the truth and the other estimates it sizes for (with a quarter to spare), with a
// 1-2-5 scale bar.
// focus: {centre: [x, y], items: [{kind: "estimate"|"truth"|"uav"|"waypoint", xy, ellipse?,
// colour?, label?, dashed?, far? (drawn if in the window, not sized for)}], note}. Returns {s (px/m), half_m, items: [{kind, x, y, a, b}]}.
function drawInset(canvas, focus) {
  const ctx = canvas.getContext("2d");
  const W = canvas.width, H = canvas.height, footer = 0;
  ctx.clearRect(0, 0, W, H);
  ctx.fillStyle = "#fbfcfd"; ctx.fillRect(0, 0, W, H - footer);
  ctx.strokeStyle = "#c9ced6"; ctx.strokeRect(0.5, 0.5, W - 1, H - footer - 1);
  ctx.fillStyle = "#556"; ctx.font = LABEL_FONT; ctx.textBaseline = "alphabetic";
  if (!focus) { ctx.fillText("no estimate yet", 10, 20); return null; }
  const [cx, cy] = focus.centre;
  let need = 0;
  for (const it of focus.items) {
    if ((it.kind !== "estimate" && it.kind !== "truth") || it.far) continue;  // far: not sized for
    need = Math.max(need, Math.hypot(it.xy[0] - cx, it.xy[1] - cy) + (it.ellipse ? it.ellipse.a_m : 0));
  }
  const half = Math.max(1.25 * need, 0.5);
  const Hd = H - footer, s = Math.min(W, Hd) / (2 * half);
  const px = (x) => W / 2 + s * (x - cx), py = (y) => Hd / 2 - s * (y - cy);
  const out = { s, half_m: half, items: [] };
  const inside = (x, y) => x >= 0 && x <= W && y >= 0 && y <= Hd;
  ctx.save();
  ctx.beginPath(); ctx.rect(0, 0, W, Hd); ctx.clip();
  const order = { uav: 0, waypoint: 1, estimate: 2, truth: 3 };
  const items = focus.items.slice().sort((a, b) => order[a.kind] - order[b.kind]);
  const labels = new LabelLayer(ctx, { x: 0, y: 0, w: W, h: Hd });
  for (const it of items) {
    const x = px(it.xy[0]), y = py(it.xy[1]);
    const rec = { kind: it.kind, label: it.label || "", x, y };
    if (it.kind === "estimate") {
      const e = drawEstimate(ctx, x, y, it.ellipse, s, it.colour || ESTIMATE_COLOUR, it.dashed ? { dashed: true, alpha: 0.6 } : {});
      if (e) { rec.a = e.a; rec.b = e.b; }
    } else if (it.kind === "truth") drawDiamond(ctx, x, y);
    else if (it.kind === "uav" && inside(x, y)) { ctx.fillStyle = it.colour; ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI); ctx.fill(); }
    else if (it.kind === "waypoint" && inside(x, y)) drawWaypoint(ctx, x, y, it.colour);
    if (inside(x, y)) { labels.mark(x, y, 7); out.items.push(rec); }
  }
  for (const r of out.items) if (r.label) labels.add(r.label, r.x, r.y, { colour: r.kind === "truth" ? "#333" : "#1d2330" });
  labels.draw();
  ctx.restore();
  // scale bar: the longest 1-2-5 length within a third of the width
  const bar = niceFloor(W / 3 / s);
  const bx = 10, by = Hd - 10;
  ctx.strokeStyle = "#1d2330"; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(bx, by); ctx.lineTo(bx + bar * s, by); ctx.stroke(); ctx.lineWidth = 1;
  ctx.fillStyle = "#1d2330"; ctx.fillText(fmtMetres(bar), bx, by - 5);
  out.bar_m = bar;
  return out;
}

// ------------------------------------------------------------------------- charts

// One chart: series [{label, colour, dashed?, points: [[slot, value], ...]}], optional log scale
// and cursor; the legend wraps. Returns [{label, points: number of finite points}].
function drawChart(canvas, series, opts) {
  const ctx = canvas.getContext("2d");
  const W = canvas.width, H = canvas.height, L = 46, R = 8, B = 20;
  ctx.clearRect(0, 0, W, H);
  ctx.textBaseline = "alphabetic";
  const log = opts && opts.log;
  const f = (v) => (log ? Math.log10(Math.max(v, 1e-12)) : v);
  ctx.font = "10px system-ui";
  // legend rows first (they set the plot's top)
  const rowsOf = [[]];
  let used = L + 6;
  for (const s of series) {
    const w = ctx.measureText(s.label).width + 12;
    if (used + w > W - R && rowsOf[rowsOf.length - 1].length) { rowsOf.push([]); used = L + 6; }
    rowsOf[rowsOf.length - 1].push([s, used]); used += w;
  }
  const Tp = 4 + 12 * rowsOf.length;
  let xmin = Infinity, xmax = -Infinity, ymin = Infinity, ymax = -Infinity;
  const counts = [];
  for (const s of series) {
    let n = 0;
    for (const [x, y] of s.points) {
      if (y == null || !isFinite(y)) continue;
      n++;
      xmin = Math.min(xmin, x); xmax = Math.max(xmax, x); ymin = Math.min(ymin, f(y)); ymax = Math.max(ymax, f(y));
    }
    counts.push({ label: s.label, points: n });
  }
  ctx.strokeStyle = "#c9ced6"; ctx.strokeRect(L, Tp, W - L - R, H - Tp - B);
  ctx.fillStyle = "#556";
  if (!isFinite(xmin)) { ctx.fillText((opts && opts.empty) || "no data yet", L + 8, Tp + 16); return counts; }
  if (xmax === xmin) xmax = xmin + 1;
  if (ymax === ymin) { ymax += 0.5; ymin -= 0.5; }
  if (!log && ymin > 0) ymin = 0;
  const px = (x) => L + ((x - xmin) / (xmax - xmin)) * (W - L - R);
  const py = (y) => H - B - ((f(y) - ymin) / (ymax - ymin)) * (H - Tp - B);
  const lab = (v) => (log ? "1e" + v.toFixed(1) : Math.abs(v) >= 100 ? v.toFixed(0) : v.toPrecision(3));
  ctx.fillText(lab(ymax), 2, Tp + 8); ctx.fillText(lab(ymin), 2, H - B);
  ctx.fillText("slot " + xmin, L, H - 6); ctx.fillText(String(xmax), W - R - 24, H - 6);
  for (const s of series) {
    ctx.strokeStyle = s.colour; ctx.lineWidth = 1.5; ctx.setLineDash(s.dashed ? [5, 3] : []); ctx.beginPath();
    let started = false, last = null;
    for (const [x, y] of s.points) {
      if (y == null || !isFinite(y)) { started = false; continue; }
      if (!started) { ctx.moveTo(px(x), py(y)); started = true; } else ctx.lineTo(px(x), py(y));
      last = [px(x), py(y)];
    }
    ctx.stroke(); ctx.lineWidth = 1; ctx.setLineDash([]);
    if (last) { ctx.fillStyle = s.colour; ctx.fillRect(last[0] - 1.5, last[1] - 1.5, 3, 3); }  // a lone point shows
  }
  rowsOf.forEach((row, i) => {
    for (const [s, x] of row) { ctx.fillStyle = s.colour; ctx.fillText(s.label, x, 12 + 12 * i); }
  });
  if (opts && opts.cursor != null) {
    ctx.strokeStyle = "#888"; ctx.beginPath(); ctx.moveTo(px(opts.cursor), Tp); ctx.lineTo(px(opts.cursor), H - B); ctx.stroke();
  }
  return counts;
}
