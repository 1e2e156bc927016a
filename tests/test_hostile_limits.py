"""The hostile corpus of a run's resources, its signals and what validation lets by.

Every input an attacker (or a hurried user) handed the v0.3 loader and engine, with
what must come of it: a run that would fill the machine is refused in one line naming
the key and the sizes; a key that does nothing is one warning; a degenerate value is
refused where it is declared, and none leaks a numpy warning; a second signal stops a
command that a first only asked to stop; the sweep engine's failures are one line
saying what is stored and how to go on. The counts of the corpus (refused, warned,
run right) are :data:`REFUSED`, :data:`WARNED` and :data:`ACCEPTED`.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from sandbox.cli import main
from sandbox.errors import SandboxWarning, ScenarioError
from sandbox.scenario import load_scenario, needs
from sandbox.scenario.reader import Reader

TWO = """\
name: two
duration: 4
reference: {type: line, start: [0, 0], heading: 0, speed: 0.5}
formation: {law: rotating}
vehicles:
  - {name: a, pose: [0, 0, 0], leader: true}
  - {name: b, pose: [-1, 0, 0], offset: [-1, 0]}
"""

#: id -> (the --set assignments, what the one line of stderr holds).
REFUSED: dict[str, tuple[list[str], str]] = {
    "duration_1e7": (["duration=1e7"], "duration: the run would need about"),
    "range_readings": (
        ["duration=1e5", "sensors={range: {beams: 1024}}"],
        "sensors.range.beams: the run would need about",
    ),
    "braking_stop_of_1e11_periods": (
        [
            "vehicle={v1_max: 1e6, max_accel: 0.001}",
            "safety={filter: cbf, barrier: braking}",
        ],
        "vehicle.max_accel: the run would need about",
    ),
    "fov_1e-300": (["sensors={range: {fov: 1e-300}}"], "fov: must be at least 0.001"),
    "max_accel_1e-300": (
        ["vehicle={max_accel: 1e-300, v1_max: 1}"],
        "max_accel: must be at least 0.001",
    ),
    "noise_floor_1e-300": (
        ["detection={method: glr, noise_floor: 1e-300}"],
        "noise_floor: too small to compute with",
    ),
    "heading_floor_1e-300": (
        ["detection={method: residual, heading_floor: 1e-300}"],
        "heading_floor: too small to compute with",
    ),
    "rate_1e-300": (
        ["sensors={range: {rate: 1e-300}}"],
        "rate: too small to compute with",
    ),
    "colour_not_one": (["vehicles[0].color=notacolour"], "not a colour"),
    "colour_with_a_handler": (
        ["vehicles[0].color='red\" onmouseover=\"alert(1)'"],
        "not a colour",
    ),
    "colour_css_function": (["vehicles[0].color=rgb(1,2,3)"], "not a colour"),
    "colour_bad_hex": (["vehicles[0].color='#12345g'"], "not a colour"),
}

#: id -> (the --set assignments, what the one warning line holds).
WARNED: dict[str, tuple[list[str], str]] = {
    "glr_shift": (
        ["detection={method: glr, shift: 4}"],
        "detection.shift: does nothing here: it applies only to the residual",
    ),
    "residual_false_alarms": (
        ["detection={method: residual, false_alarms: 0.1}"],
        "detection.false_alarms: does nothing here",
    ),
    "residual_noise_window": (
        ["detection={method: residual, noise_window: 3}"],
        "detection.noise_window: does nothing here",
    ),
    "barrier_without_filter": (
        ["safety={barrier: braking}"],
        "safety.barrier: does nothing here: it applies only to the cbf",
    ),
    "estimate_gain_without_sensing": (
        ["safety={filter: cbf, estimate_gain: 0.5, range: 3}"],
        "safety.estimate_gain: does nothing here: it acts only with barrier: braking",
    ),
    "gamma_under_braking": (
        [
            "vehicle={v1_max: 1, max_accel: 2}",
            "safety={filter: cbf, barrier: braking, gamma: 3}",
        ],
        "safety.gamma: does nothing here",
    ),
    "memory_without_sensed_obstacles": (
        ["sensors={range: {memory: 2}}"],
        "sensors.range.memory: does nothing here",
    ),
    "rate_of_one_scan": (
        ["sensors={range: {rate: 1e-9}}"],
        "sensors.range.rate: 1e-09 Hz is one scan every 1e+09 s",
    ),
    "delay_beyond_the_run": (
        ["sensing={delay: 1000}"],
        "sensing.delay: 1000 s is longer than the run (4 s)",
    ),
    "glr_window_1000": (
        ["detection={method: glr, window: 1000}"],
        "detection.window: 1000 s is longer than the run (4 s): clipped",
    ),
    "glr_noise_window_1e9": (
        ["detection={method: glr, noise_window: 1.0e9}"],
        "detection.noise_window: 1e+09 s is longer than the run (4 s): clipped",
    ),
    "residual_window_10": (
        ["detection={method: residual, window: 10}"],
        "detection.window: 10 s is longer than the run (4 s): clipped",
    ),
    "settle_dwell_beyond_the_run": (
        ["metrics={settle_dwell: 10}"],
        "no vehicle can count as settled",
    ),
    "columns_off_the_grid": (
        ["platoon={count: 2, pattern: line, spacing: 3, columns: 3}"],
        "platoon.columns: does nothing here: it acts only with pattern: grid",
    ),
}

#: id -> the --set assignments of inputs that are right and must pass in silence.
ACCEPTED: dict[str, list[str]] = {
    "one_beam": ["sensors={range: {beams: 1}}"],
    "narrowest_fov": ["sensors={range: {fov: 0.001, beams: 1024}}"],
    "set_makes_sensors": ["sensors.range.rate=5"],
    "set_makes_a_vehicles_sensors": ["vehicles[1].sensors.range.beams=8"],
    "set_beside_rate": ["sensors={range: {rate: 5}}", "sensors.range.beams=64"],
    "colour_name_any_case": ["vehicles[0].color=Teal"],
    "colour_short_hex": ["vehicles[0].color='#abc'"],
    "method_switched_on_the_command_line": [
        "detection={method: residual, shift: 4}",
        "detection.method=glr",
    ],
    "window_within_the_run": ["detection={method: glr, window: 2}"],
}


@pytest.fixture
def two(tmp_path: Path) -> Path:
    path = tmp_path / "two.yaml"
    path.write_text(TWO, encoding="utf-8")
    return path


def validate(path: Path, sets: list[str], capsys: pytest.CaptureFixture[str]):
    argv = ["validate", str(path)]
    for item in sets:
        argv += ["--set", item]
    status = main(argv)
    out, err = capsys.readouterr()
    return status, out, [line for line in err.splitlines() if line]


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_a_run_that_cannot_be_is_refused_in_one_line(
    case: str, two: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sets, text = REFUSED[case]
    status, _, err = validate(two, sets, capsys)
    assert status == 2
    assert len(err) == 1 and text in err[0], err
    assert err[0].startswith(str(two)) and "Traceback" not in err[0]


@pytest.mark.parametrize("case", sorted(WARNED))
def test_a_key_that_does_nothing_is_one_warning(
    case: str, two: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sets, text = WARNED[case]
    status, out, err = validate(two, sets, capsys)
    assert status == 0 and ": ok (" in out
    assert len(err) == 1 and err[0].startswith("warning: ") and text in err[0], err


@pytest.mark.parametrize("case", sorted(ACCEPTED))
def test_a_right_input_passes_in_silence(
    case: str, two: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    status, out, err = validate(two, ACCEPTED[case], capsys)
    assert (status, err) == (0, [])
    assert ": ok (" in out


def test_the_run_command_refuses_a_long_duration_before_it_builds(
    two: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert main(["run", str(two), "--duration", "1e7", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "duration: the run would need about" in err[0]
    assert "GB of memory" in err[0] and "[from --duration 1e+07]" in err[0]
    assert not out.exists()


def test_the_memory_bound_follows_the_machine() -> None:
    sc = load_scenario(TWO_DOC)
    found = needs.estimate(
        sc.duration, sc.dt, sc.record_every, list(sc.vehicles)
    )  # 401 samples of 2 vehicles: a few hundred kB
    record = next(n for n in found if n.key == "duration")
    # (2 * 90 + 24) bytes a sample, 401 samples, twice (the metrics read it whole)
    assert record.memory == pytest.approx(401 * (2 * 90 + 24) * 2)
    small, large = Reader({}), Reader({})
    needs.check_needs(small, found, memory=2 * record.memory)  # half of it: too much
    needs.check_needs(large, found, memory=4 * record.memory + 1e6)
    assert [p.path for p in small.problems] == ["duration"]
    assert "50% of this machine's" in small.problems[0].message
    assert large.problems == []


def test_a_record_larger_than_the_temporary_disk_is_refused(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(needs, "free_disk", lambda directory=None: ("/tiny", 1e6))
    with pytest.raises(
        ScenarioError,
        match=r"duration: the record would stream .* to "
        r"/tiny \(got 1 MB free there",
    ):
        load_scenario(TWO_DOC, overrides=["duration=4000"])


def test_the_sizes_of_the_estimate_are_the_loops_own() -> None:
    from sandbox.loop import tally
    from sandbox.loop.simulation import Simulation
    from sandbox.run import metrics, recorder

    assert needs.SPILL_BYTES == recorder.SPILL_BYTES
    assert needs.TALLY_PERIODS == tally.CHUNK
    assert needs.ALL_PAIRS_MAX == metrics.ALL_PAIRS_MAX
    sizes = []
    for n in (1, 2):
        doc = json.loads(json.dumps(TWO_DOC))
        doc["vehicles"] = doc["vehicles"][:n]
        run = Simulation(load_scenario(doc, overrides=["duration=0.5"])).run()
        kept = [run.t, run.pose, run.cmd, run.chi, run.slot, run.target, run.mode]
        kept += [run.failed, run.reference]
        sizes.append(sum(np.asarray(a).nbytes for a in kept) / len(run.t))
    assert sizes[1] - sizes[0] == needs.RECORD_VEHICLE_BYTES
    assert sizes[0] == needs.RECORD_VEHICLE_BYTES + needs.RECORD_SAMPLE_BYTES


TWO_DOC = {
    "name": "two",
    "duration": 4.0,
    "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 0.5},
    "formation": {"law": "rotating"},
    "vehicles": [
        {"name": "a", "pose": [0, 0, 0], "leader": True},
        {"name": "b", "pose": [-1, 0, 0], "offset": [-1, 0]},
    ],
}


# --------------------------------------------------------------- runs, no warnings
@pytest.mark.parametrize(
    "sensor",
    [{"beams": 1}, {"beams": 1, "fov": 1.0}, {"beams": 1024, "fov": 0.001}],
    ids=["one_beam", "one_beam_narrow", "narrowest_fov"],
)
def test_degenerate_beams_run_without_a_numpy_warning(sensor: dict) -> None:
    from sandbox.loop.simulation import Simulation

    doc = dict(TWO_DOC, duration=0.5, sensors={"range": sensor})
    doc["obstacles"] = [{"type": "circle", "center": [2.0, 1.0], "radius": 0.5}]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning of numpy included
        run = Simulation(load_scenario(doc)).run()
    assert run.status == "ok"
    # b's beam straight ahead meets a's disc: 1 m centre to centre, radius 0.25 m
    assert run.ranges[0, 1, sensor["beams"] // 2] == pytest.approx(0.75, abs=1e-6)


def test_a_window_of_1e9_s_is_clipped_to_the_run_and_the_run_is_made() -> None:
    from sandbox.loop.simulation import Simulation

    doc = dict(TWO_DOC, duration=5.0)
    doc["detection"] = {"method": "glr", "noise_window": 1.0e9, "window": 1000.0}
    with pytest.warns(SandboxWarning, match="clipped to the run's 5 s"):
        sc = load_scenario(doc)
    assert sc.detection.params["noise_window"] == 5.0
    assert sc.detection.params["window"] == 5.0
    assert Simulation(sc).run().status == "ok"


def test_a_default_span_longer_than_the_run_is_neither_warned_of_nor_changed() -> None:
    # glr's noise_window defaults to 5 s: a 2 s run keeps it, and says nothing
    doc = dict(TWO_DOC, duration=2.0, detection={"method": "glr"})
    with warnings.catch_warnings():
        warnings.simplefilter("error", SandboxWarning)
        sc = load_scenario(doc)
        again = load_scenario(sc.to_dict())  # the run directory's scenario.yaml
    assert sc.detection.params["noise_window"] == 5.0
    assert again == sc


# ------------------------------------------------------------------------ names
@pytest.mark.parametrize(
    "new",
    ["=cmd", "x\ny", "../../etc", "a\u202eb", "x" * 5000],
    ids=["formula", "newline", "path", "bidi", "long"],
)
def test_a_split_new_platoon_name_keeps_the_name_rule(new: str) -> None:
    doc = {
        "duration": 5,
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1},
        "formation": {"law": "rotating"},
        "platoons": [
            {
                "name": "A",
                "vehicles": [
                    {"name": "a0", "pose": [0, 0, 0], "leader": True},
                    {"name": "a1", "pose": [-1, 0, 0], "offset": [-1, 0]},
                ],
            }
        ],
        "events": [
            {
                "at": 1,
                "split": {
                    "platoon": "A",
                    "vehicles": ["a1"],
                    "new": new,
                    "reference": {"type": "point", "position": [0, 3]},
                },
            }
        ],
    }
    with pytest.raises(ScenarioError, match=r"events\[0\]\.split\.new: unusable name"):
        load_scenario(doc)


# ------------------------------------------------------- trust, options, messages
PLUGIN = """\
import numpy as np
from sandbox.plugins import register_strategy

@register_strategy("{name}")
def strategy(ctx):
    return np.zeros((len(ctx.pos), 2)), np.zeros(len(ctx.pos), dtype=bool)
"""


def plugin_scenario(folder: Path, name: str) -> Path:
    (folder / "mine.py").write_text(PLUGIN.format(name=name), encoding="utf-8")
    path = folder / f"{name}.yaml"
    doc = dict(TWO_DOC, duration=0.5, plugins=["mine.py"])
    doc["recovery"] = {"strategy": name, "R": 0.6}
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def test_each_command_advises_what_it_takes_to_run_plugin_code(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    path = plugin_scenario(tmp_path, "t_advice")
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(f"base: {path.name}\ngrid: {{duration: [0.5, 1]}}\n")
    assert main(["validate", str(sweep)]) == 2
    err = capsys.readouterr().err
    assert "expected --plugin mine.py to run it" in err and "--trust-plugins" not in err
    gallery = tmp_path / "gallery"
    gallery.mkdir()
    (gallery / path.name).write_text(path.read_text())
    (gallery / "mine.py").write_text((tmp_path / "mine.py").read_text())
    assert main(["gallery", str(gallery), "--out", str(tmp_path / "gifs")]) == 2
    err = capsys.readouterr().err
    assert "expected --plugin mine.py to run it" in err and "--trust-plugins" not in err
    run_dir = tmp_path / "run"
    assert main(["run", str(path), "--out", str(run_dir)]) == 2
    assert (
        "expected --trust-plugins or SANDBOX_TRUST_PLUGINS=1" in capsys.readouterr().err
    )
    assert main(["run", str(path), "--out", str(run_dir), "--trust-plugins"]) == 0
    capsys.readouterr()
    os.environ.pop("SANDBOX_TRUST_PLUGINS", None)  # set by --trust-plugins
    from sandbox.plugins import registration

    registration._REGISTRY["strategy"].pop("t_advice")
    registration._LOADED.clear()
    assert main(["view", str(run_dir), "-o", str(tmp_path / "v.html")]) == 2
    err = capsys.readouterr().err
    assert "--plugin" in err and "--trust-plugins" not in err


def test_validate_takes_trust_plugins_and_runs_no_plugin_code(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    path = plugin_scenario(tmp_path, "t_validate_trust")
    assert main(["validate", str(path), "--trust-plugins"]) == 0
    out, err = capsys.readouterr()
    assert "note: --trust-plugins changes nothing here" in err
    assert "not checked: recovery (strategy t_validate_trust)" in out
    assert "--plugin mine.py loads what you trust" in out
    assert "SANDBOX_TRUST_PLUGINS" not in os.environ


def test_an_unknown_option_prints_the_commands_usage(
    two: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["validate", str(two), "--bogus"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: sandbox validate")
    assert "unrecognized arguments: --bogus" in err


def test_validate_counts_one_vehicle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "one.yaml"
    doc = dict(TWO_DOC, vehicles=TWO_DOC["vehicles"][:1])
    doc.pop("formation")
    path.write_text(json.dumps(doc))
    assert main(["validate", str(path)]) == 0
    assert capsys.readouterr().out.strip() == f"{path}: ok (1 vehicle, 4 s)"


# ------------------------------------------------------------ the unsafe start
def test_the_unsafe_start_warning_says_what_the_filter_does() -> None:
    """The old sentence said "the filter brakes them from t = 0": it does not."""
    from sandbox.loop.simulation import Simulation

    gap = 0.62  # centres; facing each other, swapping places
    doc = {
        "duration": 0.6,
        "vehicle": {"v1_max": 2.0, "v2_max": 4.0, "max_accel": 5.0},
        "reference": {"type": "point", "position": [0, 0]},
        "formation": {"law": "virtual"},
        "safety": {"filter": "cbf", "barrier": "braking"},
        "vehicles": [
            {"name": "west", "pose": [-gap / 2, 0, 0], "offset": [2, 0]},
            {"name": "east", "pose": [gap / 2, 0, np.pi], "offset": [-2, 0]},
        ],
    }
    with pytest.warns(SandboxWarning) as caught:
        sc = load_scenario(doc)
    said = " ".join(str(w.message) for w in caught)
    assert "the start is unsafe" in said and "they may touch" in said
    assert "brakes them" not in said
    run = Simulation(sc).run()
    assert np.abs(run.cmd[run.t <= 0.3, :, 0]).max() > 0.1  # not held at rest
    gap_now = np.hypot(*(run.pose[:, 0, :2] - run.pose[:, 1, :2]).T)
    assert gap_now.min() <= 0.5 + 1e-6  # they touch (d = 0.5 m)


# ---------------------------------------------------------------- sweep engine
@pytest.mark.parametrize(
    ("options", "status", "text"),
    [
        (
            ["--scheduler", "tcp://127.0.0.1:1", "--jobs", "2"],
            2,
            "--jobs 2 with a Dask",
        ),
        (["--scheduler", "garbage://x"], 1, "cannot use the Dask scheduler"),
        (["--scheduler-file", "{address5}"], 1, "not a Dask scheduler file"),
        (["--scheduler-file", "{notjson}"], 1, "not a Dask scheduler file"),
    ],
    ids=["jobs_with_a_scheduler", "garbage_scheme", "address_5", "not_json"],
)
def test_the_sweep_engines_errors_are_one_line(
    options: list[str],
    status: int,
    text: str,
    two: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    pytest.importorskip("distributed")
    files = {"{address5}": '{"address": 5}', "{notjson}": "[1, 2"}
    for i, item in enumerate(options):
        if item in files:
            path = tmp_path / f"scheduler{i}.json"
            path.write_text(files[item])
            options[i] = str(path)
    argv = ["sweep", str(two), "--out", str(tmp_path / "study"), *options]
    assert main(argv) == status
    err = [line for line in capsys.readouterr().err.splitlines() if line]
    assert len(err) == 1 and text in err[0], err
    if status == 1:
        assert "nothing was computed (0 of 1 runs are stored in" in err[0]
        assert "run the same command again" in err[0]


def test_the_sweeps_progress_counts_what_the_store_holds(two: Path, tmp_path: Path):
    from sandbox.study.spec import build_spec
    from sandbox.study.sweep import run_sweep

    out = tmp_path / "study"
    calls: list[tuple[int, int]] = []
    run_sweep(build_spec(str(two), None, None, "0:2", ["duration=0.3"]), out)
    spec = build_spec(str(two), None, None, "0:4", ["duration=0.3"])
    run_sweep(spec, out, progress=lambda done, total: calls.append((done, total)))
    assert calls == [(2, 4), (3, 4), (4, 4)]


# -------------------------------------------------------------------- signals
def command(*argv: str) -> list[str]:
    return [sys.executable, "-m", "sandbox", *argv]


def wait_for(marker: Path, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + 120
    while not marker.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the plug-in never started"
        time.sleep(0.02)


BLOCKING = """\
import time
from pathlib import Path
import numpy as np
from sandbox.plugins import register_strategy

@register_strategy("blocking")
def blocking(ctx):
    if ctx.t > 0.2:  # a trusted plug-in that never returns
        Path("{marker}").write_text("blocked")
        time.sleep(3600)
    return np.zeros((len(ctx.pos), 2)), np.zeros(len(ctx.pos), dtype=bool)
"""

BUILDING = """\
import time
from pathlib import Path
from sandbox.model.laws import FormationLaw
from sandbox.plugins import register_law

@register_law("building")
class Building(FormationLaw):
    def __init__(self, delta, h, **params):  # built with the run: a build never done
        super().__init__(delta, h)
        Path("{marker}").write_text("building")
        time.sleep(3600)
"""


def blocked_scenario(folder: Path, code: str, section: dict) -> tuple[Path, Path]:
    marker = folder / "marker"
    (folder / "plug.py").write_text(code.format(marker=marker), encoding="utf-8")
    doc = dict(TWO_DOC, duration=2.0, plugins=["plug.py"], **section)
    path = folder / "blocked.yaml"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path, marker


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["INT", "TERM"])
def test_a_second_signal_stops_a_run_blocked_in_a_trusted_plugin(
    sig: signal.Signals, tmp_path: Path
) -> None:
    section = {"recovery": {"strategy": "blocking", "R": 0.6}}
    path, marker = blocked_scenario(tmp_path, BLOCKING, section)
    out = tmp_path / "out"
    proc = subprocess.Popen(
        command("run", str(path), "--out", str(out), "--trust-plugins"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_for(marker, proc)
    proc.send_signal(sig)
    with pytest.raises(subprocess.TimeoutExpired):  # the first only asks
        proc.wait(timeout=1.0)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    lines = err.strip().splitlines()
    assert lines[-1] == "interrupted" and "Traceback" not in err
    assert any(line.startswith("stopping: the run ends at this step") for line in lines)
    assert not out.exists()  # nothing half written


@pytest.mark.slow
def test_a_signal_during_the_build_ends_the_command_at_once(tmp_path: Path) -> None:
    path, marker = blocked_scenario(
        tmp_path, BUILDING, {"formation": {"law": "building"}}
    )
    out = tmp_path / "out"
    proc = subprocess.Popen(
        command("run", str(path), "--out", str(out), "--trust-plugins"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_for(marker, proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "interrupted" and "Traceback" not in err
    assert not out.exists()


@pytest.mark.slow
def test_a_second_signal_stops_a_sweep_blocked_in_a_plugin(tmp_path: Path) -> None:
    section = {"recovery": {"strategy": "blocking", "R": 0.6}}
    path, marker = blocked_scenario(tmp_path, BLOCKING, section)
    out = tmp_path / "study"
    proc = subprocess.Popen(
        command(
            "sweep", str(path), "--seeds", "0:3", "--out", str(out), "--trust-plugins"
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_for(marker, proc)
    proc.send_signal(signal.SIGINT)
    with pytest.raises(subprocess.TimeoutExpired):
        proc.wait(timeout=1.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert "run the same command again to compute the rest" in err
    assert (out / "results.csv").is_file()  # the store is whole: it resumes


SLOW = """\
import time
import numpy as np
from sandbox.plugins import register_strategy

@register_strategy("slow")
def slow(ctx):
    time.sleep(0.002)
    return np.zeros((len(ctx.pos), 2)), np.zeros(len(ctx.pos), dtype=bool)
"""


@pytest.mark.slow
def test_a_killed_worker_ends_the_sweep_in_one_line_keeping_its_runs(
    tmp_path: Path,
) -> None:
    path, _ = blocked_scenario(tmp_path, SLOW, {"recovery": {"strategy": "slow"}})
    out = tmp_path / "study"
    argv = ("sweep", str(path), "--seeds", "0:12", "--out", str(out), "--jobs", "2")
    proc = subprocess.Popen(
        command(*argv, "--trust-plugins"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while True:  # two workers, and a run stored
        kids = Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()
        stored = list((out / "runs").glob("*")) if (out / "runs").is_dir() else []
        if len(kids) >= 2 and stored:
            break
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.02)
    os.kill(int(kids[-1]), signal.SIGKILL)  # as the out-of-memory killer would
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 1, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("error: a worker process of --jobs 2 ended abruptly")
    assert (
        "runs finished are stored in" in last and "run the same command again" in last
    )
    assert "Traceback" not in err


# -------------------------------------------------------------------- platoons
@pytest.mark.slow
def test_ten_thousand_one_vehicle_platoons_validate(tmp_path: Path) -> None:
    """Linear in the platoons (benchmarks/bench_loader.py times it)."""
    rows = [
        f"  - {{name: p{i}, vehicles: [{{name: v{i}, pose: [{2 * i}, 0, 0], "
        "leader: true}]}"
        for i in range(10_000)
    ]
    path = tmp_path / "many.yaml"
    path.write_text(
        "duration: 5\nreference: {type: point, position: [0, 0]}\n"
        "formation: {law: rotating}\nplatoons:\n" + "\n".join(rows) + "\n"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SandboxWarning)
        sc = load_scenario(path)
    assert len(sc.platoons) == 10_000 and len(sc.vehicles) == 10_000


def test_a_platoons_method_set_for_the_world_leaves_its_keys_unwarned(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # intersection_two.yaml's recovery has beta; --set chooses no strategy for all
    assert main(["validate", "traffic/intersection_two"]) == 0
    sets = ["--set", "recovery.strategy=none"]
    assert main(["validate", "traffic/intersection_two", *sets]) == 0
    assert capsys.readouterr().err == ""
