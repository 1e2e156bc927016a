"""The scripts in examples/: each runs as a user runs it, and shows what it says."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys

import numpy as np
import pytest
from helpers import REPO

EXAMPLES = REPO / "examples"


def run_example(name: str, *args: str) -> str:
    """Run ``examples/NAME`` in a fresh interpreter; return its standard output."""
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def load_example(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_pure_pursuit_keeps_red_on_its_circle(tmp_path) -> None:
    out = run_example(
        "pure_pursuit.py", "--duration", "15", "--gif", str(tmp_path / "pp.gif")
    )
    lines = dict(line.split(":", 1) for line in out.splitlines() if ":" in line)
    red = float(lines["red, pure pursuit"].split()[2])
    blue = float(lines["blue, built-in"].split()[2])
    assert red < 0.01 and blue < 0.01  # [m], RMS over the second half
    assert int(lines["collisions"]) == 0
    assert (tmp_path / "pp.gif").stat().st_size > 10_000


def test_pure_pursuit_steers_the_circle_exactly_when_on_it() -> None:
    pp = load_example("pure_pursuit")
    # On the circle (3, 0) heading +x2 (tangent, counter-clockwise): the goal lies on
    # the same circle, so the pursuit arc is the circle itself: v2 = v / R.
    v1, v2 = pp.pure_pursuit(np.array([3.0, 0.0, np.pi / 2]), lookahead=0.8)
    assert v1 == pp.SPEED and v2 == pytest.approx(pp.SPEED / pp.RADIUS)
    # Outside it, heading along: it turns in harder than the circle.
    _, v2_out = pp.pure_pursuit(np.array([3.5, 0.0, np.pi / 2]), lookahead=0.8)
    assert v2_out > v2


@pytest.mark.skipif(
    importlib.util.find_spec("pettingzoo") is None and not os.environ.get("CI"),
    reason="needs the rl extra",
)
def test_a_random_policy_does_worse_than_the_scenarios_own_laws() -> None:
    out = run_example(
        "random_formation_policy.py", "--episodes", "1", "--duration", "4"
    )
    rows = [line.split() for line in out.splitlines()[1:]]
    returns = {(r[0], r[1]): float(r[2]) for r in rows}
    agents = {a for _, a in returns}
    assert agents == {"red", "green", "orange"}
    for agent in agents:
        assert returns["zero", agent] > returns["random", agent]
