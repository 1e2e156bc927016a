"""The hostile corpus of platoons that merge and split after a reconfiguration.

v0.3: ``sandbox run traffic/merge_split`` with a follower of A stopping at 2 s and
``reconfigure: {assign: hungarian}``, or with a platoon's leader failing under
``on_leader_failure: elect``, ended in a traceback at the merge
(``platoon_events.py``: ``matrix contains invalid numeric entries``: the failed
vehicle's slot, NaN, went into the assignment) and wrote nothing. A vehicle left
without a slot now keeps none through a merge or split, and any stage of the loop
that fails ends the run there with status ``error``, its outputs written, in one
line.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sandbox import Simulation, compute_metrics, load_run, load_scenario
from sandbox.cli import main
from sandbox.loop import platoon_events

#: The combinations that crashed at the merge: (the --set values, who failed).
CRASHED = {
    "follower_then_hungarian": (
        [
            'failures=[{"vehicle": "a1", "at": 2, "kind": "stop"}]',
            "reconfigure={assign: hungarian}",
        ],
        "a1",
    ),
    "leader_of_A_then_elect": (
        [
            'failures=[{"vehicle": "a0", "at": 2, "kind": "stop"}]',
            "on_leader_failure=elect",
        ],
        "a0",
    ),
    "leader_of_B_then_elect": (
        [
            'failures=[{"vehicle": "b0", "at": 2, "kind": "stop"}]',
            "on_leader_failure=elect",
        ],
        "b0",
    ),
}


@pytest.mark.parametrize("case", list(CRASHED))
def test_a_merge_after_a_reconfiguration_runs(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sets, failed = CRASHED[case]
    out = tmp_path / "out"
    args = ["run", "traffic/merge_split", "--duration", "16", "--out", str(out)]
    for s in sets:
        args += ["--set", s]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err and "error" not in err
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert metrics["status"] == "ok"
    merge, split = metrics["platoon_events"]
    assert merge["merge"] == {"into": "A", "from": "B"}
    # the failed vehicle is in the merged platoon without a slot; the others hold
    # distinct slots
    assert merge["offsets"][failed] is None
    held = [tuple(o) for name, o in merge["offsets"].items() if name != failed]
    assert len(set(held)) == len(held) == 4
    assert "C" in split["platoons"]
    assert load_run(out).status == "ok"  # the run directory reads back


def test_a_split_led_by_a_vehicle_without_a_slot_takes_the_next_listed() -> None:
    # b0 stops at 2 s and B elects b1; b0 keeps no slot through the merge. The split
    # lists b0 first: the new platoon C is led by a2, the next listed, offsets
    # relative to a2's.
    doc = load_scenario("traffic/merge_split").to_dict()
    doc["on_leader_failure"] = "elect"
    doc["failures"] = [{"vehicle": "b0", "at": 2, "kind": "stop"}]
    doc["events"][1]["split"]["vehicles"] = ["b0", "a2"]
    doc["duration"] = 16
    sc = load_scenario(doc)
    sim = Simulation(sc)
    run = sim.run()
    assert run.status == "ok"
    timeline = run.info["formation_timeline"]
    assert timeline["a2"][-1] == [14.0, "C", [0.0, 0.0]]
    assert timeline["b0"][-1][1:] == ["C", None]
    names, platoon, offset = run.formation_at()
    assert platoon[-1][run.names.index("b0")] == names.index("C")


def test_a_stage_that_fails_ends_the_run_with_its_outputs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # Any defect at a merge (here one made on purpose) ends the run at the merge with
    # status error: the run directory is written, one line says where and what.
    def broken(*args: object, **kwargs: object) -> None:
        raise ValueError("matrix contains invalid numeric entries")

    monkeypatch.setattr(platoon_events, "merge", broken)
    out = tmp_path / "out"
    code = main(["run", "traffic/merge_split", "--duration", "16", "--out", str(out)])
    assert code == 1
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln]
    assert len(lines) == 1 and "Traceback" not in err
    assert lines[0].startswith("error: at t = 3.800 s the run's platoons stage failed")
    assert "ValueError: matrix contains invalid numeric entries" in lines[0]
    assert "test_hostile_platoon_events.py" not in lines[0]  # the package's place
    assert f"outputs up to then are in {out}" in lines[0]
    run = load_run(out)
    assert run.status == "error" and run.t[-1] == pytest.approx(3.8)
    assert run.info["error"]["stage"] == "platoons"
    assert np.isnan(run.slot[-1]).all()  # the last sample: the plan undefined
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert metrics["status"] == "error"
    assert metrics["error"] == run.info["error"]


def test_a_stage_that_fails_in_one_world_ends_that_world_alone(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A batch of two: the first merge fails, in world 0; world 1 merges and runs on.
    real, calls = platoon_events.merge, []

    def first_fails(*args: object, **kwargs: object) -> object:
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("a defect")
        return real(*args, **kwargs)

    monkeypatch.setattr(platoon_events, "merge", first_fails)
    sc = load_scenario("traffic/merge_split", overrides=["duration=16"])
    runs = Simulation.batch([sc, sc.with_overrides("seed=1")])
    assert [r.status for r in runs] == ["error", "ok"]
    assert runs[0].t[-1] == pytest.approx(3.8) and runs[1].t[-1] == pytest.approx(16)
    assert runs[0].info["error"]["message"].startswith("RuntimeError: a defect")
    assert "platoon_events" in compute_metrics(runs[1])


def test_a_stage_that_fails_at_the_first_period_of_a_batch_ends_every_world(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The controller fails at t = 0 in a batch of two: both worlds end there with
    # status error (the loop's tally of the first world ended alone was sized to it
    # and the second world's end raised an IndexError).
    from sandbox.model import kernels

    def broken(*args: object, **kwargs: object) -> None:
        raise RuntimeError("a defect")

    monkeypatch.setattr(kernels.Controller, "step", broken)
    sc = load_scenario("paper/fig15_continuous_beta1", overrides=["duration=1"])
    runs = Simulation.batch([sc, sc.with_overrides("seed=1")])
    assert [r.status for r in runs] == ["error", "error"]
    for run in runs:
        assert run.info["error"]["stage"] == "act" and len(run.t) == 1
        assert run.info["error"]["message"].startswith("RuntimeError: a defect")
