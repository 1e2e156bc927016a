"""Test configuration: plotting is always headless."""

import pytest


@pytest.fixture(autouse=True)
def _headless_matplotlib(monkeypatch: pytest.MonkeyPatch) -> None:
    """Force matplotlib's non-GUI Agg backend (also in subprocesses the test starts)."""
    monkeypatch.setenv("MPLBACKEND", "Agg")
