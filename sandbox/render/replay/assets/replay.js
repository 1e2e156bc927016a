/* sandbox replay: plain JavaScript on a canvas; no library, no network.
 *
 * The page's data (the <script id="replay-data"> element) is written by
 * sandbox/replay/encode.py: arrays packed as base64 of zlib streams, inflated here
 * with the browser's own DecompressionStream. The automation hook for tests is
 * window.sandboxReplay (docs/replay.md): ready, seek(t), play(), pause(), state(),
 * events(), worldToPixel(x1, x2), select(name), stats().
 */
(function () {
  "use strict";
  const DATA = JSON.parse(document.getElementById("replay-data").textContent);
  const $ = (id) => document.getElementById(id);
  const MISSING = -2147483648;
  const TRAIL_SECONDS = 3.0; // [s] as the GIF
  const FLASH_SECONDS = 0.3; // [s] a collision flash, as the GIF
  const MIN_CONTACT_PX = 18; // [px] smallest vehicle radius when jumping to a contact
  const SPEEDS = [0.1, 0.2, 0.5, 1, 2, 5, 10];
  const COLOR = {
    obstacle: "#afafaf", obstacleEdge: "#6e6e6e", wall: "#7d7d7d", path: "#808080",
    avoid: "#ff8c00", external: "#0078ff", filter: "#000000", collision: "#e10000", zone: "#c8c8c8",
    neutral: "#595959",
  };

  let resolveReady, rejectReady;
  const ready = new Promise((res, rej) => { resolveReady = res; rejectReady = rej; });
  ready.catch(() => {});

  // ------------------------------------------------------------------ decoding
  function base64Bytes(text) {
    const bin = atob(text);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }

  async function inflate(bytes) {
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate"));
    return new Uint8Array(await new Response(stream).arrayBuffer());
  }

  async function unpack(p, Out) {
    const planes = await inflate(base64Bytes(p.data));
    const count = planes.length >> 2;
    const q = new Int32Array(count);
    for (let i = 0; i < count; i++) {
      q[i] = planes[i] | (planes[count + i] << 8) | (planes[2 * count + i] << 16) |
        (planes[3 * count + i] << 24);
    }
    const row = p.shape[0] > 0 ? count / p.shape[0] : count;
    for (let o = 0; o < p.order; o++) {
      for (let i = row; i < count; i++) q[i] = (q[i] + q[i - row]) | 0;
    }
    const out = new Out(count);
    for (let i = 0; i < count; i++) out[i] = q[i] === MISSING ? NaN : q[i] * p.step;
    return out;
  }

  // ------------------------------------------------------------------ model
  const M = { T: 0, n: DATA.names.length };
  const n = M.n;
  const names = DATA.names;
  const colors = DATA.colors;
  const radius = DATA.diameter.map((d) => (d || 0) / 2);
  const large = !!DATA.large;
  const events = DATA.events || [];
  const nameIndex = new Map(names.map((name, i) => [name, i]));

  let now = 0, t0 = 0, t1 = 0, span = 1;
  let playing = false, speed = 1, lastTick = null;
  let selected = -1, follow = -1; // the vehicle shown in the panel, the one the camera follows
  const cam = { scale: 1, fitScale: 1, cx: 0, cy: 0, w: 1, h: 1, fitted: false };
  let drawn = null; // {t, xy: Float64Array(2n)} of the last frame
  const stats = { frames: 0, drawMs: 0, lastDrawMs: 0 };
  const ctx = $("world").getContext("2d");
  const chartCtx = $("chart").getContext("2d");
  let chartCache = null;

  async function load() {
    if (DATA.format !== 1) throw new Error("unknown data format " + DATA.format);
    if (typeof DecompressionStream === "undefined") {
      throw new Error("this browser has no DecompressionStream: use a current Chromium or Firefox");
    }
    const A = DATA.arrays;
    const parts = await Promise.all([
      unpack(A.t, Float64Array), unpack(A.pose, Float32Array), unpack(A.cmd, Float32Array),
      unpack(A.slot, Float32Array), unpack(A.target, Float32Array),
      unpack(A.reference, Float32Array), unpack(A.state, Int8Array),
      unpack(A.slot_index, Int32Array),
    ]);
    [M.t, M.pose, M.cmd, M.slot, M.target, M.ref, M.state, M.slotIndex] = parts;
    M.T = M.t.length;
    t0 = M.t[0]; t1 = M.t[M.T - 1]; span = Math.max(t1 - t0, 1e-9);
    now = t0;
    // formation error, shape (T, n) [m]: distance to the slot, NaN without one
    M.err = new Float32Array(M.T * n);
    for (let j = 0; j < M.T * n; j++) {
      const dx = M.pose[3 * j] - M.slot[2 * j], dy = M.pose[3 * j + 1] - M.slot[2 * j + 1];
      M.err[j] = Math.hypot(dx, dy);
    }
    M.hasSlots = M.err.some((e) => Number.isFinite(e));
    M.hasPlatoon = M.slotIndex.some((s) => s >= 0);
  }

  // ------------------------------------------------------------------ sampling
  function sampleAt(time) {
    const t = M.t;
    if (time <= t[0]) return { k: 0, f: 0 };
    if (time >= t[M.T - 1]) return { k: M.T - 1, f: 0 };
    let lo = 0, hi = M.T - 1;
    while (hi - lo > 1) { const mid = (lo + hi) >> 1; if (t[mid] <= time) lo = mid; else hi = mid; }
    const dt = t[hi] - t[lo];
    return { k: lo, f: dt > 0 ? (time - t[lo]) / dt : 0 };
  }

  function lerp(arr, width, off, s, i) {
    const a = arr[(s.k * n + i) * width + off];
    if (s.f === 0 || s.k + 1 >= M.T) return a;
    const b = arr[((s.k + 1) * n + i) * width + off];
    if (!Number.isFinite(a) || !Number.isFinite(b)) return s.f < 0.5 ? a : b;
    return a + (b - a) * s.f;
  }

  function nearest(s) { return s.f < 0.5 || s.k + 1 >= M.T ? s.k : s.k + 1; }

  function positions(s) {
    const xy = new Float64Array(2 * n), th = new Float64Array(n);
    for (let i = 0; i < n; i++) {
      xy[2 * i] = lerp(M.pose, 3, 0, s, i);
      xy[2 * i + 1] = lerp(M.pose, 3, 1, s, i);
      th[i] = lerp(M.pose, 3, 2, s, i);
    }
    return { xy, th };
  }

  function vehicleState(i, s) {
    const k = nearest(s);
    const code = M.state[k * n + i];
    return {
      x1: lerp(M.pose, 3, 0, s, i), x2: lerp(M.pose, 3, 1, s, i), x3: lerp(M.pose, 3, 2, s, i),
      v1: lerp(M.cmd, 2, 0, s, i), v2: lerp(M.cmd, 2, 1, s, i),
      mode: DATA.modes[code & 3] || String(code & 3), failed: (code & 4) !== 0,
      filtered: (code & 8) !== 0,
      error: lerp(M.err, 1, 0, s, i), slot: M.slotIndex[k * n + i],
    };
  }

  function leaderAt(time) {
    // who leads at ``time``: a name, or null (the reference, or no leader)
    let lead = null;
    for (const [t, name] of DATA.leaders) if (t <= time + 1e-9) lead = name;
    return lead;
  }

  // ------------------------------------------------------------------ camera
  function resize() {
    const view = $("view"), dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, view.clientWidth), h = Math.max(1, view.clientHeight);
    const canvas = $("world");
    canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    cam.w = w; cam.h = h;
    if (!cam.fitted) fit();
    const box = $("chart-box"), chart = $("chart");
    chart.width = Math.round(Math.max(1, box.clientWidth) * dpr);
    chart.height = Math.round(Math.max(1, box.clientHeight) * dpr);
    chartCtx.setTransform(dpr, 0, 0, dpr, 0, 0);
    chartCache = null;
  }

  function fit() {
    const [x0, y0, x1, y1] = DATA.bounds.map((v) => (Number.isFinite(v) ? v : 0));
    const pad = 0.04;
    const sx = (cam.w * (1 - 2 * pad)) / Math.max(x1 - x0, 1e-9);
    const sy = (cam.h * (1 - 2 * pad)) / Math.max(y1 - y0, 1e-9);
    cam.scale = Math.max(Math.min(sx, sy), 1e-9);
    cam.fitScale = cam.scale;
    cam.cx = (x0 + x1) / 2; cam.cy = (y0 + y1) / 2;
    cam.fitted = true;
  }

  function firstView() {
    // the GIF's automatic camera: follow the leader of a run spread along a line
    const c = DATA.camera || {};
    follow = -1;
    fit();
    if (c.follow && nameIndex.has(c.follow) && c.width > 0) {
      follow = nameIndex.get(c.follow);
      cam.scale = Math.min(cam.w, cam.h) * 0.92 / c.width;
    }
  }

  function w2p(x, y) { return [cam.w / 2 + (x - cam.cx) * cam.scale, cam.h / 2 - (y - cam.cy) * cam.scale]; }
  function p2w(u, v) { return [cam.cx + (u - cam.w / 2) / cam.scale, cam.cy - (v - cam.h / 2) / cam.scale]; }

  // ------------------------------------------------------------------ drawing
  function niceLength(target) {
    if (!(target > 0) || !Number.isFinite(target)) return 1;
    const e = Math.floor(Math.log10(target)), base = Math.pow(10, e);
    let best = base;
    for (const m of [2, 5, 10]) if (m * base <= target * (1 + 1e-9)) best = m * base;
    return best;
  }

  function drawObstacles() {
    for (const ob of DATA.obstacles) {
      ctx.beginPath();
      if (ob.type === "circle") {
        const [u, v] = w2p(ob.center[0], ob.center[1]);
        ctx.arc(u, v, Math.max(ob.radius * cam.scale, 0.5), 0, 2 * Math.PI);
      } else {
        ob.points.forEach((p, j) => { const [u, v] = w2p(p[0], p[1]); if (j) ctx.lineTo(u, v); else ctx.moveTo(u, v); });
        ctx.closePath();
      }
      ctx.fillStyle = ob.wall ? COLOR.wall : COLOR.obstacle;
      ctx.strokeStyle = COLOR.obstacleEdge;
      ctx.lineWidth = 1;
      ctx.fill(); ctx.stroke();
    }
  }

  function drawPath() {
    const path = DATA.reference_path;
    if (!path || path.length < 2) return;
    ctx.beginPath();
    path.forEach((p, j) => { const [u, v] = w2p(p[0], p[1]); if (j) ctx.lineTo(u, v); else ctx.moveTo(u, v); });
    ctx.setLineDash([8, 6]); ctx.strokeStyle = COLOR.path; ctx.lineWidth = 1; ctx.stroke(); ctx.setLineDash([]);
  }

  function drawTrails(s, xy) {
    if (large) return;
    const start = sampleAt(now - TRAIL_SECONDS).k;
    const stop = s.k;
    if (stop <= start) return;
    const step = Math.max(1, Math.ceil((stop - start) / 60));
    ctx.lineWidth = n <= 20 ? 2 : 1;
    ctx.lineCap = "round";
    for (let i = 0; i < n; i++) {
      ctx.strokeStyle = colors[i];
      let prev = null;
      for (let k = start; k <= stop + 1; k += step) {
        const kk = Math.min(k, stop);
        let x = M.pose[(kk * n + i) * 3], y = M.pose[(kk * n + i) * 3 + 1];
        if (k > stop) { x = xy[2 * i]; y = xy[2 * i + 1]; }
        if (!Number.isFinite(x) || !Number.isFinite(y)) { prev = null; continue; }
        const p = w2p(x, y);
        if (prev) {
          const age = now - M.t[kk];
          ctx.globalAlpha = Math.max(0.08, 0.6 * (1 - age / TRAIL_SECONDS));
          ctx.beginPath(); ctx.moveTo(prev[0], prev[1]); ctx.lineTo(p[0], p[1]); ctx.stroke();
        }
        prev = p;
        if (k > stop) break;
      }
    }
    ctx.globalAlpha = 1;
  }

  function drawReference(s) {
    const rx = refAt(s, 0), ry = refAt(s, 1); // one point per sample
    if (!Number.isFinite(rx) || !Number.isFinite(ry)) return;
    const [u, v] = w2p(rx, ry);
    ctx.strokeStyle = COLOR.path; ctx.lineWidth = 1;
    ctx.beginPath(); ctx.moveTo(u - 5, v); ctx.lineTo(u + 5, v); ctx.moveTo(u, v - 5); ctx.lineTo(u, v + 5); ctx.stroke();
  }

  function refAt(s, c) {
    const a = M.ref[2 * s.k + c];
    if (s.f === 0 || s.k + 1 >= M.T) return a;
    const b = M.ref[2 * (s.k + 1) + c];
    if (!Number.isFinite(a) || !Number.isFinite(b)) return s.f < 0.5 ? a : b;
    return a + (b - a) * s.f;
  }

  function drawSlots(s) {
    if (large) return;
    for (let i = 0; i < n; i++) {
      const sx = lerp(M.slot, 2, 0, s, i), sy = lerp(M.slot, 2, 1, s, i);
      const rp = radius[i] * cam.scale;
      if (Number.isFinite(sx) && Number.isFinite(sy)) {
        const [u, v] = w2p(sx, sy), r = Math.min(8, Math.max(3, 0.35 * rp));
        ctx.strokeStyle = colors[i]; ctx.lineWidth = r >= 5 ? 2 : 1;
        ctx.beginPath(); ctx.arc(u, v, r, 0, 2 * Math.PI); ctx.stroke();
      }
      const gx = lerp(M.target, 2, 0, s, i), gy = lerp(M.target, 2, 1, s, i);
      if (Number.isFinite(gx) && Number.isFinite(gy)) {
        const [u, v] = w2p(gx, gy);
        if (Number.isFinite(sx) && Math.hypot(gx - sx, gy - sy) * cam.scale < 2) continue;
        const h = Math.min(6, Math.max(3, 0.25 * rp));
        ctx.strokeStyle = colors[i]; ctx.lineWidth = 1.5;
        ctx.beginPath(); ctx.moveTo(u - h, v - h); ctx.lineTo(u + h, v + h);
        ctx.moveTo(u - h, v + h); ctx.lineTo(u + h, v - h); ctx.stroke();
      }
    }
  }

  function drawBodies(s, xy, th) {
    const k = nearest(s);
    const byColor = new Map();
    for (let i = 0; i < n; i++) {
      if (!Number.isFinite(xy[2 * i]) || !Number.isFinite(xy[2 * i + 1])) continue;
      const list = byColor.get(colors[i]) || [];
      list.push(i);
      byColor.set(colors[i], list);
    }
    // avoidance (orange), external (blue) and safety-filter (black) halos under the bodies
    for (let i = 0; i < n; i++) {
      const code = M.state[k * n + i], mode = code & 3, failed = (code & 4) !== 0 || mode === 2;
      const filtered = (code & 8) !== 0 && mode !== 3;
      if (failed || (mode !== 1 && mode !== 3 && !filtered)) continue;
      const [u, v] = w2p(xy[2 * i], xy[2 * i + 1]);
      if (!Number.isFinite(u) || !Number.isFinite(v)) continue;
      const r = Math.max(radius[i] * cam.scale, 0.75);
      ctx.fillStyle = mode === 3 ? COLOR.external : filtered ? COLOR.filter : COLOR.avoid;
      ctx.beginPath(); ctx.arc(u, v, r + Math.max(2, Math.min(4, 0.25 * r)), 0, 2 * Math.PI); ctx.fill();
    }
    for (const [color, list] of byColor) {
      ctx.beginPath();
      for (const i of list) {
        const [u, v] = w2p(xy[2 * i], xy[2 * i + 1]);
        const r = Math.max(radius[i] * cam.scale, 0.75);
        ctx.moveTo(u + r, v); ctx.arc(u, v, r, 0, 2 * Math.PI);
      }
      ctx.fillStyle = color; ctx.fill();
      ctx.strokeStyle = "#000"; ctx.lineWidth = 1;
      if (list.length && radius[list[0]] * cam.scale >= 3) ctx.stroke();
    }
    ctx.strokeStyle = "#000"; ctx.lineCap = "butt";
    ctx.beginPath();
    for (let i = 0; i < n; i++) {
      const r = radius[i] * cam.scale;
      if (r < 3 || !Number.isFinite(th[i])) continue;
      const [u, v] = w2p(xy[2 * i], xy[2 * i + 1]);
      if (!Number.isFinite(u) || !Number.isFinite(v)) continue;
      ctx.moveTo(u, v); ctx.lineTo(u + r * Math.cos(th[i]), v - r * Math.sin(th[i]));
    }
    ctx.lineWidth = Math.max(2, Math.round(0.2 * Math.min(...radius) * cam.scale));
    ctx.stroke();
    // failures: a black cross over the body
    ctx.lineWidth = 2;
    for (let i = 0; i < n; i++) {
      const code = M.state[k * n + i];
      if (!((code & 4) !== 0 || (code & 3) === 2)) continue;
      const [u, v] = w2p(xy[2 * i], xy[2 * i + 1]);
      if (!Number.isFinite(u) || !Number.isFinite(v)) continue;
      const h = Math.max(radius[i] * cam.scale, 5);
      ctx.lineWidth = Math.max(2, Math.round(0.22 * h));
      ctx.beginPath(); ctx.moveTo(u - h, v - h); ctx.lineTo(u + h, v + h);
      ctx.moveTo(u - h, v + h); ctx.lineTo(u + h, v - h); ctx.stroke();
    }
  }

  function drawContacts(xy) {
    for (const e of events) {
      if (e.kind !== "collision" || e.t > now + 1e-9) continue;
      if (e.x1 === null || e.x2 === null) continue;
      const [u, v] = w2p(e.x1, e.x2);
      const fresh = now - e.t <= FLASH_SECONDS;
      ctx.strokeStyle = COLOR.collision;
      if (fresh) {
        const parties = [e.a, e.b].map((x) => nameIndex.get(x)).filter((x) => x !== undefined);
        const reach = Math.max(0, ...parties.map((i) => radius[i] * cam.scale));
        const rho = Math.max(8, 1.4 * reach);
        ctx.lineWidth = 2;
        ctx.beginPath(); ctx.arc(u, v, rho, 0, 2 * Math.PI); ctx.stroke();
        ctx.beginPath();
        for (let a = 0; a < 8; a++) {
          const c = Math.cos(a * Math.PI / 4), s = Math.sin(a * Math.PI / 4);
          ctx.moveTo(u + 1.2 * rho * c, v + 1.2 * rho * s); ctx.lineTo(u + 1.7 * rho * c, v + 1.7 * rho * s);
        }
        ctx.stroke();
      } else { // a past contact: a small red mark where it happened
        ctx.lineWidth = 1.5;
        ctx.beginPath(); ctx.moveTo(u - 3, v - 3); ctx.lineTo(u + 3, v + 3);
        ctx.moveTo(u - 3, v + 3); ctx.lineTo(u + 3, v - 3); ctx.stroke();
      }
    }
    const c = DATA.closest;
    if (c && Math.abs(now - c.t) <= FLASH_SECONDS) {
      const a = nameIndex.get(c.a), b = nameIndex.get(c.b);
      const [ua, va] = w2p(xy[2 * a], xy[2 * a + 1]), [ub, vb] = w2p(xy[2 * b], xy[2 * b + 1]);
      ctx.strokeStyle = COLOR.collision; ctx.lineWidth = 1.5; ctx.setLineDash([4, 3]);
      ctx.beginPath(); ctx.moveTo(ua, va); ctx.lineTo(ub, vb); ctx.stroke();
      const rho = Math.max(10, (Math.hypot(ub - ua, vb - va) / 2) + radius[a] * cam.scale);
      ctx.beginPath(); ctx.arc((ua + ub) / 2, (va + vb) / 2, rho, 0, 2 * Math.PI); ctx.stroke();
      ctx.setLineDash([]);
      ctx.fillStyle = COLOR.collision; ctx.font = "12px system-ui, sans-serif";
      ctx.fillText("closest approach: gap " + fmt(c.gap, 3) + " m", (ua + ub) / 2 + rho + 4, (va + vb) / 2);
    }
  }

  function drawLabels(xy) {
    ctx.font = "11px system-ui, sans-serif"; ctx.textBaseline = "middle";
    for (let i = 0; i < n; i++) {
      if (large && i !== selected) continue;
      if (!large && n > 20 && i !== selected) continue;
      const [u, v] = w2p(xy[2 * i], xy[2 * i + 1]);
      if (!Number.isFinite(u) || !Number.isFinite(v)) continue;
      const r = Math.max(radius[i] * cam.scale, 0.75);
      ctx.fillStyle = i === selected ? "#000" : "#333";
      ctx.fillText(names[i], u + r + 3, v - r - 2);
    }
    if (selected >= 0) {
      const [u, v] = w2p(xy[2 * selected], xy[2 * selected + 1]);
      if (Number.isFinite(u) && Number.isFinite(v)) {
        const r = Math.max(radius[selected] * cam.scale, 0.75) + 5;
        ctx.strokeStyle = "#0078ff"; ctx.lineWidth = 1.5; ctx.setLineDash([3, 3]);
        ctx.beginPath(); ctx.arc(u, v, r, 0, 2 * Math.PI); ctx.stroke(); ctx.setLineDash([]);
      }
    }
  }

  function drawScaleBar() {
    const len = niceLength(0.2 * cam.w / cam.scale), px = len * cam.scale;
    const x = 12, y = cam.h - 14;
    ctx.strokeStyle = "#000"; ctx.lineWidth = 2;
    ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(x + px, y);
    ctx.moveTo(x, y - 4); ctx.lineTo(x, y + 4); ctx.moveTo(x + px, y - 4); ctx.lineTo(x + px, y + 4); ctx.stroke();
    ctx.fillStyle = "#000"; ctx.font = "11px system-ui, sans-serif"; ctx.textBaseline = "bottom";
    ctx.fillText(fmtLength(len), x + px + 6, y + 5);
  }

  function fmtLength(m) { return m >= 1 ? `${+m.toPrecision(3)} m` : `${+(m * 100).toPrecision(3)} cm`; }
  function fmt(x, d) { return Number.isFinite(x) ? x.toFixed(d) : "-"; }

  function render() {
    if (!M.T) return;
    const start = performance.now();
    const s = sampleAt(now);
    const { xy, th } = positions(s);
    if (follow >= 0 && Number.isFinite(xy[2 * follow]) && Number.isFinite(xy[2 * follow + 1])) {
      cam.cx = xy[2 * follow]; cam.cy = xy[2 * follow + 1];
    }
    ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, cam.w, cam.h);
    drawObstacles();
    drawPath();
    drawTrails(s, xy);
    drawReference(s);
    drawSlots(s);
    drawContacts(xy); // under the bodies: the vehicles in contact stay visible
    drawBodies(s, xy, th);
    drawLabels(xy);
    drawScaleBar();
    drawn = { t: now, xy };
    updateHud();
    updatePanel(s);
    drawChart();
    $("cursor").style.left = (100 * (now - t0) / span) + "%";
    markNear();
    stats.frames += 1;
    stats.lastDrawMs = performance.now() - start;
    stats.drawMs += stats.lastDrawMs;
  }

  // ------------------------------------------------------------------ text
  function updateHud() {
    const hits = events.filter((e) => e.kind === "collision" && e.t <= now + 1e-9).length;
    const lead = leaderAt(now);
    let text = `t = ${now.toFixed(2)} s \u00b7 collisions so far: ${hits}`;
    if (DATA.leaders.length > 1) text += ` \u00b7 lead: ${lead || "reference"}`;
    if (follow >= 0) text += ` \u00b7 following ${names[follow]}`;
    $("hud").textContent = text;
    $("time").textContent = `t = ${now.toFixed(2)} s of ${t1.toFixed(2)} s`;
  }

  function swatch(color) { return `<span class="swatch" style="background:${color}"></span>`; }
  function esc(text) {
    return String(text).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);
  }

  function updatePanel(s) {
    const panel = $("vehicle-panel");
    if (selected < 0) {
      if (panel.dataset.vehicle !== "") {
        panel.dataset.vehicle = "";
        panel.innerHTML = '<h2>Vehicle</h2><p class="hint">Click a vehicle to follow it and read its state.</p>';
      }
      return;
    }
    const v = vehicleState(selected, s);
    const lead = leaderAt(now);
    const rows = [
      ["x1", fmt(v.x1, 3) + " m"], ["x2", fmt(v.x2, 3) + " m"], ["x3", fmt(v.x3, 3) + " rad"],
      ["v1", fmt(v.v1, 3) + " m/s"], ["v2", fmt(v.v2, 3) + " rad/s"],
      ["mode", v.mode + (v.failed && v.mode !== "failed" ? " (failed)" : "") + (v.filtered ? ` (${DATA.filter} acting)` : "")],
      ["formation error", Number.isFinite(v.error) ? fmt(v.error, 3) + " m" : "no slot"],
    ];
    if (M.hasPlatoon) {
      let text = v.slot >= 0 ? `slot ${v.slot}` : "no slot";
      if (lead === names[selected]) text += ", leader";
      rows.push(["platoon", text]);
    }
    panel.dataset.vehicle = names[selected];
    panel.innerHTML = `<h2>Vehicle</h2><div class="vname">${swatch(colors[selected])}<span id="vehicle-name">${esc(names[selected])}</span></div>` +
      `<table class="state">${rows.map(([k, x]) => `<tr><th>${k}</th><td>${esc(x)}</td></tr>`).join("")}</table>` +
      `<p class="hint">${follow === selected ? "followed: drag to stop, f to fit" : "not followed: click it to follow"}; esc deselects</p>`;
  }

  function describe(e) {
    switch (e.kind) {
      case "collision": return `collision ${e.a} \u2013 ${e.b}` + (e.healthy === false ? " (failed vehicle)" : "");
      case "failure": return `failure of ${e.vehicle}: ${e.failure}` + (e.until !== null && e.until !== undefined ? ` until ${e.until} s` : "");
      case "detection": return `${e.vehicle} detected: ${e.detected}` + (e.false_alarm ? " (false alarm)" : "");
      case "reassignment": return "slots: " + (e.changes.length ? e.changes.join(", ") : "unchanged");
      case "leader_change": return `lead: ${e.from || "reference"} \u2192 ${e.to || "reference"}`;
      case "closest": return `closest approach ${e.a} \u2013 ${e.b}: gap ${fmt(e.gap, 3)} m`;
      default: return e.kind;
    }
  }

  function glyph(e) {
    const w = 'width="14" height="14" viewBox="0 0 14 14"';
    const vc = (name) => (nameIndex.has(name) ? colors[nameIndex.get(name)] : COLOR.neutral);
    switch (e.kind) {
      case "collision": return `<svg ${w}><circle cx="7" cy="7" r="5.5" fill="${COLOR.collision}" stroke="#fff" stroke-width="1"/></svg>`;
      case "failure": return `<svg ${w}><path d="M2 2L12 12M2 12L12 2" stroke="#000" stroke-width="2.5"/></svg>`;
      case "detection": return `<svg ${w}><path d="M7 1L13 13H1Z" fill="${vc(e.vehicle)}" stroke="#000"/></svg>`;
      case "reassignment": return `<svg ${w}><path d="M1 2H13L7 13Z" fill="${COLOR.neutral}"/></svg>`;
      case "leader_change": return `<svg ${w}><path d="M7 1L13 7L7 13L1 7Z" fill="${vc(e.to)}" stroke="#000"/></svg>`;
      case "closest": return `<svg ${w}><circle cx="7" cy="7" r="5" fill="none" stroke="${COLOR.collision}" stroke-width="2" stroke-dasharray="3 2"/></svg>`;
      default: return "";
    }
  }

  function buildMarks() {
    const marks = $("marks"), list = $("events-list");
    const all = events.map((e, j) => ({ ...e, index: j }));
    if (DATA.closest) all.push({ ...DATA.closest, kind: "closest", index: -1 });
    all.sort((a, b) => a.t - b.t);
    // one lane per kind present, so that marks at the same time do not hide each other
    const lanes = [...new Set(all.map((e) => (e.kind === "closest" ? "collision" : e.kind)))];
    const LANE = 15; // [px]
    $("marks").style.height = `${Math.max(1, lanes.length) * LANE}px`;
    $("track").style.top = `${Math.max(1, lanes.length) * LANE + 2}px`;
    $("timeline").style.height = `${Math.max(1, lanes.length) * LANE + 12}px`;
    $("cursor").style.top = `${-Math.max(1, lanes.length) * LANE}px`;
    $("cursor").style.height = `${Math.max(1, lanes.length) * LANE + 10}px`;
    const frag = document.createDocumentFragment(), items = document.createDocumentFragment();
    all.forEach((e, j) => {
      const b = document.createElement("button");
      b.className = "mark"; b.dataset.kind = e.kind; b.dataset.t = String(e.t);
      b.style.left = (100 * (e.t - t0) / span) + "%";
      b.style.top = `${LANE * lanes.indexOf(e.kind === "closest" ? "collision" : e.kind)}px`;
      b.title = `${fmt(e.t, 2)} s: ${describe(e)}`;
      b.setAttribute("aria-label", b.title);
      b.innerHTML = glyph(e);
      b.addEventListener("click", (ev) => { ev.stopPropagation(); jumpTo(e); b.blur(); });
      b.addEventListener("pointerdown", (ev) => ev.stopPropagation());
      frag.appendChild(b);
      if (j < 1000) {
        const li = document.createElement("li");
        li.dataset.kind = e.kind; li.dataset.t = String(e.t);
        li.innerHTML = `<span class="et">${fmt(e.t, 2)} s</span>${glyph(e)} ${esc(describe(e))}`;
        li.querySelector("svg").style.verticalAlign = "-2px";
        li.addEventListener("click", () => jumpTo(e));
        items.appendChild(li);
      }
    });
    marks.appendChild(frag); list.appendChild(items);
    if (all.length > 1000) {
      const li = document.createElement("li"); li.textContent = `... and ${all.length - 1000} more on the timeline`;
      list.appendChild(li);
    }
    if (!all.length) { const li = document.createElement("li"); li.className = "hint"; li.textContent = "no events"; list.appendChild(li); }
  }

  let nearItem = null;
  function markNear() {
    // the latest event at or before the time shown, highlighted in the list
    const items = $("events-list").children;
    let best = null;
    for (const li of items) {
      if (li.dataset.t === undefined) continue;
      if (Number(li.dataset.t) <= now + 1e-9) best = li; else break;
    }
    if (best === nearItem) return;
    if (nearItem) nearItem.classList.remove("near");
    if (best) best.classList.add("near");
    nearItem = best;
  }

  function jumpTo(e) {
    // Seek to the event; a contact is also brought into view: centred, and zoomed in
    // until its vehicles are at least MIN_CONTACT_PX in radius.
    pause();
    const i = nameIndex.get(e.kind === "collision" || e.kind === "closest" ? e.a : e.vehicle);
    if (i !== undefined && selected < 0) selected = i;
    if (e.kind === "collision" || e.kind === "closest") {
      const parties = [e.a, e.b].map((x) => nameIndex.get(x)).filter((x) => x !== undefined);
      const r = Math.max(...parties.map((j) => radius[j]), 1e-9);
      if (r * cam.scale < MIN_CONTACT_PX) cam.scale = MIN_CONTACT_PX / r;
      const s = sampleAt(e.t), xy = positions(s).xy;
      const mx = parties.reduce((a, j) => a + xy[2 * j], 0) / parties.length;
      const my = parties.reduce((a, j) => a + xy[2 * j + 1], 0) / parties.length;
      if (Number.isFinite(mx) && Number.isFinite(my)) { follow = -1; cam.cx = mx; cam.cy = my; }
    }
    seek(e.t);
  }

  function buildHeader() {
    const S = DATA.summary, parts = [];
    const ok = S.status === "ok";
    parts.push(`<span>status: <b class="${ok ? "good" : "bad"}">${esc(S.status)}</b></span>`);
    if (S.diverged) parts.push(`<span class="bad">diverged at ${fmt(S.diverged.t, 3)} s (${esc(S.diverged.vehicle)}: ${esc(S.diverged.reason)})</span>`);
    const col = S.collisions === 0 ? "0" : `${S.collisions} (vehicle\u2013vehicle ${S.vehicle_vehicle}, vehicle\u2013obstacle ${S.vehicle_obstacle})`;
    parts.push(`<span>collisions: <b class="${S.collisions ? "bad" : "good"}">${col}</b></span>`);
    if (S.settled || S.never_settled.length) {
      const text = S.never_settled.length
        ? `${S.never_settled.length} of ${S.settled + S.never_settled.length} never settled`
        : `all settled by ${fmt(S.settling_time, 2)} s`;
      parts.push(`<span>settling: ${esc(text)}</span>`);
    }
    parts.push(`<span>converged: ${S.converged ? "yes" : "no"}</span>`);
    if (S.min_distance !== null) parts.push(`<span>min distance: ${fmt(S.min_distance, 3)} m</span>`);
    parts.push(`<span>${n} vehicle${n === 1 ? "" : "s"}, ${fmt(S.duration, 2)} s, recovery: ${esc(DATA.recovery.strategy)}${DATA.filter ? `, filter: ${esc(DATA.filter)}` : ""}</span>`);
    $("summary").innerHTML = parts.join("");
    $("notes").innerHTML = DATA.notes.map((x) => `<p>${esc(x)}</p>`).join("");
    if (DATA.description) $("scenario").title = DATA.description;
  }

  function buildLegend() {
    const rows = [];
    const leads = (name) => DATA.leaders.filter(([, who]) => who === name).map(([t], j) =>
      (DATA.leaders[0][1] === name && j === 0 ? "leader" : `leader from ${fmt(t, 2)} s`));
    if (n <= 20) names.forEach((name, i) => rows.push(`<div>${swatch(colors[i])}${esc(name)}${leads(name).length ? ` (${leads(name).join(", ")})` : ""}</div>`));
    else rows.push(`<div>${swatch(new Set(colors).size === 1 ? colors[0] : COLOR.neutral)}${n} vehicles</div>`);
    const svg = (body) => `<svg width="14" height="14" viewBox="0 0 14 14">${body}</svg>`;
    if (!large && M.hasSlots) rows.push(`<div>${svg('<circle cx="7" cy="7" r="4" fill="none" stroke="#555" stroke-width="2"/>')}slot (ring) / target (cross)</div>`);
    if (DATA.reference_path) rows.push(`<div>${svg('<path d="M0 7H5M9 7H14" stroke="#808080"/>')}reference path</div>`);
    rows.push(`<div>${svg(`<circle cx="7" cy="7" r="6" fill="${COLOR.avoid}"/><circle cx="7" cy="7" r="4" fill="#fff" stroke="#000"/>`)}avoiding</div>`);
    if (DATA.filter) rows.push(`<div>${svg(`<circle cx="7" cy="7" r="6" fill="${COLOR.filter}"/><circle cx="7" cy="7" r="4" fill="#fff" stroke="#000"/>`)}${esc(DATA.filter)} acting (safety filter)</div>`);
    rows.push(`<div>${svg('<path d="M2 2L12 12M2 12L12 2" stroke="#000" stroke-width="2.5"/>')}failed</div>`);
    rows.push(`<div>${svg(`<circle cx="7" cy="7" r="5" fill="none" stroke="${COLOR.collision}" stroke-width="2"/>`)}collision (red cross: a past one)</div>`);
    if (DATA.obstacles.length) rows.push(`<div>${svg(`<rect x="1" y="3" width="12" height="8" fill="${COLOR.obstacle}" stroke="${COLOR.obstacleEdge}"/>`)}obstacle${DATA.obstacles.some((o) => o.wall) ? ` (darker: wall)` : ""}</div>`);
    $("legend").innerHTML = rows.join("");
  }

  // ------------------------------------------------------------------ chart
  function chartSeries() {
    const T = M.T, out = [];
    if (n <= 20) {
      for (let i = 0; i < n; i++) {
        const y = new Float32Array(T);
        for (let k = 0; k < T; k++) y[k] = M.err[k * n + i];
        out.push({ y, color: colors[i], vehicle: i });
      }
    } else {
      const mx = new Float32Array(T), mean = new Float32Array(T);
      for (let k = 0; k < T; k++) {
        let m = NaN, sum = 0, c = 0;
        for (let i = 0; i < n; i++) {
          const e = M.err[k * n + i];
          if (Number.isFinite(e)) { m = Number.isFinite(m) ? Math.max(m, e) : e; sum += e; c++; }
        }
        mx[k] = m; mean[k] = c ? sum / c : NaN;
      }
      out.push({ y: mx, color: "#c00000", label: "largest" }, { y: mean, color: "#333", label: "mean" });
    }
    return out;
  }

  function drawChart() {
    // The lines are drawn once into an off-screen canvas (again when the selection or
    // the size changes); each frame copies it and draws the time cursor.
    const box = $("chart-box"), w = box.clientWidth, h = box.clientHeight;
    const dpr = window.devicePixelRatio || 1, pad = 14;
    if (!chartCache) {
      const series = chartSeries();
      let top = 0;
      for (const s of series) for (const v of s.y) if (Number.isFinite(v) && v > top) top = v;
      top = top > 0 ? top * 1.05 : 1;
      chartCache = { series, top, image: null, selected: null };
    }
    const X = (t) => (w * (t - t0)) / span, Y = (v) => h - pad - ((h - 2 * pad) * v) / chartCache.top;
    if (!chartCache.image || chartCache.selected !== selected) {
      const { series, top } = chartCache;
      const image = document.createElement("canvas");
      image.width = Math.max(1, Math.round(w * dpr)); image.height = Math.max(1, Math.round(h * dpr));
      const g = image.getContext("2d");
      g.setTransform(dpr, 0, 0, dpr, 0, 0);
      g.fillStyle = "#fff"; g.fillRect(0, 0, w, h);
      g.strokeStyle = "#e0e0e0"; g.lineWidth = 1;
      g.beginPath(); g.moveTo(0, Y(0)); g.lineTo(w, Y(0)); g.moveTo(0, Y(top / 1.05)); g.lineTo(w, Y(top / 1.05)); g.stroke();
      for (const e of events) {
        if (e.kind !== "collision") continue;
        g.strokeStyle = "rgba(225,0,0,0.35)"; g.beginPath(); g.moveTo(X(e.t), pad); g.lineTo(X(e.t), h - pad); g.stroke();
      }
      const step = Math.max(1, Math.floor(M.T / Math.max(w * 2, 1)));
      const order = series.map((s, j) => j).sort((a, b) => (series[a].vehicle === selected) - (series[b].vehicle === selected));
      for (const j of order) {
        const s = series[j];
        g.strokeStyle = s.color; g.lineWidth = s.vehicle === selected ? 2.5 : 1.2;
        g.globalAlpha = selected >= 0 && s.vehicle !== undefined && s.vehicle !== selected ? 0.45 : 1;
        g.beginPath();
        let pen = false;
        for (let k = 0; k < M.T; k += step) {
          const v = s.y[k];
          if (!Number.isFinite(v)) { pen = false; continue; }
          if (pen) g.lineTo(X(M.t[k]), Y(v)); else g.moveTo(X(M.t[k]), Y(v));
          pen = true;
        }
        g.stroke();
      }
      g.globalAlpha = 1;
      g.fillStyle = "#333"; g.font = "11px system-ui, sans-serif"; g.textBaseline = "top";
      const label = series.length && series[0].label ? " (red: largest, black: mean)" : "";
      const what = M.hasSlots ? `formation error [m]${label}; top ${fmt(top / 1.05, 3)} m` : "formation error: no vehicle has a slot";
      g.fillText(what, 4, 1);
      g.textBaseline = "bottom";
      g.fillText(`${fmt(t0, 1)} s`, 2, h);
      const endLabel = `${fmt(t1, 1)} s`;
      g.fillText(endLabel, w - g.measureText(endLabel).width - 2, h);
      chartCache.image = image; chartCache.selected = selected;
    }
    const g = chartCtx;
    g.setTransform(1, 0, 0, 1, 0, 0);
    g.drawImage(chartCache.image, 0, 0);
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.strokeStyle = "#0078ff"; g.lineWidth = 2;
    g.beginPath(); g.moveTo(X(now), 0); g.lineTo(X(now), h); g.stroke();
    if (selected >= 0 && n <= 20) {
      const v = lerp(M.err, 1, 0, sampleAt(now), selected);
      if (Number.isFinite(v)) {
        g.fillStyle = colors[selected];
        g.beginPath(); g.arc(X(now), Y(v), 4, 0, 2 * Math.PI); g.fill();
        g.strokeStyle = "#000"; g.lineWidth = 1; g.stroke();
      }
    }
  }

  // ------------------------------------------------------------------ control
  function seek(time) {
    const t = Number(time);
    if (!Number.isFinite(t)) throw new Error("seek: expected a number of seconds, got " + time);
    now = Math.min(Math.max(t, t0), t1);
    render();
  }

  function setSpeed(x) {
    speed = Math.min(10, Math.max(0.1, x));
    $("speed").value = String(Math.log10(speed));
    $("speed-label").textContent = (speed < 1 ? speed.toFixed(2) : speed.toFixed(1)) + "\u00d7";
  }

  function play() {
    if (M.T < 2) return;
    if (now >= t1) now = t0;
    playing = true; lastTick = null;
    $("play").innerHTML = "&#10074;&#10074;"; $("play").setAttribute("aria-label", "pause");
  }

  function pause() {
    playing = false; lastTick = null;
    $("play").innerHTML = "&#9654;"; $("play").setAttribute("aria-label", "play");
  }

  function stepSample(dir) {
    pause();
    const s = sampleAt(now);
    let k = s.k;
    if (dir > 0) k = Math.min(M.T - 1, s.k + 1);
    else k = s.f > 0 ? s.k : Math.max(0, s.k - 1);
    seek(M.t[k]);
  }

  function nextEvent(dir) {
    const times = events.map((e) => e.t).concat(DATA.closest ? [DATA.closest.t] : []).sort((a, b) => a - b);
    const hit = dir > 0 ? times.find((t) => t > now + 1e-6) : times.reverse().find((t) => t < now - 1e-6);
    if (hit !== undefined) { pause(); seek(hit); }
  }

  function tick(ts) {
    if (playing) {
      if (lastTick !== null) {
        now += ((ts - lastTick) / 1000) * speed;
        if (now >= t1) { now = t1; pause(); }
      }
      lastTick = ts;
      render();
    }
    requestAnimationFrame(tick);
  }

  function select(name) {
    if (name === null || name === undefined) { selected = -1; follow = -1; render(); return; }
    if (!nameIndex.has(name)) throw new Error("select: no vehicle " + name);
    selected = follow = nameIndex.get(name); render();
  }

  function vehicleAt(u, v) {
    if (!drawn) return -1;
    let best = -1, bestD = Infinity;
    for (let i = 0; i < n; i++) {
      const [pu, pv] = w2p(drawn.xy[2 * i], drawn.xy[2 * i + 1]);
      const d = Math.hypot(pu - u, pv - v);
      if (d <= Math.max(radius[i] * cam.scale, 6) && d < bestD) { best = i; bestD = d; }
    }
    return best;
  }

  function wire() {
    const view = $("view");
    let drag = null;
    view.addEventListener("pointerdown", (e) => {
      drag = { x: e.clientX, y: e.clientY, cx: cam.cx, cy: cam.cy, moved: false };
      view.setPointerCapture(e.pointerId);
      view.focus({ preventScroll: true });
    });
    view.addEventListener("pointermove", (e) => {
      if (!drag) return;
      const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      if (!drag.moved && Math.hypot(dx, dy) < 4) return;
      drag.moved = true; follow = -1; view.classList.add("dragging");
      cam.cx = drag.cx - dx / cam.scale; cam.cy = drag.cy + dy / cam.scale;
      render();
    });
    view.addEventListener("pointerup", (e) => {
      if (!drag) return;
      const moved = drag.moved;
      drag = null; view.classList.remove("dragging");
      if (moved) return;
      const r = $("world").getBoundingClientRect();
      const i = vehicleAt(e.clientX - r.left, e.clientY - r.top);
      if (i >= 0) { selected = follow = i; } else { selected = -1; follow = -1; }
      render();
    });
    view.addEventListener("wheel", (e) => {
      e.preventDefault();
      const r = $("world").getBoundingClientRect();
      const u = follow >= 0 ? cam.w / 2 : e.clientX - r.left, v = follow >= 0 ? cam.h / 2 : e.clientY - r.top;
      const [wx, wy] = p2w(u, v);
      cam.scale = Math.min(cam.fitScale * 1e4, Math.max(cam.fitScale / 100, cam.scale * Math.pow(1.0015, -e.deltaY)));
      cam.cx = wx - (u - cam.w / 2) / cam.scale; cam.cy = wy + (v - cam.h / 2) / cam.scale;
      render();
    }, { passive: false });
    const timeline = $("timeline");
    let scrub = false;
    const scrubTo = (e) => {
      const r = $("track").getBoundingClientRect();
      seek(t0 + span * Math.min(1, Math.max(0, (e.clientX - r.left) / Math.max(r.width, 1))));
    };
    timeline.addEventListener("pointerdown", (e) => { scrub = true; pause(); timeline.setPointerCapture(e.pointerId); scrubTo(e); });
    timeline.addEventListener("pointermove", (e) => { if (scrub) scrubTo(e); });
    timeline.addEventListener("pointerup", () => { scrub = false; });
    const chart = $("chart");
    let chartDrag = false;
    const chartTo = (e) => {
      const r = chart.getBoundingClientRect();
      seek(t0 + span * Math.min(1, Math.max(0, (e.clientX - r.left) / Math.max(r.width, 1))));
    };
    chart.addEventListener("pointerdown", (e) => { chartDrag = true; pause(); chart.setPointerCapture(e.pointerId); chartTo(e); });
    chart.addEventListener("pointermove", (e) => { if (chartDrag) chartTo(e); });
    chart.addEventListener("pointerup", () => { chartDrag = false; });
    const button = (id, f) => $(id).addEventListener("click", (e) => { f(); e.currentTarget.blur(); render(); });
    button("play", () => (playing ? pause() : play()));
    button("back", () => stepSample(-1));
    button("forth", () => stepSample(1));
    button("fit", () => { follow = -1; fit(); });
    $("speed").addEventListener("input", (e) => setSpeed(Math.pow(10, Number(e.target.value))));
    document.addEventListener("keydown", (e) => {
      if (e.target && e.target.id === "speed" && e.key.startsWith("Arrow")) return;
      if (e.ctrlKey || e.metaKey || e.altKey) return;
      let handled = true;
      switch (e.key) {
        case " ": playing ? pause() : play(); break;
        case "ArrowRight": if (e.shiftKey) { pause(); seek(now + 1); } else stepSample(1); break;
        case "ArrowLeft": if (e.shiftKey) { pause(); seek(now - 1); } else stepSample(-1); break;
        case "+": case "=": setSpeed(SPEEDS.find((x) => x > speed + 1e-9) || 10); break;
        case "-": case "_": setSpeed(SPEEDS.slice().reverse().find((x) => x < speed - 1e-9) || 0.1); break;
        // the start or the end, seen as the page opened (not where a jump zoomed in)
        case "Home": pause(); firstView(); seek(t0); break;
        case "End": pause(); firstView(); seek(t1); break;
        case "n": nextEvent(1); break;
        case "p": nextEvent(-1); break;
        case "f": follow = -1; fit(); break;
        case "Escape": selected = -1; follow = -1; break;
        default: handled = false;
      }
      if (handled) { e.preventDefault(); render(); }
    });
    window.addEventListener("resize", () => { resize(); render(); });
  }

  // ------------------------------------------------------------------ the hook
  function needReady() { if (!M.T) throw new Error("sandboxReplay: not ready yet (await sandboxReplay.ready)"); }

  window.sandboxReplay = {
    version: 1,
    ready,
    seek(t) { needReady(); pause(); seek(t); return now; },
    play() { needReady(); play(); },
    pause() { needReady(); pause(); render(); },
    state() {
      needReady();
      const vehicles = {};
      names.forEach((name, i) => {
        const x = drawn.xy[2 * i], y = drawn.xy[2 * i + 1];
        vehicles[name] = Number.isFinite(x) && Number.isFinite(y) ? [x, y] : null;
      });
      return {
        t: drawn.t, vehicles, playing, speed, scale: cam.scale,
        selected: selected >= 0 ? names[selected] : null, following: follow >= 0 ? names[follow] : null,
      };
    },
    events() { return JSON.parse(JSON.stringify(events)); },
    worldToPixel(x1, x2) { needReady(); return w2p(x1, x2); },
    select(name) { needReady(); select(name); },
    setSpeed(x) { setSpeed(Number(x)); },
    stats() { return { frames: stats.frames, lastDrawMs: stats.lastDrawMs, meanDrawMs: stats.frames ? stats.drawMs / stats.frames : 0 }; },
  };

  async function start() {
    // Any error on the way is shown on the page and rejects ``ready`` (never a page
    // that waits for ever).
    try {
      buildHeader();
      await load();
      buildLegend();
      buildMarks();
      resize();
      firstView();
      wire();
      setSpeed(1);
      render();
    } catch (err) {
      const box = $("message");
      box.hidden = false;
      box.textContent = "This replay cannot be shown: " + (err && err.message ? err.message : err);
      document.body.dataset.ready = "error";
      rejectReady(err);
      return;
    }
    document.body.dataset.ready = "1";
    resolveReady(true);
    requestAnimationFrame(tick);
  }

  start();
})();
