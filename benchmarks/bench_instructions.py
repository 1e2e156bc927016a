"""Instructions of single runs and vector steps, two checkouts, by callgrind.

Where a shared machine's timings scatter by more than the difference to be seen,
``valgrind --tool=callgrind`` counts the instructions a process executes, the same
count twice for the same inputs (with ``PYTHONHASHSEED=0`` and one OpenBLAS thread)
whatever else the machine does. Each row is counted in this checkout and in another
(``--other``, with its own environment): a process that builds the row and runs it
once as a warm-up, then once more (a single run and its metrics) or 100 vector steps
of ``VehicleVectorEnv`` after 20; the row's figure is that process's count less the
count of the same process without the measured part. Instructions are not seconds
(a cache miss costs more than an addition), but a change of a few percent in the same
code shows here and drowns in a timing.

    python benchmarks/bench_instructions.py --other /path/to/checkout
    python benchmarks/bench_instructions.py --other ../old --rows fig15 grid:3

About 3 minutes a row under valgrind (two processes a side, the sides in parallel).
Needs ``valgrind`` on the PATH. Not a test: a table.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: The rows: (key, name).
ROWS = {
    "grid:3": "single run, N = 3, grid (2,000 periods)",
    "grid:5": "single run, N = 5, grid",
    "grid:10": "single run, N = 10, grid",
    "fig15": "single run, Fig. 15 (1,200 periods)",
    "vector:16": "VehicleVectorEnv, 16 worlds, a vector step",
    "vector:64": "VehicleVectorEnv, 64 worlds, a vector step",
    "vector:256": "VehicleVectorEnv, 256 worlds, a vector step",
}

#: The measured process: ``ROOT KEY MEASURED`` (MEASURED 0: the warm-up alone).
PROGRAM = r"""
import sys, warnings
from pathlib import Path
root, key, measured = Path(sys.argv[1]), sys.argv[2], sys.argv[3] == "1"
sys.path[:0] = [str(root), str(root / "benchmarks")]
if key.startswith("vector:"):
    import numpy as np
    from sandbox.envs import VehicleVectorEnv
    env = VehicleVectorEnv("paper/fig15_continuous_beta1", num_envs=int(key[7:]))
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    acts = [rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
            for _ in range(120)]
    for a in acts[:20]:
        env.step(a)
    if measured:
        for a in acts[20:]:
            env.step(a)
else:
    from bench_scale import scenario_doc
    from sandbox.loop.simulation import Simulation
    from sandbox.run.metrics import compute_metrics
    from sandbox.scenario import load_scenario
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if key.startswith("grid:"):
            sc = load_scenario(scenario_doc(int(key[5:]), 2000))
        else:
            path = root / "scenarios" / "paper" / "fig15_continuous_beta1.yaml"
            sc = load_scenario(path, overrides=["duration=12"])
    compute_metrics(Simulation(sc).run())
    if measured:
        compute_metrics(Simulation(sc).run())
"""

#: Vector steps measured in a vector row (its figure is per step).
VECTOR_STEPS = 100


def count(python: str, root: Path, key: str, measured: bool) -> int:
    """Instructions of one process of ``key`` (callgrind's total)."""
    env = dict(os.environ, PYTHONHASHSEED="0", OPENBLAS_NUM_THREADS="1")
    done = subprocess.run(
        [
            "valgrind",
            "--tool=callgrind",
            "--callgrind-out-file=/dev/null",
            python,
            "-c",
            PROGRAM,
            str(root),
            key,
            "1" if measured else "0",
        ],
        capture_output=True,
        text=True,
        env=env,
        cwd=root,
    )
    found = re.search(r"Collected : (\d+)", done.stderr)
    if done.returncode != 0 or found is None:
        raise SystemExit(f"{root}: {key}: {done.stderr.strip().splitlines()[-1:]}")
    return int(found.group(1))


def measure(python: str, root: Path, key: str) -> float:
    """The row's instructions (a run, or a vector step)."""
    extra = count(python, root, key, True) - count(python, root, key, False)
    return extra / VECTOR_STEPS if key.startswith("vector:") else float(extra)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--other", type=Path, required=True, help="the other checkout")
    p.add_argument(
        "--other-python", help="its Python (default: OTHER/.venv/bin/python)"
    )
    p.add_argument("--rows", nargs="*", choices=tuple(ROWS), default=list(ROWS))
    args = p.parse_args(argv)
    if shutil.which("valgrind") is None:
        raise SystemExit("bench_instructions: valgrind is not on the PATH")
    other = args.other.resolve()
    other_python = args.other_python or str(other / ".venv" / "bin" / "python")
    print(f"other: {other}; this: {ROOT}; instructions (M) by callgrind")
    print()
    print("| row | other | this | this / other |")
    print("|---|---:|---:|---:|")
    with ThreadPoolExecutor(2) as pool:
        for key in args.rows:
            old = pool.submit(measure, other_python, other, key)
            new = pool.submit(measure, sys.executable, ROOT, key)
            a, b = old.result(), new.result()
            print(
                f"| {ROWS[key]} | {a / 1e6:.2f} | {b / 1e6:.2f} | {b / a:.3f} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
