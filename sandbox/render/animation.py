"""Headless animation of a recorded run: frames in memory and animated GIFs.

This module and its helpers are the only ones that draw frames: the camera and framing
(:mod:`sandbox.render.camera`), the palette and drawing primitives
(:mod:`sandbox.render.palette`), the text bands (:mod:`sandbox.render.overlay`: the
heads-up line, the scale bar and the legend strip) and the GIF encoder
(:mod:`sandbox.render.gif_stream`); :mod:`sandbox.render.video` writes the same frames
as MP4. They read a :class:`sandbox.run.record.Run` and never touch the simulation.
Frames are drawn with Pillow's ``ImageDraw`` (and, for large fleets, vectorized numpy
stamps of the bodies) on a canvas of palette indices: every colour a frame can contain
is known before drawing starts (white, black, greys, orange, red, blue, each vehicle's
colour and a few paler shades of it for trails), so no per-frame quantization is needed
and the GIF palette is exact. Drawing is not antialiased (that would need blended
colours outside the palette).

Timing
------
Frame ``k`` shows simulated time ``t0 + k * speed / fps`` [s] (the recorded sample
nearest to it), except the last frame, which always shows the final sample. A run
lasting ``D`` seconds gives ``round(D * fps / speed)`` frames, each displayed
``1 / fps`` seconds: a 20 s run at 25 fps gives 500 frames of 40 ms (20 s in all);
``speed=2`` gives 250 frames of 40 ms (10 s), i.e. the frame interval stays ``1 / fps``
and there are fewer frames.

GIF delays are whole centiseconds. Frame ``k`` is given the delay
``round((k + 1) * 100 / fps) - round(k * 100 / fps)`` [cs], so delays are exact when
``100 / fps`` is an integer (25 fps: 4 cs = 40 ms; 20 fps: 50 ms; 50 fps: 20 ms) and
otherwise alternate (30 fps: 30, 40, 30, ... ms) so that the total stays within 5 ms of
``frames / fps``. :func:`write_gif` accepts ``0 < fps <= 50`` because browsers slow
down delays under 20 ms. A frame identical to the previous one (a run recorded more
coarsely than the frame rate) is merged into it and their delays are added, so the GIF
may hold fewer frames than :func:`render_frames` yields; the total duration is
unchanged.

Large fleets
------------
Above :data:`LARGE_FLEET` vehicles, trails, slot marks and avoidance zones are not
drawn; bodies (with heading lines and avoidance rings) are stamped with numpy for all
vehicles at once; failure marks and collision flashes are still drawn.
"""

from __future__ import annotations

import math
import os
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sandbox.render.camera import (
    AUTO_FOLLOW_ASPECT,
    LARGE_FLEET,
    Camera,
    auto_follow,
)
from sandbox.render.gif_stream import GifStream as _GifStream
from sandbox.render.scene import Scene
from sandbox.run.record import Run

__all__ = [
    "AUTO_FOLLOW_ASPECT",
    "Camera",
    "auto_follow",
    "FramePlan",
    "LARGE_FLEET",
    "frame_plan",
    "render_frames",
    "write_gif",
]

#: Highest frame rate :func:`write_gif` accepts [1/s] (browsers slow delays < 20 ms).
MAX_GIF_FPS = 50.0
#: Frames encoded per imageio call in :func:`write_gif` (bounds memory on long runs).
GIF_CHUNK = 128


# ---------------------------------------------------------------------------- timing
@dataclass(frozen=True)
class FramePlan:
    """Which sample each frame shows, and for how long.

    Attributes
    ----------
    times : ndarray, shape (K,) [s]
        Simulated time of each frame.
    index : ndarray, shape (K,), int
        Recorded sample shown by each frame (nearest to ``times``).
    durations_ms : ndarray, shape (K,), int [ms]
        Display time of each frame, whole centiseconds (GIF delays).
    """

    times: np.ndarray
    index: np.ndarray
    durations_ms: np.ndarray

    def __len__(self) -> int:
        """Return the number of frames ``K``."""
        return len(self.times)


def frame_plan(run: Run, fps: float = 25.0, speed: float = 1.0) -> FramePlan:
    """Frame times, samples and GIF delays of an animation of ``run``.

    Parameters
    ----------
    run : Run
    fps : float [1/s]
        Frames per second of playback.
    speed : float
        Simulated seconds per second of playback.

    Returns
    -------
    FramePlan
        ``round(D * fps / speed)`` frames (at least one) for a run lasting ``D``
        seconds; see the module docstring.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0.0, 20.0, 2001)
    >>> plan = frame_plan(type("R", (), {"t": t})(), fps=25.0)
    >>> len(plan), int(plan.durations_ms.sum()), int(plan.durations_ms[0])
    (500, 20000, 40)
    """
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps: expected a positive number, got {fps!r}")
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed: expected a positive number, got {speed!r}")
    t = np.asarray(run.t, dtype=float)
    if t.size == 0:
        raise ValueError("the run has no samples")
    step = speed / fps  # [s] simulated time per frame
    count = max(1, int(round((t[-1] - t[0]) / step)))
    times = t[0] + step * np.arange(count)
    times[-1] = t[-1]  # the end state is always shown
    right = np.clip(np.searchsorted(t, times), 1, max(len(t) - 1, 1))
    left = right - 1
    nearer_left = np.abs(times - t[left]) <= np.abs(
        t[np.minimum(right, len(t) - 1)] - times
    )
    index = np.where(nearer_left, left, right).clip(0, len(t) - 1)
    centis = np.round(np.arange(count + 1) * 100.0 / fps).astype(np.int64)
    return FramePlan(times, index, np.diff(centis) * 10)


def _check_follow(follow: str | None) -> None:
    if follow is not None and not isinstance(follow, str):
        raise ValueError(
            f"follow: expected None, 'auto', 'leader' or a vehicle name, got {follow!r}"
        )


def indexed_frames(
    run: Run,
    plan: FramePlan,
    *,
    size: int,
    zones: bool,
    follow: str | None,
    trail_seconds: float,
    speed: float,
    fps: float,
    legend: bool = True,
    show_beams: bool = False,
    aspect: float | str = 1.0,
) -> tuple[Scene, Iterator[np.ndarray]]:
    _check_follow(follow)
    scene = Scene(
        run,
        size=size,
        zones=zones,
        follow=follow,
        trail_seconds=trail_seconds,
        step=speed / fps,
        legend=legend,
        beams=show_beams,
        aspect=aspect,
    )
    return scene, (scene.draw(int(k)) for k in plan.index)


# ------------------------------------------------------------------------- public API
def render_frames(
    run: Run,
    *,
    fps: float = 25.0,
    size: int = 640,
    speed: float = 1.0,
    zones: bool = False,
    follow: str | None = None,
    trail_seconds: float = 3.0,
    legend: bool = True,
    show_beams: bool = False,
    aspect: float | str = 1.0,
) -> Iterator[np.ndarray]:
    """Frames of an animation of ``run``, drawn lazily.

    Parameters
    ----------
    run : Run
    fps : float [1/s]
        Frames per second of playback.
    size : int [px]
        Width of every frame.
    speed : float
        Playback speed: simulated seconds per second of playback (2 plays twice as fast,
        with half the frames).
    zones : bool
        Draw each vehicle's avoidance radii ``R`` (and ``r``) from ``info["recovery"]``
        as thin circles: orange while the vehicle is avoiding, light grey otherwise.
    follow : {None, "auto", "leader"} or str
        Camera, see :meth:`Camera.for_run`.
    trail_seconds : float [s]
        Length of the fading trails (0 disables them).
    legend : bool
        Draw the legend strip at the bottom: each vehicle's name by its colour (or the
        fleet's size above :data:`~sandbox.render.overlay.LEGEND_NAMES_MAX` vehicles)
        and what the marks the run shows mean.
    show_beams : bool
        Draw the range sensors' beams of a run recorded with ``sensors.range``: a
        thin grey line from each vehicle's centre to each reading, a red dot where
        the beam hit (not drawn above :data:`~sandbox.render.camera.LARGE_FLEET`
        vehicles, nor for runs without scans).
    aspect : float or "run"
        Width over height of the frames: 1 (square, the default), a number from 1/4
        to 4, or ``"run"``, the aspect of the whole run's area when the camera frames
        it whole (:func:`~sandbox.render.camera.frame_height`).

    Yields
    ------
    ndarray, shape (height, size, 3), uint8
        One RGB frame per entry of :func:`frame_plan`.
    """
    plan = frame_plan(run, fps, speed)
    scene, frames = indexed_frames(
        run,
        plan,
        size=size,
        zones=zones,
        follow=follow,
        trail_seconds=trail_seconds,
        speed=speed,
        fps=fps,
        legend=legend,
        show_beams=show_beams,
        aspect=aspect,
    )
    for canvas in frames:
        yield scene.to_rgb(canvas)


def render_frame(
    run: Run,
    k: int = -1,
    *,
    size: int = 640,
    zones: bool = False,
    follow: str | None = None,
    trail_seconds: float = 3.0,
    legend: bool = True,
    show_beams: bool = False,
) -> np.ndarray:
    """One RGB frame of recorded sample ``k`` (default the last), as drawn in a GIF.

    Parameters are those of :func:`render_frames`; the camera frames the samples of
    ``run`` (or follows ``follow``). Used for the ``rgb_array`` render mode of the
    environments in :mod:`sandbox.envs`, which pass the episode so far.

    Returns
    -------
    ndarray, shape (size, size, 3), uint8
    """
    _check_follow(follow)
    scene = Scene(
        run,
        size=size,
        zones=zones,
        follow=follow,
        trail_seconds=trail_seconds,
        step=1.0 / 25.0,
        legend=legend,
        beams=show_beams,
    )
    return scene.to_rgb(scene.draw(int(k) % len(run.t)))


def write_gif(
    run: Run,
    path: str | os.PathLike[str],
    *,
    fps: float = 25.0,
    size: int = 640,
    speed: float = 1.0,
    zones: bool = False,
    follow: str | None = None,
    trail_seconds: float = 3.0,
    legend: bool = True,
    progress: Callable[[int, int], None] | None = None,
    show_beams: bool = False,
    aspect: float | str = 1.0,
) -> dict[str, Any]:
    """Write an animated GIF of ``run``, atomically.

    The GIF loops forever and uses one global palette: the run's fixed colours. imageio
    (its Pillow plugin) encodes the frames, :data:`GIF_CHUNK` at a time so memory stays
    bounded on long runs; the chunks are joined into one GIF stream written to a
    temporary file next to ``path``, which then replaces ``path``.

    Parameters
    ----------
    run : Run
    path : str or os.PathLike
        Output file; its directory is created if needed.
    fps : float [1/s]
        ``0 < fps <= 50``; see the module docstring for delays.
    size, speed, zones, follow, trail_seconds, legend, show_beams, aspect
        As in :func:`render_frames`.
    progress : callable, optional
        Called as ``progress(done, total)`` about a hundred times, in planned frames.

    Returns
    -------
    dict
        ``{"frames": k, "duration": seconds, "path": str}``: frames written (consecutive
        identical frames are merged), total display time [s] and the output path.
    """
    if not (0 < fps <= MAX_GIF_FPS):
        raise ValueError(
            f"fps: expected 0 < fps <= {MAX_GIF_FPS:g} for a GIF, got {fps!r}"
        )
    path = Path(path)
    plan = frame_plan(run, fps, speed)
    scene, frames = indexed_frames(
        run,
        plan,
        size=size,
        zones=zones,
        follow=follow,
        trail_seconds=trail_seconds,
        speed=speed,
        fps=fps,
        legend=legend,
        show_beams=show_beams,
        aspect=aspect,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        with open(tmp, "xb") as fh:
            stream = _GifStream(fh, scene.size, scene.height, scene.rgb, loop=0)
            held: list[np.ndarray] = []
            delays: list[int] = []
            total = len(plan.durations_ms)
            every = max(1, total // 100)
            pairs = zip(frames, plan.durations_ms.tolist(), strict=True)
            for k, (canvas, ms) in enumerate(pairs, 1):
                if progress is not None and (k % every == 0 or k == total):
                    progress(k, total)
                if held and np.array_equal(canvas, held[-1]):
                    delays[-1] += ms
                    continue
                if len(held) == GIF_CHUNK:  # keep the last one: its delay may grow
                    stream.add(held[:-1], delays[:-1])
                    held, delays = held[-1:], delays[-1:]
                held.append(canvas)
                delays.append(ms)
            stream.add(held, delays)
            stream.close()
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return {
        "frames": stream.frames,
        "duration": stream.duration_ms / 1000.0,
        "path": str(path),
    }
