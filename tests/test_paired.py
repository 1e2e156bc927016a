"""Two settings over the same seeds: the exact McNemar test in ``sandbox sweep table``.

v0.2 reported a comparison of strategies over the same seeds as two separate rates with
their Wilson intervals, without a paired test.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest
from scipy.stats import binomtest

from sandbox.cli import main
from sandbox.study.paired import mcnemar_p, paired_rows, sweep_settings


@pytest.mark.parametrize(
    ("b", "c"), [(0, 1), (3, 0), (5, 5), (2, 9), (17, 4), (40, 25)]
)
def test_the_p_value_is_the_exact_binomial_test_of_the_discordant_pairs(
    b: int, c: int
) -> None:
    # under H0 each discordant pair falls either way with probability 1/2
    assert mcnemar_p(b, c) == pytest.approx(binomtest(b, b + c, 0.5).pvalue, rel=1e-12)


def row(seed: int, collided: bool, settled: bool = True) -> dict[str, str]:
    return {
        "status": "ok",
        "seed": str(seed),
        "collisions.healthy": "1" if collided else "0",
        "converged": "true" if settled else "false",
    }


def test_only_the_discordant_starts_count() -> None:
    # starts 0-9: A collides on 0-5, B on 4-9: A only on 0-3 (4), B only on 6-9 (4)
    a = {s: row(s, s <= 5) for s in range(10)}
    b = {s: row(s, s >= 4) for s in range(12)}  # 10 and 11: no pair, left out
    (collision, unsettled) = paired_rows([("A", a), ("B", b)])
    assert collision == {
        "a": "A",
        "b": "B",
        "outcome": "collision",
        "pairs": 10,
        "a_only": 4,
        "b_only": 4,
        "p": 1.0,
    }
    assert unsettled["a_only"] == unsettled["b_only"] == 0


def test_runs_pair_only_when_the_other_varied_values_agree() -> None:
    rows = [
        {**row(s, s % 2 == 0), "recovery.beta": beta, "recovery.strategy": strategy}
        for s, beta, strategy in itertools.product(range(4), "15", ("none", "smooth"))
    ]
    settings = sweep_settings(
        rows, ["recovery.strategy"], ["recovery.beta", "recovery.strategy"]
    )
    assert [label for label, _ in settings] == [
        "recovery.strategy=none",
        "recovery.strategy=smooth",
    ]
    assert sorted(settings[0][1]) == [(str(s), beta) for s in range(4) for beta in "15"]


@pytest.mark.slow
def test_sweep_table_states_the_paired_test(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "study"
    argv = [
        "sweep",
        "studies/random_formup",
        "--grid",
        "recovery.strategy=none,continuous",
    ]
    assert (
        main([*argv, "--seeds", "0:6", "--set", "duration=2", "--out", str(out)]) == 0
    )
    capsys.readouterr()
    assert main(["sweep", "table", str(out)]) == 0
    text = capsys.readouterr().out
    assert "exact McNemar test" in text
    assert (
        "| recovery.strategy=none | recovery.strategy=continuous | collision |" in text
    )
    assert main(["sweep", "table", str(out), "--paired", "--format", "csv"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "a,b,outcome,pairs,a_only,b_only,p"
    assert lines[1].startswith(
        "recovery.strategy=none,recovery.strategy=continuous,collision,6,"
    )
