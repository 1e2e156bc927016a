"""The hostile corpus of run directories: damaged values, not only damaged files.

v0.3 checked the archive, the shapes and the dtypes of ``run.npz`` but not what they
hold: NaN or unordered times ended ``sandbox view`` in an ``IndexError`` of the
deadlock search, ``meta.info.failures = [1]``, ``reassignments = [{}]``,
``leader_changes = [5]`` or ``obstacles = "abc"`` in other tracebacks, and times all
zero or NaN, a pose of 1e308 or a NaN diameter were drawn silently. The same damage in
one kept run of a sweep ended ``sandbox sweep view`` with that traceback and no page.
Now :func:`sandbox.run.output.load_run_dir` refuses each in one line naming the file
and the member (exit status 2), and ``sweep view`` logs one line for that run and
writes its page.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from crafted import arrays_of, write_npz
from helpers import write_yaml

from sandbox.cli import main
from sandbox.errors import OutputError
from sandbox.run.output import load_run_dir

#: Four vehicles; the leader crashes at 1 s and red takes over (reassignments, a
#: leader change, slots), an obstacle, the residual detector (its events).
SCENARIO = {
    "name": "damaged",
    "duration": 2.0,
    "formation": {"law": "leader_ref"},
    "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1},
    "recovery": {"strategy": "continuous", "beta": 2.5},
    "reconfigure": {"assign": "hungarian", "close_gap": True},
    "on_leader_failure": "elect",
    "detection": {"method": "residual"},
    "failures": [{"vehicle": "leader", "kind": "crash", "at": 1.0}],
    "obstacles": [{"type": "circle", "name": "rock", "center": [3, 4], "radius": 0.5}],
    "vehicles": [
        {"name": "leader", "pose": [0, 0, 0], "leader": True},
        {"name": "red", "pose": [-1.5, 1, 0], "offset": [-1.5, 1]},
        {"name": "green", "pose": [-1.5, -1, 0], "offset": [-1.5, -1]},
        {"name": "orange", "pose": [-3, 0, 0], "offset": [-3, 0]},
    ],
}


@pytest.fixture(scope="module")
def valid(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("valid")
    out = root / "run"
    assert main(["run", str(write_yaml(root, SCENARIO)), "--out", str(out)]) == 0
    info = json.loads(str(arrays_of(out / "run.npz")["meta"]))["info"]
    for key in ("reassignments", "leader_changes", "slots", "detection", "obstacles"):
        assert info.get(key), key  # the valid run has each of them to damage
    return out


def craft(valid: Path, out: Path, edit: Callable[[dict], None]) -> Path:
    """A copy of the run directory ``valid`` whose ``run.npz`` ``edit`` changed."""
    out.mkdir(parents=True)
    for f in valid.iterdir():
        if f.is_file() and f.name != "run.npz":
            (out / f.name).write_bytes(f.read_bytes())
    craft_into(valid / "run.npz", out / "run.npz", edit)
    return out


def array(key: str, change: Callable[[np.ndarray], None]) -> Callable[[dict], None]:
    def edit(arrays: dict) -> None:
        value = arrays[key].copy()
        change(value)
        arrays[key] = value

    return edit


def meta(change: Callable[[dict], None]) -> Callable[[dict], None]:
    def edit(arrays: dict) -> None:
        doc = json.loads(str(arrays["meta"]))
        change(doc)
        arrays["meta"] = np.array(json.dumps(doc))

    return edit


def info(key: str, value: object) -> Callable[[dict], None]:
    return meta(lambda m: m["info"].__setitem__(key, value))


def setitem(k: object, v: float) -> Callable[[np.ndarray], None]:
    return lambda a: a.__setitem__(k, v)


def swap(a: np.ndarray) -> None:
    a[[2, 3]] = a[[3, 2]]


#: id -> (the damage, the text the one line must hold)
CASES: dict[str, tuple[Callable[[dict], None], str]] = {
    # ---- times
    "t_nan": (array("t", setitem(3, np.nan)), "t: sample 3 is nan"),
    "t_inf": (array("t", setitem(-1, np.inf)), "is inf, not a time"),
    "t_unordered": (array("t", swap), "t: not increasing (sample 3"),
    "t_all_zero": (array("t", setitem(slice(None), 0.0)), "t: not increasing"),
    "t_all_nan": (array("t", setitem(slice(None), np.nan)), "t: sample 0 is nan"),
    "t_huge": (array("t", setitem(-1, 1e300)), "not a time"),
    # ---- recorded values
    "pose_1e308": (
        array("pose", setitem((5, 0, 0), 1e308)),
        "pose: 1e+308 at [5, 0, 0]",
    ),
    "pose_inf": (array("pose", setitem((5, 1, 2), -np.inf)), "pose: -inf at [5, 1, 2]"),
    "cmd_inf": (array("cmd", setitem((1, 0, 0), np.inf)), "cmd: inf"),
    "chi_huge": (array("chi", setitem((1, 0, 1), 1e12)), "chi: 1"),
    "slot_inf": (array("slot", setitem((1, 1, 0), np.inf)), "slot: inf"),
    "target_huge": (array("target", setitem((1, 1, 0), -1e200)), "target: -1e+200"),
    "reference_inf": (array("reference", setitem((0, 0), np.inf)), "reference: inf"),
    "diameter_nan": (array("diameter", setitem(1, np.nan)), "diameter: vehicle 1"),
    "diameter_zero": (array("diameter", setitem(0, 0.0)), "diameter: vehicle 0"),
    "diameter_negative": (array("diameter", setitem(2, -0.5)), "expected > 0"),
    "mode_7": (array("mode", setitem((4, 1), 7)), "mode: code 7, expected 0 to 3"),
    "mode_negative": (array("mode", setitem((4, 1), -1)), "mode: code -1"),
    # ---- names and events
    "names_twice": (
        meta(lambda m: m.__setitem__("names", ["red", "red", "green", "orange"])),
        "meta.names: a name is given twice",
    ),
    "name_empty": (
        meta(lambda m: m["names"].__setitem__(2, "")),
        "meta.names[2]: '' is not a name",
    ),
    "name_line_break": (
        meta(lambda m: m["names"].__setitem__(2, "a\nb")),
        "meta.names[2]",
    ),
    "name_too_long": (
        meta(lambda m: m["names"].__setitem__(2, "x" * 5000)),
        "meta.names[2]",
    ),
    "color_control": (
        meta(lambda m: m["colors"].__setitem__(0, "red\x00")),
        "meta.colors[0]",
    ),
    "event_nan_time": (
        meta(lambda m: m.__setitem__("events", [[float("nan"), "a", "b", "x"] * 1])),
        "an event is not",
    ),
    "event_unknown_kind": (
        meta(
            lambda m: m.__setitem__(
                "events", [[0.5, "red", "green", "teleport", None, True, 0.0]]
            )
        ),
        "an event is not",
    ),
    # ---- info
    "failures_1": (info("failures", [1]), "meta.info.failures[0]: got 1, expected a"),
    "failures_empty": (info("failures", [{}]), "meta.info.failures[0]: no vehicle"),
    "failures_not_list": (info("failures", "abc"), "meta.info.failures: got 'abc'"),
    "failure_at_nan": (
        info("failures", [{"vehicle": "red", "kind": "stop", "at": None, "until": 1}]),
        "meta.info.failures[0].at: got None",
    ),
    "failure_unknown_vehicle": (
        info(
            "failures", [{"vehicle": "ghost", "kind": "stop", "at": 1, "until": None}]
        ),
        "meta.info.failures[0].vehicle: got 'ghost', expected the name of a vehicle",
    ),
    "reassignments_empty": (
        info("reassignments", [{}]),
        "meta.info.reassignments[0]: no t",
    ),
    "reassignment_to_text": (
        info("reassignments", [{"t": 1.0, "assignment": {"red": "first"}}]),
        "meta.info.reassignments[0].assignment.red: got 'first'",
    ),
    "leader_changes_5": (
        info("leader_changes", [5]),
        "meta.info.leader_changes[0]: got 5, expected a mapping",
    ),
    "leader_change_to_ghost": (
        info("leader_changes", [{"t": 1.0, "from": "leader", "to": "ghost"}]),
        "meta.info.leader_changes[0].to: got 'ghost'",
    ),
    "obstacles_abc": (
        info("obstacles", "abc"),
        "meta.info.obstacles: got 'abc', expected a list",
    ),
    "obstacle_without_center": (
        info("obstacles", [{"type": "circle", "radius": 1}]),
        "meta.info.obstacles[0]: no center",
    ),
    "obstacle_one_point": (
        info("obstacles", [{"type": "polygon", "points": [[0, 0]]}]),
        "meta.info.obstacles[0].points: got [[0, 0]], expected at least two",
    ),
    "obstacle_blob": (
        info("obstacles", [{"type": "blob"}]),
        "meta.info.obstacles[0].type: got 'blob', expected circle or polygon",
    ),
    "slots_of_a_ghost": (
        info("slots", {"ghost": [[0.0, 1]]}),
        "meta.info.slots: got 'ghost'",
    ),
    "slots_short_row": (
        info("slots", {"red": [[0.0]]}),
        "meta.info.slots.red[0]: got [0.0], expected a list of 2 values",
    ),
    "detection_events_bad": (
        info("detection", {"method": "residual", "events": [{"vehicle": "red"}]}),
        "meta.info.detection.events[0]: no t",
    ),
    "loop_metrics_short": (
        info("loop_metrics", {"effort_v1": [1.0], "motor": {}}),
        "meta.info.loop_metrics.effort_v1: got [1.0], expected a list of 4",
    ),
    "failed_at_text": (info("failed_at", {"red": "soon"}), "meta.info.failed_at.red"),
    "reference_path_flat": (
        info("reference_path", [[1.0]]),
        "meta.info.reference_path[0]: got [1.0], expected a point",
    ),
    "dt_zero": (info("dt", 0), "meta.info.dt: got 0"),
    "record_every_zero": (info("record_every", 0), "meta.info.record_every: got 0"),
    "platoon_events_bad": (
        info("platoon_events", [{"t": "x"}]),
        "meta.info.platoon_events[0].t: got 'x'",
    ),
    "formation_timeline_bad": (
        info("formation_timeline", {"red": [[0.0, "A", [1]]]}),
        "meta.info.formation_timeline.red[0][2]: got [1], expected a point",
    ),
    "diverged_bad": (info("diverged", {"t": "x"}), "meta.info.diverged.t"),
    "recovery_bad": (info("recovery", {"R": "big"}), "meta.info.recovery.R"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_damaged_values_are_refused_in_one_line(
    case: str,
    valid: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    edit, text = CASES[case]
    run_dir = craft(valid, tmp_path / "run", edit)
    with pytest.raises(OutputError) as caught:
        load_run_dir(run_dir)
    message = str(caught.value)
    assert message.startswith(f"not a valid run directory: {run_dir} (run.npz: ")
    assert text in message
    assert "\n" not in message
    gif = tmp_path / "x.gif"
    for argv in (
        ["view", str(run_dir)],
        ["render", str(run_dir), "--gif", str(gif)],
        ["plot", str(run_dir)],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("error: not a valid run directory: "), err
        assert err.count("\n") == 1 and "Traceback" not in err
    assert not gif.exists() and not (run_dir / "replay.html").exists()
    assert not (run_dir / "figures").exists()


def test_the_valid_run_is_viewed(valid: Path, tmp_path: Path) -> None:
    assert main(["view", str(valid), "-o", str(tmp_path / "ok.html")]) == 0


def test_sweep_view_logs_a_damaged_run_and_writes_its_page(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = write_yaml(tmp_path, {**SCENARIO, "duration": 1.2})
    study = tmp_path / "study"
    argv = ["sweep", str(src), "--grid", "recovery.beta=1,2,5", "--out", str(study)]
    assert main([*argv, "--keep-runs"]) == 0
    kept = sorted((study / "run_dirs").iterdir())
    assert len(kept) == 3
    damaged = kept[1]
    (damaged / "run.npz").rename(tmp_path / "good.npz")
    craft_into(tmp_path / "good.npz", damaged / "run.npz", array("t", swap))
    capsys.readouterr()
    assert main(["sweep", "view", str(study)]) == 0
    captured = capsys.readouterr()
    lines = [ln for ln in captured.err.splitlines() if ln]
    assert len(lines) == 1 and damaged.name in lines[0], captured.err
    assert "t: not increasing" in lines[0] and "Traceback" not in captured.err
    assert "(3 runs, 2 with a replay)" in captured.out
    assert (study / "sweep.html").is_file()


def craft_into(good: Path, target: Path, edit: Callable[[dict], None]) -> None:
    """Write ``target``: the members of the ``run.npz`` ``good`` that ``edit`` left."""
    arrays = arrays_of(good)
    edit(arrays)
    write_npz(target, arrays)
