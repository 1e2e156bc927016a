"""Pictures of a recorded run: GIFs, MP4 videos, report-style figures, the replay page.

Everything here reads a :class:`~sandbox.Run` and draws it, headless; nothing here
simulates (but :mod:`~sandbox.render.gallery`, which runs the scenarios it shows)::

    from sandbox.render import plot_run, write_gif

    write_gif(run, "runs/demo.gif", fps=25, size=640)
    plot_run(run, "runs/demo")            # trajectories.png, formation_error.png, ...

The names are imported on first use, so ``import sandbox.render`` loads neither Pillow
nor matplotlib.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

#: Public name -> module it is imported from on first use.
_EXPORTS = {
    "FramePlan": "sandbox.render.animation",
    "frame_plan": "sandbox.render.animation",
    "render_frame": "sandbox.render.animation",
    "render_frames": "sandbox.render.animation",
    "write_gif": "sandbox.render.animation",
    "VideoError": "sandbox.render.video",
    "VideoUnavailable": "sandbox.render.video",
    "video_available": "sandbox.render.video",
    "write_mp4": "sandbox.render.video",
    "FIGURES": "sandbox.render.figures",
    "plot_run": "sandbox.render.figures",
    "write_html": "sandbox.render.replay",
}

__all__ = [
    "FIGURES",
    "FramePlan",
    "VideoError",
    "VideoUnavailable",
    "frame_plan",
    "plot_run",
    "render_frame",
    "render_frames",
    "video_available",
    "write_gif",
    "write_html",
    "write_mp4",
]

if TYPE_CHECKING:
    from sandbox.render.animation import (
        FramePlan,
        frame_plan,
        render_frame,
        render_frames,
        write_gif,
    )
    from sandbox.render.figures import FIGURES, plot_run
    from sandbox.render.replay import write_html
    from sandbox.render.video import (
        VideoError,
        VideoUnavailable,
        video_available,
        write_mp4,
    )


def __getattr__(name: str) -> Any:
    """Import a public name on first use (PEP 562)."""
    try:
        module = _EXPORTS[name]
    except KeyError:
        raise AttributeError(
            f"module 'sandbox.render' has no attribute {name!r}"
        ) from None
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The module's names, the lazily imported ones included."""
    return sorted({*globals(), *_EXPORTS})
