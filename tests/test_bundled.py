"""Bundled scenarios: named like ``paper/rotating_circle``, run from any directory,
listed by the names ``run`` accepts, copied for editing without replacing a file.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import SCENARIOS

from sandbox import load_scenario
from sandbox.cli import main
from sandbox.scenario import bundled


@pytest.fixture()
def elsewhere(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working directory outside the repository, without a scenarios/ folder."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_every_file_of_the_scenarios_folder_has_a_name() -> None:
    files = sorted(SCENARIOS.rglob("*.yaml"))
    assert bundled.scenarios_dir().resolve() == SCENARIOS.resolve()
    assert bundled.names() == sorted(
        p.relative_to(SCENARIOS).with_suffix("").as_posix() for p in files
    )
    assert "paper/rotating_circle" in bundled.names()


@pytest.mark.parametrize(
    "name",
    [
        "paper/rotating_circle",
        "paper/rotating_circle.yaml",
        "scenarios/paper/rotating_circle",
    ],
)
def test_a_name_finds_its_file(name: str, elsewhere: Path) -> None:
    assert bundled.resolve(name) == SCENARIOS / "paper" / "rotating_circle.yaml"


def test_an_existing_file_wins_over_a_bundled_name(elsewhere: Path) -> None:
    mine = elsewhere / "paper" / "rotating_circle.yaml"
    mine.parent.mkdir()
    mine.write_text("my own", encoding="utf-8")
    assert bundled.resolve("paper/rotating_circle.yaml") == Path(
        "paper/rotating_circle.yaml"
    )


@pytest.mark.parametrize(
    "name", ["paper/rotating_circle", "paper/rotating_circle.yaml"]
)
def test_load_scenario_takes_a_bundled_name(name: str, elsewhere: Path) -> None:
    # As on the command line: load_scenario (and the environments, which call it)
    # accept a bundled name from any directory.
    from sandbox import load_scenario

    by_name = load_scenario(name)
    by_file = load_scenario(SCENARIOS / "paper" / "rotating_circle.yaml")
    assert by_name.name == "rotating_circle"
    assert by_name.to_dict() == by_file.to_dict()


def test_load_scenario_prefers_an_existing_file(elsewhere: Path) -> None:
    from sandbox import ScenarioError, load_scenario

    mine = elsewhere / "paper" / "rotating_circle.yaml"
    mine.parent.mkdir()
    mine.write_text("name: [", encoding="utf-8")
    with pytest.raises(ScenarioError):
        load_scenario("paper/rotating_circle.yaml")
    with pytest.raises(ScenarioError, match="no such file"):
        load_scenario("paper/no_such_scenario")


@pytest.mark.parametrize("name", ["../pyproject", "/etc/passwd", "", "paper/../../x"])
def test_a_name_never_reaches_outside_the_folder(name: str) -> None:
    assert bundled.find(name) is None


def test_run_by_name_from_another_directory(elsewhere: Path, capsys) -> None:
    code = main(["run", "paper/rotating_circle", "--duration", "0.5"])
    assert code == 0
    assert (elsewhere / "runs" / "rotating_circle" / "trajectory.csv").is_file()
    assert "rotating_circle: status ok" in capsys.readouterr().out


def test_an_unknown_name_is_one_line_with_a_suggestion(elsewhere: Path, capsys) -> None:
    assert main(["run", "paper/rotating_circl"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert err.startswith("paper/rotating_circl: cannot read the scenario")
    assert "did you mean paper/rotating_circle" in err
    assert not (elsewhere / "runs").exists()


@pytest.mark.slow
def test_list_prints_names_that_run_and_validate_accept(elsewhere: Path, capsys):
    assert main(["list"]) == 0
    listing, footer = capsys.readouterr().out.split("\n\n")
    lines = listing.splitlines()
    names, descriptions = lines[::2], lines[1::2]
    assert names == [n for n in bundled.names() if n != bundled.REFERENCE]
    assert all(d.startswith("    ") and d.strip() for d in descriptions)
    assert "sandbox copy" in footer
    assert main(["validate", *names]) == 0


def test_copy_writes_an_identical_editable_file(elsewhere: Path, capsys) -> None:
    source = SCENARIOS / "paper" / "rotating_circle.yaml"
    assert main(["copy", "paper/rotating_circle"]) == 0
    copy = elsewhere / "rotating_circle.yaml"
    assert copy.read_bytes() == source.read_bytes()
    (elsewhere / "into").mkdir()
    assert main(["copy", "paper/rotating_circle.yaml", "into"]) == 0
    assert (elsewhere / "into" / "rotating_circle.yaml").is_file()
    assert main(["copy", "reference", "ref.yaml"]) == 0
    assert main(["validate", "ref.yaml"]) == 0


def test_a_copy_is_named_after_its_file(elsewhere: Path, capsys) -> None:
    # v0.2 kept the bundled name: the copy's runs replaced runs/rotating_circle/
    source = SCENARIOS / "paper" / "rotating_circle.yaml"
    assert main(["copy", "paper/rotating_circle", "my_circle.yaml"]) == 0
    copy = (elsewhere / "my_circle.yaml").read_text(encoding="utf-8")
    assert load_scenario(elsewhere / "my_circle.yaml").name == "my_circle"
    original = source.read_text(encoding="utf-8")
    assert copy == original.replace("name: rotating_circle", "name: my_circle", 1)
    assert main(["copy", "reference", "ref.yaml"]) == 0
    line = next(
        x
        for x in (elsewhere / "ref.yaml").read_text().splitlines()
        if x.startswith("name:")
    )
    assert line.startswith("name: ref ") and "# default" in line  # the comment stays


def test_copy_never_replaces_a_file(elsewhere: Path, capsys) -> None:
    mine = elsewhere / "mine.yaml"
    mine.write_text("my edits\n", encoding="utf-8")
    assert main(["copy", "paper/rotating_circle", "mine.yaml"]) == 1
    assert mine.read_text(encoding="utf-8") == "my edits\n"
    err = capsys.readouterr().err
    assert err.startswith("error: mine.yaml: exists, not replaced")


def test_copy_of_an_unknown_name_fails_cleanly(elsewhere: Path, capsys) -> None:
    assert main(["copy", "paper/nope"]) == 2
    assert "cannot read the scenario" in capsys.readouterr().err
    assert list(elsewhere.iterdir()) == []


def test_the_environments_take_a_bundled_name(elsewhere: Path) -> None:
    pytest.importorskip("gymnasium")
    from sandbox.envs import VehicleEnv

    env = VehicleEnv("failures/follower_stop", agent="red")
    obs, _ = env.reset(seed=0)
    assert env.task.source.scenario.name == "follower_stop"
    assert obs.shape == (7 + 6 * 3,)
