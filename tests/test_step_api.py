"""The step-wise API: observe, step with overrides, done, result."""

from __future__ import annotations

import re

import numpy as np
import pytest
from helpers import SCENARIOS

from sandbox import load_scenario
from sandbox.loop.simulation import Simulation
from sandbox.physics.world import PhysicalState
from sandbox.render import render_frames
from sandbox.run.output import write_csv
from sandbox.run.record import MODE_AVOID, MODE_EXTERNAL, MODE_FAILED, MODE_FORMATION

#: Shortened bundled runs warn that their failure never starts: not the point here.
pytestmark = pytest.mark.filterwarnings("ignore:.*never starts:sandbox.SandboxWarning")

ARRAYS = ("t", "pose", "cmd", "chi", "slot", "target", "mode", "failed", "reference")

#: Two vehicles facing each other 4 m apart, holding their starts: red, the leader, on
#: a point reference, green in its fixed-law slot 4 m ahead of red.
DUEL = {
    "duration": 2.0,
    "dt": 0.01,
    "vehicle": {"diameter": 0.5, "v1_max": 1.0, "max_accel": 5.0, "v2_max": 4.0},
    "reference": {"type": "point", "position": [-2, 0]},
    "formation": {"law": "fixed"},
    "recovery": {"strategy": "none"},
    "vehicles": [
        {"name": "red", "pose": [-2, 0, 0], "leader": True},
        {"name": "green", "pose": [2, 0, np.pi], "offset": [4, 0]},
    ],
}


def platoon(duration: float = 4.0, *sets: str):
    """The failures platoon (continuous recovery, a stop failure at 3 s), shortened."""
    return load_scenario(
        SCENARIOS / "failures" / "follower_stop.yaml",
        overrides=[f"duration={duration}", "record_every=3", *sets],
    )


def stepped(scenario, **overrides_at) -> Simulation:
    sim = Simulation(scenario)
    while not sim.done:
        sim.step(**overrides_at)
    return sim


# ------------------------------------------------------------------ the plain loop
@pytest.mark.parametrize(
    "path",
    [
        "failures/follower_stop.yaml",
        "failures/obstacle_field.yaml",
        "paper/fig15_continuous_beta5.yaml",
    ],
)
def test_stepping_without_overrides_is_bit_identical_to_run(path: str) -> None:
    sc = load_scenario(SCENARIOS / path, overrides=["duration=3.5", "record_every=2"])
    ref = Simulation(sc).run()
    sim = Simulation(sc)
    obs = sim.observe()
    steps = 0
    while not sim.done:
        obs = sim.step()
        steps += 1
    run = sim.result()
    assert steps == sim.steps == 350
    assert obs.t == pytest.approx(3.5)
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(run, name), getattr(ref, name))
    assert run.events == ref.events and run.status == ref.status == "ok"
    assert sim.result() is run  # further calls return the same run


def test_the_observation_is_the_recorded_sample_and_a_copy() -> None:
    sim = Simulation(platoon(3.5, "record_every=1"))
    seen = []
    obs = sim.observe()
    while not sim.done:
        seen.append(obs)
        obs = sim.step()
    run = sim.result()
    for k in (0, 1, 200, 320):  # 320: red failed since 3.0 s
        o = seen[k]
        assert o.t == pytest.approx(run.t[k])
        np.testing.assert_array_equal(o.pose, run.pose[k])
        np.testing.assert_array_equal(o.chi, run.chi[k])
        np.testing.assert_array_equal(o.slot, run.slot[k])
        np.testing.assert_array_equal(o.target, run.target[k])
        np.testing.assert_array_equal(o.mode, run.mode[k])
        np.testing.assert_array_equal(o.failed, run.failed[k])
    assert seen[320].failed[seen[320].index("red")]
    assert run.mode[320, 1] == MODE_FAILED
    # Writing into an observation changes nothing in the simulation.
    sim2 = Simulation(platoon(0.5))
    o = sim2.observe()
    o.pose[:] = 99.0
    o.target[:] = 99.0
    assert np.all(sim2.observe().pose < 10.0) and np.all(sim2.observe().target < 10.0)


# ------------------------------------------------------------------ command overrides
def test_commands_override_within_limits_and_are_recorded_as_external() -> None:
    sim = Simulation(load_scenario(DUEL))
    sim.step(commands={"red": (0.3, 0.5)})
    for _ in range(199):
        sim.step(commands={"red": (5.0, -9.0)})  # beyond v1_max = 1, v2_max = 4
    run = sim.result()
    red = run.cmd[:, 0]
    # From rest, max_accel = 5 m/s^2 over 10 ms: v1 rises by at most 0.05 m/s a step.
    assert red[0].tolist() == [0.05, 0.5]
    assert red[1, 0] == pytest.approx(0.10)
    assert np.max(np.abs(np.diff(red[:200, 0]))) <= 0.05 + 1e-12
    assert red[100:200, 0] == pytest.approx(1.0) and red[100:200, 1] == pytest.approx(
        -4.0
    )
    assert np.all(run.mode[:200, 0] == MODE_EXTERNAL)
    assert np.all(run.mode[:, 1] == MODE_FORMATION)
    assert run.mode[200, 0] == MODE_FORMATION  # the last sample: its own controller
    # red drives a circle of radius 1 / 4 m clockwise: its heading turns by about
    # -4 rad/s x 2 s (less the motor's lag), it stays within 2 x 0.25 m of its start.
    assert run.pose[-1, 0, 2] < -6.0
    assert np.hypot(*(run.pose[:, 0, :2] - run.pose[0, 0, :2]).T).max() < 0.55


def test_overridden_vehicles_keep_their_physics_and_collisions_count() -> None:
    doc = dict(DUEL, duration=6.0)
    sim = Simulation(load_scenario(doc))
    while not sim.done:
        sim.step(commands={"green": (1.0, 0.0)})  # straight at red
    run = sim.result()
    assert [(e.a, e.b) for e in run.events][:1] == [("red", "green")]
    # The contact stops green: bodies never overlap by more than the solver's slop.
    gap = np.hypot(*(run.pose[:, 0, :2] - run.pose[:, 1, :2]).T)
    assert gap.min() > 0.5 - 0.02


def test_failures_apply_on_top_of_user_commands() -> None:
    sim = Simulation(platoon(4.0))
    while not sim.done:
        sim.step(commands={"red": (0.8, 0.0)})
    run = sim.result()
    red = run.names.index("red")
    after = run.t > 3.0 + 1e-9
    # stopped: v2 = 0 at once, v1 braked at max_accel = 5 m/s^2 (0.05 m/s a period)
    assert np.all(run.cmd[after, red, 1] == 0.0)
    periods = np.round((run.t[after] - 3.0) / 0.01) + 1  # braking periods so far
    braked = np.maximum(0.8 - 0.05 * periods, 0.0)  # from the user's 0.8 m/s
    np.testing.assert_allclose(run.cmd[after, red, 0], braked, atol=1e-12)
    assert np.all(run.mode[after, red] == MODE_FAILED)
    assert np.all(
        run.mode[(run.t < 3.0 - 1e-9) & (run.t < run.t[-1]), red] == MODE_EXTERNAL
    )


def test_array_overrides_with_nan_rows_equal_the_mapping_form() -> None:
    a, b = Simulation(platoon(1.0)), Simulation(platoon(1.0))
    rows = np.full((4, 2), np.nan)
    rows[2] = 0.4, 0.1  # green
    while not a.done:
        a.step(commands={"green": (0.4, 0.1)})
        b.step(commands=rows)
    ra, rb = a.result(), b.result()
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(ra, name), getattr(rb, name))
    assert np.all(ra.mode[:-1, 2] == MODE_EXTERNAL)


# ------------------------------------------------------------------ target overrides
def test_a_target_override_is_a_set_point_the_vehicle_reaches() -> None:
    sim = Simulation(load_scenario(dict(DUEL, duration=8.0)))
    goal = (2.0, 2.0)
    while not sim.done:
        obs = sim.step(targets={"green": goal})
    run = sim.result()
    assert np.hypot(*(obs.pose[1, :2] - goal)) < 0.05
    np.testing.assert_array_equal(
        run.target[:-1, 1], np.tile(goal, (len(run.t) - 1, 1))
    )
    assert np.all(run.mode[:-1, 1] == MODE_EXTERNAL)
    assert run.slot[0, 1].tolist() == [2.0, 0.0]  # the slot stays the law's


def test_a_target_shift_of_zero_is_the_plain_run() -> None:
    # Overriding with the planned target itself reproduces the run except the mode.
    sc = load_scenario(DUEL | {"duration": 0.5})
    ref = Simulation(sc).run()
    sim = Simulation(sc)
    obs = sim.observe()
    while not sim.done:
        obs = sim.step(targets={"red": obs.target[0]})
    run = sim.result()
    # Set-points drop the feed-forward, zero here (a point reference holds still).
    np.testing.assert_array_equal(run.pose, ref.pose)
    assert np.all(run.mode[:-1, 0] == MODE_EXTERNAL)


# ------------------------------------------------------------------ errors and ending
@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (
            {"commands": {"gren": (1, 0)}},
            "commands: unknown vehicle 'gren' (vehicles: red, green); "
            "did you mean 'green'?",
        ),
        (
            {"targets": {"red": (1, 0, 3)}},
            "targets['red']: expected 2 numbers, got (1, 0, 3)",
        ),
        (
            {"commands": {"red": (np.inf, 0)}},
            "commands['red']: expected 2 finite numbers",
        ),
        (
            {"commands": np.zeros((3, 2))},
            "commands: expected a mapping by vehicle name or an array of shape "
            "(2, 2), got shape (3, 2)",
        ),
        (
            {"targets": np.array([[np.nan, 1.0], [0, 0]])},
            "targets: row 0 ('red') has one NaN",
        ),
    ],
)
def test_bad_overrides_are_clear_errors(kwargs, message) -> None:
    sim = Simulation(load_scenario(DUEL))
    with pytest.raises(ValueError, match=re.escape(message)):
        sim.step(**kwargs)


def test_stepping_past_the_end_raises_and_an_early_result_is_interrupted() -> None:
    sim = stepped(load_scenario(DUEL | {"duration": 0.05}))
    with pytest.raises(RuntimeError, match="the run is over"):
        sim.step()
    early = Simulation(load_scenario(DUEL))
    for _ in range(10):
        early.step()
    run = early.result()
    assert run.status == "interrupted" and len(run.t) == 11
    assert run.info["interrupted"]["t"] == pytest.approx(0.1)


def test_divergence_ends_a_stepped_run(monkeypatch: pytest.MonkeyPatch) -> None:

    from sandbox.loop.stepping import LoopPhysics

    read = LoopPhysics.read
    calls = {"n": 0}

    def poisoned(self: LoopPhysics):
        pos, theta, vel = read(self)
        calls["n"] += 1
        if calls["n"] > 20:
            pos[1, 0] = np.nan
        return pos, theta, vel

    monkeypatch.setattr(LoopPhysics, "read", poisoned)
    sim = Simulation(load_scenario(DUEL))
    while not sim.done:
        obs = sim.step()
    assert np.isnan(obs.target).all()
    run = sim.result()
    assert run.status == "diverged" and run.info["diverged"]["vehicle"] == "green"
    assert len(run.t) == 21


# ------------------------------------------------------------------ outputs
def test_trajectory_csv_and_frames_show_the_external_mode(tmp_path) -> None:
    sim = Simulation(load_scenario(DUEL | {"duration": 0.4}))
    while not sim.done:
        sim.step(commands={"green": (0.5, 0.0)})
    run = sim.result()
    write_csv(run, tmp_path / "trajectory.csv")
    rows = (tmp_path / "trajectory.csv").read_text().splitlines()[1:]
    modes = {(r.split(",")[1], r.split(",")[9]) for r in rows}
    assert ("green", "external") in modes and ("red", "formation") in modes
    frame = next(iter(render_frames(run, size=200, fps=10)))
    blue = np.all(frame == (0, 120, 255), axis=-1)
    assert blue.sum() > 10  # the blue ring of the overridden vehicle
    plain = next(iter(render_frames(Simulation(load_scenario(DUEL)).run(), size=200)))
    assert not np.all(plain == (0, 120, 255), axis=-1).any()


# ------------------------------------------------------------- the physics interface
class KinematicWorld:
    """Exact unicycle integration of eq. (1), no contacts: a second Physics."""

    def __init__(self, scenario) -> None:
        vs = scenario.vehicles
        self.pose = np.array([v.pose for v in vs], dtype=float)
        self.cmd = np.zeros((len(vs), 2))
        self.events: list = []
        self.failed = None

    def read_state(self) -> PhysicalState:
        v1, v2 = self.cmd.T
        th = self.pose[:, 2]
        vel = np.stack((v1 * np.cos(th), v1 * np.sin(th)), -1)
        return PhysicalState(self.pose[:, :2].copy(), th.copy(), vel, v2.copy())

    def write_commands(self, theta, v1, v2, dt) -> None:
        self.cmd = np.stack((v1, v2), -1)

    def step(self, dt, substeps, t0) -> None:
        v1, v2 = self.cmd.T
        th = self.pose[:, 2] + 0.5 * v2 * dt
        self.pose[:, 0] += v1 * np.cos(th) * dt
        self.pose[:, 1] += v1 * np.sin(th) * dt
        self.pose[:, 2] += v2 * dt

    def immobilize(self, index: int) -> None:
        pass


def test_another_physics_back_end_runs_under_the_same_loop() -> None:
    sc = load_scenario(DUEL | {"duration": 1.0})
    sim = Simulation(sc, world=KinematicWorld(sc))
    while not sim.done:
        obs = sim.step(commands={"red": (0.5, 0.0), "green": (0.0, 1.0)})
    # 1 s at 0.5 m/s straight, but v1 ramps by max_accel h = 0.05 m/s per step from 0:
    # the first 9 steps fall short by 0.45 + 0.40 + ... + 0.05 = 2.25 m/s, x 0.01 s.
    assert obs.pose[0, 0] == pytest.approx(-2.0 + 0.5 * 1.0 - 0.0225)
    assert obs.pose[1, 2] == pytest.approx(np.pi + 1.0)  # turned 1 rad in place
    assert np.all(sim.result().mode[:-1] == MODE_EXTERNAL)
    assert MODE_AVOID not in sim.result().mode


def test_a_zero_shift_drives_as_the_built_in_stack_and_a_shift_moves_the_slot() -> None:
    sc = platoon(2.0)
    ref = Simulation(sc).run()
    zero, moved = Simulation(sc), Simulation(sc)
    while not zero.done:
        zero.step(shifts={"green": (0.0, 0.0)})
        moved.step(shifts={"green": (0.0, -0.5)})  # 0.5 m to the right of the slot
    a, b = zero.result(), moved.result()
    np.testing.assert_array_equal(a.pose, ref.pose)  # the feed-forward is kept
    assert np.all(a.mode[:-1, 2] == MODE_EXTERNAL)
    green = b.names.index("green")
    offset = b.pose[-1, green, :2] - b.slot[-1, green]
    assert offset == pytest.approx((0.0, -0.5), abs=0.1)
    np.testing.assert_allclose(
        b.target[:-1, green] - b.slot[:-1, green],
        [[0, -0.5]] * (len(b.t) - 1),
        atol=1e-9,
    )


def test_run_reports_progress_about_a_hundred_times_and_stops_when_asked() -> None:
    sc = load_scenario(DUEL | {"duration": 3.0})  # 300 steps: every 3rd reported
    calls: list[tuple[int, int]] = []
    run = Simulation(sc).run(progress=lambda k, steps: calls.append((k, steps)))
    assert calls == [(k, 300) for k in range(0, 300, 3)]
    assert run.status == "ok" and len(run.t) == 301
    polls = iter(range(1000))
    stopped = Simulation(sc).run(should_stop=lambda: next(polls) >= 50)
    assert stopped.status == "interrupted" and len(stopped.t) == 51
    np.testing.assert_array_equal(stopped.pose, run.pose[:51])


# ------------------------------------------------------------------ the slot's motion
def test_the_observation_gives_the_slots_velocity_and_acceleration() -> None:
    # virtual_fixed: every slot is the reference (a 5 m circle at 1 m/s) plus a fixed
    # offset, so its velocity is the circle's, of norm 1 m/s, and its acceleration the
    # centripetal 1^2 / 5 = 0.2 m/s^2 towards the centre.
    sim = Simulation(load_scenario("paper/virtual_fixed", overrides=["duration=1"]))
    for _ in range(50):
        obs = sim.step()
    np.testing.assert_allclose(np.hypot(*obs.slot_vel.T), 1.0, rtol=1e-9)
    np.testing.assert_allclose(np.hypot(*obs.slot_acc.T), 0.2, rtol=1e-9)
    centre = obs.slot - obs.slot[obs.index("leader")]  # the offsets
    inward = -(obs.slot - centre)  # the reference point to the centre (0, 0)
    cos = np.sum(inward * obs.slot_acc, axis=1) / (np.hypot(*inward.T) * 0.2)
    np.testing.assert_allclose(cos, 1.0, rtol=1e-9)


def test_an_estimating_law_gives_its_backward_differences() -> None:
    # own_estimate, eqs. (18)-(19): a follower's x_ref' is the backward difference of
    # its slot over h, x_ref'' that of x_ref' (a controller need not difference them
    # itself); the leader's are the reference's own derivatives (a 5 m circle at
    # 1 m/s from (5, 0): x_ref' = (-sin(t/5), cos(t/5))).
    sc = load_scenario("paper/own_estimate_circle", overrides=["duration=1"])
    sim = Simulation(sc)
    seen = [sim.step() for _ in range(20)]
    h, lead = sc.dt, seen[0].index("leader")
    follow = [i for i in range(seen[0].n) if i != lead]
    for a, b, c in zip(seen[5:], seen[6:], seen[7:], strict=False):
        np.testing.assert_allclose(
            b.slot_vel[follow], (b.slot - a.slot)[follow] / h, atol=1e-9
        )
        np.testing.assert_allclose(
            c.slot_acc[follow], (c.slot_vel - b.slot_vel)[follow] / h, atol=1e-6
        )
        exact = [-np.sin(b.t / 5.0), np.cos(b.t / 5.0)]
        np.testing.assert_allclose(b.slot_vel[lead], exact, atol=1e-9)
    assert np.abs(seen[-1].slot_vel).max() > 0.5  # the slots move


def test_the_slots_motion_is_each_worlds_own_in_a_batch() -> None:
    a = load_scenario("paper/rotating_circle", overrides=["duration=1"])
    doc = a.to_dict()
    doc["vehicles"][0]["pose"] = [4.8, 0.1, 1.4]  # the leader's start: its estimates
    b = load_scenario(doc)
    batch = Simulation.stacked([a, b])
    alone = [Simulation(a), Simulation(b)]
    for _ in range(30):
        both = batch.step()
        one = [sim.step() for sim in alone]
    for got, want in zip(both, one, strict=True):
        np.testing.assert_array_equal(got.slot_vel, want.slot_vel)
        np.testing.assert_array_equal(got.slot_acc, want.slot_acc)
    assert not np.array_equal(both[0].slot_acc, both[1].slot_acc)
