"""Peer benchmark: IR-SIM (``ir-sim`` on PyPI, import ``irsim``) stepping N unicycle
robots.

Builds an IR-SIM world of ``n`` differential-drive ("diff" kinematics) circle robots
from a
temporary YAML file, headless, and times ``steps`` calls of ``env.step`` with one
constant
command per robot. Only the stepping loop is timed; parsing the YAML and building the
objects are not.

World configuration (see ``_world_yaml``):

* ``world.step_time = dt``; ``collision_mode: stop`` (IR-SIM's default: every step the
  robots' shapely geometries go into an STRtree, one batched ``intersects`` query finds
  the
  overlapping pairs, and colliding robots are stopped). Left on, because it is the part
  of
  IR-SIM comparable to our simulator's pymunk collision handling.
* ``n`` robots, ``kinematics: {name: diff}``, ``shape: {name: circle, radius: 0.2}``, no
  sensors, no behavior, laid out by IR-SIM's ``manual`` distribution on a square grid
  with
  1 m spacing, all with heading 0 and goal far away (so no robot "arrives").
* Every robot gets the same constant command ``[v, w] = [0.5, 0.2]`` (m/s, rad/s): the
grid
  moves as a rigid formation, so no robot ever touches another and none is stopped; the
  collision query still runs every step over all robots.
* ``headless=True`` (no figure, no window, no keyboard/mouse), ``save_ani=False``,
  ``log_level="WARNING"``; ``MPLBACKEND=Agg`` is set before importing ``irsim``.

Run ``python benchmarks/irsim_peer.py`` for a table at N = 10, 100, 1000 and 10000
(``--quick`` skips 10000, whose world alone takes ~10 s to build).
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import sys
import tempfile
import time
from typing import Any

os.environ.setdefault("MPLBACKEND", "Agg")

#: Constant command given to every robot: linear [m/s], angular [rad/s].
COMMAND = (0.5, 0.2)
#: Robot radius [m] and grid spacing [m].
RADIUS = 0.2
SPACING = 1.0

_irsim: Any = None


def _import_irsim() -> Any:
    """Import ``irsim`` once, silencing the backend probe it prints at import time."""
    global _irsim
    if _irsim is None:
        import matplotlib

        matplotlib.use("Agg")
        # irsim.env.env_base tries TkAgg/Qt5Agg at import and prints each failure.
        with contextlib.redirect_stdout(io.StringIO()):
            import irsim
        _irsim = irsim
    return _irsim


def irsim_available() -> bool:
    """Whether ``irsim`` can be imported here."""
    try:
        _import_irsim()
    except Exception:
        return False
    return True


def irsim_version() -> str:
    """Installed IR-SIM version, or ``"unavailable"``."""
    try:
        return str(_import_irsim().__version__)
    except Exception:
        return "unavailable"


def default_steps(n: int) -> int:
    """Steps used for ``n`` robots by ``__main__``: ``max(5, 20000 // n)``."""
    return max(5, 20000 // n)


def _world_yaml(n: int, dt: float) -> str:
    """YAML text of a world with ``n`` diff-drive circle robots on a grid."""
    cols = max(1, math.ceil(math.sqrt(n)))
    rows = math.ceil(n / cols)
    side = SPACING * max(cols, rows) + 2.0
    states = []
    for i in range(n):
        r, c = divmod(i, cols)
        states.append(f"[{1.0 + c * SPACING:.3f}, {1.0 + r * SPACING:.3f}, 0.0]")
    far = 1.0e6
    lines = [
        "world:",
        f"  height: {side:.3f}",
        f"  width: {side:.3f}",
        f"  step_time: {dt!r}",
        f"  sample_time: {dt!r}",
        "  offset: [0, 0]",
        "  collision_mode: stop",
        "  control_mode: auto",
        "",
        "robot:",
        f"  - number: {n}",
        "    distribution: {name: manual}",
        "    kinematics: {name: diff}",
        f"    shape: {{name: circle, radius: {RADIUS}}}",
        "    state: [" + ", ".join(states) + "]",
        f"    goal: [{far}, {far}, 0]",
        "    vel_max: [10.0, 10.0]",
        "    vel_min: [-10.0, -10.0]",
        "    plot: {show_trajectory: false}",
        "",
    ]
    return "\n".join(lines)


def _make_env(n: int, dt: float, seed: int, path: str) -> Any:
    irsim = _import_irsim()
    with open(path, "w", encoding="utf-8") as f:
        f.write(_world_yaml(n, dt))
    env = irsim.make(
        path,
        display=False,
        headless=True,
        save_ani=False,
        log_level="WARNING",
        seed=seed,
    )
    if env.robot_number != n:
        raise RuntimeError(f"IR-SIM built {env.robot_number} robots, expected {n}")
    return env


def measure_irsim(n: int, steps: int, dt: float = 0.01, seed: int = 0) -> dict:
    """Time ``steps`` IR-SIM steps of ``n`` diff-drive robots under constant commands.

    Returns ``{"n", "steps", "seconds", "steps_per_s", "vehicle_steps_per_s"}``;
    ``seconds``
    is the wall time of the stepping loop only (construction and one untimed warm-up
    step
    excluded). Also checks that
    the robots moved and that none collided, so a silently broken run is not reported
    as a
    fast one.
    """
    import numpy as np

    if n < 1 or steps < 1:
        raise ValueError("n and steps must be positive")
    with tempfile.TemporaryDirectory(prefix="irsim_peer_") as tmp:
        env = _make_env(n, dt, seed, os.path.join(tmp, "world.yaml"))
        try:
            action = [np.array([[COMMAND[0]], [COMMAND[1]]]) for _ in range(n)]
            env.step(action=action, action_id=0)  # untimed warm-up (one-time costs)
            start_state = env.get_robot_state().copy()
            t0 = time.perf_counter()
            for _ in range(steps):
                env.step(action=action, action_id=0)
            seconds = time.perf_counter() - t0
            robots = env.robot_list
            moved = float(np.linalg.norm(robots[0].state[:2, 0] - start_state[:2, 0]))
            collided = sum(bool(r.collision) for r in robots)
            if moved <= 0.0:
                raise RuntimeError("IR-SIM robots did not move")
            if collided:
                raise RuntimeError(
                    f"{collided} IR-SIM robots collided; benchmark invalid"
                )
        finally:
            with contextlib.suppress(Exception):
                plt = sys.modules.get("matplotlib.pyplot")
                if plt is not None:
                    plt.close("all")
            del env
    return {
        "n": n,
        "steps": steps,
        "seconds": seconds,
        "steps_per_s": steps / seconds,
        "vehicle_steps_per_s": n * steps / seconds,
    }


def _print_row(r: dict) -> None:
    print(
        f"{r['n']:>6} {r['steps']:>6} {r['seconds']:>9.3f} "
        f"{r['steps_per_s']:>10.1f} {r['vehicle_steps_per_s']:>16.0f}"
    )


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not irsim_available():
        print("IR-SIM not installed (pip install ir-sim); skipping.")
        return 0
    ns = [10, 100, 1000]
    print(
        f"IR-SIM {irsim_version()}, diff robots, dt=0.01, collision_mode=stop, headless"
    )
    print(
        f"{'N':>6} {'steps':>6} {'seconds':>9} {'steps/s':>10} {'vehicle-steps/s':>16}"
    )
    for n in ns:
        _print_row(measure_irsim(n, default_steps(n)))
    if "--quick" in argv:
        print("N=10000 skipped: --quick given.")
    else:
        # Feasible: ~10 s to build the world and ~4 s for 5 steps on a 2-core machine.
        _print_row(measure_irsim(10000, default_steps(10000)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
