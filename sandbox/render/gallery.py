"""The gallery: every bundled scenario of given folders run and rendered to a GIF.

``sandbox gallery`` (default folders ``scenarios/paper`` and ``scenarios/failures``,
output ``renders/``) makes the GIFs committed in ``renders/`` and shown in the README. A
GIF over the size budget is rendered again smaller (fewer pixels, then fewer frames per
second) until it fits. A run that spreads along a line (a platoon on a straight
reference) would be drawn tiny in a square frame that holds all of it: its camera
follows what happens instead (``follow="auto"``:
:func:`sandbox.render.camera.auto_follow` chooses,
:func:`sandbox.render.camera.action_track` frames; the camera of ``sandbox run --gif``
too).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from sandbox.loop.simulation import Simulation
from sandbox.render.animation import AUTO_FOLLOW_ASPECT, auto_follow, write_gif
from sandbox.run.record import Run
from sandbox.scenario import load_scenario

#: Largest GIF the gallery keeps [bytes].
MAX_GIF_BYTES = 3_000_000
#: Above this ratio of the sides of the area a run covers, the camera follows the
#: leader.
MAX_ASPECT = AUTO_FOLLOW_ASPECT
#: ``(size [px], fps)`` tried in turn until a GIF fits the budget.
ATTEMPTS = ((560, 25.0), (480, 20.0), (400, 15.0), (320, 10.0))


def scenario_files(folders: list[Path]) -> list[Path]:
    """The ``.yaml`` files directly in each folder, sorted by name."""
    files: list[Path] = []
    for folder in folders:
        files += sorted(Path(folder).glob("*.yaml"))
    return files


def camera_follow(run: Run) -> str | None:
    """``"leader"`` for a run spread along a line (a moving camera), else None.

    The choice of the automatic camera (:func:`sandbox.render.animation.auto_follow`),
    which ``sandbox run --gif`` and ``sandbox render`` use too; the gallery's GIFs are
    drawn with ``follow="auto"``, whose moving window follows what happens.
    """
    return auto_follow(run)


def render_gallery(
    folders: list[Path],
    out_dir: Path,
    *,
    zones: bool = False,
    log: Callable[[str], None] = print,
) -> list[dict]:
    """Run every scenario of ``folders`` and write ``out_dir/<scenario file stem>.gif``.

    Returns one record per GIF: ``{"scenario", "path", "bytes", "size", "fps",
    "frames"}``. Raises :class:`~sandbox.errors.ScenarioError` on an invalid file.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    records = []
    for path in scenario_files(folders):
        scenario = load_scenario(path, trust_plugins=False)  # never plug-in code
        run = Simulation(scenario).run()
        target = out_dir / f"{path.stem}.gif"
        for size, fps in ATTEMPTS:
            info = write_gif(
                run, target, fps=fps, size=size, zones=zones, follow="auto"
            )
            nbytes = target.stat().st_size
            if nbytes <= MAX_GIF_BYTES:
                break
        record = {
            "scenario": str(path),
            "path": str(target),
            "bytes": nbytes,
            "size": size,
            "fps": fps,
            "frames": info["frames"],
            "follow": camera_follow(run),
        }
        log(
            f"{target}: {nbytes / 1e6:.2f} MB, {size} px, {fps:g} fps, "
            f"{info['frames']} frames ({run.status}, {len(run.events)} collisions)"
        )
        records.append(record)
    return records
