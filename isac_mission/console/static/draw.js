// Drawing for the isac-mission console: the map of the operating area and the time-series
// charts, on plain 2-D canvases (no library). Scenario plane: x east, y north, metres.
"use strict";

const PALETTE = ["#1565c0", "#c62828", "#2e7d32", "#6a1b9a", "#ef6c00", "#00838f", "#4e342e", "#ad1457"];

function colourOf(i) { return PALETTE[((i % PALETTE.length) + PALETTE.length) % PALETTE.length]; }

// The world-to-canvas transform: the area [0, W] x [0, H] plus every base station and start
// point, with a margin, fitted to the canvas with equal scales; y up.
function mapTransform(canvas, config) {
  const xs = [0, config.area[0]], ys = [0, config.area[1]];
  for (const p of (config.bs_xy || []).concat(config.uav_start_xy || [])) { xs.push(p[0]); ys.push(p[1]); }
  let x0 = Math.min(...xs), x1 = Math.max(...xs), y0 = Math.min(...ys), y1 = Math.max(...ys);
  const pad = 0.06 * Math.max(x1 - x0, y1 - y0, 1);
  x0 -= pad; x1 += pad; y0 -= pad; y1 += pad;
  const s = Math.min(canvas.width / (x1 - x0), canvas.height / (y1 - y0));
  const ox = (canvas.width - s * (x1 - x0)) / 2, oy = (canvas.height - s * (y1 - y0)) / 2;
  return {
    s,
    px: (x) => ox + s * (x - x0),
    py: (y) => canvas.height - oy - s * (y - y0),
  };
}

// scene: {config, layers: [{label, colour, uavs: [{m, xy, trail, wp, mode, link, eta, bs}],
//          target: {xy, ellipse} | null, truth: [x, y] | null,
//          tracks: [{id, confirmed, x, ellipse}] | undefined (a multi-target mission's),
//          truths: [{index, x}] | undefined (its present targets)}]}
function drawMap(canvas, scene) {
  const ctx = canvas.getContext("2d");
  const c = scene.config;
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!c) return;
  const T = mapTransform(canvas, c);
  // operating area
  ctx.fillStyle = "#fbfcfd"; ctx.strokeStyle = "#9aa3b0"; ctx.lineWidth = 1;
  ctx.fillRect(T.px(0), T.py(c.area[1]), T.s * c.area[0], T.s * c.area[1]);
  ctx.strokeRect(T.px(0), T.py(c.area[1]), T.s * c.area[0], T.s * c.area[1]);
  ctx.fillStyle = "#8a93a0"; ctx.font = "11px system-ui";
  ctx.fillText(`${c.area[0]} m x ${c.area[1]} m`, T.px(0) + 4, T.py(0) - 4);
  // control-range circles (clipped to the canvas: only where they fall on the map)
  const bs = c.bs_xy || [];
  ctx.save();
  ctx.beginPath(); ctx.rect(0, 0, canvas.width, canvas.height); ctx.clip();
  ctx.setLineDash([5, 4]); ctx.strokeStyle = "rgba(90,100,120,0.45)";
  for (const b of bs) {
    if (!(c.d_th > 0)) break;
    ctx.beginPath(); ctx.arc(T.px(b[0]), T.py(b[1]), T.s * c.d_th, 0, 2 * Math.PI); ctx.stroke();
  }
  ctx.restore();
  const multi = scene.layers.length > 1;
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
  // base stations, with the vehicles each serves
  bs.forEach((b, k) => {
    const x = T.px(b[0]), y = T.py(b[1]);
    ctx.fillStyle = "#37474f"; ctx.fillRect(x - 6, y - 6, 12, 12);
    const served = [];
    for (const L of scene.layers) for (const u of L.uavs) if (u.bs === k) served.push((multi ? L.label + ":" : "") + "U" + u.m);
    ctx.fillStyle = "#263238"; ctx.font = "12px system-ui";
    ctx.fillText(`BS${k}` + (served.length ? " \u2192 " + served.join(", ") : ""), x + 9, y - 7);
  });
  for (const L of scene.layers) {
    for (const u of L.uavs) {
      const col = multi ? L.colour : colourOf(u.m);
      if (u.trail && u.trail.length > 1) {
        ctx.strokeStyle = col; ctx.globalAlpha = 0.55; ctx.lineWidth = 1.5;
        ctx.beginPath(); ctx.moveTo(T.px(u.trail[0][0]), T.py(u.trail[0][1]));
        for (let i = 1; i < u.trail.length; i++) ctx.lineTo(T.px(u.trail[i][0]), T.py(u.trail[i][1]));
        ctx.stroke(); ctx.globalAlpha = 1; ctx.lineWidth = 1;
      }
      if (!u.xy) continue;
      const x = T.px(u.xy[0]), y = T.py(u.xy[1]);
      if (u.wp) {
        const wx = T.px(u.wp[0]), wy = T.py(u.wp[1]);
        ctx.strokeStyle = col; ctx.setLineDash([3, 3]);
        ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(wx, wy); ctx.stroke(); ctx.setLineDash([]);
        ctx.beginPath(); ctx.moveTo(wx - 4, wy - 4); ctx.lineTo(wx + 4, wy + 4);
        ctx.moveTo(wx - 4, wy + 4); ctx.lineTo(wx + 4, wy - 4); ctx.stroke();
      }
      ctx.fillStyle = u.link === "lost" ? "#fff" : col; ctx.strokeStyle = col; ctx.lineWidth = 2;
      ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI); ctx.fill(); ctx.stroke(); ctx.lineWidth = 1;
      const parts = [(multi ? L.label + " " : "") + "U" + u.m];
      if (u.mode) parts.push(u.mode);
      if (u.link && u.link !== "ok") parts.push("LINK " + u.link.toUpperCase());
      if (u.eta != null) parts.push("\u03b7 " + u.eta.toFixed(2));
      ctx.fillStyle = "#1d2330"; ctx.font = "11px system-ui";
      ctx.fillText(parts.join(" \u00b7 "), x + 9, y + 4);
    }
    // target estimate, its 2-sigma ellipse, and the truth
    if (L.target && L.target.xy) {
      const x = T.px(L.target.xy[0]), y = T.py(L.target.xy[1]);
      const e = L.target.ellipse;
      ctx.strokeStyle = multi ? L.colour : "#d84315";
      if (e) {
        ctx.beginPath();
        ctx.ellipse(x, y, Math.max(T.s * e.a_m, 1), Math.max(T.s * e.b_m, 1), -e.angle_rad, 0, 2 * Math.PI);
        ctx.globalAlpha = 0.15; ctx.fillStyle = ctx.strokeStyle; ctx.fill(); ctx.globalAlpha = 1; ctx.stroke();
      }
      ctx.beginPath(); ctx.moveTo(x - 7, y); ctx.lineTo(x + 7, y); ctx.moveTo(x, y - 7); ctx.lineTo(x, y + 7);
      ctx.lineWidth = 2; ctx.stroke(); ctx.lineWidth = 1;
    }
    if (L.truth) {
      const x = T.px(L.truth[0]), y = T.py(L.truth[1]);
      ctx.fillStyle = "#000"; ctx.beginPath();
      ctx.moveTo(x, y - 6); ctx.lineTo(x + 5, y); ctx.lineTo(x, y + 6); ctx.lineTo(x - 5, y); ctx.closePath(); ctx.fill();
    }
    // several targets: every track (tentative ones faint and dashed) and every true target
    for (const tr of L.tracks || []) drawTrack(ctx, T, tr, multi ? L.colour : "#d84315");
    for (const t of L.truths || []) {
      const x = T.px(t.x[0]), y = T.py(t.x[1]);
      ctx.fillStyle = "#000"; ctx.beginPath();
      ctx.moveTo(x, y - 6); ctx.lineTo(x + 5, y); ctx.lineTo(x, y + 6); ctx.lineTo(x - 5, y); ctx.closePath(); ctx.fill();
      ctx.fillStyle = "#556"; ctx.font = "10px system-ui"; ctx.fillText("t" + t.index, x + 6, y + 13);
    }
  }
  // legend
  ctx.font = "11px system-ui"; ctx.fillStyle = "#556";
  const several = scene.layers.some((L) => L.tracks || L.truths);
  ctx.fillText("\u25a0 BS   \u25cf UAV (hollow: link lost)   \u00d7 waypoint   + estimate (2\u03c3 ellipse)   \u25c6 truth" +
    (several ? "   T<id> track (dashed: tentative)   t<i> target" : ""), 8, canvas.height - 8);
}

// One track of a multi-target mission as the single target's estimate is drawn (a cross and
// its 2-sigma ellipse), labelled with its id; a tentative one fainter and dashed.
function drawTrack(ctx, T, tr, colour) {
  const x = T.px(tr.x[0]), y = T.py(tr.x[1]);
  const e = tr.ellipse;
  ctx.save();
  ctx.strokeStyle = colour;
  if (!tr.confirmed) { ctx.globalAlpha = 0.45; ctx.setLineDash([4, 3]); }
  const alpha = ctx.globalAlpha;
  if (e) {
    ctx.beginPath();
    ctx.ellipse(x, y, Math.max(T.s * e.a_m, 1), Math.max(T.s * e.b_m, 1), -e.angle_rad, 0, 2 * Math.PI);
    ctx.globalAlpha = alpha * (tr.confirmed ? 0.15 : 0.08); ctx.fillStyle = colour; ctx.fill();
    ctx.globalAlpha = alpha; ctx.stroke();
  }
  ctx.beginPath(); ctx.moveTo(x - 7, y); ctx.lineTo(x + 7, y); ctx.moveTo(x, y - 7); ctx.lineTo(x, y + 7);
  ctx.lineWidth = tr.confirmed ? 2 : 1.5; ctx.stroke();
  ctx.fillStyle = colour; ctx.font = (tr.confirmed ? "bold " : "") + "11px system-ui";
  ctx.fillText("T" + tr.id, x + 8, y - 8);
  ctx.restore();
}

// One chart: series [{label, colour, points: [[slot, value], ...]}], optional log scale.
function drawChart(canvas, series, opts) {
  const ctx = canvas.getContext("2d");
  const W = canvas.width, H = canvas.height, L = 46, R = 8, Tp = 8, B = 20;
  ctx.clearRect(0, 0, W, H);
  const log = opts && opts.log;
  const f = (v) => (log ? Math.log10(Math.max(v, 1e-12)) : v);
  let xmin = Infinity, xmax = -Infinity, ymin = Infinity, ymax = -Infinity;
  for (const s of series) for (const [x, y] of s.points) {
    if (y == null || !isFinite(y)) continue;
    xmin = Math.min(xmin, x); xmax = Math.max(xmax, x); ymin = Math.min(ymin, f(y)); ymax = Math.max(ymax, f(y));
  }
  ctx.strokeStyle = "#c9ced6"; ctx.strokeRect(L, Tp, W - L - R, H - Tp - B);
  ctx.fillStyle = "#556"; ctx.font = "10px system-ui";
  if (!isFinite(xmin)) { ctx.fillText("no data yet", L + 8, Tp + 16); return; }
  if (xmax === xmin) xmax = xmin + 1;
  if (ymax === ymin) { ymax += 0.5; ymin -= 0.5; }
  if (!log && ymin > 0) ymin = 0;
  const px = (x) => L + ((x - xmin) / (xmax - xmin)) * (W - L - R);
  const py = (y) => H - B - ((f(y) - ymin) / (ymax - ymin)) * (H - Tp - B);
  const lab = (v) => (log ? "1e" + v.toFixed(1) : Math.abs(v) >= 100 ? v.toFixed(0) : v.toPrecision(3));
  ctx.fillText(lab(ymax), 2, Tp + 8); ctx.fillText(lab(ymin), 2, H - B);
  ctx.fillText("slot " + xmin, L, H - 6); ctx.fillText(String(xmax), W - R - 24, H - 6);
  let lx = L + 6;
  for (const s of series) {
    ctx.strokeStyle = s.colour; ctx.lineWidth = 1.5; ctx.beginPath();
    let started = false;
    for (const [x, y] of s.points) {
      if (y == null || !isFinite(y)) { started = false; continue; }
      if (!started) { ctx.moveTo(px(x), py(y)); started = true; } else ctx.lineTo(px(x), py(y));
    }
    ctx.stroke(); ctx.lineWidth = 1;
    ctx.fillStyle = s.colour; ctx.fillText(s.label, lx, Tp + 12); lx += ctx.measureText(s.label).width + 12;
  }
  if (opts && opts.cursor != null) {
    ctx.strokeStyle = "#888"; ctx.beginPath(); ctx.moveTo(px(opts.cursor), Tp); ctx.lineTo(px(opts.cursor), H - B); ctx.stroke();
  }
}
