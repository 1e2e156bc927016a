"""A user controller through the step API: pure pursuit for one vehicle.

red follows a circle by pure pursuit (the goal point a fixed arc length ahead of its
projection on the path; curvature ``2 sin(alpha) / l_d`` to the goal, speed constant)
while blue tracks its reference with the built-in controller. The script prints red's
cross-track error and blue's tracking error over the second half of the run, and the
collisions; ``--gif`` also writes an animation.

Run it::

    python examples/pure_pursuit.py [--duration 30] [--gif pure_pursuit.gif]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from sandbox import Simulation, load_scenario
from sandbox.loop.observation import Observation
from sandbox.render import write_gif

SCENARIO = Path(__file__).with_name("pure_pursuit.yaml")
CENTER = np.array([0.0, 0.0])  # red's path: a circle about CENTER [m]
RADIUS = 3.0  # [m]
SPEED = 0.8  # red's speed [m/s]


def pure_pursuit(
    pose: np.ndarray, lookahead: float, speed: float = SPEED
) -> tuple[float, float]:
    """Commands ``(v1, v2)`` [m/s, rad/s] that steer ``pose`` along the circle.

    The goal is the point of the circle ``lookahead`` [m] of arc ahead
    (counter-clockwise) of the vehicle's angle about the centre; ``alpha`` is the
    goal's bearing from the heading and ``l_d`` its distance, and the arc through the
    goal has curvature ``2 sin(alpha) / l_d``.
    """
    x, y, heading = pose
    phi = np.arctan2(y - CENTER[1], x - CENTER[0]) + lookahead / RADIUS
    goal = CENTER + RADIUS * np.array([np.cos(phi), np.sin(phi)])
    dx, dy = goal[0] - x, goal[1] - y
    alpha = np.arctan2(dy, dx) - heading
    distance = max(np.hypot(dx, dy), 1e-9)
    return speed, speed * 2.0 * np.sin(alpha) / distance


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Run the example; return the figures it prints."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0, help="[s]")
    parser.add_argument("--lookahead", type=float, default=0.8, help="[m]")
    parser.add_argument("--gif", type=Path, help="also write an animation here")
    args = parser.parse_args(argv)

    scenario = load_scenario(SCENARIO, overrides=[f"duration={args.duration}"])
    sim = Simulation(scenario)
    obs: Observation = sim.observe()
    red = obs.index("red")
    while not sim.done:
        v1, v2 = pure_pursuit(obs.pose[red], args.lookahead)
        obs = sim.step(commands={"red": (v1, v2)})
    run = sim.result()

    late = run.t >= run.t[-1] / 2
    radius = np.hypot(*(run.pose[late, red, :2] - CENTER).T)
    blue = run.names.index("blue")
    figures = {
        "red_cross_track_rms": float(np.sqrt(np.mean((radius - RADIUS) ** 2))),
        "blue_tracking_rms": float(
            np.sqrt(np.mean(run.formation_error[late, blue] ** 2))
        ),
        "collisions": float(len(run.events)),
    }
    print(f"red, pure pursuit:  cross-track RMS {figures['red_cross_track_rms']:.4f} m")
    print(f"blue, built-in:     tracking RMS    {figures['blue_tracking_rms']:.4f} m")
    print(f"collisions:         {len(run.events)}")
    print(f"(second half of the run, t >= {run.t[-1] / 2:.1f} s)")
    if args.gif is not None:
        write_gif(run, args.gif, fps=25, size=480)
        print(f"wrote {args.gif}")
    return figures


if __name__ == "__main__":
    main()
