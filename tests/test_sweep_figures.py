"""What the sweep's rates figure draws (``sandbox.study.figures``).

Lines that coincide stay visible (set apart along x, each its own marker and
dashes), categories are points with error bars and not joined by lines, and a
settling panel without a settled run says so rather than showing an empty axis.
"""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from helpers import PAPER

from sandbox.cli import main
from sandbox.study import figures

matplotlib.use("Agg")


@pytest.fixture
def drawn(monkeypatch) -> list:
    """The figures ``sweep plot`` saves, kept for inspection."""
    saved: list = []
    real = figures.save_figure
    monkeypatch.setattr(
        figures, "save_figure", lambda fig, path: (saved.append(fig), real(fig, path))
    )
    return saved


def lines_of(ax) -> list:
    """The data lines of an axis (not the error bars' caps and bars)."""
    return [line for line in ax.get_lines() if line.get_marker() not in ("", "_")]


@pytest.mark.slow
def test_categories_and_coinciding_lines_and_no_settled_run(tmp_path, drawn) -> None:
    out = tmp_path / "out"
    argv = ["sweep", str(PAPER / "fig15_continuous_beta1.yaml"), "--seeds", "0:2"]
    argv += ["--set", "duration=0.3", "--grid", "recovery.strategy=none,continuous"]
    argv += ["--grid", "recovery.tangential=0,1", "--out", str(out)]
    assert main(argv) == 0
    assert main(["sweep", "plot", str(out)]) == 0
    fig = drawn[0]  # rates_recovery_strategy.png
    collisions, unsettled, settling = fig.axes[:3]
    for ax in (collisions, unsettled):
        lines = lines_of(ax)
        assert len(lines) == 2  # tangential 0 and 1
        # every run is unsettled at 0.3 s: the two lines hold the same values ...
        np.testing.assert_array_equal(*(line.get_ydata() for line in lines))
        # ... and are set apart along x, with markers of their own, not joined
        first, second = (np.asarray(line.get_xdata()) for line in lines)
        assert (second - first > 0.05).all()
        assert lines[0].get_marker() != lines[1].get_marker()
        assert all(line.get_linestyle() == "None" for line in lines)
    texts = [t.get_text() for t in settling.texts]
    assert texts == ["no run settled"] and not list(settling.get_yticks())
    assert settling.get_xlim() == collisions.get_xlim()


def test_the_lines_are_spread_over_a_third_of_the_smallest_step() -> None:
    # 3 lines over x = 1, 2.5, 5: the smallest step is 1.5, the spread 0.2 * 1.5
    np.testing.assert_allclose(figures.dodges([1, 2.5, 5], 3), [-0.15, 0, 0.15])
    assert figures.dodges([0.0], 1).tolist() == [0.0]
