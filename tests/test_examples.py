"""The scripts in examples/: each runs as a user runs it, and shows what it says."""

from __future__ import annotations

import importlib.util
import json
import os
import re
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


@pytest.mark.slow
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


@pytest.mark.slow
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


# ------------------------------------------------------------ a strategy plug-in
def sandbox_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sandbox", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
    )


@pytest.mark.slow
def test_the_keep_right_plug_in_is_selected_from_yaml_and_avoids_the_collision(
    tmp_path,
) -> None:
    scenario = str(EXAMPLES / "keep_right.yaml")
    for label, extra in (("kr", []), ("none", ["--set", "recovery.strategy=none"])):
        done = sandbox_cli(
            "run",
            scenario,
            "--duration",
            "8",
            "--out",
            str(tmp_path / label),
            "--trust-plugins",
            *extra,
        )
        assert done.returncode == 0, done.stderr
    kr = json.loads((tmp_path / "kr" / "metrics.json").read_text())
    none = json.loads((tmp_path / "none" / "metrics.json").read_text())
    assert kr["collisions"]["total"] == 0 and none["collisions"]["total"] >= 1
    assert kr["min_distance"] > 0.5  # d = 0.5 m: never in contact
    assert kr["vehicles"]["orange"]["mode_switches"] > 0  # it did yield
    listed = sandbox_cli("plugins", "--plugin", str(EXAMPLES / "keep_right.py"))
    assert listed.returncode == 0, listed.stderr
    assert "keep_right" in listed.stdout
    assert re.search(r"radius: length, default 3d \[m\]", listed.stdout)
    # validate never runs the file's plug-in code: its keys are checked once the
    # plug-in is named (trusted) with --plugin
    unchecked = sandbox_cli("validate", scenario, "--set", "recovery.gain=-1")
    assert (
        unchecked.returncode == 0
        and "recovery (strategy keep_right)" in unchecked.stdout
    )
    plugin = str(EXAMPLES / "keep_right.py")
    bad = sandbox_cli(
        "validate", scenario, "--plugin", plugin, "--set", "recovery.gain=-1"
    )
    assert bad.returncode == 2 and "recovery.gain" in bad.stderr


@pytest.fixture
def keep_right():
    from sandbox import plugins

    module = load_example("keep_right")
    yield module.keep_right
    plugins.unregister("strategy", "keep_right")


def test_keep_right_yields_to_the_right_of_what_is_ahead_only(keep_right) -> None:
    from sandbox.plugins import StrategyContext

    # a at the origin heading +x1, b 1 m ahead heading -x1 (head-on), c 1 m behind a.
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0]])
    ctx = StrategyContext(
        t=0.0,
        dt=0.01,
        pos=pos,
        theta=np.array([0.0, np.pi, 0.0]),
        vel=np.zeros((3, 2)),
        slot=pos.copy(),
        diameter=np.full(3, 0.5),
        may_avoid=np.ones(3, dtype=bool),
        failed=np.zeros(3, dtype=bool),
        params={"radius": 1.5, "gain": 1.0},
        R=1.5,
        obstacle_field=None,
    )
    shift, active = keep_right(ctx)
    # 1 m away within 1.5 m: 1.5 x (1 - 1 / 1.5) = 0.5 m to each one's right.
    np.testing.assert_allclose(shift[0], [0.0, -0.5], atol=1e-12)  # right of +x1
    np.testing.assert_allclose(shift[1], [0.0, 0.5], atol=1e-12)  # right of -x1
    # c has a ahead of it, 1 m: it yields too; a ignores c behind it (b is nearer).
    np.testing.assert_allclose(shift[2], [0.0, -0.5], atol=1e-12)
    assert active.tolist() == [True, True, True]
    ctx.pos = np.array([[0.0, 0.0], [-1.0, 0.0], [5.0, 5.0]])  # b behind a, c far
    ctx.theta = np.zeros(3)
    shift, active = keep_right(ctx)
    assert active.tolist() == [False, True, False]
