"""Several platoons in one world (``platoons:``): loading, errors, the loop, metrics."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from sandbox import Simulation, compute_metrics, load_scenario
from sandbox.errors import ScenarioError
from sandbox.run.expectations import evaluate
from sandbox.testing import assert_platoon

NORTH = math.pi / 2

TWO = """\
name: two
duration: 4
vehicle: {diameter: 0.5, mass: 10.0, v1_max: 2.0, v2_max: 4.0, max_accel: 5.0}
formation: {law: leader_ref, rotate: true}
recovery: {strategy: continuous, beta: 1.0, R: 3d, r: 1.5d}
platoons:
  - name: east
    reference: {type: line, start: [-8, 0], heading: 0, speed: 1.0}
    vehicles:
      - {name: e0, pose: [-8, 0, 0], leader: true}
      - {name: e1, pose: [-9.6, 0, 0], offset: [-1.6, 0]}
  - name: north
    color: red
    reference: {type: line, start: [0, -8], heading: 1.5707963267948966, speed: 1}
    platoon: {count: 1, pattern: line, spacing: 1.6}
    vehicles:
      - {name: n0, pose: [0, -8, 1.5707963267948966], leader: true}
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "s.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_two_platoons_load_with_their_own_references_and_colours(tmp_path):
    sc = load_scenario(_write(tmp_path, TWO))
    assert [p.name for p in sc.platoons] == ["east", "north"]
    assert [v.name for v in sc.vehicles] == ["e0", "e1", "n0", "north-v0"]
    assert [v.color for v in sc.vehicles] == ["blue", "blue", "red", "red"]
    assert sc.platoons[1].rows == (2, 3) and sc.platoons[1].leader == 2
    assert sc.platoons[1].scenario.reference.params["heading"] == pytest.approx(NORTH)
    # the document parses back to the same scenario, and --set reaches every platoon
    again = load_scenario(sc.to_dict())
    assert again == dataclasses.replace(sc, source=None)
    changed = sc.with_overrides("recovery.beta=2")
    assert {p.scenario.recovery.params["beta"] for p in changed.platoons} == {2.0}
    # --set reaches into an entry too, with a hint for a misspelt key
    own = load_scenario(
        _write(tmp_path, TWO), ["platoons[0].recovery={strategy: none}"]
    )
    assert [p.scenario.recovery.strategy for p in own.platoons] == [
        "none",
        "continuous",
    ]
    with pytest.raises(ScenarioError, match="did you mean 'color'"):
        load_scenario(_write(tmp_path, TWO), ["platoons[0].colr=red"])


def test_each_platoon_follows_its_own_leader_and_metrics_say_so(tmp_path):
    sc = load_scenario(_write(tmp_path, TWO))
    sim = Simulation(sc)
    assert sim.observe().platoon == ("east", "east", "north", "north")
    run = sim.run()
    # e1's slot is 1.6 m behind e0 along +x1; north-v0's 1.6 m behind n0 along +x2
    np.testing.assert_allclose(
        run.slot[-1, 1], run.pose[-1, 0, :2] + [-1.6, 0], atol=1e-9
    )
    np.testing.assert_allclose(
        run.slot[-1, 3], run.pose[-1, 2, :2] + [0, -1.6], atol=1e-9
    )
    m = compute_metrics(run)
    assert set(m["platoons"]) == {"east", "north"}
    assert m["platoons"]["north"]["vehicles"] == ["n0", "north-v0"]
    assert (
        m["collisions"]["inter_platoon"] + m["collisions"]["intra_platoon"]
        == (m["collisions"]["vehicle_vehicle"])
    )
    sub = run.platoon("north")
    assert sub.names == ["n0", "north-v0"] and sub.pose.shape[1] == 2
    np.testing.assert_allclose(sub.reference[-1], [0, -8 + 4.0], atol=1e-9)
    with pytest.raises(KeyError, match="east, north"):
        run.platoon("west")
    json.dumps(m)  # plain JSON


def test_a_crossing_without_recovery_has_inter_platoon_contacts(tmp_path):
    # both leaders reach the origin at t = 8 s and nobody avoids: a contact between
    # the platoons, counted as inter-platoon, and asserted by sandbox.testing
    text = TWO.replace("duration: 4", "duration: 10").replace(
        "recovery: {strategy: continuous, beta: 1.0, R: 3d, r: 1.5d}",
        "recovery: {strategy: none}",
    )
    run = Simulation(load_scenario(_write(tmp_path, text))).run()
    m = compute_metrics(run)
    assert m["collisions"]["inter_platoon"] >= 1
    assert m["platoons"]["east"]["collisions"]["inter_platoon"] >= 1
    with pytest.raises(AssertionError, match="platoon east: .* inter_platoon"):
        assert_platoon(run, "east", inter_platoon=0)


def test_expectations_of_platoons_are_read_and_evaluated(tmp_path):
    text = TWO + (
        "expect:\n  collisions: {inter_platoon: 0}\n"
        "  platoons:\n    east: {collisions: {intra_platoon: 0}, converged: false}\n"
    )
    sc = load_scenario(_write(tmp_path, text))
    outcomes = evaluate(sc.expect, Simulation(sc).run())
    keys = [o.key for o in outcomes]
    assert keys == [
        "status",
        "collisions.inter_platoon",
        "platoons.east.converged",
        "platoons.east.collisions.intra_platoon",
    ]
    assert load_scenario(sc.to_dict()).expect == sc.expect


LEADERLESS = TWO.replace("      - {name: e0, pose: [-8, 0, 0], leader: true}", "")
BAD = [
    (
        LEADERLESS.replace("leader_ref, rotate: true", "virtual"),
        "s.yaml:9: platoons[0].vehicles: platoon east has no leader (got no vehicle "
        "with leader: true; expected exactly one leader per platoon)",
    ),
    (
        TWO.replace("name: n0", "name: e1"),
        "s.yaml:17: platoons[1].vehicles[0].name: vehicle e1 is in two platoons (got "
        "east and north; expected each vehicle in one platoon",
    ),
    (
        TWO.replace("name: north", "name: east"),
        "s.yaml:12: platoons[1].name: duplicate platoon name (got 'east', also "
        "platoons[0]",
    ),
    (
        TWO + "vehicles:\n  - {name: x, pose: [5, 5, 0]}\n",
        "s.yaml:18: vehicles: top-level vehicles: beside platoons:",
    ),
    (
        TWO.replace("law: leader_ref, rotate: true", "law: leader_rf"),
        "s.yaml:4: formation.law: unknown formation law",
    ),
    (
        TWO.replace("speed: 1}", "speed: -1}"),
        "s.yaml:14: platoons[1].reference.speed: must be at least 0",
    ),
    (
        TWO + "expect:\n  platoons:\n    west: {converged: true}\n",
        "s.yaml:20: expect.platoons.west: no such platoon",
    ),
    (
        TWO.replace("pose: [-9.6, 0, 0]", "pose: [0.1, -8, 0]"),
        "platoons[1]: n0 starts overlapping e1 of platoon east",
    ),
]


@pytest.mark.parametrize(("text", "message"), BAD)
def test_bad_platoons_are_one_line_errors_with_file_line_and_field(
    tmp_path, text, message
):
    with pytest.raises(ScenarioError) as info:
        load_scenario(_write(tmp_path, text))
    lines = str(info.value).splitlines()
    assert any(message in line for line in lines), lines


def test_collision_counts_of_platoons_need_platoons(tmp_path):
    text = (
        "reference: {type: point, position: [1, 0]}\n"
        "vehicles: [{name: a, pose: [0, 0, 0]}]\n"
        "expect: {collisions: {inter_platoon: 0}}\n"
    )
    with pytest.raises(ScenarioError, match=re.escape("counted only in a world of")):
        load_scenario(_write(tmp_path, text))


EVENTS = TWO.replace("duration: 4", "duration: 6") + (
    "events:\n"
    "  - when: {platoon: north, within: 12.0, of: east}\n"
    "    merge: {into: east, from: north}\n"
    "  - at: 3\n"
    "    split: {platoon: east, vehicles: [n0, e1], new: third,\n"
    "            reference: {type: line, start: [-8, -3], heading: 0, speed: 1}}\n"
)


def test_a_merge_and_a_split_fire_and_are_recorded(tmp_path):
    sc = load_scenario(_write(tmp_path, EVENTS))
    assert [e.kind for e in sc.events] == ["merge", "split"]
    assert load_scenario(sc.to_dict()).events == sc.events
    sim = Simulation(sc)
    run = sim.run()
    fired = compute_metrics(run)["platoon_events"]
    # the leaders start 11.3 m apart: the merge fires at once; the split at 3 s
    assert [e["t"] for e in fired] == [0.0, 3.0]
    assert fired[0]["platoons"] == {"east": ["e0", "e1", "n0", "north-v0"]}
    # north's slots go behind east's last one (1.6 m spacing), assigned by distance
    assert sorted(map(tuple, fired[0]["offsets"].values())) == sorted(
        [(0.0, 0.0), (-1.6, 0.0), (-3.2, 0.0), (-4.8, 0.0)]
    )
    assert fired[1]["platoons"] == {"east": ["e0", "north-v0"], "third": ["n0", "e1"]}
    assert sim.platoons.of_vehicles() == ("east", "third", "third", "east")


MERGE_SPLIT = Path(__file__).parents[1] / "scenarios" / "traffic" / "merge_split.yaml"


def _merge_split_reconfiguring(tmp_path: Path) -> Path:
    """merge_split.yaml with platoon A closing its gaps and a1 stopping at 8 s."""
    text = MERGE_SPLIT.read_text()
    text = text.replace(
        "  - name: A\n    color: blue\n",
        "  - name: A\n    color: blue\n"
        "    reconfigure: {assign: hungarian, close_gap: true}\n",
    )
    text = text[: text.index("expect:")] + (
        "failures:\n  - {vehicle: a1, at: 8, kind: stop}\n"
    )
    path = tmp_path / "merge_reconfigure.yaml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_events_and_a_platoons_reconfiguration_work_together(tmp_path):
    # B merges into A at 3.8 s; a1 stops at 8 s and A, now five vehicles, closes up
    # behind it; at 14 s a2 and b0 split off as C, A keeping a0, a1 and b1
    run = Simulation(load_scenario(_merge_split_reconfiguring(tmp_path))).run()
    m = compute_metrics(run)
    assert m["collisions"]["total"] == 0
    assert [e["t"] for e in m["platoon_events"]] == [3.8, 14.0]
    moved = m["reassignments"][0]
    assert moved["t"] == 8.01
    assert moved["assignment"] == {"a0": 0, "a1": None, "a2": 1, "b0": 2, "b1": 3}
    # the fleet-wide timeline: platoon and offset through the merge, the
    # reassignment and the split (null: no slot)
    timeline = m["formation_timeline"]
    assert timeline["a1"] == [[0.0, "A", [-1.6, 0.0]], [8.01, "A", None]]
    assert timeline["b0"] == [
        [0.0, "B", [0.0, 0.0]],
        [3.8, "A", [-4.8, 0.0]],
        [8.01, "A", [-3.2, 0.0]],
        [14.0, "C", [-1.6, 0.0]],
    ]
    assert timeline["a2"][-1] == [14.0, "C", [0.0, 0.0]]
    names, platoon, offset = run.formation_at()
    assert names == ["A", "B", "C"]
    k = int(np.searchsorted(run.t, 10.0))
    assert platoon[k].tolist() == [0, 0, 0, 0, 0]
    assert np.isnan(offset[k, 1]).all()
    assert offset[k, [2, 3, 4], 0].tolist() == [-1.6, -3.2, -4.8]
    assert platoon[-1].tolist() == [0, 0, 2, 2, 0]
    # each vehicle's slot, the same in the slot timeline
    assert m["slots"]["a2"] == [[0.0, 2], [8.01, 1], [14.0, 2]]


def test_formation_without_events_is_the_files(tmp_path):
    run = Simulation(load_scenario(_write(tmp_path, TWO))).run()
    assert "formation_timeline" not in compute_metrics(run)
    names, platoon, offset = run.formation_at()
    assert names == ["east", "north"]
    assert platoon[-1].tolist() == [0, 0, 1, 1]
    assert offset[-1].tolist() == [[0.0, 0.0], [-1.6, 0.0], [0.0, 0.0], [-1.6, 0.0]]


BAD_EVENTS = [
    (
        "events:\n  - at: 1\n    merge: {into: west, from: north}\n",
        "s.yaml:20: events[0].merge.into: no such platoon",
    ),
    (
        "events:\n  - at: 9\n    merge: {into: east, from: north}\n",
        "s.yaml:19: events[0].at: the event can never fire (got at = 9 s, the run "
        "lasts 4 s",
    ),
    (
        "events:\n  - when: {platoon: east, within: 1, of: east}\n"
        "    merge: {into: east, from: north}\n",
        "s.yaml:19: events[0].when.of: the event can never fire",
    ),
    (
        "events:\n  - at: 1\n    split: {platoon: east, vehicles: [e0], new: x,\n"
        "            reference: {type: point, position: [0, 0]}}\n",
        "events[0].split.vehicles[0]: e0 leads platoon east",
    ),
    (
        "events:\n  - at: 1\n",
        "s.yaml:19: events[0]: needs exactly one of merge and split",
    ),
]


@pytest.mark.parametrize(("events", "message"), BAD_EVENTS)
def test_bad_events_are_one_line_errors(tmp_path, events, message):
    with pytest.raises(ScenarioError) as info:
        load_scenario(_write(tmp_path, TWO + events))
    lines = str(info.value).splitlines()
    assert any(message in line for line in lines), lines


def test_an_agent_sees_which_neighbours_share_its_platoon(tmp_path):
    pytest.importorskip("gymnasium")
    from sandbox.envs import VehicleEnv

    env = VehicleEnv(_write(tmp_path, TWO), agent="e1", neighbours=2)
    obs, _ = env.reset(seed=0)
    # 7 own entries, 2 x 6 per neighbour, then a same-platoon flag per neighbour:
    # e1's two nearest are e0 (1.6 m, its platoon) and north's leader n0 (8.1 m)
    assert obs.shape == (7 + 12 + 2,) == env.observation_space.shape
    assert obs[-2:].tolist() == [1.0, 0.0]
    _, _, _, _, info = env.step(np.zeros(2, dtype=np.float32))
    assert info["platoon"] == "east"


def test_sweeps_batch_platoons_of_one_structure(tmp_path):
    from sandbox.loop.plan import structure_key

    path = _write(tmp_path, TWO)
    one, other = load_scenario(path), load_scenario(path, overrides=["seed=7"])
    assert structure_key(one) == structure_key(other)
    runs = Simulation.batch([one, other])
    alone = Simulation(other).run()
    assert runs[1].pose.tobytes() == alone.pose.tobytes()


@pytest.mark.slow
def test_each_platoon_keeps_its_own_recovery_and_filter(tmp_path):
    # east avoids nobody (recovery none) and has the CBF filter; north avoids
    # (continuous) without a filter: only north's vehicles are ever in avoid mode
    text = TWO.replace("duration: 4", "duration: 10").replace(
        "    reference: {type: line, start: [-8, 0], heading: 0, speed: 1.0}\n",
        "    reference: {type: line, start: [-8, 0], heading: 0, speed: 1.0}\n"
        "    recovery: {strategy: none}\n"
        "    safety: {filter: cbf}\n",
    )
    sc = load_scenario(_write(tmp_path, text))
    assert sc.platoons[0].scenario.recovery.strategy == "none"
    assert sc.platoons[1].scenario.recovery.strategy == "continuous"
    run = Simulation(sc).run()
    avoided = (run.mode == 1).any(axis=0)  # MODE_AVOID
    assert not avoided[:2].any() and avoided[2:].any()
    assert run.info["safety"]["filter"] == "cbf"


RECONFIGURED = """\
duration: 12
vehicle: {diameter: 0.5, mass: 10.0, v1_max: 2.0, v2_max: 4.0, max_accel: 5.0}
formation: {law: leader_ref, rotate: true}
recovery: {strategy: continuous, beta: 1.0, R: 3d, r: 1.5d, leader_avoids: true}
platoons:
  - name: A
    reference: {type: line, start: [0, 0], heading: 0, speed: 1.0}
    reconfigure: {assign: hungarian, close_gap: true}
    on_leader_failure: elect
    platoon: {count: 3, pattern: line, spacing: 1.6}
    vehicles:
      - {name: a0, pose: [0, 0, 0], leader: true}
  - name: B
    reference: {type: line, start: [0, 4], heading: 0, speed: 1.0}
    platoon: {count: 2, pattern: line, spacing: 1.6}
    vehicles:
      - {name: b0, pose: [0, 4, 0], leader: true}
failures:
  - {vehicle: a0, at: 3, kind: crash}
"""


@pytest.mark.slow
def test_a_platoon_reconfigures_itself_and_no_other(tmp_path):
    sc = load_scenario(_write(tmp_path, RECONFIGURED))
    assert sc.reconfigure.assign == "none"  # the world's: each platoon has its own
    assert load_scenario(sc.to_dict()) == dataclasses.replace(sc, source=None)
    run = Simulation(sc).run()
    m = compute_metrics(run)
    # A's leader crashes at 3 s: the follower nearest its slot leads from the next
    # period, A's column closes up; B (no reconfiguration) keeps its slots
    assert m["leader_changes"] == [
        {"t": 3.01, "from": "a0", "to": "A-v0", "mode": "elect"}
    ]
    assert m["reassignments"][0]["assignment"] == {
        "a0": None,
        "A-v0": 0,
        "A-v1": 1,
        "A-v2": 2,
    }
    assert run.slot_index[-1].tolist() == [-1, 0, 1, 2, 4, 5, 6]
    assert m["platoons"]["A"]["converged"] and m["platoons"]["B"]["converged"]


def test_pictures_label_by_platoon(tmp_path):
    from sandbox.render.camera import _legend_items
    from sandbox.render.figures import formation_error_figure, trajectories_figure
    from sandbox.render.palette import build_palette

    run = Simulation(load_scenario(_write(tmp_path, TWO))).run()
    fig = formation_error_figure(run)
    assert [ax.get_title(loc="left") for ax in fig.axes] == [
        "platoon east",
        "platoon north",
    ]
    labels = [t.get_text() for t in trajectories_figure(run).legends[0].get_texts()]
    assert labels == ["east", "north"]
    _, body, _ = build_palette(run.colors)
    items = _legend_items(run, body, False)
    assert [i.label for i in items[:2]] == ["east", "north"]


def test_a_reconfiguring_platoon_sees_the_estimate_under_the_braking_barrier(
    tmp_path, monkeypatch
):
    # Under sensing and the braking barrier the law sees the others through their
    # estimate (Simulation.believed), a platoon with its own reconfiguration too:
    # its leader's pose in its law's context is the estimate, not the noisy copy.
    from sandbox.behaviour.reconfigure import Reconfiguration

    text = RECONFIGURED.replace("duration: 12", "duration: 4") + (
        "sensing: {position_noise: 0.02, delay: 0.05}\n"
        "safety: {filter: cbf, barrier: braking}\n"
    )
    seen_by = {}
    react = Reconfiguration.react

    def spy(self, state, t, known):
        seen_by[state.names] = state  # what each platoon's reconfiguration reads
        return react(self, state, t, known)

    monkeypatch.setattr(Reconfiguration, "react", spy)
    sim = Simulation(load_scenario(_write(tmp_path, text)))
    for _ in range(20):
        sim.step()
    (view,) = [v for v in sim.platoons.views if v.group.name == "A"]
    state = seen_by[view.names]  # this period's, read at its plan
    assert np.array_equal(state.believed, sim.believed[view.rows])
    assert not np.allclose(state.believed, state.seen)
    ctx = state.law_context(sim.t, state.offset, {})
    assert np.array_equal(ctx.leader_pos, state.believed[state.leader, :2])
