// The range sensors' beams (sandbox run --html --show-beams): three pieces the page's
// Python inserts into replay.js after the anchor line that precedes each (a page
// without scans keeps replay.js as it is, byte for byte).
// @@ after:     M.hasPlatoon = M.slotIndex.some((s) => s >= 0);
    // range-sensor scans, shape (T, n, B) [m]
    if (DATA.beams) M.beams = await unpack(DATA.beams.ranges, Float32Array);
// @@ before:   function drawBodies(s, xy, th) {
  function drawBeams(s, xy, th) {
    const B = DATA.beams, k = nearest(s), w = B.width;
    const dot = Math.max(1.5, Math.min(3, 0.15 * radius[0] * cam.scale));
    ctx.lineWidth = 1;
    for (let i = 0; i < n; i++) {
      const reach = B.reach[i];
      if (reach === null || !Number.isFinite(xy[2 * i])) continue;
      const [u0, v0] = w2p(xy[2 * i], xy[2 * i + 1]);
      for (let b = 0; b < w; b++) {
        const r = M.beams[(k * n + i) * w + b], a = B.angles[i][b];
        if (!Number.isFinite(r) || a === null) continue;
        const [u, v] = w2p(xy[2 * i] + r * Math.cos(th[i] + a), xy[2 * i + 1] + r * Math.sin(th[i] + a));
        ctx.strokeStyle = "rgba(150,150,150,0.55)";
        ctx.beginPath(); ctx.moveTo(u0, v0); ctx.lineTo(u, v); ctx.stroke();
        if (r < reach - 1e-6) {
          ctx.fillStyle = "#d62728";
          ctx.beginPath(); ctx.arc(u, v, dot, 0, 2 * Math.PI); ctx.fill();
        }
      }
    }
  }

// @@ before:     drawContacts(xy); // under the bodies: the vehicles in contact stay visible
    if (M.beams && !large) drawBeams(s, xy, th);
