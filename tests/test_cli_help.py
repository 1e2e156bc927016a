"""The command line's manners: ``--version``, help on every argument, examples, a fast
start (no scipy.spatial, matplotlib or physics engine imported to build the parser or
to validate a small file), and progress bars only where someone watches.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import numpy as np
import pytest
from helpers import PAPER

import sandbox
from sandbox.cli import build_parser, main
from sandbox.cli.common import progress, progress_enabled

HEAVY = (
    "scipy.spatial",
    "matplotlib",
    "pymunk",
    "pandas",
    "pyarrow",
    "tqdm",
    "numpy",
)


def imported_after(code: str) -> set[str]:
    """The top-level-or-dotted modules of HEAVY loaded after running ``code``."""
    probe = (
        f"import sys, json\n{code}\n"
        f"print(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    return set(json.loads(out.splitlines()[-1]))


def test_importing_the_cli_loads_nothing_heavy() -> None:
    # Not even numpy: `sandbox --help` costs the interpreter's start and little more.
    assert imported_after("import sandbox.cli; sandbox.cli.build_parser()") == set()


def test_help_and_validate_of_a_small_file_stay_off_the_heavy_imports() -> None:
    code = (
        "from sandbox.cli import main\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        f"main(['validate', {str(PAPER / 'rotating_circle.yaml')!r}])"
    )
    assert imported_after(code) == {"numpy"}  # the loader needs numpy, nothing more


def test_a_run_never_imports_matplotlib(tmp_path) -> None:
    code = (
        "from sandbox.cli import main\n"
        f"main(['run', 'paper/rotating_circle', '--duration', '0.5', "
        f"'--out', {str(tmp_path / 'o')!r}])"
    )
    loaded = imported_after(code)
    assert "pymunk" in loaded  # the probe sees what a run imports
    assert "matplotlib" not in loaded


def test_version(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"sandbox {sandbox.__version__}"


def test_no_command_prints_the_help(capsys: pytest.CaptureFixture) -> None:
    assert main([]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: sandbox")
    for command in ("run", "list", "copy", "validate", "plot", "compare"):
        assert f"\n    {command} " in out


def subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (sub,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


@pytest.mark.parametrize("name", sorted(subparsers()))
def test_every_argument_has_help_and_every_command_an_example(name: str) -> None:
    parser = subparsers()[name]
    missing = [
        "/".join(a.option_strings) or a.dest
        for a in parser._actions
        if not isinstance(a, argparse._HelpAction) and not a.help
    ]
    assert missing == [], f"sandbox {name}: arguments without help text: {missing}"
    assert parser.epilog and parser.epilog.startswith("examples:\n"), name
    examples = parser.epilog.splitlines()[1:]
    assert examples and all(
        line.strip().startswith(f"sandbox {name}") for line in examples
    ), f"sandbox {name}: every example line runs 'sandbox {name}'"


def test_progress_is_silent_off_a_terminal(capsys, monkeypatch) -> None:
    monkeypatch.delenv("SANDBOX_PROGRESS", raising=False)
    assert not progress_enabled()  # pytest's captured stderr is no terminal
    with progress(10, "work") as bar:
        bar(5)
        bar.advance()
        bar.write("a line")
    assert capsys.readouterr() == ("a line\n", "")


def test_progress_is_silent_under_ci_even_on_a_terminal(monkeypatch) -> None:
    monkeypatch.delenv("SANDBOX_PROGRESS", raising=False)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    monkeypatch.setenv("CI", "true")
    assert not progress_enabled()
    monkeypatch.setenv("CI", "")
    assert progress_enabled()


def test_the_progress_line_is_erased_before_the_summary(
    tmp_path, capsys, monkeypatch
) -> None:
    monkeypatch.setenv("SANDBOX_PROGRESS", "1")
    out = tmp_path / "o"
    assert (
        main(["run", "paper/rotating_circle", "--duration", "1", "--out", str(out)])
        == 0
    )
    captured = capsys.readouterr()
    assert "simulating:" in captured.err and "%|" in captured.err  # a tqdm bar, ETA
    # the bar's last drawing is blanked out and the cursor is back at column 0,
    # so the summary on stdout starts on a clean line
    assert captured.err.endswith("\r")
    assert captured.err.rsplit("\r", 2)[-2].strip() == ""
    assert captured.out.startswith("rotating_circle: status ok")


def test_the_overlap_check_without_scipy_finds_what_the_kd_tree_finds(
    monkeypatch,
) -> None:
    from sandbox.scenario import checks as scenario

    rng = np.random.default_rng(3)
    pos = rng.uniform(0, 6, size=(120, 2))
    rad = rng.uniform(0.1, 0.6, size=120)
    brute = set(scenario.overlapping_pairs(pos, rad, 10_000))
    monkeypatch.setattr(scenario, "BRUTE_FORCE_PAIRS", 0)
    tree = set(scenario.overlapping_pairs(pos, rad, 10_000))
    assert len(brute) > 20  # the discs do overlap
    assert {(a, b) for a, b, _ in brute} == {(a, b) for a, b, _ in tree}
