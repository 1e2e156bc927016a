"""Contact episodes: one collision event per encounter of a pair.

An episode opens at the pair's first contact and closes only once the gap between the
two surfaces has exceeded ``metrics.contact_release`` (default 1 cm). Each test drives
the physics directly with open-loop commands, and checks the same motion with a release
distance of a nanometre, which counts every contact onset as the physics reports it
(the counting of earlier versions): the difference is what the episodes merge.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import PAPER, SCENARIOS, run_scenario, write_yaml

from sandbox import load_scenario
from sandbox.errors import ScenarioError
from sandbox.physics.world import CONTACT_RELEASE, World
from sandbox.scenario import ObstacleSpec, VehicleSpec

H = 0.01  # control period [s]
SUBSTEPS = 4
#: A release distance that closes an episode at every separation.
EVERY_ONSET = 1e-9


def drive(world: World, commands) -> World:
    """Drive with ``commands(step, state) -> (v1, v2)`` arrays until it returns None."""
    step = 0
    while True:
        state = world.read_state()
        out = commands(step, state)
        if out is None:
            return world
        world.write_commands(state.theta, *out, H)
        world.step(H, SUBSTEPS, step * H)
        step += 1


def wall_at(x: float) -> ObstacleSpec:
    """A 0.1 m wall along x1 = ``x`` (its face at ``x - 0.05``)."""
    return ObstacleSpec("wall", "wall", start=(x, -20.0), end=(x, 20.0), thickness=0.1)


def push_back_push(back_off: float, release: float = CONTACT_RELEASE) -> World:
    """Drive into a wall at 0.5 m/s, back off ``back_off`` metres, push again."""
    world = World((VehicleSpec("a", (0.0, 0.0, 0.0)),), (wall_at(1.0),), release)
    back_steps = int(round(back_off / 0.1 / H))

    def commands(step, state):
        if step < 250:  # contact after 1.4 s, then pressed for a second
            return np.array([0.5]), np.zeros(1)
        if step < 250 + back_steps:  # reverse at 0.1 m/s (v1 < 0: an open-loop test)
            return np.array([-0.1]), np.zeros(1)
        if step < 250 + back_steps + 30:  # wait
            return np.zeros(1), np.zeros(1)
        if step < 250 + back_steps + 200:
            return np.array([0.5]), np.zeros(1)
        return None

    return drive(world, commands)


def test_bounce_and_return_within_the_release_gap_is_one_episode() -> None:
    world = push_back_push(0.005)  # 5 mm: within the 1 cm release distance
    assert len(world.events) == 1
    event = world.events[0]
    assert event.t == pytest.approx(1.4, abs=0.02)
    assert event.end is None  # pressed against the wall at the end
    assert 0.0 < event.penetration < 0.005
    # counted at every onset, the same motion gives two contacts
    assert len(push_back_push(0.005, EVERY_ONSET).events) == 2


def test_bounce_and_return_beyond_the_release_gap_is_two_episodes() -> None:
    world = push_back_push(0.03)  # 3 cm: beyond the release distance
    assert [e.b for e in world.events] == ["wall", "wall"]
    first, second = world.events
    # the first closes once the gap exceeds 1 cm, i.e. 1 cm into the 0.1 m/s retreat
    assert first.end == pytest.approx(2.5 + 0.01 / 0.1, abs=0.03)
    assert second.t > first.end and second.end is None
    # a release of 5 cm merges them again
    assert len(push_back_push(0.03, 0.05).events) == 1


def weave(steps: int):
    """Vehicle ``b`` drives beside ``a`` at 1 m/s and weaves into it and away."""

    def commands(step, state):
        if step >= steps:
            return None
        aim = -0.3 if np.sin(step * 0.15) > 0 else 0.2
        v2 = np.array([0.0, -3.0 * (state.theta[1] - aim)])
        return np.ones(2), v2

    return commands


def test_grinding_side_by_side_is_one_episode() -> None:
    pair = (VehicleSpec("a", (0.0, 0.0, 0.0)), VehicleSpec("b", (0.0, 0.6, 0.0)))
    world = drive(World(pair, ()), weave(500))
    assert [(e.a, e.b, e.kind) for e in world.events] == [("a", "b", "vehicle_vehicle")]
    assert world.events[0].t == pytest.approx(1.89, abs=0.02)
    onsets = drive(World(pair, (), EVERY_ONSET), weave(500)).events
    assert len(onsets) >= 5  # the physics reports a new contact at every rub


def test_sustained_push_is_one_open_episode() -> None:
    # a pushes b (which brakes with an equal motor) for 3 s
    pair = (VehicleSpec("a", (0.0, 0.0, 0.0)), VehicleSpec("b", (0.8, 0.0, 0.0)))

    def commands(step, state):
        return (np.array([0.5, 0.0]), np.zeros(2)) if step < 360 else None

    world = drive(World(pair, ()), commands)
    assert len(world.events) == 1
    event = world.events[0]
    assert event.t == pytest.approx(0.6, abs=0.02) and event.end is None
    assert 0.0 < event.penetration < 0.005
    assert world.in_contact().tolist() == [True, True]


def test_sliding_along_a_wall_is_one_episode() -> None:
    # heading 0.2 rad into a wall along x2 = 0.32 m, weaving: it scrapes along it
    wall = ObstacleSpec("wall", "wall", start=(-5, 0.32), end=(50, 0.32))

    def commands(step, state):
        if step >= 500:
            return None
        aim = 0.2 if np.sin(step * 0.3) > 0 else -0.1
        return np.ones(1), -4.0 * (state.theta - aim)

    world = drive(World((VehicleSpec("a", (0.0, 0.0, 0.0)),), (wall,)), commands)
    assert len(world.events) == 1
    state = world.read_state()
    assert state.pos[0, 0] > 3.0  # it kept moving along the wall
    assert world.events[0].penetration < 0.005


def test_events_in_metrics_carry_end_healthy_and_penetration() -> None:
    _, metrics = run_scenario(
        SCENARIOS / "failures" / "follower_stop.yaml", "recovery.strategy=none"
    )
    events = metrics["collisions"]["events"]
    # red runs into the stopped orange and grinds past it: one encounter (3 contact
    # onsets when every onset was counted)
    assert len(events) == 1
    (event,) = events
    assert set(event) == {"t", "end", "a", "b", "kind", "healthy", "penetration"}
    assert (event["a"], event["b"], event["healthy"]) == ("red", "orange", False)
    assert event["end"] > event["t"]
    assert 0.0 < event["penetration"] < 0.01


def test_fig12_contacts_of_one_encounter_are_one_event() -> None:
    # red cuts past the leader: one episode (three contact onsets, 0.525-0.85 s, with
    # the controller of earlier versions; the bundled start of earlier versions)
    _, metrics = run_scenario(
        PAPER / "fig12_no_recovery.yaml",
        "vehicles[1].pose=[1.2, -0.9, 2.0]",
        "vehicles[2].pose=[-2.2, 1.6, -0.8]",
        duration=2.0,
    )
    events = metrics["collisions"]["events"]
    assert [(e["a"], e["b"]) for e in events] == [("leader", "red")]
    assert 0.5 < events[0]["t"] < events[0]["end"] < 1.0


@pytest.mark.parametrize("value", [0, -0.01, "far"])
def test_contact_release_must_be_a_positive_length(tmp_path, value) -> None:
    doc = {
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [{"pose": [0, 0, 0]}],
        "metrics": {"contact_release": value},
    }
    with pytest.raises(ScenarioError, match="metrics.contact_release"):
        load_scenario(write_yaml(tmp_path, doc))


def test_contact_release_is_read_from_the_scenario() -> None:
    base = PAPER / "fig12_no_recovery.yaml"
    assert load_scenario(base).metrics.contact_release == CONTACT_RELEASE
    sc = load_scenario(base, overrides=["metrics.contact_release=0.05"])
    assert sc.metrics.contact_release == 0.05
