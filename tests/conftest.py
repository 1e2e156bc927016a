"""Test configuration: headless plotting; a fixture that restores the registry."""

import pytest

from sandbox.plugins import registration


@pytest.fixture(autouse=True)
def _headless_matplotlib(monkeypatch: pytest.MonkeyPatch) -> None:
    """Force matplotlib's non-GUI Agg backend (also in subprocesses the test starts)."""
    monkeypatch.setenv("MPLBACKEND", "Agg")


@pytest.fixture
def registry_snapshot():
    """Restore the plug-in registry (and the loaded-file cache) after a test."""
    registration._ensure_builtins()
    saved = {k: dict(v) for k, v in registration._REGISTRY.items()}
    loaded = dict(registration._LOADED)
    yield
    for k, v in saved.items():
        registration._REGISTRY[k].clear()
        registration._REGISTRY[k].update(v)
    registration._LOADED.clear()
    registration._LOADED.update(loaded)
