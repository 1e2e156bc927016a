"""The test tiers: ``pytest -m "not slow"`` (quick, first) and the whole suite.

docs/testing.md gives the two commands and their measured times. The marks are read
from the test files (an AST walk, no inner pytest session: this test is quick).
"""

from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def _is_slow(node: ast.expr) -> bool:
    return ast.unparse(node) in ("pytest.mark.slow", "[pytest.mark.slow]")


def slow_tests() -> tuple[set[str], set[str]]:
    """``(slow, quick)`` test functions as ``path::name``."""
    slow, quick = set(), set()
    for path in sorted(TESTS.rglob("test_*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        whole = any(
            isinstance(n, ast.Assign)
            and any(getattr(t, "id", None) == "pytestmark" for t in n.targets)
            and _is_slow(n.value)
            for n in tree.body
        )
        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and node.name.startswith("test_"):
                name = f"{path.relative_to(TESTS.parent).as_posix()}::{node.name}"
                marked = whole or any(_is_slow(d) for d in node.decorator_list)
                (slow if marked else quick).add(name)
    return slow, quick


def test_the_quick_tier_leaves_the_long_runs_to_the_whole_suite() -> None:
    slow, quick = slow_tests()
    assert len(slow) >= 50 and len(quick) >= 300
    # the heaviest ones measured (docs/testing.md) are in the whole suite only
    for heavy in (
        "tests/test_sweep_dask.py::test_dask_gives_the_local_results",
        "tests/test_safety_benchmark.py::test_the_door_under_the_recommended",
        "tests/test_check.py::test_the_bundled_claims_hold",
        "tests/test_failure_scenarios.py::test_obstacle_field",
    ):
        assert any(t.startswith(heavy) for t in slow), heavy
    # the quick tier still checks determinism, counted collisions and the CLI
    for kept in (
        "tests/test_determinism.py::test_same_seed_same_arrays_other_seed_other_start",
        "tests/test_determinism.py::test_crossing_case_really_collides",
        "tests/test_obstacles.py::test_the_collision_helper_asserts_a_count_in_two",
        "tests/test_cli_help.py::test_version",
        "tests/test_tiers.py::test_the_quick_tier_leaves_the_long_runs",
    ):
        assert any(t.startswith(kept) for t in quick), kept
