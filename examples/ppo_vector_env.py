"""PPO from stable-baselines3 on the vector environment: many worlds in one loop.

Trains one follower of ``failures/follower_stop`` (orange, which must keep its slot
and get past red, whose motors stop at 3 s) with ``action="commands"``: the policy
drives orange's motors (speed and turn rate) while the others run the scenario's
laws. The zero action leaves orange standing as the platoon drives away: the
baseline a policy that learned anything beats. Prints the mean return of the zero
policy, of the untrained policy and of the trained one over the same evaluation
seeds, and the training's wall time. (With ``action="shift"`` the zero action is the
scenario's own controller, a far stronger baseline: this budget does not beat it.)

Needs the extra ``sb3`` (stable-baselines3 and PyTorch)::

    pip install 'platoon-sandbox[sb3]'
    python examples/ppo_vector_env.py                  # the defaults, a few minutes
    python examples/ppo_vector_env.py --steps 2000     # a smoke run

:class:`sandbox.envs.SB3VecEnv` is the adapter: the vector environment as a
stable-baselines3 ``VecEnv``, resetting in the step an episode ends as SB3 expects.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
import torch
from stable_baselines3 import PPO

from sandbox.envs import SB3VecEnv

SCENARIO = "failures/follower_stop"
AGENT = "orange"
ACTION = "commands"
#: The evaluation's seeds: world k of the evaluation starts with EVAL_SEED + k.
EVAL_SEED = 10_000


def mean_return(
    env: SB3VecEnv, act: Callable[[np.ndarray], np.ndarray], seed: int
) -> float:
    """The mean return of one episode in every world, actions from ``act(obs)``."""
    env.seed(seed)
    obs = env.reset()
    total = np.zeros(env.num_envs)
    done = np.zeros(env.num_envs, dtype=bool)
    while not done.all():
        obs, reward, ended, _ = env.step(act(obs))
        total += np.where(done, 0.0, reward)
        done |= ended
    return float(total.mean())


def main(argv: list[str] | None = None) -> int:
    """Train, and print the returns before and after."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=30_000, help="training env steps")
    p.add_argument("--envs", type=int, default=16, help="worlds in the vector env")
    p.add_argument("--eval", type=int, default=16, help="evaluation episodes")
    p.add_argument("--duration", type=float, help="episode length [s] (default 15)")
    p.add_argument("--seed", type=int, default=0, help="seed of PPO and the training")
    args = p.parse_args(argv)
    torch.set_num_threads(1)  # small networks: threads cost more than they give
    kwargs = {"agent": AGENT, "action": ACTION, "repeat": 10}
    scenario: str | dict = SCENARIO
    if args.duration is not None:
        from sandbox import load_scenario

        scenario = load_scenario(SCENARIO, overrides=[f"duration={args.duration!r}"])
        scenario = scenario.to_dict()
    train = SB3VecEnv(scenario, num_envs=args.envs, **kwargs)
    test = SB3VecEnv(scenario, num_envs=args.eval, **kwargs)

    def zero(obs: np.ndarray) -> np.ndarray:
        return np.zeros((len(obs), 2), dtype=np.float32)

    baseline = mean_return(test, zero, EVAL_SEED)
    train.seed(args.seed)
    model = PPO(
        "MlpPolicy",
        train,
        n_steps=128,
        batch_size=256,
        seed=args.seed,
        verbose=0,
        device="cpu",
    )

    def policy(obs: np.ndarray) -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    before = mean_return(test, policy, EVAL_SEED)
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps)
    wall = time.perf_counter() - start
    after = mean_return(test, policy, EVAL_SEED)
    last = EVAL_SEED + args.eval - 1
    print(f"mean return of {args.eval} episodes (seeds {EVAL_SEED}-{last}):")
    print(f"zero policy (standing still): {baseline:.3f}")
    print(f"PPO before training: {before:.3f}")
    print(f"PPO after {args.steps} env steps: {after:.3f}")
    print(f"training wall time: {wall:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
