"""The replay page in a real browser: headless Chromium driven by Playwright.

The browser and its helpers are those of ``tests/browser.py``; the tests are skipped,
saying why, only when the system's Chromium or Playwright is missing.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from browser import ARGS, CHROMIUM, TIMEOUT_MS, Page, require_browser, wait_until
from crafted import crafted_run
from helpers import SCENARIOS
from PIL import Image, ImageColor

from sandbox import simulate
from sandbox.render import render_frame
from sandbox.render.camera import Camera
from sandbox.render.replay import write_html
from sandbox.run.record import CollisionEvent, Run
from sandbox.scenario import load_scenario

sync_api = require_browser()


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


@pytest.fixture(scope="module")
def collision_run() -> Run:
    """The bundled Fig. 12 run: no recovery, one contact (leader and red)."""
    run = simulate(load_scenario(SCENARIOS / "paper" / "fig12_no_recovery.yaml"))
    assert run.events
    return run


@pytest.fixture(scope="module")
def page(
    browser: object, collision_run: Run, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Page]:
    path = write_html(collision_run, tmp_path_factory.mktemp("p") / "replay.html")
    p = Page(browser, path)
    yield p
    p.context.close()


def recorded_xy(run: Run, t: float) -> np.ndarray:
    """The positions (n, 2) [m] at ``t``, linear between the recorded samples."""
    return np.stack(
        [
            [np.interp(t, run.t, run.pose[:, i, c]) for c in range(2)]
            for i in range(run.n_vehicles)
        ]
    )


def test_no_request_leaves_the_file(page: Page) -> None:
    page.js("window.sandboxReplay.play()")
    page.page.wait_for_timeout(200)
    page.js("window.sandboxReplay.pause()")
    assert page.requests == [page.url]  # the page itself, nothing else
    assert page.errors == []


def test_events_are_the_recorded_ones(page: Page, collision_run: Run) -> None:
    events = page.js("window.sandboxReplay.events()")
    hits = [e for e in events if e["kind"] == "collision"]
    assert [(e["t"], e["a"], e["b"]) for e in hits] == [
        (pytest.approx(e.t, abs=1e-6), e.a, e.b) for e in collision_run.events
    ]
    marks = page.page.locator("#marks .mark[data-kind=collision]")
    assert marks.count() == len(collision_run.events)


def test_seeking_a_collision_draws_both_vehicles_where_recorded(
    page: Page, collision_run: Run
) -> None:
    run = collision_run
    for ev in run.events:
        page.js(f"window.sandboxReplay.seek({ev.t!r})")
        state = page.js("window.sandboxReplay.state()")
        assert state["t"] == pytest.approx(ev.t)
        want = recorded_xy(run, ev.t)
        for name in (ev.a, ev.b):
            i = run.names.index(name)
            got = np.array(state["vehicles"][name])
            assert np.linalg.norm(got - want[i]) * state["scale"] <= 1.0  # [px]
            # and the canvas has the vehicle's colour there: a point inside the
            # body, off its heading line
            u, v = page.js(f"window.sandboxReplay.worldToPixel({got[0]}, {got[1]})")
            theta = np.interp(ev.t, run.t, run.pose[:, i, 2])
            r = run.diameter[i] / 2 * state["scale"]
            off = (u - 0.5 * r * math.sin(theta), v - 0.5 * r * math.cos(theta))
            assert canvas_color(page, off) == ImageColor.getrgb(run.colors[i])


def canvas_color(page: Page, uv: tuple[float, float]) -> tuple[int, int, int]:
    """The colour drawn at canvas point ``uv`` [CSS px]."""
    rgba = page.js(
        f"""(() => {{
        const c = document.getElementById('world'), dpr = window.devicePixelRatio || 1;
        const d = c.getContext('2d').getImageData(
            Math.floor({uv[0]} * dpr), Math.floor({uv[1]} * dpr), 1, 1).data;
        return [d[0], d[1], d[2]];
    }})()"""
    )
    return tuple(rgba)


def test_play_advances_time(page: Page) -> None:
    page.js("window.sandboxReplay.seek(1.0)")
    page.js("window.sandboxReplay.play()")
    page.page.wait_for_timeout(400)
    state = page.js("window.sandboxReplay.state()")
    page.js("window.sandboxReplay.pause()")
    assert state["playing"] is True
    assert 1.05 < state["t"] < 3.0  # about 0.4 s at 1x


def test_keys_step_and_toggle(page: Page, collision_run: Run) -> None:
    page.js("window.sandboxReplay.seek(2.0)")
    page.page.locator("#view").focus()
    page.page.keyboard.press("ArrowRight")
    t = page.js("window.sandboxReplay.state()")["t"]
    k = int(np.argmin(np.abs(collision_run.t - 2.0)))
    assert t == pytest.approx(collision_run.t[k + 1])  # one sample on
    page.page.keyboard.press("ArrowLeft")
    assert page.js("window.sandboxReplay.state()")["t"] == pytest.approx(2.0)
    page.page.keyboard.press("+")
    assert page.js("window.sandboxReplay.state()")["speed"] == 2
    page.page.keyboard.press("-")
    page.page.keyboard.press("-")
    assert page.js("window.sandboxReplay.state()")["speed"] == 0.5
    page.page.keyboard.press(" ")
    assert page.js("window.sandboxReplay.state()")["playing"] is True
    page.page.keyboard.press(" ")
    assert page.js("window.sandboxReplay.state()")["playing"] is False
    page.js("window.sandboxReplay.setSpeed(1)")


def test_clicking_a_vehicle_shows_its_name(page: Page, collision_run: Run) -> None:
    page.js("window.sandboxReplay.seek(5.0)")
    state = page.js("window.sandboxReplay.state()")
    box = page.canvas_box()
    for name in ("green", "red"):
        x, y = state["vehicles"][name]
        u, v = page.js(f"window.sandboxReplay.worldToPixel({x}, {y})")
        page.page.mouse.click(box["x"] + u, box["y"] + v)
        assert page.page.locator("#vehicle-name").inner_text() == name
        assert page.js("window.sandboxReplay.state()")["selected"] == name
        panel = page.page.locator("#vehicle-panel").inner_text()
        for label in ("x1", "x2", "x3", "v1", "v2", "mode", "formation error"):
            assert label in panel
        state = page.js("window.sandboxReplay.state()")  # the camera follows now
    page.page.keyboard.press("Escape")
    assert page.js("window.sandboxReplay.state()")["selected"] is None


def test_clicking_the_first_contact_on_the_timeline_jumps_to_it(
    page: Page, collision_run: Run
) -> None:
    page.js("window.sandboxReplay.seek(10.0)")
    page.page.locator("#marks .mark[data-kind=collision]").first.click()
    state = page.js("window.sandboxReplay.state()")
    assert state["t"] == pytest.approx(collision_run.events[0].t)
    assert page.js("window.sandboxReplay.state()")["playing"] is False


def test_screenshot_at_a_collision_matches_the_gif_frame(
    page: Page, collision_run: Run, tmp_path: Path
) -> None:
    """The vehicles sit where the GIF draws them at the same sample."""
    run = collision_run
    k = int(np.argmin(np.abs(run.t - run.events[0].t)))
    page.js("window.sandboxReplay.select(null)")
    page.page.keyboard.press("f")  # the whole run, as the GIF's camera below
    page.js(f"window.sandboxReplay.seek({float(run.t[k])!r})")
    shot = tmp_path / "page.png"
    page.page.locator("#world").screenshot(path=str(shot))
    img = np.asarray(Image.open(shot).convert("RGB"))
    frame = render_frame(run, k, size=640, follow=None)
    cam = Camera.for_run(run, 640, None)
    state = page.js("window.sandboxReplay.state()")
    for i in range(run.n_vehicles):
        want = run.pose[k, i, :2]
        rgb = ImageColor.getrgb(run.colors[i])
        # the GIF: centroid of the body's colour near where the camera puts it
        gif_xy = cam.pixel_to_world(
            blob(frame, cam.world_to_pixel(want), run.diameter[i] / 2 * cam.scale, rgb)
        )
        # the page: the same near where it projects the record (CSS px = image px)
        u, v = page.js(f"window.sandboxReplay.worldToPixel({want[0]}, {want[1]})")
        scale = state["scale"]  # [px/m]
        assert img.shape[1] == round(page.canvas_box()["width"])
        c = blob(img, np.array([u, v]), run.diameter[i] / 2 * scale, rgb)
        page_xy = want + np.array([c[0] - u, v - c[1]]) / scale
        # both within about a GIF pixel of each other (and of the record)
        assert np.linalg.norm(gif_xy - page_xy) <= 1.5 / cam.scale
        assert np.linalg.norm(page_xy - want) <= 1.5 / cam.scale


def blob(img: np.ndarray, uv: np.ndarray, r: float, rgb: tuple) -> np.ndarray:
    """Centroid [px] of the pixels of exactly ``rgb`` within ``1.3 r`` of ``uv``."""
    reach = max(3.0, 1.3 * r)
    rows, cols = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    near = np.hypot(cols + 0.5 - uv[0], rows + 0.5 - uv[1]) <= reach
    hit = near & np.all(np.abs(img.astype(int) - rgb) <= 2, axis=-1)
    assert hit.sum() >= 3, "the body is not drawn there"
    return np.array([cols[hit].mean() + 0.5, rows[hit].mean() + 0.5])


@pytest.mark.slow
def test_a_large_fleet_plays_at_an_interactive_rate(
    browser: object, tmp_path: Path
) -> None:
    """1,000 vehicles (as scale/grid_1000): each frame drawn in well under 50 ms."""
    n, T = 1000, 601
    t = np.linspace(0.0, 60.0, T)
    k = np.arange(n)
    base = np.stack((2.0 * (k % 32), 2.0 * (k // 32)), -1).astype(float)
    pose = np.zeros((T, n, 3))
    pose[:, :, 0] = base[None, :, 0] + np.cos(t / 10)[:, None] * 5
    pose[:, :, 1] = base[None, :, 1] + np.sin(t / 10)[:, None] * 5
    pose[:, :, 2] = t[:, None] / 10 + np.pi / 2
    run = Run(
        t=t,
        pose=pose,
        cmd=np.zeros((T, n, 2)),
        chi=np.zeros((T, n, 2)),
        slot=pose[:, :, :2].copy(),
        target=pose[:, :, :2].copy(),
        mode=np.zeros((T, n), np.int8),
        failed=np.zeros((T, n), bool),
        reference=np.full((T, 2), np.nan),
        names=[f"v{i}" for i in range(n)],
        colors=["tab:blue"] * n,
        diameter=np.full(n, 0.5),
        leader=-1,
    )
    p = Page(browser, write_html(run, tmp_path / "grid.html"))
    try:
        p.js("window.sandboxReplay.setSpeed(10)")
        p.js("window.sandboxReplay.play()")
        p.page.wait_for_timeout(1500)
        p.js("window.sandboxReplay.pause()")
        stats = p.js("window.sandboxReplay.stats()")
        assert stats["frames"] >= 10  # in 1.5 s: at least some 7 frames a second
        assert stats["meanDrawMs"] < 50
        assert p.js("window.sandboxReplay.state()")["t"] > 5
        assert "1,000 vehicles" in p.page.locator("#notes").inner_text()
    finally:
        p.context.close()


def odd_run(kind: str) -> Run:
    """Runs the page must show without an error (see the ids of the test below)."""
    if kind == "one_failed_diverged_vehicle":
        doc = {
            "name": "alone",
            "duration": 0.5,
            "reference": {"type": "point", "position": [0, 0]},
            "vehicles": [{"name": "solo", "pose": [1, 0, 0]}],
            "failures": [{"vehicle": "solo", "kind": "stop", "at": 0.1}],
        }
        import tempfile

        from helpers import write_yaml

        with tempfile.TemporaryDirectory() as tmp:
            run = simulate(load_scenario(write_yaml(Path(tmp), doc)))
        run.status = "diverged"
        run.info["diverged"] = {"t": 0.45, "vehicle": "solo", "reason": "test"}
        run.pose[-5:] = np.nan
        return run
    if kind == "one_sample":
        run = odd_run("one_failed_diverged_vehicle")
        for key in ("t", "pose", "cmd", "chi", "slot", "target", "mode", "failed"):
            setattr(run, key, getattr(run, key)[:1])
        run.reference = run.reference[:1]
        run.pose[:] = 0.0
        return run
    files = {
        "obstacles_no_events": ("failures", "obstacle_field.yaml"),
        "walls": ("safety", "door.yaml"),
    }
    folder, name = files[kind]
    return simulate(
        load_scenario(SCENARIOS / folder / name, overrides=["duration=1.5"])
    )


@pytest.mark.parametrize(
    "kind",
    [
        "one_failed_diverged_vehicle",
        "one_sample",
        "obstacles_no_events",
        "walls",
        "decimated",
    ],
)
def test_odd_runs_open_play_and_seek(
    browser: object, tmp_path: Path, kind: str
) -> None:
    run = odd_run(kind if kind != "decimated" else "walls")
    budget = run.n_vehicles * len(run.t) // 7 if kind == "decimated" else None
    page = write_html(run, tmp_path / "odd.html", max_vehicle_samples=budget)
    p = Page(browser, page)
    try:
        p.js("window.sandboxReplay.play()")
        p.page.wait_for_timeout(100)
        p.js(f"window.sandboxReplay.seek({float(run.t[-1])})")
        state = p.js("window.sandboxReplay.state()")
        assert state["t"] == pytest.approx(run.t[-1])
        assert sorted(state["vehicles"]) == sorted(run.names)
        p.page.keyboard.press("ArrowLeft")
        p.page.keyboard.press("n")
        p.page.mouse.click(100, 100)
        assert p.errors == []
        assert p.page.locator("#message").is_hidden()
        if kind == "decimated":  # said on the page; drawn between the samples kept
            assert "Decimated in time" in p.page.locator("#notes").inner_text()
            t = float(run.t[len(run.t) // 2])
            p.js(f"window.sandboxReplay.seek({t})")
            drawn = p.js("window.sandboxReplay.state()")["vehicles"]
            for i, name in enumerate(run.names):
                want = [np.interp(t, run.t, run.pose[:, i, c]) for c in (0, 1)]
                assert drawn[name] == pytest.approx(want, abs=0.02)  # [m] 7 samples
        if kind == "one_failed_diverged_vehicle":
            assert state["vehicles"]["solo"] is None  # not finite: not drawn
            assert "diverged" in p.page.locator("#summary").inner_text()
    finally:
        p.context.close()


def test_sweep_page_sorts_filters_and_links(browser: object, tmp_path: Path) -> None:
    """Two runs of the head-on pair: cut before the contact (0.5 s) and after it."""
    from helpers import HEADON, write_yaml

    from sandbox.cli import main

    scenario = str(write_yaml(tmp_path, HEADON))
    out = tmp_path / "study"
    args = ["sweep", scenario, "--grid", "duration=0.5,1.5", "--out", str(out)]
    assert main([*args, "--keep-runs"]) == 0
    assert main(["sweep", "view", str(out)]) == 0
    ctx = browser.new_context()
    ctx.set_default_timeout(TIMEOUT_MS)
    page = ctx.new_page()
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    url = (out / "sweep.html").resolve().as_uri()
    page.goto(url)
    try:
        rows = page.locator("#results tbody tr")
        assert rows.count() == 2
        duration = page.locator("#results th", has_text="duration")
        duration.click()
        duration.click()  # descending: the longer run first
        first = rows.nth(0).locator("td").nth(2).inner_text()
        assert first == "1.5"
        page.select_option("#collisions", "none")
        assert rows.count() == 1
        assert rows.nth(0).locator("td").nth(2).inner_text() == "0.5"
        page.select_option("#collisions", "some")
        assert rows.count() == 1
        rows.nth(0).locator("a").click()
        wait_until(page, "document.body.dataset.ready === '1'")
        kinds = {e["kind"] for e in page.evaluate("window.sandboxReplay.events()")}
        assert kinds == {"collision"}
        assert all(r.startswith("file://") for r in requests)
    finally:
        ctx.close()


def test_a_damaged_page_says_so(
    browser: object, collision_run: Run, tmp_path: Path
) -> None:
    path = write_html(collision_run, tmp_path / "replay.html")
    html = path.read_text(encoding="utf-8")
    start = html.index('"pose":{"data":"') + len('"pose":{"data":"')
    path.write_text(html[:start] + "AAAA" + html[start + 4 :], encoding="utf-8")
    ctx = browser.new_context()
    ctx.set_default_timeout(TIMEOUT_MS)
    page = ctx.new_page()
    try:
        page.goto(path.resolve().as_uri())
        wait_until(page, "document.body.dataset.ready !== undefined")
        assert page.evaluate("document.body.dataset.ready") == "error"
        message = page.locator("#message")
        assert message.is_visible()
        assert "cannot be shown" in message.inner_text()
    finally:
        ctx.close()


@pytest.mark.slow
def test_two_platoons_draw_both_reference_paths_in_their_colours(
    browser: object, tmp_path: Path
) -> None:
    """Each platoon's dashed reference path shows in its colour along all of it."""
    run = simulate(load_scenario(SCENARIOS / "traffic" / "intersection_two.yaml"))
    p = Page(browser, write_html(run, tmp_path / "two.html"))
    try:
        p.page.keyboard.press("f")  # the whole run
        p.js("window.sandboxReplay.seek(0)")  # no trails yet over the paths
        drawn = p.js("window.sandboxReplay.platoons()")
        assert drawn["paths"] == ["east", "north"]
        shot = tmp_path / "two.png"
        p.page.locator("#world").screenshot(path=str(shot))
        img = np.asarray(Image.open(shot).convert("RGB")).astype(float)
        refs = {name: run.platoon(name).reference for name in drawn["paths"]}
        for name, color in (("east", "blue"), ("north", "red")):
            assert drawn["points"][name] == pytest.approx(refs[name][0], abs=1e-3)
            # inner points of the path (an end may fall in a gap) away from every
            # vehicle and from the other path
            others = np.concatenate([r for m, r in refs.items() if m != name])
            far = [
                x
                for x in refs[name][20:-20:40]
                if np.min(np.linalg.norm(run.pose[0, :, :2] - x, axis=1)) > 1.5
                and np.min(np.linalg.norm(others - x, axis=1)) > 0.5
            ]
            assert len(far) >= 10
            hits = [
                tinted(img, p.js(f"window.sandboxReplay.worldToPixel({x}, {y})"), color)
                for x, y in far
            ]
            # a dash is at most 3 px away from any point of a path (6 px gaps)
            assert np.mean(hits) >= 0.9, (name, hits)
        legend = p.page.locator("#legend").inner_text()
        assert "east reference" in legend and "north reference" in legend
        assert p.errors == []
    finally:
        p.context.close()


def tinted(img: np.ndarray, uv: list[float], color: str, reach: float = 4.0) -> bool:
    """Whether a pixel within ``reach`` [px] of ``uv`` is ``color`` over white.

    A pixel ``white - a (white - color)`` with ``a`` at least 0.3 (an antialiased
    line of the colour), within 40 of it; grey or another colour is not.
    """
    rows, cols = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    near = np.hypot(cols + 0.5 - uv[0], rows + 0.5 - uv[1]) <= reach
    e = 255.0 - np.asarray(ImageColor.getrgb(color), dtype=float)
    d = 255.0 - img[near]
    a = d @ e / (e @ e)
    residual = np.linalg.norm(d - a[:, None] * e, axis=1)
    return bool(np.any((a >= 0.3) & (residual <= 40.0)))


def test_a_platoon_formed_by_a_split_shows_its_reference_from_the_split_on(
    browser: object, tmp_path: Path
) -> None:
    run = simulate(load_scenario(SCENARIOS / "traffic" / "merge_split.yaml"))
    p = Page(browser, write_html(run, tmp_path / "split.html"))
    try:
        p.js("window.sandboxReplay.seek(2)")  # A and B; C does not exist yet
        drawn = p.js("window.sandboxReplay.platoons()")
        assert drawn["paths"] == ["A", "B", "C"]
        assert sorted(drawn["points"]) == ["A", "B"]
        p.js("window.sandboxReplay.seek(16)")  # B merged at 3.8 s, C split at 14 s
        points = p.js("window.sandboxReplay.platoons()")["points"]
        assert sorted(points) == ["A", "C"]
        assert points["C"] == pytest.approx([16.0, -2.0], abs=1e-3)
        legend = p.page.locator("#legend").inner_text()
        assert "C reference (from 14.00 s)" in legend
        assert "B reference (until 3.80 s)" in legend
        assert p.errors == []
    finally:
        p.context.close()


def test_home_after_a_jump_to_an_event_shows_the_vehicles(
    browser: object, tmp_path: Path
) -> None:
    """A jump zooms in on a contact 90 m from the start; Home shows the start whole.

    Two vehicles drive 100 m east side by side and touch at 9 s. Before, Home kept the
    jump's view (zoomed in on the contact) and showed an empty canvas until ``f``.
    """
    t = np.linspace(0.0, 10.0, 101)
    pose = np.zeros((101, 2, 3))
    pose[:, :, 0] = 10.0 * t[:, None]  # [m] 10 m/s east
    pose[:, 1, 1] = 2.1  # [m] side by side, 0.1 m apart
    run = crafted_run(
        t,
        pose,
        names=["a", "b"],
        colors=["blue", "red"],
        diameter=np.full(2, 2.0),
        events=[CollisionEvent(9.0, "a", "b", "vehicle_vehicle", 9.1, True, 0.0)],
    )
    p = Page(browser, write_html(run, tmp_path / "jump.html"))
    try:
        box = p.canvas_box()

        def in_view() -> list[bool]:
            seen = []
            state = p.js("window.sandboxReplay.state()")
            for i, name in enumerate(run.names):
                x, y = state["vehicles"][name]
                u, v = p.js(f"window.sandboxReplay.worldToPixel({x}, {y})")
                inside = 0 <= u < box["width"] and 0 <= v < box["height"]
                r = run.diameter[i] / 2 * state["scale"]  # [px] off the heading line
                rgb = ImageColor.getrgb(run.colors[i])
                seen.append(inside and canvas_color(p, (u, v + 0.5 * r)) == rgb)
            return seen

        p.page.locator("#marks .mark[data-kind=collision]").first.click()
        assert p.js("window.sandboxReplay.state()")["t"] == pytest.approx(9.0)
        assert in_view() == [True, True]  # the jump shows the contact
        p.page.locator("#view").focus()
        p.page.keyboard.press("Home")
        assert p.js("window.sandboxReplay.state()")["t"] == pytest.approx(0.0)
        assert in_view() == [True, True]
        p.page.locator("#marks .mark[data-kind=collision]").first.click()
        p.page.keyboard.press("End")
        assert p.js("window.sandboxReplay.state()")["t"] == pytest.approx(10.0)
        assert in_view() == [True, True]
        assert p.errors == []
    finally:
        p.context.close()
