"""The hostile corpus of the replay and sweep pages: names that try to become code.

A scenario (or a crafted run directory, or a sweep store's directory) may name things
with the page's own placeholders, with ``</script>``, ``<!--``, U+2028 or an element
with an inline handler. v0.3 filled the template by successive replacements (a name
``{{DATA}}`` received the data, description and all, unescaped), escaped ``<!--`` as
``<\\!--`` (not JSON: a blank page) and let inline handlers run. Now every such text
must stay text: checked in the HTML without a browser for every bundled scenario's
name and description, and in Chromium (``tests/browser.py``) for pages made by real
runs, by crafted runs and by a sweep: the page shows, no handler runs.
"""

from __future__ import annotations

import base64
import dataclasses
import hashlib
import json
import re
from collections.abc import Iterator
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
import yaml
from browser import ARGS, CHROMIUM, Page, require_browser, wait_until
from crafted import crafted_run
from helpers import HEADON, SCENARIOS, write_yaml

from sandbox import simulate
from sandbox.cli import main
from sandbox.render.replay import replay_html, write_html
from sandbox.render.replay.encode import beam_data, decimation, replay_data
from sandbox.render.replay.page import PLACEHOLDERS
from sandbox.run.metrics import compute_metrics
from sandbox.run.record import Run
from sandbox.scenario import load_scenario

#: Texts that must stay text on a page: every placeholder of its template, and what
#: ends a script, opens a comment, ends a JavaScript line or holds an inline handler.
HOSTILE = [
    *(f"{{{{{p}}}}}" for p in PLACEHOLDERS),
    "{{DATA}}{{SCRIPT}}",
    "</script><script>window.__pwned = 1</script>",
    "</SCRIPT >",
    "<!--",
    "<!-- <script>",
    "a\u2028b\u2029c",
    '<img src="data:," onerror="window.__pwned = 2">',
    '"><svg onload="window.__pwned = 3">',
    "&lt;b&gt; &amp; <b>bold</b>",
    "]]></title><h1 id=scenario>",
]
#: The handler payloads above set this global: it must stay undefined.
PWNED = "window.__pwned === undefined"


# ------------------------------------------------------------- the HTML, no browser
class PageParts(HTMLParser):
    """The parts of a page that matter here: title, h1, scripts, the policy."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.scripts: list[tuple[dict, str]] = []
        self.titles: list[str] = []
        self.h1: list[str] = []
        self.csp: list[str] = []
        self._in: str | None = None
        self._attrs: dict = {}
        self._text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list) -> None:
        if tag == "meta" and dict(attrs).get("http-equiv") == "Content-Security-Policy":
            self.csp.append(dict(attrs)["content"])
        if tag in ("script", "title", "h1"):
            self._in, self._attrs, self._text = tag, dict(attrs), []

    def handle_data(self, data: str) -> None:
        if self._in is not None:
            self._text.append(data)

    def handle_endtag(self, tag: str) -> None:
        if tag != self._in:
            return
        text = "".join(self._text)
        if tag == "script":
            self.scripts.append((self._attrs, text))
        else:
            (self.titles if tag == "title" else self.h1).append(text)
        self._in = None


def check_page(html: str, name: str, description: str) -> None:
    """The page shows ``name`` as text, embeds the data whole, runs its script only."""
    parts = PageParts()
    parts.feed(html)
    assert parts.titles == [f"{name} - sandbox replay"]
    assert parts.h1 == [name]
    assert [a.get("type") for a, _ in parts.scripts] == ["application/json", None]
    (_, data_text), (_, script) = parts.scripts
    assert not set(data_text) & set("<>&\u2028\u2029")  # in their \uXXXX forms
    data = json.loads(data_text)
    assert (data["scenario"], data["description"]) == (name, description)
    # one policy, running the inline script by its hash; no 'unsafe-inline' script
    (csp,) = parts.csp
    script_src = re.search(r"script-src ([^;]*)", csp).group(1).split()
    digest = base64.b64encode(hashlib.sha256(script.encode()).digest()).decode()
    assert script_src == [f"'sha256-{digest}'"]


@pytest.fixture(scope="module")
def small() -> tuple[Run, dict]:
    """A short run of two vehicles and its metrics (the page's body)."""
    run = simulate(load_headon(duration=0.3))
    return run, compute_metrics(run)


def load_headon(**changes: object) -> object:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        return load_scenario(write_yaml(Path(tmp), {**HEADON, **changes}))


def bundled_texts() -> Iterator[tuple[str, str, str]]:
    """``(file, name, description)`` of every bundled scenario and sweep file."""
    for path in sorted(SCENARIOS.rglob("*.yaml")):
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
        doc = doc.get("base", doc) if isinstance(doc.get("base"), dict) else doc
        name = str(doc.get("name") or path.stem)
        yield str(path.relative_to(SCENARIOS)), name, str(doc.get("description") or "")


def substituted(
    small: tuple[Run, dict], texts: list[str], pages: int | None = None
) -> int:
    """Pages of the small run named as each bundled scenario, with each text in.

    The name goes in as the page's title (the loader refuses some of the texts in a
    name), the description as the scenario's; returns how many pages were checked.
    """
    run, metrics = small
    count = 0
    for file, name, description in bundled_texts():
        for bad in texts:
            pairs = ((f"{name}{bad}", f"{bad}{description}{bad}"), (bad, bad))
            for new_name, new_description in pairs:
                sc = dataclasses.replace(run.scenario, description=new_description)
                described = dataclasses.replace(run, scenario=sc)
                page = replay_html(described, metrics, title=new_name)
                try:
                    check_page(page, new_name, new_description)
                except AssertionError as exc:
                    raise AssertionError(f"{file} with {bad!r}: {exc}") from None
                count += 1
    return count


@pytest.mark.slow
def test_every_bundled_name_and_description_stays_text(
    small: tuple[Run, dict],
) -> None:
    """Each bundled scenario's name and description with all hostile texts in it."""
    assert substituted(small, ["".join(HOSTILE)]) >= 2 * 60


@pytest.mark.slow
def test_every_bundled_name_and_description_with_each_hostile_text(
    small: tuple[Run, dict],
) -> None:
    """The same with each hostile text alone: about 2,000 pages."""
    assert substituted(small, HOSTILE) >= 2 * 60 * len(HOSTILE)


def test_a_page_holds_the_data_once(small: tuple[Run, dict]) -> None:
    """v0.3: a title ``{{DATA}}`` received the data a second time, unescaped."""
    run, metrics = small
    sc = dataclasses.replace(run.scenario, name="{{DATA}}", description="x")
    info = {**run.info, "scenario_name": "{{DATA}}"}
    page = replay_html(dataclasses.replace(run, scenario=sc, info=info), metrics)
    check_page(page, "{{DATA}}", "x")
    assert page.count('"format":1') == 1


# ------------------------------------------------------------------ the beams' budget
def test_the_beams_count_in_the_pages_budget() -> None:
    """16 vehicles of 1,024 beams for 60 s: thinned to the readings' budget, said so.

    v0.3 counted vehicle-samples only and wrote a 72.5 MB page (in 146 s and 4 GB).
    """
    assert decimation(6001, 16) == 1
    assert decimation(6001, 16, beams=1024) == 50  # 98.3 M readings / 2 M
    T, n, B = 601, 4, 1024
    t = np.linspace(0.0, 60.0, T)
    pose = np.zeros((T, n, 3))
    pose[:, :, 0] = np.arange(n) * 2.0
    run = crafted_run(
        t,
        pose,
        ranges=np.full((T, n, B), 3.0, dtype=np.float32),
        beam_angles=np.tile(np.linspace(-np.pi, np.pi, B, endpoint=False), (n, 1)),
    )
    data = replay_data(run, beams=B)
    want = -(-T * n * B // 2_000_000)  # 2.46 M readings: every 2nd sample
    assert data["stride"] == want == 2
    assert data["samples"] * n * B <= 2_000_000 + n * B  # the last sample is kept too
    assert "range readings" in " ".join(data["notes"])
    beams = beam_data(run, data)
    assert beams["ranges"]["shape"] == [data["samples"], n, B]
    # without the beams the same run is not thinned
    assert replay_data(run)["stride"] == 1


# ------------------------------------------------------------------ in the browser
@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    sync_api = require_browser()  # skips these tests only, saying what is missing
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


def accepted(doc: dict, bad: str) -> dict:
    """``doc`` with ``bad`` in every field the loader lets hold it.

    Names refuse quotes, slashes and control characters (``</script>``, U+2028), so
    they keep their own where ``bad`` is refused; a description takes any text.
    """
    import tempfile

    from sandbox.errors import ScenarioError

    out = json.loads(json.dumps(doc))
    out["description"] = bad
    named = (out, out["platoons"][1]["vehicles"][0], out["platoons"][1])
    for where in (*named, out["obstacles"][0]):
        old = where["name"]
        where["name"] = bad
        try:
            with tempfile.TemporaryDirectory() as tmp:
                load_scenario(write_yaml(Path(tmp), out))
        except ScenarioError:
            where["name"] = old
    return out


#: Two platoons of one vehicle each and an obstacle, 0.3 s.
NAMED = {
    "name": "named",
    "duration": 0.3,
    "platoons": [
        {
            "name": "p1",
            "reference": {"type": "point", "position": [0, 0]},
            "vehicles": [{"name": "a", "pose": [0, 0, 0], "leader": True}],
        },
        {
            "name": "p2",
            "reference": {"type": "point", "position": [3, 0]},
            "vehicles": [{"name": "b", "pose": [3, 0, 0], "leader": True}],
        },
    ],
    "obstacles": [{"type": "circle", "name": "o", "center": [5, 5], "radius": 0.5}],
}


def shows_safely(page: object, title: str) -> None:
    """The page decoded its data, shows ``title`` as text, and ran no handler."""
    page.page.wait_for_timeout(150)  # an injected image's onerror would have fired
    assert page.js(PWNED)
    assert page.errors == []
    assert page.js("document.getElementById('scenario').textContent") == title
    assert page.page.locator("#message").is_hidden()
    assert page.js("window.sandboxReplay.events()") is not None


@pytest.mark.parametrize("bad", HOSTILE)
def test_names_of_a_real_run_stay_text_in_the_browser(
    browser: object, tmp_path: Path, bad: str
) -> None:
    doc = accepted(NAMED, bad)
    run = simulate(load_scenario(write_yaml(tmp_path, doc)))
    p = Page(browser, write_html(run, tmp_path / "replay.html"))
    try:
        shows_safely(p, doc["name"])
        assert p.js("document.getElementById('scenario').title") == bad
        legend = p.js("document.getElementById('legend').textContent")
        for v in run.names:
            assert v in legend
    finally:
        p.context.close()


def test_the_name_data_with_a_handler_in_the_description(
    browser: object, tmp_path: Path
) -> None:
    """v0.3: the data, description and all, pasted unescaped where the name was."""
    handler = '<img src=data:,x onerror="window.__pwned = 4">'
    doc = {**NAMED, "name": "{{DATA}}", "description": handler}
    run = simulate(load_scenario(write_yaml(tmp_path, doc)))
    out = tmp_path / "run"
    assert main(["view", str(write_dir(run, out))]) == 0
    p = Page(browser, out / "replay.html")
    try:
        shows_safely(p, "{{DATA}}")
        assert p.js("document.getElementById('scenario').title") == handler
    finally:
        p.context.close()


def write_dir(run: Run, out: Path) -> Path:
    from sandbox.run.output import write_run_dir

    return write_run_dir(run, compute_metrics(run), out)


def crafted(bad: str) -> Run:
    """A run as a crafted ``run.npz`` may hold it: names the loader would refuse."""
    T, n = 11, 2
    pose = np.zeros((T, n, 3))
    pose[:, 1, 0] = 2.0
    return crafted_run(
        np.linspace(0.0, 1.0, T),
        pose,
        slot=pose[:, :, :2].copy(),
        target=pose[:, :, :2].copy(),
        names=[bad, f"2{bad}"],
        colors=["blue", "red"],
        leader=0,
        info={
            "scenario_name": bad,
            "obstacles": [
                {"name": bad, "type": "circle", "center": [5, 5], "radius": 0.5}
            ],
            "recovery": {"strategy": bad},
        },
    )


@pytest.mark.parametrize("bad", HOSTILE)
def test_names_of_a_crafted_run_stay_text_in_the_browser(
    browser: object, tmp_path: Path, bad: str
) -> None:
    run = crafted(bad)
    p = Page(browser, write_html(run, tmp_path / "replay.html"))
    try:
        shows_safely(p, bad)
        p.js(f"window.sandboxReplay.select({json.dumps(bad)})")
        assert p.js("document.getElementById('vehicle-name').textContent") == bad
    finally:
        p.context.close()


def test_the_policy_blocks_inline_handlers(
    browser: object, tmp_path: Path, small: tuple[Run, dict]
) -> None:
    """Whatever reaches the page's HTML, no inline handler of it runs."""
    run, _ = small
    p = Page(browser, write_html(run, tmp_path / "replay.html"))
    try:
        p.js(
            "document.body.insertAdjacentHTML('beforeend', "
            '\'<img src="data:,x" onerror="window.__pwned = 9">\')'
        )
        p.page.wait_for_timeout(200)
        assert p.js(PWNED)
        assert p.violations  # the browser says it refused the handler
    finally:
        p.context.close()


@pytest.mark.parametrize("folder", ["{{DATA}}", "{{SCRIPT}}<!--", "{{TITLE}}&amp;"])
def test_a_sweep_store_named_like_a_placeholder(
    browser: object, tmp_path: Path, folder: str
) -> None:
    scenario = str(write_yaml(tmp_path, HEADON))
    out = tmp_path / folder
    argv = ["sweep", scenario, "--grid", "duration=0.3,0.5", "--out", str(out)]
    assert main([*argv, "--keep-runs"]) == 0
    assert main(["sweep", "view", str(out)]) == 0
    p = Page(browser, out / "sweep.html", ready=False)
    try:
        wait_until(p.page, "window.sandboxSweep !== undefined")
        assert len(p.js("window.sandboxSweep.rows()")) == 2
        assert p.page.locator("#title").inner_text() == f"sweep {folder}"
        assert p.js(PWNED) and p.errors == []
    finally:
        p.context.close()
