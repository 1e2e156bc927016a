"""A scenario's warnings: ``warnings.warn`` with SandboxWarning; one line in the CLI."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import pytest
import yaml

import sandbox
from sandbox import SandboxWarning, load_scenario
from sandbox.cli import main
from sandbox.errors import SandboxWarning as FromErrors

MINIMAL = {
    "name": "demo",
    "duration": 2,
    "reference": {"type": "circle", "center": [0, 0], "radius": 5, "speed": 1},
    "formation": {"law": "rotating"},
    "vehicles": [
        {"name": "leader", "pose": [5, 0, 1.5708], "leader": True},
        {"name": "red", "pose": [4, -1, 1.5708], "offset": [-1, 1]},
        {"name": "green", "pose": [6, -1, 1.5708], "offset": [-1, -1]},
    ],
}
SLOTS = "slots of red and green are 0.3 m apart, closer than a diameter"
RADIUS = "R = 0.4 m is smaller than the vehicle diameter 0.5 m"


@pytest.fixture
def doubtful(tmp_path: Path) -> Path:
    """A valid scenario with two warnings: slots too close, R below a diameter."""
    doc = yaml.safe_load(yaml.safe_dump(MINIMAL))
    doc["vehicles"][2]["offset"] = [-1, 0.7]  # 0.3 m from red's slot, d = 0.5 m
    doc["recovery"] = {"strategy": "discontinuous", "R": 0.4}
    doc["duration"] = 0.5
    path = tmp_path / "doubt.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def test_the_category_is_public_and_a_user_warning() -> None:
    assert sandbox.SandboxWarning is FromErrors
    assert issubclass(SandboxWarning, UserWarning)
    assert "SandboxWarning" in sandbox.__all__


def test_the_loader_warns_and_keeps_the_warnings(doubtful: Path) -> None:
    with pytest.warns(SandboxWarning) as caught:
        scenario = load_scenario(doubtful)
    messages = [str(w.message) for w in caught]
    assert messages == list(scenario.warnings) and len(messages) == 2
    assert any(SLOTS in m for m in messages) and any(RADIUS in m for m in messages)
    # each one points at the caller's code, not at the loader's
    assert {w.filename for w in caught} == {__file__}


def test_an_error_filter_makes_a_warning_an_error(doubtful: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", SandboxWarning)
        with pytest.raises(SandboxWarning, match="doubt.yaml"):
            load_scenario(doubtful)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SandboxWarning)
        assert len(load_scenario(doubtful).warnings) == 2


@pytest.mark.filterwarnings("default::sandbox.SandboxWarning")
@pytest.mark.parametrize("command", ["validate", "run"])
def test_the_cli_prints_one_line_per_warning(
    doubtful: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    argv = [command, str(doubtful)]
    if command == "run":
        argv += ["--out", str(tmp_path / "out")]
    assert main(argv) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if line]
    assert len(err) == 2 and all(line.startswith("warning: ") for line in err)
    assert RADIUS in err[0] and SLOTS in err[1]  # in the order of their lines


def test_python_w_error_makes_the_cli_refuse(doubtful: Path) -> None:
    argv = [sys.executable, "-W", "error", "-m", "sandbox", "validate", str(doubtful)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.startswith("error: ") and RADIUS in done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    plain = subprocess.run(argv[:1] + argv[3:], capture_output=True, text=True)
    assert plain.returncode == 0
    assert plain.stderr.count("warning: ") == 2 and "Traceback" not in plain.stderr
