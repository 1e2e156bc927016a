// Cars (model: bicycle): pieces the page's Python inserts into replay.js at the anchor
// line that follows each. Each car gets its chassis from the rear axle (the disc's
// centre) to the front axle and its two wheels, the front one turned by the steering
// angle (sandbox/render/cars.py); a page without cars keeps replay.js as it is.
// @@ after:     M.hasPlatoon = M.slotIndex.some((s) => s >= 0);
    // each car's steering angle, shape (T, n) [rad]; NaN on a unicycle's row
    M.steer = await unpack(DATA.cars.steer, Float32Array);
// @@ before:   function drawBodies(s, xy, th) {
  function drawCars(s, xy, th) {
    const C = DATA.cars, k = nearest(s);
    const r = radius.length ? Math.min(...radius) * cam.scale : 1;
    ctx.strokeStyle = "#000"; ctx.lineCap = "butt";
    for (let i = 0; i < n; i++) {
      const L = C.wheelbase[i], delta = M.steer[k * n + i];
      if (L === null || !Number.isFinite(delta) || !Number.isFinite(xy[2 * i])) continue;
      const x = xy[2 * i], y = xy[2 * i + 1], a = th[i], half = 0.5 * C.wheel * 2 * radius[i];
      const fx = x + L * Math.cos(a), fy = y + L * Math.sin(a);
      const line = (x0, y0, x1, y1, w) => {
        const [u0, v0] = w2p(x0, y0), [u1, v1] = w2p(x1, y1);
        ctx.lineWidth = w; ctx.beginPath(); ctx.moveTo(u0, v0); ctx.lineTo(u1, v1); ctx.stroke();
      };
      line(x, y, fx, fy, Math.max(1, Math.round(0.12 * r)));
      const thick = Math.max(2, Math.round(0.3 * r)), c = Math.cos(a), sn = Math.sin(a);
      line(x - half * c, y - half * sn, x + half * c, y + half * sn, thick);
      const ct = Math.cos(a + delta), st = Math.sin(a + delta);
      line(fx - half * ct, fy - half * st, fx + half * ct, fy + half * st, thick);
    }
  }

// @@ after:     drawBodies(s, xy, th);
    if (M.steer && !large) drawCars(s, xy, th);
