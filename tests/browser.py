"""Pages in a real browser for the tests: the system's headless Chromium, Playwright.

The browser is the system's (``/usr/bin/chromium``, Debian's ``chromium`` package that
``.ci/run`` installs), never a download; the Python side is the ``view`` extra. A test
module calls :func:`require_browser` first: it is skipped, saying why, only when one of
the two is missing.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

CHROMIUM = "/usr/bin/chromium"
#: Longest wait for the page or an element [ms].
TIMEOUT_MS = 20_000
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def require_browser() -> ModuleType:
    """Playwright's sync API, or skip the calling module saying what is missing."""
    sync_api = pytest.importorskip(
        "playwright.sync_api", reason="needs playwright (pip install 'sandbox[view]')"
    )
    if not os.access(CHROMIUM, os.X_OK):
        pytest.skip(
            f"needs the system's Chromium at {CHROMIUM} (apt-get install chromium)",
            allow_module_level=True,
        )
    return sync_api


def wait_until(page: Any, expr: str) -> None:
    """Poll ``expr`` in the page until it is true, for at most TIMEOUT_MS.

    Not ``page.wait_for_function``: when its first check fails it polls through an
    ``eval`` in the page, which the replay's content security policy forbids (a slow
    machine then fails the test instead of waiting).
    """
    deadline = time.monotonic() + TIMEOUT_MS / 1000
    while not page.evaluate(expr):
        if time.monotonic() > deadline:
            raise AssertionError(f"the page never showed {expr}")
        page.wait_for_timeout(20)


class Page:
    """A replay page open in the browser, with the requests it made.

    ``errors`` collects the page's uncaught errors and ``violations`` what its
    content security policy refused (an inline handler the policy blocked, say).
    With ``ready=True`` (the default) the page must have decoded its data.
    """

    def __init__(self, browser: Any, path: Path, ready: bool = True) -> None:
        self.url = path.resolve().as_uri()
        self.context = browser.new_context(viewport={"width": 1200, "height": 800})
        self.requests: list[str] = []
        self.errors: list[str] = []
        self.console: list[str] = []
        self.context.set_default_timeout(TIMEOUT_MS)
        self.page = self.context.new_page()
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.on("console", lambda m: self.console.append(m.text))
        self.page.goto(self.url)
        if ready:
            # bounded: a page that never gets ready fails the test, never hangs it
            wait_until(self.page, "document.body.dataset.ready !== undefined")
            assert self.page.evaluate("document.body.dataset.ready") == "1", self.errors
            assert self.page.evaluate("window.sandboxReplay.ready") is True

    def js(self, expr: str) -> Any:
        return self.page.evaluate(expr)

    def canvas_box(self) -> dict:
        return self.page.locator("#world").bounding_box()

    @property
    def violations(self) -> list[str]:
        """The console's reports of what the content security policy refused."""
        return [m for m in self.console if "Content Security Policy" in m]
