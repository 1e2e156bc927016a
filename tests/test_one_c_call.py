"""One C call per control period for all worlds (sandbox/physics/_cstep.c).

The extension is optional: where it is built, the C path must be taken and give the
bytes of the Python path; where it is not, the Python path runs and only the
assertions about the C path are skipped.
"""

from __future__ import annotations

import ctypes

import numpy as np
import pytest
from helpers import PAPER, write_yaml

from sandbox import compute_metrics, load_scenario
from sandbox.loop.simulation import Simulation
from sandbox.physics import stepping
from sandbox.physics.world import World
from sandbox.run.output import write_run_dir

BUILT = stepping._cstep is not None
needs_c = pytest.mark.skipif(not BUILT, reason="sandbox.physics._cstep not built")

#: Form-ups without recovery: contact episodes open inside C calls and close later.
CONTACTS = {
    "name": "c_contacts",
    "duration": 2.5,
    "vehicle": {"v1_max": 2.0, "max_accel": 5.0, "v2_max": 8.0},
    "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1},
    "formation": {"law": "rotating"},
    "recovery": {"strategy": "none"},
    "obstacles": [{"type": "circle", "center": [2.0, 2.0], "radius": 0.5}],
    "vehicles": [
        {"name": "leader", "pose": [0, 0, 0], "leader": True},
        {"name": "red", "pose": [1, 1, 0], "offset": [-1, 0.5]},
        {"name": "green", "pose": [1, -1, 0], "offset": [-1, -0.5]},
    ],
    "randomize": {
        "vehicles[1].pose": {"uniform": [[-2.5, -2.5, -3.14], [2.5, 2.5, 3.14]]},
        "vehicles[2].pose": {"uniform": [[-2.5, -2.5, -3.14], [2.5, 2.5, 3.14]]},
    },
}


class Counted:
    """``_cstep`` with its calls counted, and those that returned on a new episode."""

    def __init__(self, module):
        self.module, self.calls, self.early = module, 0, 0

    def advance(self, *args):
        self.calls += 1
        done = self.module.advance(*args)
        clock = args[12]  # the clock's address, after the 12 arguments before it
        if ctypes.c_double.from_address(clock + 8).value:  # clock[1] raised
            self.early += 1
        return done


@pytest.fixture(params=["c", "python"])
def path(request, monkeypatch):
    """Each test twice: with the C loop (where built) and with the Python path."""
    if request.param == "python":
        monkeypatch.setattr(stepping, "_cstep", None)
    return request.param


def files_of(run, directory) -> dict[str, bytes]:
    out = write_run_dir(run, compute_metrics(run), directory)
    return {p.name: p.read_bytes() for p in sorted(out.iterdir()) if p.is_file()}


def contact_scenarios(tmp_path, seeds=range(6)):
    path = write_yaml(tmp_path, CONTACTS)
    return [load_scenario(path, overrides=[f"seed={s}"]) for s in seeds]


def free_scenarios():
    sc = PAPER / "rotating_circle.yaml"
    return [load_scenario(sc, overrides=["duration=2", f"seed={k}"]) for k in (0, 1)]


@needs_c
def test_without_contacts_every_period_after_the_first_is_one_c_call(monkeypatch):
    counted = Counted(stepping._cstep)
    monkeypatch.setattr(stepping, "_cstep", counted)
    scenarios = free_scenarios()
    sim = Simulation.stacked(scenarios)
    runs = sim.run_all()
    assert sim.physics._stepper._one_call is not None
    assert not any(r.events for r in runs)
    periods = int(round(scenarios[0].duration / scenarios[0].dt))
    # the first period steps world by world (it checks the bodies in), then one call
    assert counted.calls == periods - 1 and counted.early == 0


@needs_c
def test_an_episode_opened_in_a_c_call_hands_the_period_to_python(
    tmp_path, monkeypatch
):
    counted = Counted(stepping._cstep)
    monkeypatch.setattr(stepping, "_cstep", counted)
    runs = Simulation.stacked(contact_scenarios(tmp_path)).run_all()
    events = sum(len(r.events) for r in runs)
    assert events >= 3
    # each episode opened inside a C call ended it early; the others opened while
    # some world had an open episode (the Python path)
    assert 1 <= counted.early <= events
    assert counted.calls > counted.early


@pytest.mark.parametrize("kind", ["contacts", "free"])
def test_the_c_loop_gives_the_bytes_of_the_python_path(kind, path, tmp_path):
    scenarios = contact_scenarios(tmp_path) if kind == "contacts" else free_scenarios()
    runs = Simulation.stacked(scenarios).run_all()
    stepping_now = stepping._cstep
    stepping._cstep = None  # the reference: the Python path, world after world too
    try:
        python = Simulation.stacked(scenarios).run_all()
        alone = [Simulation(sc).run() for sc in scenarios]
    finally:
        stepping._cstep = stepping_now
    for k, run in enumerate(runs):
        got = files_of(run, tmp_path / f"{path}{k}")
        for reference in (python[k], alone[k]):
            want = files_of(reference, tmp_path / f"reference{k}")
            assert got == want, (kind, path, k)
    if kind == "contacts":
        assert sum(len(r.events) for r in runs) >= 3


def test_one_call_false_takes_the_python_path(monkeypatch):
    monkeypatch.setattr(stepping.WorldStepper, "one_call", False)
    sim = Simulation.stacked(free_scenarios())
    sim.run_all()
    assert sim.physics._stepper is not None
    assert sim.physics._stepper._one_call is None


def test_a_world_keeps_its_clock_alone_and_leaves_the_shared_one_when_stopped():
    sc = load_scenario(PAPER / "fig15_continuous_beta1.yaml", overrides=["duration=1"])
    world = World(sc.vehicles, sc.obstacles)
    world.time = 0.25
    assert world.time == 0.25 and type(world.time) is float
    sim = Simulation.stacked([sc, sc])
    sim.run_all()
    physics = sim.physics
    stepper = physics._stepper
    assert stepper is not None
    worlds = physics.worlds
    stepper.live([0])
    assert worlds[0]._clock is stepper._clock
    assert worlds[1]._clock is not stepper._clock
    stepper._clock[0] = 7.0
    assert worlds[0].time == 7.0 and worlds[1].time != 7.0
    assert np.array_equal(World(sc.vehicles, sc.obstacles)._clock, [0.0, 0.0])
