"""Tests of the replay page without a browser: data, sizes, bad input, determinism.

The page's script decodes what :func:`sandbox.render.replay.encode.pack` writes exactly
as :func:`~sandbox.render.replay.encode.unpack` does; ``tests/test_replay_browser.py``
checks the page itself in Chromium.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from helpers import HEADON, SCENARIOS, write_yaml

from sandbox import load_run, simulate
from sandbox.cli import main
from sandbox.render.replay import ReplayError, replay_html, write_html
from sandbox.render.replay.encode import (
    MAX_VEHICLE_SAMPLES,
    pack,
    replay_data,
    unpack,
)
from sandbox.scenario import load_scenario

#: The 60 s run of 10 vehicles recorded every control period (6,001 samples).
TEN = {
    "name": "ten_60s",
    "duration": 60,
    "dt": 0.01,
    "seed": 0,
    "vehicle": {"diameter": 0.5, "v1_max": 2.0, "v2_max": 8.0, "max_accel": 5.0},
    "reference": {"type": "circle", "center": [0, 0], "radius": 10, "speed": 1.0},
    "formation": {"law": "virtual"},
    "platoon": {"count": 10, "pattern": "grid", "columns": 5, "spacing": 1.5},
    "recovery": {"strategy": "continuous", "R": 1.5, "r": 0.75, "beta": 1.0},
}


def embedded(html: str) -> dict:
    """The data a page embeds."""
    m = re.search(
        r'<script id="replay-data" type="application/json">(.*?)</script>', html, re.S
    )
    assert m is not None
    return json.loads(m.group(1))


@pytest.fixture(scope="module")
def headon() -> object:
    """Two vehicles driven into each other: one contact at t = 0.75 s."""
    return simulate(load_scenario_doc(HEADON))


def load_scenario_doc(doc: dict, *overrides: str) -> object:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        return load_scenario(write_yaml(Path(tmp), doc), overrides=list(overrides))


# ------------------------------------------------------------------ packing
@pytest.mark.parametrize("order", [0, 1, 2])
def test_pack_round_trips_within_half_a_step(order: int) -> None:
    rng = np.random.default_rng(0)
    values = np.cumsum(rng.normal(0.0, 0.01, (500, 7, 3)), axis=0) * 100.0
    values[10, 3, 1] = np.nan
    values[11, 2, 0] = np.inf
    packed = pack(values, 1e-4, order)
    back = unpack(packed)
    finite = np.isfinite(values)
    assert back.shape == values.shape
    assert np.array_equal(np.isnan(back), ~finite)
    # quantised to whole steps: at most half a step off
    assert np.max(np.abs(back[finite] - values[finite])) <= 0.5e-4 + 1e-12


def test_pack_widens_the_step_for_large_values() -> None:
    values = np.array([[1e9], [-1e9], [0.5]])  # 1e9 m / 1e-4 m overflows int32
    packed = pack(values, 1e-4)
    assert packed["step"] > 1e-4
    assert np.allclose(unpack(packed), values, atol=packed["step"])


def test_smooth_motion_packs_small() -> None:
    # 6,000 samples of a vehicle on a circle at 1 m/s: the second differences are
    # near zero, so the packed text is a small fraction of the 48 kB of float64.
    t = np.arange(6000) * 0.01
    xy = np.stack((10 * np.cos(t / 10), 10 * np.sin(t / 10)), -1)
    packed = pack(xy, 1e-4)
    assert len(packed["data"]) < 0.1 * xy.nbytes


# ------------------------------------------------------------------ content
def test_collision_event_names_its_parties_and_place(headon: object) -> None:
    data = replay_data(headon)
    hits = [e for e in data["events"] if e["kind"] == "collision"]
    assert len(hits) == len(headon.events) == 1
    ev = headon.events[0]
    assert (hits[0]["a"], hits[0]["b"]) == (ev.a, ev.b)
    assert hits[0]["t"] == pytest.approx(ev.t, abs=1e-6)
    # the middle of the two at the sample nearest to the contact
    k = int(np.argmin(np.abs(headon.t - ev.t)))
    mid = headon.pose[k, :, :2].mean(axis=0)
    assert [hits[0]["x1"], hits[0]["x2"]] == pytest.approx(mid.tolist(), abs=1e-6)
    assert data["closest"] is None  # only for runs without a contact
    assert data["summary"]["collisions"] == 1


def test_positions_decode_to_the_recorded_ones(headon: object) -> None:
    data = replay_data(headon)
    pose = unpack(data["arrays"]["pose"])
    assert np.max(np.abs(pose - headon.pose)) <= 0.5e-4 + 1e-12
    assert np.max(np.abs(unpack(data["arrays"]["t"]) - headon.t)) <= 0.5e-6 + 1e-12
    state = unpack(data["arrays"]["state"]).astype(int)
    assert np.array_equal(state & 3, headon.mode)
    assert np.array_equal((state & 4) > 0, headon.failed)


def test_reconfiguration_events_are_marked() -> None:
    scenario = load_scenario(
        SCENARIOS / "failures" / "leader_crash_elect.yaml", overrides=["duration=4"]
    )
    run = simulate(scenario)
    kinds = [e["kind"] for e in replay_data(run)["events"]]
    assert kinds.count("failure") == len(run.info["failures"]) == 1
    assert kinds.count("leader_change") == len(run.info["leader_changes"]) == 1
    assert kinds.count("reassignment") == len(run.info["reassignments"]) >= 1
    data = replay_data(run)
    lead = next(e for e in data["events"] if e["kind"] == "leader_change")
    assert (lead["from"], lead["to"]) == ("leader", "red")
    # Run.leader is the leader at the end; the page's timeline starts with the first
    assert run.names[run.leader] == "red"
    assert data["leaders"] == [[0.0, "leader"], [lead["t"], "red"]]


def test_detections_are_marked() -> None:
    scenario = load_scenario(
        SCENARIOS / "failures" / "detect_follower_crash.yaml",
        overrides=["duration=4"],
    )
    run = simulate(scenario)
    marks = [e for e in replay_data(run)["events"] if e["kind"] == "detection"]
    recorded = run.info["detection"]["events"]
    assert len(marks) == len(recorded) >= 1
    assert [(m["vehicle"], m["t"]) for m in marks] == [
        (d["vehicle"], pytest.approx(d["t"])) for d in recorded
    ]


def test_closest_approach_of_a_run_without_contact() -> None:
    scenario = load_scenario(
        SCENARIOS / "paper" / "fig13_discontinuous_beta1.yaml",
        overrides=["duration=4"],
    )
    run = simulate(scenario)
    assert not run.events
    closest = replay_data(run)["closest"]
    # the smallest gap between two surfaces over every sample, computed directly
    p = run.pose[:, :, :2]
    d = np.linalg.norm(p[:, :, None] - p[:, None, :], axis=-1)
    d[:, np.arange(3), np.arange(3)] = np.inf
    assert closest["gap"] == pytest.approx(d.min() - 0.5, abs=1e-6)


def test_walls_are_told_apart_from_obstacles() -> None:
    scenario = load_scenario(
        SCENARIOS / "safety" / "door.yaml", overrides=["duration=0.2"]
    )
    obstacles = replay_data(simulate(scenario))["obstacles"]
    assert [o["wall"] for o in obstacles] == [True, True]
    assert [o["name"] for o in obstacles] == ["wall_north", "wall_south"]


def test_a_long_record_is_decimated_with_a_note(headon: object) -> None:
    budget = -(-headon.n_vehicles * len(headon.t) // 4)  # a quarter, rounded up
    data = replay_data(headon, max_vehicle_samples=budget)
    assert data["stride"] == 4
    assert data["samples"] == len(range(0, len(headon.t), 4)) + (
        (len(headon.t) - 1) % 4 != 0
    )
    t = unpack(data["arrays"]["t"])
    assert t[-1] == pytest.approx(headon.t[-1])  # the end is always kept
    assert any("Decimated" in note for note in data["notes"])
    assert replay_data(headon)["notes"] == []
    assert MAX_VEHICLE_SAMPLES >= 1_000_000


# ------------------------------------------------------------------ the page
def test_page_has_no_address_to_fetch(headon: object) -> None:
    html = replay_html(headon)
    assert not re.search(r"https?://|//cdn|@import|<link|\ssrc=", html)
    assert "default-src 'none'" in html  # the browser refuses any request
    assert "</script" not in embedded_text(html)


def embedded_text(html: str) -> str:
    start = html.index('<script id="replay-data"')
    start = html.index(">", start) + 1
    return html[start : html.index("</script>", start)]


def test_sweep_page_is_deterministic(tmp_path: Path) -> None:
    from sandbox.study.sweep_page import write_sweep_html

    scenario = str(write_yaml(tmp_path, {**HEADON, "duration": 0.3}))
    out = tmp_path / "study"
    assert main(["sweep", scenario, "--seeds", "0:2", "--out", str(out)]) == 0
    a = write_sweep_html(out, tmp_path / "a.html")["path"].read_bytes()
    b = write_sweep_html(out, tmp_path / "b.html")["path"].read_bytes()
    assert a == b
    assert embedded(a.decode())["links"] == {}  # nothing kept: nothing linked


def test_same_run_gives_the_same_bytes(tmp_path: Path, headon: object) -> None:
    a = write_html(headon, tmp_path / "a.html").read_bytes()
    b = write_html(headon, tmp_path / "b.html").read_bytes()
    again = simulate(headon.scenario)
    c = write_html(again, tmp_path / "c.html").read_bytes()
    assert a == b == c


@pytest.mark.slow
def test_sixty_seconds_of_ten_vehicles_fit_in_two_megabytes(tmp_path: Path) -> None:
    run = simulate(load_scenario_doc(TEN))
    assert run.n_vehicles == 10 and len(run.t) == 6001  # every control period
    path = write_html(run, tmp_path / "ten.html")
    assert path.stat().st_size <= 2_000_000
    assert replay_data(run)["stride"] == 1  # embedded whole


def test_output_that_is_not_a_replay_is_never_overwritten(
    tmp_path: Path, headon: object
) -> None:
    other = tmp_path / "notes.html"
    other.write_text("<p>mine</p>", encoding="utf-8")
    with pytest.raises(ReplayError, match="is not a replay page"):
        write_html(headon, other)
    assert other.read_text(encoding="utf-8") == "<p>mine</p>"
    earlier = write_html(headon, tmp_path / "replay.html")
    write_html(headon, earlier)  # an earlier replay is replaced
    with pytest.raises(ReplayError, match="must be an .html file"):
        write_html(headon, tmp_path / "replay.txt")


# ------------------------------------------------------------------ the command
@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("runs")
    out = tmp / "headon"
    assert main(["run", str(write_yaml(tmp, HEADON)), "--out", str(out)]) == 0
    return out


def test_view_writes_the_page_into_the_run_dir(
    run_dir: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["view", str(run_dir)]) == 0
    page = run_dir / "replay.html"
    data = embedded(page.read_text(encoding="utf-8"))
    assert data["names"] == load_run(run_dir).names
    assert "replay: " in capsys.readouterr().out


def _one_line_error(capsys: pytest.CaptureFixture, *words: str) -> None:
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    for word in words:
        assert word in err


def test_view_of_something_else_than_a_run_dir(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["view", str(tmp_path)]) == 2
    _one_line_error(capsys, str(tmp_path), "not a valid run directory")
    assert list(tmp_path.iterdir()) == []


def test_view_of_a_damaged_run(
    tmp_path: Path, run_dir: Path, capsys: pytest.CaptureFixture
) -> None:
    bad = tmp_path / "bad"
    bad.mkdir()
    raw = (run_dir / "run.npz").read_bytes()
    (bad / "run.npz").write_bytes(raw[: len(raw) // 2])
    assert main(["view", str(bad)]) == 2
    _one_line_error(capsys, "run.npz")
    assert not (bad / "replay.html").exists()


def test_view_refuses_an_output_that_is_not_a_replay(
    tmp_path: Path, run_dir: Path, capsys: pytest.CaptureFixture
) -> None:
    other = tmp_path / "page.html"
    other.write_text("keep me", encoding="utf-8")
    assert main(["view", str(run_dir), "-o", str(other)]) == 2
    _one_line_error(capsys, str(other), "not a replay page")
    assert other.read_text(encoding="utf-8") == "keep me"


def test_run_html_writes_the_replay(tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert main(["run", str(write_yaml(tmp_path, HEADON)), "--out", str(out)]) == 0
    (out / "replay.html").write_text("not a page", encoding="utf-8")
    scenario = str(write_yaml(tmp_path, HEADON))
    # refused before simulating: the run directory is left as it was
    assert main(["run", scenario, "--out", str(out), "--html"]) == 2
    assert (out / "replay.html").read_text(encoding="utf-8") == "not a page"
    (out / "replay.html").unlink()
    assert main(["run", scenario, "--out", str(out), "--html"]) == 0
    assert embedded((out / "replay.html").read_text(encoding="utf-8"))["names"] == [
        "east",
        "west",
    ]


def test_render_exports_write_html() -> None:
    from sandbox import render

    assert render.write_html is write_html


# ------------------------------------------------------------------ sweeps
def test_sweep_keep_runs_and_view(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    scenario = str(write_yaml(tmp_path, {**HEADON, "duration": 1.0}))
    out = tmp_path / "study"
    args = ["sweep", scenario, "--grid", "vehicle.diameter=0.5,0.6", "--out", str(out)]
    assert main([*args, "--keep-runs"]) == 0
    kept = sorted(p.name for p in (out / "run_dirs").iterdir())
    assert len(kept) == 2
    assert main(["sweep", "view", str(out)]) == 0
    html = (out / "sweep.html").read_text(encoding="utf-8")
    data = embedded(html)
    assert sorted(data["links"]) == kept
    for link in data["links"].values():
        page = out / link
        assert page.is_file()
        assert embedded(page.read_text(encoding="utf-8"))["names"] == ["east", "west"]
    rows = {r[data["header"].index("run_id")] for r in data["rows"]}
    assert rows == set(kept)
    capsys.readouterr()
    assert main(["sweep", "view", str(tmp_path)]) == 2
    _one_line_error(capsys, "not a sweep directory")


def test_failed_or_diverged_runs_still_give_a_page(tmp_path: Path) -> None:
    # one vehicle, failed from the start: no slot error, no pair, a failure mark
    doc = {
        "name": "alone",
        "duration": 0.5,
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [{"name": "solo", "pose": [1, 0, 0]}],
        "failures": [{"vehicle": "solo", "kind": "stop", "at": 0.1}],
    }
    run = simulate(load_scenario_doc(doc))
    data = replay_data(run)
    assert data["closest"] is None
    assert [e["kind"] for e in data["events"]] == ["failure"]
    run.status = "diverged"
    run.pose[-1] = np.nan  # a state that turned non-finite
    page = write_html(run, tmp_path / "alone.html")
    back = unpack(embedded(page.read_text(encoding="utf-8"))["arrays"]["pose"])
    assert np.isnan(back[-1]).all() and np.isfinite(back[:-1]).all()
    assert math.isfinite(embedded(page.read_text(encoding="utf-8"))["bounds"][0])


# ------------------------------------------------------------------ platoons
#: The keys of a page's data without ``platoons:`` (and without beams).
ONE_PLATOON_KEYS = {
    "format", "scenario", "description", "names", "colors", "diameter", "leader",
    "arrays", "samples", "recorded_samples", "stride", "events", "closest", "summary",
    "obstacles", "reference_path", "bounds", "recovery", "camera", "leaders", "modes",
    "large", "notes",
}  # fmt: skip
ONE_PLATOON_ARRAYS = {
    "t", "pose", "cmd", "slot", "target", "reference", "state", "slot_index",
}  # fmt: skip


@pytest.fixture(scope="module")
def two_platoons() -> object:
    """The bundled intersection of two platoons (east in blue, north in red)."""
    return simulate(load_scenario(SCENARIOS / "traffic" / "intersection_two.yaml"))


def test_two_platoons_carry_both_references_in_their_colours(
    two_platoons: object,
) -> None:
    run = two_platoons
    data = replay_data(run)
    assert [p["name"] for p in data["platoons"]] == ["east", "north"]
    # the platoon's colour, the one its vehicles are drawn in (e0 and n0)
    assert [p["color"] for p in data["platoons"]] == ["#0000ff", "#ff0000"]
    assert [data["colors"][run.names.index(v)] for v in ("e0", "n0")] == [
        "#0000ff",
        "#ff0000",
    ]
    assert all(p["since"] is None and p["until"] is None for p in data["platoons"])
    refs = unpack(data["arrays"]["platoon_reference"])
    assert refs.shape == (data["samples"], 2, 2)  # (T, P, 2)
    for k, name in enumerate(("east", "north")):
        want = run.platoon(name).reference
        assert np.max(np.abs(refs[:, k] - want)) <= 0.5e-4 + 1e-12
    # east drives along x2 = -0.6 m from x1 = -8 m, north along x1 = 0.6 m
    assert refs[0].ravel().tolist() == pytest.approx([-8.0, -0.6, 0.6, -8.0], abs=1e-4)
    assert np.ptp(refs[:, 0, 1]) == 0 and np.ptp(refs[:, 1, 0]) == 0
    # the page draws them with the platoons' pieces of the script; the same run gives
    # the same bytes
    html = replay_html(run)
    assert "drawPlatoonPaths()" in html
    assert replay_html(simulate(run.scenario)) == html


def test_a_platoon_formed_by_a_split_has_its_reference_from_the_split_on() -> None:
    run = simulate(load_scenario(SCENARIOS / "traffic" / "merge_split.yaml"))
    data = replay_data(run)
    entries = {p["name"]: p for p in data["platoons"]}
    assert list(entries) == ["A", "B", "C"]
    assert (entries["B"]["until"], entries["C"]["since"]) == (3.8, 14.0)
    assert entries["C"]["color"] not in (entries["A"]["color"], entries["B"]["color"])
    refs = unpack(data["arrays"]["platoon_reference"])
    t = unpack(data["arrays"]["t"])
    c = refs[:, 2]
    assert np.isnan(c[t < 14.0 - 1e-9]).all()
    # C's line starts at (0, -2) at the run's time 0: at t its point is (t, -2)
    after = t >= 14.0 - 1e-9
    assert np.max(np.abs(c[after] - np.stack([t[after], -2 + 0 * t[after]], 1))) < 1e-3
    b = refs[:, 1]  # B merged into A at 3.8 s: no reference of its own after it
    assert np.isfinite(b[t < 3.8 - 1e-9]).all() and np.isnan(b[t >= 3.8 - 1e-9]).all()
    assert np.isfinite(refs[:, 0]).all()  # A from start to end


def test_a_run_of_one_platoon_keeps_its_data_keys_and_script(headon: object) -> None:
    from sandbox.render.replay.page import asset

    data = replay_data(headon)
    assert set(data) == ONE_PLATOON_KEYS
    assert set(data["arrays"]) == ONE_PLATOON_ARRAYS
    html = replay_html(headon)
    assert asset("replay.js").replace("</script", "<\\/script") in html
    assert "drawPlatoon" not in html
