"""Vector RL environments: the one loop against Gymnasium's SyncVectorEnv.

``VehicleVectorEnv(scenario, num_envs=K)`` steps K worlds in one pass of the loop per
control period; ``gymnasium.vector.SyncVectorEnv`` over K ``VehicleEnv``s steps them
one after the other. Both run the same scenario (the Fig. 15 platoon of three
vehicles, one learning vehicle per world) with random actions through episode ends
(autoreset), for ``--steps`` vector steps after a warm-up; the table gives env steps
per second (one env step = one world advanced one control period) and robot steps per
second (vehicles advanced, all of them, not only the learner), and the ratio of the
vector env over SyncVectorEnv measured in the same run (median of ``--repeat``).
IR-SIM's figure for comparison is measured by ``benchmarks/irsim_peer.py``.

    python benchmarks/bench_vector_env.py             # num_envs 64, 3 repetitions
    python benchmarks/bench_vector_env.py --envs 16 --steps 200 --repeat 1
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import gymnasium as gym
import numpy as np

from sandbox.envs import VehicleEnv, VehicleVectorEnv

SCENARIO = "paper/fig15_continuous_beta1"
#: Vehicles of the scenario (robot steps = env steps x this).
VEHICLES = 3


def timed(env, steps: int, seed: int) -> float:
    """Env steps per second of ``steps`` random vector steps (after 20 warm-up)."""
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    shape = env.action_space.shape
    for _ in range(20):
        env.step(rng.uniform(-1, 1, size=shape).astype(np.float32))
    t0 = time.perf_counter()
    for _ in range(steps):
        env.step(rng.uniform(-1, 1, size=shape).astype(np.float32))
    return steps * env.num_envs / (time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--envs", type=int, default=64, help="num_envs")
    p.add_argument("--steps", type=int, default=400, help="vector steps timed")
    p.add_argument("--repeat", type=int, default=3, help="repetitions (median)")
    args = p.parse_args(argv)
    K = args.envs
    vector = VehicleVectorEnv(SCENARIO, num_envs=K)
    sync = gym.vector.SyncVectorEnv(
        [lambda: VehicleEnv(SCENARIO) for _ in range(K)],
        autoreset_mode=gym.vector.AutoresetMode.NEXT_STEP,
    )
    single = VehicleEnv(SCENARIO)
    rates: dict[str, list[float]] = {"vector": [], "sync": [], "single": []}
    load_before = os.getloadavg()
    for rep in range(args.repeat):
        rates["single"].append(timed(_Single(single), args.steps, rep))
        rates["sync"].append(timed(sync, max(10, args.steps // 4), rep))
        rates["vector"].append(timed(vector, args.steps, rep))
    load_after = os.getloadavg()
    print(
        f"{SCENARIO}, {VEHICLES} vehicles a world, num_envs {K}, median of "
        f"{args.repeat}; load average {load_before[0]:.2f} before, "
        f"{load_after[0]:.2f} after"
    )
    print()
    print("| environment | env steps/s | robot steps/s | over SyncVectorEnv |")
    print("|---|---:|---:|---:|")
    sync_rate = statistics.median(rates["sync"])
    for name, label in (
        ("single", "VehicleEnv (one world)"),
        ("sync", f"SyncVectorEnv of {K} VehicleEnv"),
        ("vector", f"VehicleVectorEnv, num_envs={K}"),
    ):
        rate = statistics.median(rates[name])
        print(
            f"| {label} | {rate:,.0f} | {VEHICLES * rate:,.0f} | "
            f"{rate / sync_rate:.2f}x |"
        )
    return 0


class _Single:
    """One VehicleEnv seen as a vector of one (resets itself at episode ends)."""

    def __init__(self, env: VehicleEnv) -> None:
        self.env, self.num_envs = env, 1
        self.action_space = env.action_space

    def reset(self, seed: int) -> None:
        self.env.reset(seed=seed)

    def step(self, action: np.ndarray) -> None:
        *_, terminated, truncated, _ = self.env.step(action)
        if terminated or truncated:
            self.env.reset()


if __name__ == "__main__":
    raise SystemExit(main())
