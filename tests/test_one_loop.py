"""The one loop: every feature run K worlds at once gives each world's files alone.

Each case is a bundled scenario (or a small document) with per-world differences
(seeds, starts, failure times); the worlds run together through
``Simulation.batch`` and each alone through ``Simulation(scenario).run()``, and
every output file of ``sandbox run`` (trajectory, metrics, scenario, run.npz,
manifest) must be the same bytes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import write_yaml

from sandbox import compute_metrics, load_scenario
from sandbox.errors import PluginRunError
from sandbox.loop.plan import structure_key
from sandbox.loop.simulation import Simulation
from sandbox.plugins import register_law, register_strategy, unregister
from sandbox.run import recorder as recording
from sandbox.run.output import write_run_dir

pytestmark = pytest.mark.filterwarnings("ignore::sandbox.SandboxWarning")

#: Per-world overrides that vary the runs of one structure.
STARTS = [
    ["seed=0"],
    ["seed=1", "vehicles[1].pose=[-1.2, 0.9, 0.3]"],
    ["seed=2", "vehicles[2].pose=[-0.8, -1.4, -0.2]"],
]

#: (bundled scenario, fixed overrides) covering the loop's features.
CASES = {
    "laws_and_avoidance": ("paper/fig15_continuous_beta1", ["duration=3"]),
    "discontinuous_leader_avoids": (
        "paper/fig16_leader_avoids_discontinuous_beta1",
        ["duration=3"],
    ),
    "tangential": (
        "paper/fig15_continuous_beta1",
        ["duration=3", "recovery.tangential=0.5", "recovery.strategy=smooth"],
    ),
    "virtual_rotating": ("paper/virtual_rotating", ["duration=3"]),
    "own_estimate": ("paper/own_estimate_circle", ["duration=3"]),
    "leader_ref": ("paper/leader_ref_drift", ["duration=3"]),
    "stuck_steering": ("failures/follower_stuck_steering", ["duration=4"]),
    "spin": ("failures/follower_spin", ["duration=4"]),
    "stop": ("failures/follower_stop", ["duration=4"]),
    "crash": ("failures/follower_crash", ["duration=4"]),
    "uncontrolled": ("failures/uncontrolled_into_leader", ["duration=4"]),
    "obstacles": ("failures/obstacle_field", ["duration=4"]),
    "sensing": (
        "paper/fig15_continuous_beta1",
        [
            "duration=3",
            "sensing.position_noise=0.02",
            "sensing.heading_noise=0.01",
            "sensing.delay=0.02",
            "sensing.loss=0.1",
        ],
    ),
    "cbf": ("safety/circle_swap_3", ["duration=4"]),
    "cbf_braking_sensed": (
        "safety/circle_swap_3_jittered",
        ["duration=4", "sensing.position_noise=0.01"],
    ),
    "cbf_braking_estimate_delayed_lossy": (
        "safety/circle_swap_3_jittered",
        [
            "duration=4",
            "safety.filter=cbf",
            "safety.barrier=braking",
            "safety.estimate_gain=0.2",
            "sensing.position_noise=0.02",
            "sensing.heading_noise=0.01",
            "sensing.delay=0.05",
            "sensing.loss=0.1",
        ],
    ),
    "cbf_door": ("safety/door", ["duration=4"]),
    "cbf_priority_slot_distance": (
        "safety/door",
        ["duration=6", "safety.filter=cbf", "safety.priority=slot_distance"],
    ),
    "cbf_priority_index_braking": (
        "safety/door",
        [
            "duration=6",
            "safety.filter=cbf",
            "safety.barrier=braking",
            "safety.priority=index",
        ],
    ),
    "cbf_eight_braking": (
        "safety/circle_swap_8",
        ["duration=3", "safety.barrier=braking"],
    ),
    # the run toward a runaway and the braking's second try, world by world
    "cbf_braking_runaway_sensed": (
        "failures/uncontrolled_into_leader",
        [
            "duration=5",
            "safety.filter=cbf",
            "safety.barrier=braking",
            "recovery.tangential=1",
            "sensing.position_noise=0.02",
            "sensing.delay=0.05",
            "detection.method=residual",
        ],
    ),
    "cbf_residual_crash": (
        "failures/detect_follower_crash",
        ["duration=4", "safety.filter=cbf"],
    ),
    "residual_detector": ("failures/detect_follower_stop", ["duration=4"]),
    "glr_detector_sensed": (
        "failures/detect_follower_stuck_steering",
        ["duration=4", "detection.method=glr", "sensing.position_noise=0.02"],
    ),
    "reconfigure_handover": ("failures/leader_crash_elect", ["duration=5"]),
    "reconfigure_hungarian": ("failures/column_close", ["duration=5"]),
    # each world's own law (it re-forms) on the copies it receives
    "reconfigure_sensed": (
        "failures/column_close",
        ["duration=3", "sensing.position_noise=0.02", "sensing.delay=0.02"],
    ),
    "command_schedules": ("paper/leader_ref_drift", ["duration=3"]),
    "range_sensors_sensed_obstacles": (
        "failures/obstacle_field",
        [
            "duration=4",
            "sensors={range: {beams: 24, max_range: 3, noise: 0.01, rate: 20}}",
            "recovery.obstacles=sensed",
        ],
    ),
    "range_sensors_cbf": (
        "safety/door",
        ["duration=3", "sensors={range: {beams: 16, max_range: 2}}"],
    ),
}


def files_of(run, directory) -> dict[str, bytes]:
    out = write_run_dir(run, compute_metrics(run), directory)
    return {p.name: p.read_bytes() for p in sorted(out.iterdir()) if p.is_file()}


def assert_batch_is_alone(scenarios, tmp_path, runs=None) -> list:
    runs = Simulation.batch(scenarios) if runs is None else runs
    assert len(runs) == len(scenarios)
    for k, (sc, run) in enumerate(zip(scenarios, runs, strict=True)):
        alone = files_of(Simulation(sc).run(), tmp_path / f"alone{k}")
        together = files_of(run, tmp_path / f"batch{k}")
        assert together.keys() == alone.keys()
        for name in alone:
            assert together[name] == alone[name], (sc.name, k, name)
    return runs


def scenarios_of(name: str, fixed: list[str], starts=STARTS) -> list:
    scenarios = []
    for extra in starts:
        try:
            scenarios.append(load_scenario(name, overrides=[*fixed, *extra]))
        except Exception:  # a start that does not fit the scenario: the seed alone
            scenarios.append(load_scenario(name, overrides=[*fixed, extra[0]]))
    return scenarios


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_every_feature_batched_gives_the_bytes_alone(case, tmp_path):
    name, fixed = CASES[case]
    scenarios = scenarios_of(name, fixed)
    assert len({structure_key(sc) for sc in scenarios}) == 1  # one loop, K = 3
    assert_batch_is_alone(scenarios, tmp_path)


def test_seeds_of_sensing_and_detection_in_one_loop(tmp_path):
    fixed = ["duration=2", "sensing.position_noise=0.02", "sensing.loss=0.2"]
    scenarios = scenarios_of("failures/detect_follower_stop", fixed)
    runs = assert_batch_is_alone(scenarios, tmp_path)
    assert runs[0].pose.tobytes() != runs[1].pose.tobytes()  # own random streams


def test_a_diverging_world_an_ending_one_and_an_interrupted_batch(tmp_path):
    doc = {
        "duration": 1.5,
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1},
        "formation": {"law": "rotating"},
        "recovery": {"strategy": "flaky", "R": 1.5},
        "vehicle": {"v1_max": 2.0, "v2_max": 8.0},
        "vehicles": [
            {"name": "lead", "pose": [0, 0, 0], "leader": True},
            {"name": "red", "pose": [-1, 1, 0], "offset": [-1, 1]},
        ],
    }
    calls = []

    @register_strategy("flaky", {"beta": 1.0})
    def flaky(ctx):  # beta is free per world; 2 breaks the plug-in at 0.7 s
        calls.append(ctx.n)
        if ctx.params["beta"] == 2.0 and ctx.t >= 0.7:
            raise RuntimeError("flaky broke")
        return np.zeros((ctx.n, 2)), np.zeros(ctx.n, dtype=bool)

    try:
        path = write_yaml(tmp_path, doc)
        runaway = {"vehicle": "red", "kind": "uncontrolled", "v1": 2000.0, "at": 0.3}
        scenarios = [
            load_scenario(path, overrides=["seed=0"]),
            load_scenario(path, overrides=["seed=1", "recovery.beta=2"]),
            load_scenario(path, overrides=["seed=2"]).with_overrides(
                f"failures=[{runaway}]".replace("'", '"')
            ),
        ]
        assert len({structure_key(sc) for sc in scenarios}) == 1
        sim = Simulation.stacked(scenarios)
        runs = sim.run_all()
        assert [r.status for r in runs] == ["ok", "error", "diverged"]
        assert "flaky broke" in runs[1].info["error"]["message"]
        assert set(calls) == {2}  # a plug-in without batched=True: world by world
        assert_batch_is_alone(scenarios, tmp_path, runs)
        # Interrupted: the worlds stop together and nothing is returned.
        polls = []
        stopped = Simulation.stacked(scenarios[:1] * 2).run_all(
            should_stop=lambda: polls.append(1) or len(polls) > 20
        )
        assert stopped is None
        alone = Simulation(scenarios[0])
        run = alone.run(should_stop=lambda: len(polls) > 40 or polls.append(1))
        assert run.status == "interrupted"
    finally:
        unregister("strategy", "flaky")
    assert PluginRunError  # the error class the loop turns into status "error"


def test_the_step_api_over_k_worlds_equals_each_world_stepped_alone():
    scenarios = scenarios_of("paper/fig15_continuous_beta1", ["duration=1"])
    together = Simulation.stacked(scenarios)
    alone = [Simulation(sc) for sc in scenarios]
    rng = np.random.default_rng(4)
    while not together.done:
        speeds = rng.uniform(-0.5, 0.5, size=(3, 3, 2))
        speeds[:, 0] = np.nan  # the leaders keep their controllers
        shifts = [None, {"red": (0.1, 0.0)}, None]
        obs = together.step(commands=speeds, shifts=shifts)
        for w, sim in enumerate(alone):
            one = sim.step(commands=speeds[w], shifts=shifts[w])
            assert one.pose.tobytes() == obs[w].pose.tobytes()
            assert one.mode.tobytes() == obs[w].mode.tobytes()
    for w, sim in enumerate(alone):
        assert together.result(w).pose.tobytes() == sim.result().pose.tobytes()
    with pytest.raises(ValueError, match=r"shape \(3, 3, 2\)"):
        Simulation.stacked(scenarios).step(commands=np.zeros((2, 3, 2)))


def test_a_record_spilled_to_disk_is_batched_too(tmp_path, monkeypatch):
    monkeypatch.setattr(recording, "SPILL_BYTES", 10_000)
    scenarios = scenarios_of("paper/fig15_continuous_beta1", ["duration=1"])
    sim = Simulation.stacked(scenarios)
    assert sim.recorder.on_disk
    runs = sim.run_all()
    assert isinstance(runs[0].pose, np.memmap) or runs[0].pose.base is not None
    assert_batch_is_alone(scenarios, tmp_path, runs)


@pytest.mark.slow
def test_several_platoons_in_one_loop_give_the_runs_alone(tmp_path):
    # Each world's platoons are its own (their laws, references, filter and events);
    # the crash inside one platoon comes at another time in each world.
    scenarios = [
        load_scenario(
            "traffic/failure_crash",
            overrides=["duration=12", f"seed={seed}", f"failures[0].at={at}"],
        )
        for seed, at in ((0, 8.0), (1, 9.0), (2, 10.0))
    ]  # each seed draws the first platoon's speed (randomize:)
    assert len({structure_key(sc) for sc in scenarios}) == 1
    runs = assert_batch_is_alone(scenarios, tmp_path)
    assert runs[0].pose.tobytes() != runs[2].pose.tobytes()
    sim = Simulation.stacked(scenarios)
    assert sim.observe(1).platoon == Simulation(scenarios[1]).observe().platoon


#: Worlds that re-form apart: each world's own failures (free per world), so that the
#: leader is handed over at another time in each world, or never.
REFORMING = [
    ["seed=0", "failures[0].at=1.0"],
    ["seed=1", "failures[0].at=2.2", "vehicles[1].pose=[-1.2, 0.9, 0.3]"],
    ["seed=2", "failures=[]"],
    ["seed=3", "failures=[{vehicle: red, at: 1.5, kind: stop}]"],
]


@pytest.mark.parametrize(
    "name, fixed",
    [
        ("failures/leader_crash_elect", ["formation={law: fixed}"]),
        ("failures/leader_crash_elect", ["formation={law: rotating}"]),
        ("failures/leader_crash_elect", ["formation={law: own_estimate}"]),
        ("failures/leader_crash_elect", ["recovery.target_derivatives=estimate"]),
        # the reference at rest from 1.8 s: the offsets keep its last tangent (45 deg)
        (
            "failures/leader_crash_elect",
            ["reference={type: waypoints, points: [[0, 0], [1.3, 1.3]], speed: 1}"],
        ),
        ("failures/leader_crash_virtual", []),
        (
            "failures/leader_crash_virtual",
            ["reference={type: waypoints, points: [[0, 0], [1.3, 1.3]], speed: 1}"],
        ),
        ("failures/leader_crash_virtual", ["formation={law: virtual, rotate: true}"]),
    ],
    ids=[
        "fixed",
        "rotating",
        "own_estimate",
        "leader_ref",
        "leader_ref_at_rest",
        "virtual",
        "virtual_at_rest",
        "to_virtual",
    ],
)
def test_worlds_that_re_form_apart_share_one_law_and_give_the_bytes_alone(
    name, fixed, tmp_path
):
    # The built-in law stays one call for all worlds through each world's handover
    # and reassignment (loop/reforming.py); the worlds the virtual leader takes over
    # follow a second one.
    scenarios = [
        load_scenario(name, overrides=["duration=4", *fixed, *extra])
        for extra in REFORMING
    ]
    assert len({structure_key(sc) for sc in scenarios}) == 1
    sim = Simulation.stacked(scenarios)
    formation = sim._formation  # one law for every world (loop/formation.py)
    assert formation.reforming is not None and not formation.per_world
    runs = sim.run_all()
    changes = [len(r.info["leader_changes"]) for r in runs]
    assert changes == [1, 1, 0, 0]
    assert [len(r.info["reassignments"]) for r in runs] == [1, 1, 0, 1]
    virtual = scenarios[0].on_leader_failure == "virtual"  # a new law where it fails
    assert formation.reforming.virtual.tolist() == [virtual, virtual, False, False]
    if not virtual:  # the new leader's pose is gathered in worlds 0 and 1 only
        elected = [r.info["leader_changes"][0]["to"] for r in runs[:2]]
        names = [v.name for v in scenarios[0].vehicles]
        leaders = formation.reforming.leaders.tolist()
        assert [names[i] for i in leaders[:2]] == elected and leaders[2:] == [0, 0]
    assert_batch_is_alone(scenarios, tmp_path, runs)


def test_a_detector_that_clears_re_forms_each_world_at_its_own_events(tmp_path):
    # The residual detector finds the leader's spin and clears it when it ends: a
    # world re-forms at each change of what its platoon believes, another never.
    fixed = [
        "duration=9",
        "reconfigure={assign: hungarian, close_gap: false}",
        "on_leader_failure=elect",
    ]
    starts = [
        ["seed=0"],
        ["seed=1", "failures[0].at=2.0", "failures[0].until=5.0"],
        ["seed=2", "failures=[]"],
    ]
    scenarios = [
        load_scenario("failures/detect_leader_spin", overrides=[*fixed, *extra])
        for extra in starts
    ]
    sim = Simulation.stacked(scenarios)
    assert sim._formation.reforming is not None
    runs = sim.run_all()
    events = [len(r.info["reassignments"]) for r in runs]
    assert events[0] >= 2 and events[1] >= 2 and events[2] == 0
    assert_batch_is_alone(scenarios, tmp_path, runs)


def test_every_failure_kind_of_many_worlds_at_once_gives_the_bytes_alone(tmp_path):
    # Six worlds, each with its own failure of red: from four active failures on the
    # loop applies the built-in kinds at once (Failures, RULED_FROM), alone
    # each world calls its kind's function; the files must not tell them apart.
    from sandbox.model.failures import RULED_FROM

    kinds = [
        "{vehicle: red, at: 1.0, kind: stuck_steering}",
        "{vehicle: red, at: 1.2, kind: stuck_steering, v2: -0.8}",
        "{vehicle: red, at: 1.1, kind: stop}",
        "{vehicle: red, at: 0.9, kind: spin, v2: 3.0}",
        "{vehicle: red, at: 1.3, until: 2.0, kind: uncontrolled, v1: 2.0, v2: 0.5}",
        "{vehicle: red, at: 1.0, kind: crash}",
    ]
    scenarios = [
        load_scenario(
            "failures/follower_stop",
            overrides=["duration=3", f"seed={k}", f"failures=[{kind}]"],
        )
        for k, kind in enumerate(kinds)
    ]
    assert len({structure_key(sc) for sc in scenarios}) == 1
    assert len(scenarios) >= RULED_FROM > 1  # at once together, one by one alone
    runs = assert_batch_is_alone(scenarios, tmp_path)
    assert all(r.failed[-1, 1] for r in runs[:4]) and not runs[4].failed[-1, 1]


def test_command_schedules_of_many_worlds_at_once_give_the_bytes_alone(tmp_path):
    # Each world's leader has its own schedule (rows at other times, another count,
    # zero before its first row): the loop looks the rows in force up for all worlds
    # at once (CommandSchedules), only when some schedule passes a row.
    schedules = [
        "[[0.0, 1.0, 0.2], [1.5, 1.0, 0.0]]",
        "[[0.5, 0.8, 0.1], [1.0, 1.2, -0.2], [2.5, 0.0, 0.0]]",
        "[[0.0, 1.0, 0.0]]",
    ]
    scenarios = [
        load_scenario(
            "paper/leader_ref_drift",
            overrides=["duration=3", f"seed={k}", f"vehicles[0].drive.schedule={rows}"],
        )
        for k, rows in enumerate(schedules)
    ]
    assert len({structure_key(sc) for sc in scenarios}) == 1
    runs = assert_batch_is_alone(scenarios, tmp_path)
    # the commands applied are the rows in force (the first sample of each period)
    cmd = runs[1].cmd[:, 0]
    t = runs[1].t
    assert np.all(cmd[t < 0.5] == 0.0)
    assert np.allclose(cmd[(t >= 1.0) & (t < 2.5)], [1.2, -0.2])
    assert np.all(cmd[t >= 2.5] == 0.0)


@pytest.mark.slow
def test_the_platoons_sections_of_many_worlds_are_called_once_for_all(tmp_path):
    # Each recovery and safety section of the worlds' platoons is one call for all
    # worlds (loop/platoon_sections.py), a world's own beta on its rows; the files
    # are those of each world alone.
    from sandbox.loop.platoon_sections import PlatoonSections

    scenarios = [
        load_scenario("traffic/head_on_narrow", overrides=["duration=6", *extra])
        for extra in (["seed=0"], ["seed=1", "recovery.beta=2.0"], ["seed=2"])
    ]
    assert len({structure_key(sc) for sc in scenarios}) == 1
    sim = Simulation.stacked(scenarios)
    assert isinstance(sim.strategy.__self__, PlatoonSections)
    safety = sim._safety  # the safety stage (loop/safety.py)
    assert isinstance(safety.filter.__self__, PlatoonSections) and safety.batched
    runs = sim.run_all()
    assert any(r.info["safety"]["active_steps"] for r in runs)  # the filter acted
    assert_batch_is_alone(scenarios, tmp_path, runs)
    # A world whose platoons divide into other sections (its second platoon's own
    # beta): the sections are called world by world, with the same bytes.
    own = scenarios[0].with_overrides(
        "platoons[1].recovery={strategy: continuous, beta: 3.0, R: 3d, r: 1.5d, "
        "tangential: 1.0, leader_avoids: true}"
    )
    apart = [scenarios[2], own]
    sim = Simulation.stacked(apart)  # world by world
    assert not isinstance(sim.strategy.__self__, PlatoonSections)
    assert sim._safety.batched is False
    assert_batch_is_alone(apart, tmp_path / "apart")


#: The traffic scenes but failure_crash (test_several_platoons_... runs it).
TRAFFIC = sorted(
    p.stem
    for p in (Path(__file__).parents[1] / "scenarios" / "traffic").glob("*.yaml")
    if p.stem != "failure_crash"
)


@pytest.mark.slow
@pytest.mark.parametrize("name", TRAFFIC)
def test_every_traffic_scenario_in_one_loop_gives_the_runs_alone(name, tmp_path):
    scenarios = [
        load_scenario(f"traffic/{name}", overrides=["duration=15", f"seed={seed}"])
        for seed in range(3)
    ]
    assert_batch_is_alone(scenarios, tmp_path)


def test_a_batched_plug_in_law_is_called_world_by_world_while_worlds_re_form(tmp_path):
    # The loop restarts one world's history only in the built-in laws: a plug-in law
    # registered with batched=True is called with each world's rows while its worlds
    # can re-form, and gives the bytes alone.
    shapes = []

    @register_law("ahead_of_leader", batched=True)
    def ahead_of_leader(ctx):
        shapes.append(np.shape(ctx.pos))
        slot = np.asarray(ctx.leader_pos) + ctx.offset
        return slot, np.zeros_like(slot), np.zeros_like(slot)

    try:
        scenarios = [
            load_scenario(
                "failures/column_close",
                overrides=["duration=4", "formation={law: ahead_of_leader}", *extra],
            )
            for extra in (["seed=0"], ["seed=1", "failures[0].at=2.0"])
        ]
        sim = Simulation.stacked(scenarios)
        assert sim._formation.per_world and sim._formation.reforming is None
        runs = sim.run_all()
        assert set(shapes) == {(len(scenarios[0].vehicles), 2)}  # one world's rows
        assert [len(r.info["reassignments"]) for r in runs] == [1, 1]
        assert [r.status for r in runs] == ["ok", "ok"]  # the stopped one: no slot
        assert_batch_is_alone(scenarios, tmp_path, runs)
    finally:
        unregister("law", "ahead_of_leader")
