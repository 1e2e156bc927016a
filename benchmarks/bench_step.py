"""Benchmark of the step-wise API: what stepping from Python costs over ``run()``.

Run with ``python benchmarks/bench_step.py``. For the failures platoon (4 vehicles) and
a 1,000-vehicle grid it times, per control period, ``Simulation.run()``, the loop of
``step()`` without overrides (an ``Observation`` of copies every step), ``step()`` with
a command override for one vehicle, and one ``FormationEnv`` step (when the ``rl``
extra is installed; observations of every agent, rewards). CPU time, the best of
``--repeat`` runs, ratios against ``run()`` measured in the same process. Not a test.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sandbox import Simulation, load_scenario  # noqa: E402

CASES = {
    "platoon (4)": ("scenarios/failures/follower_stop.yaml", 5.0),
    "grid (1000)": ("scenarios/scale/grid_1000.yaml", 1.0),
}


def best(fn, repeat: int) -> float:
    """Smallest CPU time of ``repeat`` calls [s]."""
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return min(times)


def variants(sc, formation_env) -> dict:
    """The loops to time for one scenario, by label."""
    name = sc.vehicles[-1].name

    def plain() -> None:
        Simulation(sc).run()

    def stepped(commands=None) -> None:
        sim = Simulation(sc)
        while not sim.done:
            sim.step(commands=commands)
        sim.result()

    out = {
        "run()": plain,
        "step()": stepped,
        "step(commands=one)": lambda: stepped({name: (0.5, 0.0)}),
    }
    if formation_env is not None and len(sc.vehicles) < 100:
        doc = sc.to_dict()

        def env_loop() -> None:
            env = formation_env(doc)
            env.reset()
            zero = {a: np.zeros(2, np.float32) for a in env.possible_agents}
            while env.agents:
                env.step(zero)

        out["FormationEnv.step"] = env_loop
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    try:
        from sandbox.envs import FormationEnv
    except ImportError:
        FormationEnv = None
    print(f"{'case':14} {'variant':24} {'us/period':>10} {'x run()':>8}")
    for label, (path, duration) in CASES.items():
        sc = load_scenario(ROOT / path, overrides=[f"duration={duration}"])
        steps = int(round(duration / sc.dt))
        base = None
        for variant, fn in variants(sc, FormationEnv).items():
            per = best(fn, args.repeat) / steps * 1e6
            base = base or per
            print(f"{label:14} {variant:24} {per:10.1f} {per / base:8.2f}")


if __name__ == "__main__":
    main()
