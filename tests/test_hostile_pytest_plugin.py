"""The hostile corpus of the pytest plugin: a scenario that lists plug-in code.

v0.3's plugin ran the plug-ins of every scenario it loaded (``sandbox_run`` and
``test_*.yaml`` items passed ``trust_plugins=True``), although a scenario is data and
the command line runs such code only on an opt-in. Now the plugin asks for the same
opt-in: pytest's ``--trust-plugins``, the ini option ``sandbox_trust_plugins`` or
``SANDBOX_TRUST_PLUGINS=1``; without one the test fails with the loader's line and the
plug-in's code never runs.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from helpers import HEADON

pytest_plugins = ["pytester"]
QUIET = ("-p", "no:cacheprovider", "-p", "no:hypothesispytest")
YAML = ("-o", "sandbox_yaml=true")

#: A plug-in that says when its code runs (the marker file) and registers a strategy.
PLUGIN = """\
from pathlib import Path

import numpy as np

from sandbox.plugins import register_strategy

Path(__file__).with_suffix(".ran").write_text("ran")


@register_strategy("{name}")
def idle(ctx):
    return np.zeros((len(ctx.pos), 2)), np.zeros(len(ctx.pos), dtype=bool)
"""

TEST = """\
def test_fixture(sandbox_run):
    assert sandbox_run("listed.yaml").status == "ok"
"""


@pytest.fixture(autouse=True, scope="module")
def _warm_imports() -> None:
    """Import what an inner session imports lazily (see tests/test_pytest_plugin.py)."""
    import sandbox.loop.simulation  # noqa: F401
    from sandbox.testing import check_scenario  # noqa: F401


@pytest.fixture
def project(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch, registry_snapshot: None
) -> tuple[pytest.Pytester, Path]:
    """A project whose scenarios list a plug-in file never loaded in this process."""
    monkeypatch.delenv("SANDBOX_TRUST_PLUGINS", raising=False)
    name = f"idle_{pytester.path.name.replace('-', '_')}"[:60]
    plugin = pytester.path / f"{name}.py"
    plugin.write_text(PLUGIN.format(name=name), encoding="utf-8")
    doc = {
        **HEADON,
        "plugins": [plugin.name],
        "recovery": {"strategy": name},
        "expect": {"collisions": {"total": 1}},
    }
    for file in ("listed.yaml", "test_listed.yaml"):
        (pytester.path / file).write_text(yaml.safe_dump(doc), encoding="utf-8")
    pytester.makepyfile(test_fixture=TEST)
    return pytester, plugin.with_suffix(".ran")


def test_without_an_opt_in_no_plugin_code_runs(
    project: tuple[pytest.Pytester, Path],
) -> None:
    pytester, ran = project
    result = pytester.runpytest(*QUIET, *YAML, "-rf")
    result.assert_outcomes(failed=2)
    out = result.stdout.str()
    assert "plug-in code is not run without trust" in out
    assert "--trust-plugins" in out
    assert not ran.exists()


@pytest.mark.parametrize("opt_in", ["option", "ini", "environment"])
def test_each_opt_in_runs_the_plugin(
    project: tuple[pytest.Pytester, Path],
    monkeypatch: pytest.MonkeyPatch,
    opt_in: str,
) -> None:
    pytester, ran = project
    args = [*QUIET, *YAML]
    if opt_in == "option":
        args.append("--trust-plugins")
    elif opt_in == "ini":
        args += ["-o", "sandbox_trust_plugins=true"]
    else:
        monkeypatch.setenv("SANDBOX_TRUST_PLUGINS", "1")
    result = pytester.runpytest(*args)
    result.assert_outcomes(passed=2)
    assert ran.read_text() == "ran"
