"""Reconfiguration and leader handover (``reconfigure:``, ``on_leader_failure:``).

The bundled scenarios ``scenarios/failures/column_close.yaml`` and
``leader_crash_{virtual,elect}.yaml`` are run once each; the other cases are short
documents written here.
"""

from __future__ import annotations

import copy
from functools import cache

import numpy as np
import pytest
from helpers import SCENARIOS, run_scenario, window, write_yaml

from sandbox import SandboxWarning, load_scenario
from sandbox.cli import main
from sandbox.errors import ScenarioError
from sandbox.loop.simulation import Simulation
from sandbox.model.laws import BatchDifference, FormationLaw

FAILURES = SCENARIOS / "failures"
#: The robot of the failure scenarios: v1_max [m/s], max_accel [m/s^2], v2_max [rad/s].
V1_MAX, ACCEL_MAX, V2_MAX = 2.0, 5.0, 8.0


@cache
def result(name: str, *sets: str):
    """``(run, metrics)`` of ``scenarios/failures/<name>.yaml``, run once."""
    return run_scenario(FAILURES / f"{name}.yaml", *sets)


def slot_error(run, name: str) -> np.ndarray:
    """Distance [m] of a vehicle to its recorded slot, per sample."""
    i = run.names.index(name)
    return np.hypot(*(run.pose[:, i, :2] - run.slot[:, i]).T)


def column(**changes) -> dict:
    """A 4-vehicle column at 1 m/s, 2 m apart; red (second) stops at 1 s."""
    doc = {
        "duration": 3.0,
        "vehicle": {"diameter": 0.5, "v1_max": 2.0, "max_accel": 5.0, "v2_max": 8.0},
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1.0},
        "formation": {"law": "rotating"},
        "recovery": {"strategy": "continuous", "beta": 2.5, "tangential": 1.0},
        "vehicles": [
            {"name": "leader", "pose": [0, 0, 0], "leader": True},
            {"name": "red", "pose": [-2, 0, 0], "offset": [-2, 0]},
            {"name": "green", "pose": [-4, 0, 0], "offset": [-4, 0]},
            {"name": "orange", "pose": [-6, 0, 0], "offset": [-6, 0]},
        ],
        "failures": [{"vehicle": "red", "at": 1.0, "kind": "stop"}],
    }
    doc.update(changes)
    return doc


# ------------------------------------------------------------------ the targets
@pytest.mark.slow
def test_the_column_closes_to_four_slots_within_10_s_without_contact() -> None:
    run, m = result("column_close")
    assert m["collisions"]["total"] == 0
    # one event (red stops at 3 s), one reassignment: everyone behind moves up one slot
    assert m["reassignments"] == [
        {
            "t": 3.0,
            "assignment": {
                "leader": 0,
                "red": None,
                "green": 1,
                "orange": 2,
                "purple": 3,
            },
        }
    ]
    late = window(run, 13.0)  # within 10 s of the stop
    for name in ("green", "orange", "purple"):
        assert slot_error(run, name)[late].max() < 0.1, name
    # the column itself: four vehicles 2 m apart in the lane, red's gap closed
    x = run.pose[late][:, [0, 2, 3, 4], 0]
    np.testing.assert_allclose(np.diff(x, axis=1), -2.0, atol=0.1)
    np.testing.assert_allclose(run.pose[late][:, [0, 2, 3, 4], 1], 0.0, atol=0.1)
    assert np.isnan(run.slot[-1, run.names.index("red")]).all()  # no slot any more


@pytest.mark.slow
def test_the_column_closes_when_the_detector_finds_the_stop_under_noise() -> None:
    # what the platoon believes, not the truth: the event is the detection
    run, m = result(
        "column_close",
        "detection.method=residual",
        "sensing.position_noise=0.01",
        "sensing.heading_noise=0.005",
    )
    (found,) = m["detections"]
    assert found["vehicle"] == "red" and 3.0 < found["t"] < 3.5
    (event,) = m["reassignments"]
    assert event["t"] == found["t"]
    assert event["assignment"] == {
        "leader": 0,
        "red": None,
        "green": 1,
        "orange": 2,
        "purple": 3,
    }
    assert m["collisions"]["total"] == 0
    late = window(run, 13.0)
    for name in ("green", "orange", "purple"):
        assert slot_error(run, name)[late].max() < 0.1, name


@pytest.mark.slow
def test_the_run_records_who_holds_which_slot() -> None:
    # red stops at 3 s; from the next period everyone behind it holds the slot ahead
    run, m = result("column_close")
    assert m["slots"] == {
        "leader": [[0.0, 0]],
        "red": [[0.0, 1], [3.01, None]],
        "green": [[0.0, 2], [3.01, 1]],
        "orange": [[0.0, 3], [3.01, 2]],
        "purple": [[0.0, 4], [3.01, 3]],
    }
    index = run.slot_index
    assert (index[window(run, 0.0, 3.01)] == [0, 1, 2, 3, 4]).all()
    assert (index[window(run, 3.01)] == [0, -1, 1, 2, 3]).all()
    # the slot recorded is the one driven to: its offset from the reference point
    offsets = np.array([v.offset for v in run.scenario.vehicles])
    for i in (2, 3, 4):
        where = run.reference[-1] + offsets[index[-1, i]]
        np.testing.assert_allclose(run.pose[-1, i, :2], where, atol=0.1)
    # and where the recorded slot positions are defined, they agree with the index
    assert np.isnan(run.slot[window(run, 3.01), 1]).all()
    changes = run.slot_changes()
    assert [(c["vehicle"], c["from"], c["to"]) for c in changes] == [
        ("red", 1, None),
        ("green", 2, 1),
        ("orange", 3, 2),
        ("purple", 4, 3),
    ]
    assert {c["t"] for c in changes} == {3.01}


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["virtual", "elect"])
def test_a_leader_change_is_in_the_slot_record(mode) -> None:
    # Either way red ends in slot 0 (elect: as the leader; virtual: the reference's
    # own slot, offset 0), orange takes red's slot 1 and green keeps its slot 2.
    run, m = result(f"leader_crash_{mode}")
    assert m["slots"] == {
        "leader": [[0.0, 0], [3.01, None]],
        "red": [[0.0, 1], [3.01, 0]],
        "green": [[0.0, 2]],
        "orange": [[0.0, 3], [3.01, 1]],
    }
    assert run.slot_index[-1].tolist() == [-1, 0, 2, 1]


@pytest.mark.slow
@pytest.mark.parametrize(("mode", "heir"), [("virtual", None), ("elect", "red")])
def test_after_a_leader_crash_the_formation_settles_again(mode, heir) -> None:
    run, m = result(f"leader_crash_{mode}")
    assert m["leader_changes"] == [
        {"t": 3.0, "from": "leader", "to": heir, "mode": mode}
    ]
    assert len(m["reassignments"]) == 1
    assert m["collisions"]["total"] == 0
    assert m["converged"]
    late = window(run, 13.0)
    for name in ("red", "green", "orange"):
        assert slot_error(run, name)[late].max() < 0.1, (mode, name)
    # red ends on the reference point itself: the leader's slot (virtual: offset 0)
    red = run.names.index("red")
    np.testing.assert_allclose(run.pose[-1, red, :2], run.reference[-1], atol=0.01)


@pytest.mark.parametrize("name", ["leader_crash_virtual", "leader_crash_elect"])
def test_no_commanded_speed_exceeds_the_limits_at_handover(name) -> None:
    run, _ = result(name)
    healthy = [run.names.index(v) for v in ("red", "green", "orange")]
    near = window(run, 2.5, 5.0)
    cmd = run.cmd[near][:, healthy]
    assert np.abs(cmd[..., 0]).max() <= V1_MAX + 1e-9
    assert np.abs(cmd[..., 1]).max() <= V2_MAX + 1e-9
    dv1 = np.abs(np.diff(cmd[..., 0], axis=0)) / np.diff(run.t[near])[:, None]
    assert dv1.max() <= ACCEL_MAX * (1 + 1e-6)


def _handover_without_limits(reseed: bool, monkeypatch) -> float:
    """Largest error [m/s] of the leader-velocity estimate after an election."""
    doc = {
        "duration": 1.0,
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1.0},
        "formation": {"law": "fixed"},
        "on_leader_failure": "elect",
        "vehicles": [
            {"name": "leader", "pose": [0, 0, 0], "leader": True},
            {"name": "red", "pose": [-1, 0, 0], "offset": [-1, 0]},
            {"name": "green", "pose": [-2, 0, 0], "offset": [-2, 0]},
        ],
        "failures": [{"vehicle": "leader", "at": 0.5, "kind": "crash"}],
    }
    if not reseed:  # the world's law and the one law of the loop's worlds keep
        # their histories (loop/reforming.py takes the world's re-seeded one in)
        monkeypatch.setattr(FormationLaw, "reseed", lambda self: None)
        monkeypatch.setattr(BatchDifference, "restart", lambda self, w, alone: None)
    sim = Simulation(load_scenario(doc))
    top = 0.0
    while not sim.done:
        sim.step()
        if sim.leader == 1 and sim.t < 0.6:  # red leads (until it meets the wreck):
            # green's feed-forward is red's velocity
            error = sim.plan.v_ref[2] - sim.fleet.vel[1]
            top = max(top, float(np.hypot(*error)))
    return top


def test_the_estimators_are_re_seeded_at_a_leader_change(monkeypatch) -> None:
    # Without limits (no v1_max) the commands follow the law's feed-forward: the jump
    # of the leader from (0.5, 0) to red at (-0.5, 0) would read 1 m / 0.01 s = 100
    # m/s; re-seeded, the estimate is red's own velocity (a backward difference).
    assert _handover_without_limits(True, monkeypatch) < 0.5
    assert _handover_without_limits(False, monkeypatch) > 50.0


# ------------------------------------------------------------------ events only
def test_a_fault_that_clears_makes_exactly_two_reassignments() -> None:
    doc = column(
        reconfigure={"assign": "hungarian", "close_gap": True},
        failures=[{"vehicle": "red", "at": 1.0, "until": 2.0, "kind": "stop"}],
    )
    run, m = run_scenario(doc)
    got = [(e["t"], e["assignment"]) for e in m["reassignments"]]
    assert got[0] == (1.0, {"leader": 0, "red": None, "green": 1, "orange": 2})
    # red is healthy again: all four vehicles get one of the four slots
    assert got[1][0] == 2.0
    assert sorted(got[1][1].values()) == [0, 1, 2, 3]
    assert m["leader_changes"] == []
    # between the events the recorded slots move smoothly (no switching): the slot
    # of each vehicle jumps only at the samples right after the two events
    slot = run.slot[:, 1:]  # followers' slots, (T, 3, 2); NaN: none
    has = np.isfinite(slot).all(axis=-1)
    step = np.hypot(*np.diff(slot, axis=0).transpose(2, 0, 1))
    jump = np.where(has[1:] & has[:-1], step > 0.1, has[1:] != has[:-1])
    # (the plan of the event's own period is kept: the new slots act 0.01 s later)
    assert run.t[np.flatnonzero(jump.any(axis=1)) + 1].round(6).tolist() == [1.01, 2.01]


def test_without_close_gap_the_failed_slot_stays_empty() -> None:
    run, m = run_scenario(column(reconfigure={"assign": "hungarian"}))
    assert [e["assignment"] for e in m["reassignments"]] == [
        {"leader": 0, "red": None, "green": 2, "orange": 3}
    ]
    # the healthy vehicles drive as in v0.1 (only the failed red loses its slot)
    v01, _ = run_scenario(column())
    healthy = [0, 2, 3]
    np.testing.assert_allclose(run.pose[:, healthy], v01.pose[:, healthy], atol=1e-3)


@pytest.mark.slow
def test_the_defaults_are_bit_identical_to_no_keys() -> None:
    doc = column()
    explicit = dict(
        doc,
        reconfigure={"assign": "none", "close_gap": False},
        on_leader_failure="keep",
    )
    assert Simulation(load_scenario(explicit)).reconfiguration is None
    a, ma = run_scenario(doc)
    b, mb = run_scenario(explicit)
    for key in ("pose", "cmd", "chi", "slot", "target", "mode"):
        assert np.array_equal(getattr(a, key), getattr(b, key), equal_nan=True), key
    assert ma == mb
    assert "reassignments" not in ma and "slots" not in ma
    # without reconfiguration vehicle k holds slot k throughout
    assert (a.slot_index == np.arange(a.n_vehicles)).all() and a.slot_changes() == []


def test_the_keys_round_trip_through_the_resolved_scenario() -> None:
    sc = load_scenario(FAILURES / "leader_crash_elect.yaml")
    doc = sc.to_dict()
    assert doc["reconfigure"] == {"assign": "hungarian", "close_gap": True}
    assert doc["on_leader_failure"] == "elect"
    assert load_scenario(copy.deepcopy(doc)) == load_scenario(doc)
    assert "reconfigure" not in load_scenario(column()).to_dict()


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"reconfigure": {"assign": "greedy"}}, "reconfigure.assign"),
        ({"reconfigure": {"close_gap": True}}, "reconfigure.close_gap"),
        ({"reconfigure": {"close_gap": "yes"}}, "reconfigure.close_gap"),
        ({"reconfigure": {"gap": True}}, "reconfigure.gap"),
        ({"reconfigure": "hungarian"}, "reconfigure"),
        ({"on_leader_failure": "vote"}, "on_leader_failure"),
    ],
)
def test_bad_values_name_the_field(changes: dict, field: str) -> None:
    with pytest.raises(ScenarioError) as err:
        load_scenario(column(**changes))
    assert f"{field}:" in str(err.value)


def test_a_handover_without_a_reference_is_one_line_and_exit_2(
    tmp_path, capsys
) -> None:
    doc = column(on_leader_failure="virtual")
    del doc["reference"]
    doc["vehicles"][0]["drive"] = {"type": "commands", "schedule": [[0, 1.0, 0.0]]}
    path = write_yaml(tmp_path, doc)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "on_leader_failure: virtual needs a reference" in err[0]
    assert str(path) in err[0]


def test_a_handover_without_a_leader_warns_that_it_has_no_effect() -> None:
    doc = column(on_leader_failure="elect", formation={"law": "virtual"})
    with pytest.warns(SandboxWarning, match="on_leader_failure: elect has no effect"):
        sc = load_scenario(doc)
    assert any("on_leader_failure" in w and "no effect" in w for w in sc.warnings)


@pytest.mark.slow
def test_reconfiguring_worlds_in_one_loop_give_the_runs_alone() -> None:
    # each world re-forms on its own events, its law its own, in the one loop
    base = load_scenario(FAILURES / "column_close.yaml")
    scenarios = [base.with_overrides(f"seed={s}") for s in range(3)]
    scenarios.append(base.with_overrides("failures[0].at=1.5"))
    runs = Simulation.stacked(scenarios).run_all()
    for sc, run in zip(scenarios, runs, strict=True):
        alone = Simulation(sc).run()
        assert run.pose.tobytes() == alone.pose.tobytes()
        assert run.info["slots"] == alone.info["slots"]
        assert run.info["reassignments"] == alone.info["reassignments"]
    assert runs[3].info["reassignments"] != runs[0].info["reassignments"]


def test_a_plug_in_law_class_is_reconfigured_as_the_built_in_it_copies(
    registry_snapshot,
):
    # A user's FormationLaw subclass is guarded (plugins/registration.py); the
    # reassignment writes its offsets (delta) and deep-copies it through the guard,
    # so it re-forms exactly as the built-in law it copies.
    from sandbox.model.laws import FixedFormation
    from sandbox.plugins import register_law

    @register_law("fixed_copy", frame="world")
    class FixedCopy(FixedFormation):
        """The fixed law, as a user's class."""

    runs = [
        Simulation(
            load_scenario(
                "failures/column_close",
                overrides=["duration=6", f"formation={{law: {law}}}"],
            )
        ).run()
        for law in ("fixed", "fixed_copy")
    ]
    assert [r.status for r in runs] == ["ok", "ok"]
    assert len(runs[1].info["reassignments"]) == 1
    assert runs[0].pose.tobytes() == runs[1].pose.tobytes()
    assert runs[0].info["slots"] == runs[1].info["slots"]
