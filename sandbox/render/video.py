"""MP4 video of a recorded run: the frames of the animation, encoded as H.264.

A GIF of a long run is large (256 colours, little compression between frames); an MP4 of
the same frames is a fraction of its size and plays in every presentation program.
:func:`write_mp4` draws exactly the frames
:func:`sandbox.render.animation.render_frames` yields (same camera, legend, timing:
frame ``k`` shows simulated time ``t0 + k * speed / fps``) and pipes them to the ffmpeg
executable that the optional ``imageio-ffmpeg`` package ships (``pip install
'platoon-sandbox[video]'``). The video has a constant frame rate ``fps``; it lasts
``frames / fps`` seconds.

Encoding: H.264 (libx264) in yuv420p, constant quality (CRF 18, visually lossless for
these flat-colour frames), one encoder thread and ffmpeg's bit-exact flags, so the same
run gives the same bytes. yuv420p needs even sides: an odd ``size`` gets one white
column and row more.
"""

from __future__ import annotations

import math
import os
import subprocess
import tempfile
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from sandbox._about import install_hint
from sandbox.errors import SandboxError
from sandbox.render.animation import frame_plan, indexed_frames
from sandbox.run.record import Run

__all__ = [
    "MAX_MP4_FPS",
    "MP4_CRF",
    "VideoError",
    "VideoUnavailable",
    "require_video",
    "video_available",
    "write_mp4",
]

#: Highest frame rate :func:`write_mp4` accepts [1/s].
MAX_MP4_FPS = 120.0
#: Constant-quality factor of the H.264 encoder (0 lossless .. 51 worst).
MP4_CRF = 18


class VideoUnavailable(SandboxError):
    """MP4 output was asked for, but the optional ``imageio-ffmpeg`` is missing."""


class VideoError(SandboxError):
    """ffmpeg could not write the video (its last message says why)."""


def video_available() -> bool:
    """Whether MP4 output works here (``imageio-ffmpeg`` and its ffmpeg are present)."""
    try:
        import imageio_ffmpeg

        return bool(imageio_ffmpeg.get_ffmpeg_exe())
    except (ImportError, RuntimeError):
        return False


def require_video() -> None:
    """Raise :class:`VideoUnavailable` with the install command unless MP4 works."""
    if not video_available():
        raise VideoUnavailable(
            "MP4 output needs the optional extra 'video' (imageio-ffmpeg): "
            f"{install_hint('video')}"
        )


def write_mp4(
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
    """Write an MP4 video of ``run``, atomically (temporary file, then rename).

    Parameters
    ----------
    run : Run
    path : str or os.PathLike
        Output file; its directory is created if needed.
    fps : float [1/s]
        ``0 < fps <=`` :data:`MAX_MP4_FPS`.
    size, speed, zones, follow, trail_seconds, legend, show_beams, aspect
        As in :func:`sandbox.render.animation.render_frames`.
    progress : callable, optional
        Called as ``progress(done, total)`` about a hundred times, in frames.

    Returns
    -------
    dict
        ``{"frames": k, "duration": seconds, "path": str}``.

    Raises
    ------
    VideoUnavailable
        Without ``imageio-ffmpeg``.
    VideoError
        When ffmpeg fails (a full disk, say).
    ValueError
        On a frame rate out of range (and the renderer's own checks).
    """
    if not (math.isfinite(fps) and 0 < fps <= MAX_MP4_FPS):
        raise ValueError(
            f"fps: expected 0 < fps <= {MAX_MP4_FPS:g} for an MP4, got {fps!r}"
        )
    require_video()
    import imageio_ffmpeg

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
    wide = scene.size + scene.size % 2  # [px] yuv420p needs even sides
    high = scene.height + scene.height % 2
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    command = [
        imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-loglevel", "error", "-y",
        "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{wide}x{high}",
        "-framerate", f"{fps:.12g}", "-i", "pipe:0",
        "-an", "-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", str(MP4_CRF),
        "-threads", "1", "-fflags", "+bitexact", "-flags:v", "+bitexact",
        "-map_metadata", "-1", "-movflags", "+faststart", "-f", "mp4", str(tmp),
    ]  # fmt: skip
    count = 0
    with tempfile.TemporaryFile() as log:
        proc = subprocess.Popen(
            command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log
        )
        try:
            assert proc.stdin is not None
            frame = np.full((high, wide, 3), 255, dtype=np.uint8)
            with proc.stdin:
                total = len(plan.durations_ms)
                every = max(1, total // 100)
                for canvas in frames:
                    frame[: scene.height, : scene.size] = scene.to_rgb(canvas)
                    proc.stdin.write(frame.tobytes())
                    count += 1
                    if progress is not None and (count % every == 0 or count == total):
                        progress(count, total)
            if proc.wait() != 0:
                log.seek(0)
                lines = log.read().decode("utf-8", "replace").strip().splitlines()
                why = lines[-1] if lines else f"exit status {proc.returncode}"
                raise VideoError(f"{path}: ffmpeg failed: {why}")
            os.replace(tmp, path)
        except BaseException:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            tmp.unlink(missing_ok=True)
            raise
    return {"frames": count, "duration": count / fps, "path": str(path)}
