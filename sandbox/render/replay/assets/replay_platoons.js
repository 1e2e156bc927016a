// Several platoons (platoons:): pieces the page's Python inserts into replay.js at the
// anchor line that follows each (after it, before it, or instead of it). Every
// platoon's reference path and point are drawn in its colour, and the legend names
// each; a page of one platoon keeps replay.js as it is, byte for byte.
// @@ after:     M.hasPlatoon = M.slotIndex.some((s) => s >= 0);
    // each platoon's reference point, shape (T, P, 2) [m]; NaN while it does not exist
    M.platoonRef = await unpack(A.platoon_reference, Float32Array);
    M.platoonSeen = PLATOONS.map((_, p) => M.t.some((_, k) => Number.isFinite(M.platoonRef[2 * (k * PLATOONS.length + p)])));
// @@ before:   function drawTrails(s, xy) {
  const PLATOONS = DATA.platoons;
  const platoonDrawn = { paths: [], points: {} }; // what the last frame drew (the hook)

  function drawPlatoonPaths() {
    // each platoon's path through its finite samples (a gap where it is NaN), dashed
    const P = PLATOONS.length;
    platoonDrawn.paths = [];
    ctx.setLineDash([8, 6]); ctx.lineWidth = 1.5;
    for (let p = 0; p < P; p++) {
      let pen = false, count = 0;
      ctx.beginPath();
      for (let k = 0; k < M.T; k++) {
        const x = M.platoonRef[2 * (k * P + p)], y = M.platoonRef[2 * (k * P + p) + 1];
        if (!Number.isFinite(x) || !Number.isFinite(y)) { pen = false; continue; }
        const [u, v] = w2p(x, y);
        if (pen) ctx.lineTo(u, v); else ctx.moveTo(u, v);
        pen = true; count += 1;
      }
      if (count < 2) continue;
      ctx.strokeStyle = PLATOONS[p].color; ctx.stroke();
      platoonDrawn.paths.push(PLATOONS[p].name);
    }
    ctx.setLineDash([]);
  }

  function platoonRefAt(s, p, c) {
    const P = PLATOONS.length, a = M.platoonRef[2 * (s.k * P + p) + c];
    if (s.f === 0 || s.k + 1 >= M.T) return a;
    const b = M.platoonRef[2 * ((s.k + 1) * P + p) + c];
    if (!Number.isFinite(a) || !Number.isFinite(b)) return s.f < 0.5 ? a : b;
    return a + (b - a) * s.f;
  }

  function drawPlatoonReferences(s) {
    // each existing platoon's reference point: a cross in its colour
    platoonDrawn.points = {};
    ctx.lineWidth = 1.5;
    PLATOONS.forEach((pl, p) => {
      const rx = platoonRefAt(s, p, 0), ry = platoonRefAt(s, p, 1);
      if (!Number.isFinite(rx) || !Number.isFinite(ry)) return;
      const [u, v] = w2p(rx, ry);
      ctx.strokeStyle = pl.color;
      ctx.beginPath(); ctx.moveTo(u - 6, v); ctx.lineTo(u + 6, v); ctx.moveTo(u, v - 6); ctx.lineTo(u, v + 6); ctx.stroke();
      platoonDrawn.points[pl.name] = [rx, ry];
    });
  }

// @@ instead:     drawPath();
    drawPlatoonPaths();
// @@ instead:     drawReference(s);
    drawPlatoonReferences(s);
// @@ instead:     if (DATA.reference_path) rows.push(`<div>${svg('<path d="M0 7H5M9 7H14" stroke="#808080"/>')}reference path</div>`);
    PLATOONS.forEach((pl, p) => {
      if (!M.platoonSeen[p]) return;
      const when = [pl.since !== null ? `from ${fmt(pl.since, 2)} s` : "", pl.until !== null ? `until ${fmt(pl.until, 2)} s` : ""].filter(Boolean).join(", ");
      rows.push(`<div>${svg(`<path d="M0 7H5M9 7H14" stroke="${pl.color}" stroke-width="1.5"/>`)}${esc(pl.name)} reference${when ? ` (${when})` : ""}</div>`);
    });
// @@ before:   async function start() {
  // the platoons' references the last frame drew: {paths: [names], points: {name: [x1, x2]}}
  window.sandboxReplay.platoons = () => { needReady(); return JSON.parse(JSON.stringify(platoonDrawn)); };

