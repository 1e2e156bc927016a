"""A plug-in that fails mid-run ends the run with status ``error``, written and named.

v0.2 gave a traceback and no output directory for an exception, exit 0 and no message
for ``SystemExit``, and accepted a NaN shift with status ``ok``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sandbox import Simulation, load_run, load_scenario
from sandbox.cli import main

STRATEGY = """\
import numpy as np

from sandbox.plugins import register_strategy


@register_strategy("{name}")
def failing(ctx):
    '''Fails at 0.3 s.'''
    if ctx.t >= 0.3:
        {action}
    return np.zeros((ctx.n, 2)), np.zeros(ctx.n, dtype=bool)
"""


@pytest.fixture(autouse=True)
def trusted(monkeypatch: pytest.MonkeyPatch, registry_snapshot: None) -> None:
    """These runs load their own plug-ins; the registry is restored after each."""
    monkeypatch.setenv("SANDBOX_TRUST_PLUGINS", "1")


def scenario(tmp_path: Path, name: str, action: str) -> Path:
    plugin = tmp_path / f"{name}.py"
    plugin.write_text(STRATEGY.format(name=name, action=action), encoding="utf-8")
    path = tmp_path / f"{name}.yaml"
    path.write_text(
        f"name: {name}\nplugins: [{name}.py]\nduration: 1.0\n"
        "reference: {type: line, speed: 0.5}\nformation: {law: rotating}\n"
        f"recovery: {{strategy: {name}}}\n"
        "vehicles:\n"
        "  - {name: leader, pose: [0, 0, 0], leader: true}\n"
        "  - {name: red, pose: [-2, 0.5, 0], offset: [-2, 0.5]}\n",
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize(
    ("name", "action", "said"),
    [
        ("t_raises", "raise RuntimeError('no luck')", "RuntimeError: no luck"),
        ("t_exits", "raise SystemExit(0)", "SystemExit"),
        ("t_nan", "return np.full((ctx.n, 2), np.nan), np.ones(ctx.n, bool)", "NaN"),
    ],
)
def test_the_run_ends_with_status_error_and_its_outputs(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    name: str,
    action: str,
    said: str,
) -> None:
    path = scenario(tmp_path, name, action)
    out = tmp_path / "run"
    assert main(["run", str(path), "--out", str(out)]) == 1
    err = [x for x in capsys.readouterr().err.splitlines() if x.startswith("error")]
    assert len(err) == 1 and f"recovery strategy {name}" in err[0] and said in err[0]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["status"] == "error"
    assert metrics["error"]["t"] == pytest.approx(0.3)
    assert name in metrics["error"]["plugin"] and said in metrics["error"]["message"]
    run = load_run(out)
    assert run.status == "error" and run.t[-1] == pytest.approx(0.3)


def test_the_message_gives_the_line_of_the_plugin(tmp_path: Path) -> None:
    path = scenario(tmp_path, "t_line", "raise ValueError('bad')")
    run = Simulation(load_scenario(path)).run()
    assert run.status == "error"
    # the raise is on line 10 of the plug-in file
    assert f"{tmp_path / 't_line.py'}, line 10" in run.info["error"]["message"]


def test_a_plugin_that_exits_while_it_is_imported_is_one_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = scenario(tmp_path, "t_import_exit", "pass")
    plugin = tmp_path / "t_import_exit.py"
    plugin.write_text("raise SystemExit(0)\n" + plugin.read_text(), encoding="utf-8")
    assert main(["run", str(path), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert "plug-in cannot be loaded" in err and "SystemExit" in err


def test_a_law_may_leave_a_vehicle_without_a_slot_without_a_target() -> None:
    # A reconfiguration gives a vehicle without a slot a NaN offset; a plug-in law's
    # NaN target there is what the built-in laws give (no slot), not an error, while
    # a NaN for a vehicle with a slot still ends the run.
    import numpy as np

    from sandbox.errors import PluginRunError
    from sandbox.plugins import register_law
    from sandbox.plugins.registration import LawContext, make_law

    @register_law("offset_only")
    def offset_only(ctx):
        return ctx.offset, np.zeros_like(ctx.offset), np.zeros_like(ctx.offset)

    def context(offset):
        n = len(offset)
        return LawContext(
            t=0.0, dt=0.01, pos=np.zeros((n, 2)), theta=np.zeros(n),
            vel=np.zeros((n, 2)), offset=offset, leader=0, leader_pos=None,
            leader_theta=None, reference=None, params={}, memory={},
        )  # fmt: skip

    law = make_law("offset_only", {}, np.zeros((3, 2)), 0.01)
    slotless = np.array([[0.0, 0.0], [np.nan, np.nan], [-1.0, 0.5]])
    slot = law.targets(context(slotless))[0]
    assert np.isnan(slot[1]).all() and np.isfinite(slot[[0, 2]]).all()

    @register_law("nan_everywhere")
    def nan_everywhere(ctx):
        nan = np.full(np.shape(ctx.offset), np.nan)
        return nan, nan, nan

    law = make_law("nan_everywhere", {}, np.zeros((3, 2)), 0.01)
    with pytest.raises(PluginRunError, match="NaN"):
        law.targets(context(slotless))
