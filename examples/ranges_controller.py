"""A user controller through the step API that sees obstacles only through its LiDAR.

The rover of ``ranges_controller.yaml`` drives to its goal through a field of boxes
and posts. Its controller reads ``obs.ranges`` (72 beams, 4 m) and its own pose and
goal, never the scenario's obstacles: each beam's hit point, in the rover's frame, is
a point to keep clear of, and the rule follows the free gap nearest the goal:

1. for each beam direction ``phi``, the free run of the rover's disc (radius ``rho``
   = half its diameter plus a margin) along it: the nearest hit ``x_k`` whose
   distance from the ray is below ``rho``, at ``x_k . u - sqrt(rho^2 - perp_k^2)``;
2. the heading is the direction whose free run reaches ``LOOK`` [m] (or the goal),
   nearest the goal's bearing; if none does, the direction with the longest run;
3. ``v2`` turns toward it (``K_HEADING``), ``v1`` slows with the free run ahead.

Run it::

    python examples/ranges_controller.py [--duration 40] [--gif ranges.gif]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from sandbox import Simulation, load_scenario
from sandbox.render import write_gif

SCENARIO = Path(__file__).with_name("ranges_controller.yaml")
GOAL = np.array([18.0, 0.0])  # [m]
SPEED = 1.0  # cruise speed [m/s]
MARGIN = 0.2  # clearance kept beyond the rover's radius [m]
LOOK = 2.0  # free run a heading must offer [m]
K_HEADING = 3.0  # heading gain [1/s]


def free_run(
    ranges: np.ndarray, angles: np.ndarray, rho: float, max_range: float
) -> np.ndarray:
    """How far a disc of radius ``rho`` [m] can go along each beam direction [m].

    ``ranges`` (B,) [m] and ``angles`` (B,) [rad] are one scan in the vehicle's frame;
    a beam reading ``max_range`` hit nothing and blocks nothing.
    """
    hit = ranges < max_range - 1e-9
    points = ranges[hit, None] * np.stack(
        (np.cos(angles[hit]), np.sin(angles[hit])), -1
    )
    u = np.stack((np.cos(angles), np.sin(angles)), -1)  # candidate directions (B, 2)
    along = u @ points.T  # (B, hits)
    perp2 = np.sum(points**2, axis=1)[None, :] - along**2
    blocks = (perp2 < rho * rho) & (along > -rho)
    run = along - np.sqrt(np.maximum(rho * rho - perp2, 0.0))
    return np.where(blocks, run, max_range).min(axis=1, initial=max_range)


def steer(
    pose: np.ndarray, ranges: np.ndarray, angles: np.ndarray, rho: float, reach: float
) -> tuple[float, float]:
    """Commands ``(v1, v2)`` [m/s, rad/s] toward :data:`GOAL` from one scan."""
    x, y, heading = pose
    to_goal = GOAL - (x, y)
    distance = float(np.hypot(*to_goal))
    if distance < 0.1:
        return 0.0, 0.0
    bearing = np.angle(np.exp(1j * (np.arctan2(to_goal[1], to_goal[0]) - heading)))
    run = free_run(ranges, angles, rho, reach)
    need = min(LOOK, distance)
    open_ = run >= need
    offset = np.abs(np.angle(np.exp(1j * (angles - bearing))))
    if open_.any():
        k = int(np.argmin(np.where(open_, offset, np.inf)))
    else:
        k = int(np.argmax(run))
    # the beam nearest straight ahead tells how far the rover can go as it heads now
    ahead = run[int(np.argmin(np.abs(angles)))]
    error = float(angles[k])
    v1 = (
        SPEED * float(np.clip((ahead - 0.1) / LOOK, 0.0, 1.0)) * max(0.0, np.cos(error))
    )
    v1 = min(v1, distance)  # slow down on the goal
    return v1, K_HEADING * error


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Run the example; return the figures it prints."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=40.0, help="[s]")
    parser.add_argument("--gif", type=Path, help="also write an animation here")
    args = parser.parse_args(argv)

    scenario = load_scenario(SCENARIO, overrides=[f"duration={args.duration}"])
    (spec,) = scenario.range_specs()
    rho = scenario.vehicles[0].diameter / 2 + MARGIN
    sim = Simulation(scenario)
    obs = sim.observe()
    rover = obs.index("rover")
    while not sim.done:
        v1, v2 = steer(
            obs.pose[rover],
            obs.ranges[rover],
            obs.beam_angles[rover],
            rho,
            spec.max_range,
        )
        obs = sim.step(commands={"rover": (v1, v2)})
    run = sim.result()
    end = run.pose[-1, rover, :2]
    closest = float(np.nanmin(run.ranges[:, rover]))
    figures = {
        "goal_distance": float(np.hypot(*(GOAL - end))),
        "progress": float(end[0]),
        "collisions": float(len(run.events)),
        "closest": closest,
    }
    print(f"distance to the goal at the end: {figures['goal_distance']:.3f} m")
    print(f"progress along x1:               {figures['progress']:.2f} m")
    print(f"closest range read:              {closest:.3f} m")
    print(f"collisions:                      {len(run.events)}")
    if args.gif is not None:
        write_gif(run, args.gif, fps=25, size=480, show_beams=True)
        print(f"wrote {args.gif}")
    return figures


if __name__ == "__main__":
    main()
