"""Benchmark of start-up time: what a ``sandbox`` command costs before it does anything.

Run with ``python benchmarks/bench_import.py``. Each case is a fresh interpreter
(``sys.executable``), timed from spawn to exit; the bare interpreter (``python -c
pass``) is measured alongside, interleaved with the cases, so the table's ratio to it
and the difference ("import" column: the cost above the interpreter's own start) hold
even on a busy machine. Medians of ``--repeat`` runs. Target: ``sandbox --help`` and
``sandbox validate`` of a small file under 0.3 s of import.

``--source DIR`` times the package of another checkout (put first on ``sys.path``),
e.g. the commit before the imports were made lazy::

    git worktree add /tmp/before <commit> && python benchmarks/bench_import.py \
        --source /tmp/before

Not a test.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TARGET_S = 0.3  # [s] of import above the bare interpreter

#: name -> (Python code run by a fresh interpreter, whether the target applies)
CASES = {
    "python -c pass": ("pass", False),
    "import sandbox": ("import sandbox", False),
    "import sandbox.cli": ("import sandbox.cli", False),
    "sandbox --help": (
        "import sys\nfrom sandbox.cli import main\nsys.argv[0] = 'sandbox'\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass",
        True,
    ),
    "sandbox validate SMALL": (
        "from sandbox.cli import main\nmain(['validate', {small!r}])",
        True,
    ),
    "import sandbox.loop.simulation": ("import sandbox.loop.simulation", False),
    "import sandbox.render.figures": ("import sandbox.render.figures", False),
}


def timed(code: str, env: dict[str, str], cwd: str) -> float:
    """Wall time [s] of one fresh interpreter running ``code`` in ``cwd``."""
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        cwd=cwd,
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    return time.perf_counter() - start


def main() -> None:
    """Print the table of start-up times."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="runs per case (default 7)")
    ap.add_argument(
        "--source",
        type=Path,
        default=REPO,
        help="checkout whose sandbox package is timed (default this one)",
    )
    args = ap.parse_args()
    source = args.source.resolve()
    small = str(source / "scenarios" / "paper" / "rotating_circle.yaml")
    env = dict(os.environ, PYTHONPATH=str(source), PYTHONDONTWRITEBYTECODE="")
    codes = {name: code.format(small=small) for name, (code, _) in CASES.items()}
    times: dict[str, list[float]] = {name: [] for name in codes}
    # `python -c` puts the working directory first on sys.path: run elsewhere, so
    # that the package timed is the one of --source
    with tempfile.TemporaryDirectory() as cwd:
        for code in codes.values():  # warm the file cache and the bytecode
            timed(code, env, cwd)
        for _ in range(args.repeat):
            for name, code in codes.items():  # interleaved: the same load for all
                times[name].append(timed(code, env, cwd))
    median = {name: statistics.median(t) for name, t in times.items()}
    base = median["python -c pass"]
    print(f"source: {source}; Python {sys.version.split()[0]}; median of {args.repeat}")
    print()
    print("| command | wall [s] | import [s] | ratio to `python -c pass` | target |")
    print("|---|---:|---:|---:|---|")
    for name, (_, targeted) in CASES.items():
        extra = median[name] - base
        verdict = ""
        if targeted:
            verdict = "ok" if extra < TARGET_S else f"over {TARGET_S:g} s"
        print(
            f"| `{name}` | {median[name]:.3f} | {extra:.3f} | "
            f"{median[name] / base:.1f} | {verdict} |"
        )


if __name__ == "__main__":
    main()
