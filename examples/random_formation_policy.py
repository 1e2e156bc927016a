"""A random policy on ``FormationEnv``, against the zero action (the scenario's laws).

Every follower of the failures platoon (``scenarios/failures/follower_stop.yaml``:
red's motors stop at 3 s in orange's lane) is an agent whose action shifts its target
(``action="shift"``, up to 2 d = 1 m). The random policy samples each action
uniformly; the zero action leaves the built-in law and recovery strategy in charge.
The script prints each agent's mean return over the episodes, with its parts from the
step infos (formation error [m s], collisions, effort [m/s]), for both policies.
Needs the ``rl`` extra.

Run it::

    python examples/random_formation_policy.py [--episodes 3] [--gif random.gif]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml

from sandbox.envs import FormationEnv

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios/failures/follower_stop.yaml"
PARTS = ("error", "collisions", "effort")


def episode(
    env: FormationEnv, seed: int, policy: str, frames: list | None = None
) -> dict[str, dict[str, float]]:
    """One episode of ``policy`` ("random" or "zero"); each agent's return and parts."""
    env.reset(seed=seed)
    for agent in env.possible_agents:
        env.action_space(agent).seed(seed)
    total = {a: dict.fromkeys(("return", *PARTS), 0.0) for a in env.possible_agents}
    while env.agents:
        if policy == "random":
            actions = {a: env.action_space(a).sample() for a in env.agents}
        else:
            actions = {a: np.zeros(2, np.float32) for a in env.agents}
        _, rewards, _, _, infos = env.step(actions)
        for agent, r in rewards.items():
            total[agent]["return"] += r
            for part in PARTS:
                total[agent][part] += infos[agent][part]
        if frames is not None:
            frames.append(env.render())
    return total


def main(argv: list[str] | None = None) -> dict[str, dict[str, dict[str, float]]]:
    """Run both policies; return ``{policy: {agent: {return, parts}}}`` (means)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--duration", type=float, default=6.0, help="[s]")
    parser.add_argument("--repeat", type=int, default=10, help="periods per action")
    parser.add_argument("--gif", type=Path, help="write the last random episode here")
    args = parser.parse_args(argv)

    doc = yaml.safe_load(SCENARIO.read_text(encoding="utf-8"))
    doc["duration"] = args.duration
    env = FormationEnv(
        doc,
        action="shift",
        repeat=args.repeat,
        render_mode="rgb_array" if args.gif else None,
    )
    results: dict[str, dict[str, dict[str, float]]] = {}
    header = ("policy", "agent", "return", "error", "collisions", "effort")
    print("{:8} {:8} {:>10} {:>10} {:>10} {:>10}".format(*header))
    frames: list[np.ndarray] = []
    for policy in ("zero", "random"):
        runs = []
        for seed in range(args.episodes):
            last = policy == "random" and seed == args.episodes - 1
            runs.append(
                episode(env, seed, policy, frames if args.gif and last else None)
            )
        mean = {
            a: {k: float(np.mean([r[a][k] for r in runs])) for k in runs[0][a]}
            for a in env.possible_agents
        }
        for agent, m in mean.items():
            print(
                f"{policy:8} {agent:8} {m['return']:10.3f} {m['error']:10.3f} "
                f"{m['collisions']:10.1f} {m['effort']:10.3f}"
            )
        results[policy] = mean
    if args.gif is not None:
        import imageio.v3 as iio

        fps = env.metadata["render_fps"]
        iio.imwrite(args.gif, np.stack(frames), duration=1000 / fps, loop=0)
        print(f"wrote {args.gif} ({len(frames)} frames)")
    return results


if __name__ == "__main__":
    main()
