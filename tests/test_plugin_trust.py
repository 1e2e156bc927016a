"""A scenario is data: the plug-in code it lists runs only on an explicit opt-in.

Each test writes a scenario whose plug-in file leaves a mark on disk when its code runs,
so "the code did not run" is observed, not assumed.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from sandbox import load_scenario
from sandbox.cli import main
from sandbox.errors import ScenarioError
from sandbox.scenario.trust import UncheckedScenario

PLUGIN = """\
from pathlib import Path

Path(__file__).with_name("ran.txt").write_text("the plug-in's code ran")

from sandbox.plugins import register_strategy


@register_strategy("{name}", params={{"amount": 0.1}})
def strategy(ctx):
    '''Shifts nothing.'''
    import numpy as np

    return np.zeros((ctx.n, 2)), np.zeros(ctx.n, dtype=bool)
"""


@pytest.fixture(autouse=True)
def untrusted(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SANDBOX_TRUST_PLUGINS", raising=False)


def scenario(tmp_path: Path, name: str, plugins: list[str] | None = None) -> Path:
    (tmp_path / "mine.py").write_text(PLUGIN.format(name=name), encoding="utf-8")
    listed = plugins if plugins is not None else ["mine.py"]
    text = (
        f"name: trust\nplugins: {listed}\nduration: 0.5\n"
        "reference: {type: line, speed: 0.5}\nformation: {law: rotating}\n"
        f"recovery: {{strategy: {name}, amount: 0.2}}\n"
        "vehicles:\n"
        "  - {name: leader, pose: [0, 0, 0], leader: true}\n"
        "  - {name: red, pose: [-2, 0.5, 0], offset: [-2, 0.5]}\n"
    )
    path = tmp_path / "trust.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_validate_never_runs_the_code_a_file_lists(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    path = scenario(tmp_path, "t_validate")
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr()
    assert not (tmp_path / "ran.txt").exists()
    assert "ok, not checked: recovery (strategy t_validate)" in out.out
    assert "loading plug-in code" not in out.err


def test_validate_checks_the_listed_paths_and_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    path = scenario(tmp_path, "t_paths", plugins=["missing.py", "no such module"])
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "plugins[0]: no such plug-in file" in err
    assert "plugins[1]: not a module name" in err


def test_validate_does_not_import_a_listed_module(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    registry_snapshot: None,
) -> None:
    (tmp_path / "t_module_plugin.py").write_text(
        PLUGIN.format(name="t_module"), encoding="utf-8"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    path = scenario(tmp_path, "t_module", plugins=["t_module_plugin"])
    assert main(["validate", str(path)]) == 0
    assert "t_module_plugin" not in sys.modules
    assert not (tmp_path / "ran.txt").exists()
    assert "not checked" in capsys.readouterr().out


def test_a_run_without_trust_is_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    path = scenario(tmp_path, "t_refused")
    out = tmp_path / "run"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "plugins: plug-in code is not run without trust (got mine.py" in err[0]
    assert "--trust-plugins" in err[0] and "SANDBOX_TRUST_PLUGINS=1" in err[0]
    assert not (tmp_path / "ran.txt").exists()
    assert not out.exists()


def test_trust_on_the_command_line_runs_it_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    path = scenario(tmp_path, "t_trusted")
    out = tmp_path / "run"
    assert main(["run", str(path), "--out", str(out), "--trust-plugins"]) == 0
    err = capsys.readouterr().err
    assert f"loading plug-in code: {tmp_path / 'mine.py'}" in err
    assert (tmp_path / "ran.txt").exists()


def test_trust_from_the_environment_and_from_python(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, registry_snapshot: None
) -> None:
    path = scenario(tmp_path, "t_env")
    with pytest.raises(ScenarioError, match="not run without trust"):
        load_scenario(path)
    with pytest.raises(ScenarioError, match="not run without trust"):
        load_scenario(path, trust_plugins=False)
    monkeypatch.setenv("SANDBOX_TRUST_PLUGINS", "1")
    with pytest.raises(ScenarioError, match="not run without trust"):
        load_scenario(path, trust_plugins=False)  # the argument wins
    monkeypatch.delenv("SANDBOX_TRUST_PLUGINS")
    assert load_scenario(path, trust_plugins=True).recovery.strategy == "t_env"


def test_a_plugin_named_on_the_command_line_is_trusted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    path = scenario(tmp_path, "t_named")
    out = tmp_path / "run"
    plugin = str(tmp_path / "mine.py")
    assert main(["run", str(path), "--out", str(out), "--plugin", plugin]) == 0
    assert (out / "metrics.json").exists()


def test_set_reaches_a_plugins_own_keys_once_it_is_trusted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    # v0.2 applied --set before loading the plug-ins: "recovery.amount names no field"
    path = scenario(tmp_path, "t_order")
    sc = load_scenario(path, overrides=["recovery.amount=0.3"], trust_plugins=True)
    assert sc.recovery.params["amount"] == 0.3
    out = tmp_path / "run"
    argv = ["run", str(path), "--out", str(out), "--trust-plugins"]
    assert main([*argv, "--set", "recovery.amount=0.4"]) == 0


def test_validate_leaves_a_plugins_keys_set_on_the_command_line_unchecked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    path = scenario(tmp_path, "t_set_unchecked")
    assert main(["validate", str(path), "--set", "recovery.amount=0.3"]) == 0
    assert "not checked" in capsys.readouterr().out
    with pytest.raises(UncheckedScenario) as info:
        load_scenario(path, check_only=True)
    assert info.value.unchecked == [("recovery", "strategy t_set_unchecked")]
    assert not (tmp_path / "ran.txt").exists()


def test_validate_still_reports_the_problems_it_can_check(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    path = scenario(tmp_path, "t_other")
    path.write_text(path.read_text().replace("duration: 0.5", "duration: -1"))
    assert main(["validate", str(path)]) == 2
    assert "duration" in capsys.readouterr().err
