"""One frame of the animation drawn: the world, the vehicles, their trails and marks.

:class:`Scene` holds what every frame of a run shares (the camera, the palette, the
static layer of obstacles and the reference path, the bands of text) and draws frame
``k``: trails, slots and targets, safe zones, the bodies with their headings, the
collision flashes and the heads-up line, on a canvas of palette indices
(:mod:`sandbox.render.palette`). :mod:`sandbox.render.animation` turns a run into such
frames and GIFs.
"""

from __future__ import annotations

import math

import numpy as np
from PIL import Image, ImageDraw

from sandbox.render.camera import (
    LARGE_FLEET,
    Camera,
    camera_track,
    drawn_obstacles,
    frame_height,
    reference_path,
    run_bands,
)
from sandbox.render.cars import car_bodies, car_lines, car_wheelbases
from sandbox.render.overlay import (
    TextStamps,
    draw_bottom_band,
)
from sandbox.render.palette import (
    BLACK,
    BLUE,
    OBSTACLE,
    OBSTACLE_EDGE,
    ORANGE,
    PATH,
    RED,
    WHITE,
    ZONE,
    build_palette,
    dash_segments,
    flat_points,
    nice_length,
    stamp_discs,
)
from sandbox.render.platoons import platoon_paths, platoon_references
from sandbox.run.constrained import constrained_mask
from sandbox.run.record import MODE_AVOID, MODE_EXTERNAL, MODE_FAILED, Run

#: How long a collision flash stays visible [s] (simulated; at least 1.5 frames).
COLLISION_FLASH = 0.3
_TRAIL_POINTS = 40  # at most about this many points per trail
_DASH_PX = (8.0, 6.0)  # reference path: dash and gap lengths [px]
_MIN_DETAIL_PX = 3.0  # bodies smaller than this radius [px] get no edge nor heading


class Scene:
    """What stays the same from frame to frame, and the drawing of one frame."""

    def __init__(
        self,
        run: Run,
        *,
        size: int,
        zones: bool,
        follow: str | None,
        trail_seconds: float,
        step: float,
        legend: bool = True,
        beams: bool = False,
        aspect: float | str = 1.0,
    ) -> None:
        if int(size) < 64:
            raise ValueError(f"size: expected at least 64 px, got {size!r}")
        self.run = run
        self.size = int(size)  # [px] the width
        self.height = frame_height(run, self.size, follow, aspect)  # [px]
        self.t = np.asarray(run.t, dtype=float)
        self.pos = np.asarray(run.pose[:, :, :2], dtype=float)
        self.theta = np.asarray(run.pose[:, :, 2], dtype=float)
        self.n = run.n_vehicles
        self.large = self.n > LARGE_FLEET
        self.rgb, self.body, self.trail_idx = build_palette(run.colors)
        self.camera = Camera.for_run(run, self.size, follow, legend, aspect)
        self.bands = run_bands(run, self.size, legend, self.height)
        self.stamps = TextStamps(self.bands.px)
        framing = camera_track(run, follow)
        self.track = None if framing is None else framing[0]
        self.radius_px = np.asarray(run.diameter, dtype=float) / 2.0 * self.camera.scale
        self.mode = np.asarray(run.mode)
        self.failed_raw = np.asarray(run.failed, dtype=bool)
        self.slot = np.asarray(run.slot, dtype=float)
        self.reference = np.asarray(run.reference, dtype=float).reshape(-1, 2)
        # Trails: a fixed sample grid, so the polylines do not shimmer between frames.
        self.trail_seconds = float(trail_seconds)
        self.trails = (
            not self.large and self.trail_seconds > 0 and self.trail_idx.shape[1] > 0
        )
        dt = float(np.median(np.diff(self.t))) if len(self.t) > 1 else 1.0
        window = self.trail_seconds / dt if dt > 0 else 1.0
        self.trail_stride = max(1, int(math.ceil(window / _TRAIL_POINTS)))
        self.trail_start = np.searchsorted(self.t, self.t - self.trail_seconds)
        self.trail_width = 2 if self.n <= 20 else 1
        # Recovery zones.
        rec = run.info.get("recovery") if isinstance(run.info, dict) else None
        rec = rec if isinstance(rec, dict) else {}
        self.strategy = recovery_label(run, str(rec.get("strategy", "-")))
        # The vehicles a safety filter constrained (a black ring), None: never.
        self.constrained = constrained_mask(run)
        self.zone_radii = [
            float(v) for v in (rec.get("R"), rec.get("r")) if v is not None and v > 0
        ]
        self.zones = bool(zones) and not self.large and bool(self.zone_radii)
        # Range-sensor beams (a run recorded with sensors.range).
        self.beams = (
            bool(beams)
            and not self.large
            and run.ranges is not None
            and run.beam_angles is not None
        )
        if self.beams:
            self.ranges = np.asarray(run.ranges, dtype=float)
            self.beam_angles = np.asarray(run.beam_angles, dtype=float)
            self.reach = _beam_reach(run, self.ranges)
        # Cars (model: bicycle): chassis and wheels, the front one steered.
        self.wheelbase = car_wheelbases(run)
        if self.wheelbase is not None:
            self.steer = np.asarray(run.steer, dtype=float)
            self.diameter = np.asarray(run.diameter, dtype=float)
        # Static geometry.
        self.obstacles = drawn_obstacles(run)
        path = reference_path(run)
        on, off = (v / self.camera.scale for v in _DASH_PX)
        self.dashes = (
            np.zeros((0, 2, 2)) if path is None else dash_segments(path, on, off)
        )
        paths = platoon_paths(run)  # with platoons: every platoon's reference
        if paths is not None:
            self.reference = platoon_references(run)
            self.dashes = np.concatenate(
                [np.zeros((0, 2, 2))] + [dash_segments(p, on, off) for _, p in paths]
            )
        self.bar = nice_length(0.22 * self.size / self.camera.scale)
        self.bottom_band = draw_bottom_band(
            self.bands,
            bar_m=self.bar,
            bar_px=self.bar * self.camera.scale,
            white=WHITE,
            black=BLACK,
            marks={"path": PATH, "orange": ORANGE, "blue": BLUE, "red": RED},
        )
        # Collisions: where and when to flash.
        self._prepare_events(step)
        label = run.info.get("scenario_name") if isinstance(run.info, dict) else None
        self.hud_prefix = str(label) if label else ""
        # Reconfiguration on the heads-up line: who leads (after a handover) and how
        # many reassignments so far (runs without them draw neither).
        info = run.info if isinstance(run.info, dict) else {}
        leads = info.get("leader_changes") or []
        self.lead_t = np.array([c["t"] for c in leads], dtype=float)
        self.lead_to = [c["to"] or "reference" for c in leads]
        moves = info.get("reassignments") or []
        self.reassign_t = np.array([e["t"] for e in moves], dtype=float)
        self.background = (
            None if self.track is not None else self._background(self.camera)
        )

    # ------------------------------------------------------------ preparation
    def _prepare_events(self, step: float) -> None:
        index = {name: k for k, name in enumerate(self.run.names)}
        times, where, reach = [], [], []
        for ev in self.run.events:
            k = int(np.clip(np.searchsorted(self.t, ev.t), 0, len(self.t) - 1))
            bodies = [index[x] for x in (ev.a, ev.b) if x in index]
            if not bodies:
                continue
            p = self.pos[k, bodies].mean(axis=0)
            if not np.isfinite(p).all():
                continue
            times.append(float(ev.t))
            where.append(p)
            reach.append(float(self.radius_px[bodies].max()))
        order = np.argsort(times, kind="stable")
        self.flash_t = np.asarray(times, dtype=float)[order]
        self.flash_at = np.asarray(where, dtype=float).reshape(-1, 2)[order]
        self.flash_r = np.asarray(reach, dtype=float)[order]
        self.event_t = np.sort(np.array([float(e.t) for e in self.run.events]))
        self.flash_for = max(COLLISION_FLASH, 1.5 * step)

    def _background(self, cam: Camera) -> Image.Image:
        """White canvas with obstacles and reference path."""
        img = Image.new("L", (self.size, self.height), WHITE)
        draw = ImageDraw.Draw(img)
        for kind, geom in self.obstacles:
            if kind == "circle":
                (cx, cy), r = geom
                u, v = cam.world_to_pixel([cx, cy]) - 0.5
                rp = r * cam.scale
                draw.ellipse(
                    [u - rp, v - rp, u + rp, v + rp],
                    fill=OBSTACLE,
                    outline=OBSTACLE_EDGE,
                )
            else:
                pts = flat_points(cam.world_to_pixel(geom))
                draw.polygon(pts, fill=OBSTACLE, outline=OBSTACLE_EDGE)
        if len(self.dashes):
            seg = cam.world_to_pixel(self.dashes)  # (k, 2, 2)
            lo, hi = seg.min(axis=1), seg.max(axis=1)
            edge = np.array([self.size, self.height]) + 2
            seen = (hi > -2).all(axis=1) & (lo < edge).all(axis=1)
            for a in seg[seen]:
                draw.line(flat_points(a), fill=PATH, width=1)
        return img

    # ------------------------------------------------------------ one frame
    def draw(self, k: int) -> np.ndarray:
        """Palette-index canvas (height, size) uint8 of recorded sample ``k``."""
        cam = self.camera
        if self.track is not None:
            cam = cam.centered_on(self.track[k])
            img = self._background(cam)
        else:
            assert self.background is not None
            img = self.background.copy()
        failed = self.failed_raw[k] | (self.mode[k] == MODE_FAILED)
        avoid = (self.mode[k] == MODE_AVOID) & ~failed
        external = (self.mode[k] == MODE_EXTERNAL) & ~failed
        ring = np.where(external, BLUE, ORANGE)
        ringed = avoid | external
        if self.constrained is not None:
            filtered = self.constrained[k] & ~failed & ~external
            ring = np.where(filtered, BLACK, ring)
            ringed = ringed | filtered
        draw = ImageDraw.Draw(img)
        draw.fontmode = "1"
        if self.trails:
            self._draw_trails(draw, cam, k)
        ref = self.reference[k] if k < len(self.reference) else np.full(2, np.nan)
        for point in np.reshape(ref, (-1, 2)):  # one per platoon with platoons:
            if np.isfinite(point).all():
                u, v = cam.world_to_pixel(point) - 0.5
                draw.line([u - 4, v, u + 4, v], fill=PATH, width=1)
                draw.line([u, v - 4, u, v + 4], fill=PATH, width=1)
        if self.zones:
            self._draw_zones(draw, cam, k, avoid, failed)
        if self.beams:
            self._draw_beams(draw, cam, k)
        centers = cam.world_to_pixel(self.pos[k])
        radius = np.maximum(self.radius_px, 0.75)  # [px] every body shows
        halo = max(2.0, min(4.0, 0.25 * float(np.median(radius))))  # [px]
        if self.large:  # vectorized stamps; no slot marks
            canvas = np.array(img)
            stamp_discs(
                canvas,
                centers,
                radius,
                fill=self.body,
                edge=np.full(self.n, BLACK),
                heading=self.theta[k],
                heading_width=np.maximum(2.0, 0.2 * radius),
                detail=radius >= _MIN_DETAIL_PX,
                halo=ringed,
                halo_width=halo,
                halo_color=ring,
            )
            img = Image.fromarray(canvas)
            draw = ImageDraw.Draw(img)
            draw.fontmode = "1"
        else:
            self._draw_slots(draw, cam.world_to_pixel(self.slot[k]))
            self._draw_bodies(draw, centers, radius, self.theta[k], ringed, halo, ring)
            if self.wheelbase is not None:
                self._draw_cars(draw, cam, k, radius)
        self._draw_failures(draw, centers[failed], radius[failed])
        self._draw_flashes(draw, cam, self.t[k])
        self._draw_hud(draw, img, self.t[k])
        img.paste(self.bottom_band, (0, self.height - self.bands.bottom))
        return np.asarray(img)

    def _draw_slots(self, draw: ImageDraw.ImageDraw, slots: np.ndarray) -> None:
        ring = np.clip(0.35 * self.radius_px, 3.0, 8.0)  # [px]
        for i in np.flatnonzero(np.isfinite(slots).all(axis=1)):
            u, v = slots[i] - 0.5
            r = ring[i]
            width = 2 if r >= 5 else 1
            draw.ellipse(
                [u - r, v - r, u + r, v + r], outline=int(self.body[i]), width=width
            )

    def _draw_bodies(
        self,
        draw: ImageDraw.ImageDraw,
        centers: np.ndarray,
        radius: np.ndarray,
        theta: np.ndarray,
        avoid: np.ndarray,
        halo: float,
        ring: np.ndarray | None = None,
    ) -> None:
        """Bodies (fill, black edge, heading line) and rings of avoiders.

        The ring is orange, or the palette index ``ring[i]`` (blue for vehicles in
        external mode, black for those a safety filter constrained).
        """
        ok = np.isfinite(centers).all(axis=1) & np.isfinite(theta)
        for i in np.flatnonzero(ok):
            u, v = centers[i] - 0.5
            r = float(radius[i])
            if avoid[i]:
                h = r + halo
                color = ORANGE if ring is None else int(ring[i])
                draw.ellipse([u - h, v - h, u + h, v + h], fill=color)
            box = [u - r, v - r, u + r, v + r]
            if r < _MIN_DETAIL_PX:
                draw.ellipse(box, fill=int(self.body[i]))
                continue
            draw.ellipse(box, fill=int(self.body[i]), outline=BLACK, width=1)
            tip = (u + r * math.cos(theta[i]), v - r * math.sin(theta[i]))
            width = max(2, int(round(0.2 * r)))
            draw.line([u, v, *tip], fill=BLACK, width=width)

    def _draw_cars(
        self, draw: ImageDraw.ImageDraw, cam: Camera, k: int, radius: np.ndarray
    ) -> None:
        """The cars' chassis and wheels (:func:`~sandbox.render.cars.car_lines`)."""
        pose = np.column_stack((self.pos[k], self.theta[k]))
        steer = self.steer[k]
        cars = np.flatnonzero(np.isfinite(steer))
        bodies = car_bodies(pose, steer, self.wheelbase, self.diameter)
        for i, corners in zip(cars, cam.world_to_pixel(bodies), strict=True):
            draw.polygon(flat_points(corners), outline=int(self.body[i]), width=1)
        chassis, wheels = car_lines(pose, steer, self.wheelbase, self.diameter)
        r = float(np.median(radius))
        thin, thick = max(1, round(0.12 * r)), max(2, round(0.3 * r))
        for width, lines in ((thin, chassis), (thick, wheels)):
            for a in cam.world_to_pixel(lines):
                draw.line(flat_points(a), fill=BLACK, width=width)

    def _draw_trails(self, draw: ImageDraw.ImageDraw, cam: Camera, k: int) -> None:
        k0 = int(self.trail_start[k])
        stride = self.trail_stride
        grid = np.arange(-(-k0 // stride) * stride, k, stride)
        idx = np.concatenate((grid, [k]))
        if len(idx) < 2:
            return
        pts = cam.world_to_pixel(self.pos[idx]) - 0.5  # (m, n, 2), ImageDraw's pixels
        age = self.t[k] - self.t[idx[1:]]  # each segment takes its newer end's age
        levels = self.trail_idx.shape[1]
        band = np.minimum((age / self.trail_seconds * levels).astype(int), levels - 1)
        cuts = np.flatnonzero(np.diff(band)) + 1
        for seg in np.split(np.arange(len(band)), cuts):
            b = band[seg[0]]
            chunk = pts[seg[0] : seg[-1] + 2]  # points of the segments, ends shared
            good = np.isfinite(chunk).all(axis=(0, 2))
            for i in np.flatnonzero(good):
                draw.line(
                    chunk[:, i].ravel().tolist(),
                    fill=int(self.trail_idx[i, b]),
                    width=self.trail_width,
                )

    def _draw_zones(
        self,
        draw: ImageDraw.ImageDraw,
        cam: Camera,
        k: int,
        avoid: np.ndarray,
        failed: np.ndarray,
    ) -> None:
        centers = cam.world_to_pixel(self.pos[k]) - 0.5
        for i in range(self.n):
            if failed[i] or not np.isfinite(centers[i]).all():
                continue
            color = ORANGE if avoid[i] else ZONE
            u, v = centers[i]
            for rz in self.zone_radii:
                rp = rz * cam.scale
                draw.ellipse([u - rp, v - rp, u + rp, v + rp], outline=color, width=1)

    def _draw_beams(self, draw: ImageDraw.ImageDraw, cam: Camera, k: int) -> None:
        """Each beam from the centre to its reading; a red dot where it hit."""
        r = self.ranges[k]  # (n, B) [m]
        angle = self.theta[k][:, None] + self.beam_angles
        ray = np.stack((np.cos(angle), np.sin(angle)), -1)
        ends = cam.world_to_pixel(self.pos[k][:, None, :] + r[..., None] * ray) - 0.5
        centers = cam.world_to_pixel(self.pos[k]) - 0.5
        hit = r < self.reach[:, None] - 1e-6
        dot = 1.5 if self.size < 400 else 2.0  # [px]
        for i, b in zip(*np.nonzero(np.isfinite(r)), strict=True):
            if not (np.isfinite(centers[i]).all() and np.isfinite(ends[i, b]).all()):
                continue
            draw.line([*centers[i], *ends[i, b]], fill=ZONE, width=1)
        for i, b in zip(*np.nonzero(hit), strict=True):
            u, v = ends[i, b]
            draw.ellipse([u - dot, v - dot, u + dot, v + dot], fill=RED)

    def _draw_failures(
        self, draw: ImageDraw.ImageDraw, centers: np.ndarray, radius: np.ndarray
    ) -> None:
        for c, r in zip(centers, radius, strict=True):
            if not np.isfinite(c).all():
                continue
            u, v = c - 0.5
            h = max(float(r), 5.0)
            width = max(2, int(round(0.22 * h)))
            draw.line([u - h, v - h, u + h, v + h], fill=BLACK, width=width)
            draw.line([u - h, v + h, u + h, v - h], fill=BLACK, width=width)

    def _draw_flashes(self, draw: ImageDraw.ImageDraw, cam: Camera, now: float) -> None:
        if len(self.flash_t) == 0:
            return
        lo = np.searchsorted(self.flash_t, now - self.flash_for, side="right")
        hi = np.searchsorted(self.flash_t, now, side="right")
        for j in range(lo, hi):
            u, v = cam.world_to_pixel(self.flash_at[j]) - 0.5
            rho = max(8.0, 1.4 * float(self.flash_r[j]))
            draw.ellipse([u - rho, v - rho, u + rho, v + rho], outline=RED, width=2)
            for a in np.arange(8) * (np.pi / 4):
                c, s = math.cos(a), math.sin(a)
                draw.line(
                    [
                        u + 1.2 * rho * c,
                        v + 1.2 * rho * s,
                        u + 1.7 * rho * c,
                        v + 1.7 * rho * s,
                    ],
                    fill=RED,
                    width=2,
                )

    def _draw_hud(
        self, draw: ImageDraw.ImageDraw, img: Image.Image, now: float
    ) -> None:
        """The heads-up line: scenario, time, collisions, lead, recovery strategy.

        The lead and the number of reassignments so far only with such events.
        """
        hits = int(np.searchsorted(self.event_t, now, side="right"))
        draw.rectangle([0, 0, self.size - 1, self.bands.top - 1], fill=WHITE)
        x, y = max(4, int(0.02 * self.size)), 3
        if self.hud_prefix:
            x = self.stamps.paste(img, (x, y), self.hud_prefix, BLACK)
        x = self.stamps.paste(img, (x, y), "t =", BLACK) - self.bands.px // 2
        x = self.stamps.paste_number(img, (x, y), f"{now:.2f}", BLACK)
        x = self.stamps.paste(img, (x, y), " s", BLACK)
        x = self.stamps.paste(img, (x, y), f"collisions: {hits}", BLACK)
        led = int(np.searchsorted(self.lead_t, now, side="right"))
        if led:
            x = self.stamps.paste(img, (x, y), f"lead: {self.lead_to[led - 1]}", BLACK)
        if len(self.reassign_t):
            moved = int(np.searchsorted(self.reassign_t, now, side="right"))
            x = self.stamps.paste(img, (x, y), f"reassigned: {moved}", BLACK)
        for last in (f"recovery: {self.strategy}", "recovery: per platoon"):
            if x + self.stamps.mask(last).width <= self.size:  # whole, or not at all
                self.stamps.paste(img, (x, y), last, BLACK)
                break
            if ":" not in self.strategy:  # one strategy: no shorter form
                break

    def to_rgb(self, canvas: np.ndarray) -> np.ndarray:
        """RGB image (H, W, 3) uint8 of a palette-index canvas."""
        img = Image.fromarray(canvas)
        img.putpalette(self.rgb.tobytes())
        return np.asarray(img.convert("RGB"))


def recovery_label(run: Run, top: str) -> str:
    """The recovery strategy the heads-up line names: ``top``, or each platoon's.

    With ``platoons:`` whose strategies differ, each platoon's by its name
    (``"east: continuous, north: none"``); one strategy shared by every platoon is
    named once, as is the top-level ``top`` of a run of one platoon.
    """
    sc = run.scenario
    groups = getattr(sc, "platoons", ()) if sc is not None else ()
    if not groups:
        return top
    own = [(g.name, g.scenario.recovery.strategy) for g in groups]
    if len({strategy for _, strategy in own}) == 1:
        return own[0][1]
    return ", ".join(f"{name}: {strategy}" for name, strategy in own)


def _beam_reach(run: Run, ranges: np.ndarray) -> np.ndarray:
    """Each vehicle's ``max_range`` [m] (a reading there hit nothing), shape (n,)."""
    specs = None
    if run.scenario is not None and hasattr(run.scenario, "range_specs"):
        specs = run.scenario.range_specs()
    if specs is not None and len(specs) == run.n_vehicles:
        return np.array([np.inf if s is None else s.max_range for s in specs])
    with np.errstate(all="ignore"):  # no scenario: the longest reading seen
        reach = np.nanmax(ranges, axis=(0, 2)) if ranges.size else np.zeros(0)
    return np.where(np.isfinite(reach), reach, np.inf)
