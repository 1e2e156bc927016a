"""The test tiers: ``pytest -m "not slow"`` (quick, first) and the whole suite.

docs/testing.md gives the two commands and their measured times.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def collected(*args: str) -> set[str]:
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:randomly"]
        + ["-p", "no:cacheprovider", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return {line for line in done.stdout.splitlines() if "::" in line}


def test_the_quick_tier_leaves_the_long_runs_to_the_whole_suite() -> None:
    every = collected()
    quick = collected("-m", "not slow")
    assert quick < every
    slow = every - quick
    assert len(slow) >= 50
    # the heaviest ones measured (docs/testing.md) are in the whole suite only
    for heavy in (
        "tests/test_sweep_dask.py::",
        "tests/test_safety_benchmark.py::test_the_door_under_the_recommended",
        "tests/test_check.py::test_the_bundled_claims_hold",
    ):
        assert any(t.startswith(heavy) for t in slow), heavy
        assert not any(t.startswith(heavy) for t in quick), heavy
    # the quick tier still checks determinism, counted collisions and the CLI
    for kept in (
        "tests/test_determinism.py::test_same_seed_same_arrays_other_seed_other_start",
        "tests/test_determinism.py::test_crossing_case_really_collides",
        "tests/test_tiers.py::",
        "tests/test_cli_help.py::",
    ):
        assert any(t.startswith(kept) for t in quick), kept
