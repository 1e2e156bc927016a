"""Each compiled path against its numpy form, within the tolerances of sandbox.accel.

Every compiled path (``sandbox/accel.py``) is the fast form of a stage whose numpy
form stays the reference. Each test here runs a stage, or a whole run, both ways on
the same inputs (the numpy form with :func:`sandbox.accel.switched_off`) and compares
the outputs within the tolerance its path states in ``sandbox/accel.py``: never bit
for bit, so that they hold on any CPU (the C library's ``atan2``, ``exp`` or ``log``
and numpy's own SIMD loops may round a last bit apart). Where a path is off (not
built, or ``SANDBOX_ACCEL=0``) its tests are skipped; the numpy forms run in every
other test of the suite either way.
"""

from __future__ import annotations

import ctypes
import json
import re
from dataclasses import replace

import numpy as np
import pytest
from helpers import PAPER, write_yaml

from sandbox import accel, compute_metrics, load_scenario
from sandbox.behaviour import recovery, residual_state, tracks
from sandbox.behaviour.detection import residual_pass
from sandbox.behaviour.pair_field import CONTINUOUS, DISCONTINUOUS, ShiftKernel
from sandbox.behaviour.residual_kernel import ResidualPass
from sandbox.behaviour.safety import accounting, qp
from sandbox.behaviour.safety.accounting import FilterStep, RunningExtremes
from sandbox.behaviour.safety.cbf import PARAMS, CBFState, filter_commands
from sandbox.behaviour.sensing import Broadcast
from sandbox.geometry.neighbours import AllPairsByWorld, NeighbourList
from sandbox.loop.divergence import RowsView, healthy
from sandbox.loop.simulation import Simulation
from sandbox.model.flatness import Gains
from sandbox.model.kernels import Controller, motor_model
from sandbox.model.law_kernel import LawKernel, covers, overwrite_rows
from sandbox.model.laws import LawInputs
from sandbox.model.obstacle_field import ObstacleField
from sandbox.model.obstacles import ObstacleSpec
from sandbox.physics.world import World, motor_limits, motor_limits_numpy
from sandbox.plugins.contexts import DetectorContext, FilterContext, StrategyContext
from sandbox.plugins.registration import make_law

#: Tolerances of sandbox/accel.py's table, by what they bound.
TIGHT = {"rtol": 1e-12, "atol": 1e-12}  # one period's arithmetic
RUNS = {"rtol": 1e-9, "atol": 1e-9}  # whole runs, residuals, fits
SPEEDS = {"rtol": 0.0, "atol": 1e-9}  # the filter's projections [m/s]


def needs(*names: str) -> pytest.MarkDecorator:
    """Skip where one of the compiled paths ``names`` is off here."""
    off = [name for name in names if accel.module(name) is None]
    return pytest.mark.skipif(bool(off), reason=f"compiled paths off: {off}")


def close(got, want, tolerance: dict) -> None:
    """Arrays (or numbers) of the same shape within ``tolerance``, NaN where NaN."""
    np.testing.assert_allclose(got, want, equal_nan=True, **tolerance)


def assert_runs_close(got, want) -> None:
    """Two runs of one scenario: every recorded array within RUNS, the same events."""
    for name in ("t", "pose", "cmd", "chi", "slot", "target", "reference"):
        close(getattr(got, name), getattr(want, name), RUNS)
    for name in ("mode", "failed"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert got.status == want.status
    assert [(e.a, e.b) for e in got.events] == [(e.a, e.b) for e in want.events]
    close([e.t for e in got.events], [e.t for e in want.events], RUNS)
    assert (
        json.dumps(got.info.get("detection"), default=str)
        == json.dumps(want.info.get("detection"), default=str)
        or got.info.get("detection") is None
    )
    metrics = compute_metrics(got), compute_metrics(want)
    close_tree(*metrics)


def close_tree(a, b) -> None:
    """Two JSON-like trees: the same keys and texts, numbers within RUNS."""
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            close_tree(a[key], b[key])
    elif isinstance(a, list | tuple):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            close_tree(x, y)
    elif isinstance(a, bool) or a is None or isinstance(a, str):
        assert a == b
    else:
        close(a, b, RUNS)


def both_ways(make, *names: str):
    """``make()`` with every compiled path on, then with ``names`` off (default all)."""
    got = make()
    with accel.switched_off(*names):
        want = make()
    return got, want


# ------------------------------------------------------------------ whole runs
#: Runs without contacts: name, overrides, seeds (0: one run, else a batch).
FREE_RUNS = {
    "rotating": ("paper/rotating_circle", ["duration=3"], 0),
    "virtual_rotating": ("paper/virtual_rotating", ["duration=3"], 0),
    "leader_ref": ("paper/leader_ref_drift", ["duration=3"], 0),
    "own_estimate_batch": ("paper/own_estimate_circle", ["duration=2"], 2),
    "fixed": ("paper/fixed_circle", ["duration=3"], 0),
    "discontinuous": ("paper/fig13_discontinuous_beta1", ["duration=4"], 0),
    "detector_filter_batch": (
        "failures/detect_follower_stop",
        ["duration=5", "safety.filter=cbf", "sensing.delay=0.02", "sensing.loss=0.1"],
        2,
    ),
    "circle_swap_filter": (
        "safety/circle_swap_8",
        ["duration=5", "safety.filter=cbf"],
        0,
    ),
}


def _runs(name: str, overrides: list[str], seeds: int) -> list:
    if seeds:
        scenarios = [
            load_scenario(name, overrides=[*overrides, f"seed={s}"])
            for s in range(seeds)
        ]
        return Simulation.batch(scenarios)
    return [Simulation(load_scenario(name, overrides=overrides)).run()]


@pytest.mark.parametrize("case", sorted(FREE_RUNS))
def test_runs_without_contacts_agree_with_the_numpy_path(case):
    name, overrides, seeds = FREE_RUNS[case]
    got, want = both_ways(lambda: _runs(name, overrides, seeds))
    assert not any(r.events for r in want)
    for a, b in zip(got, want, strict=True):
        assert_runs_close(a, b)


@needs("residual", "fits")
def test_the_detector_finds_the_same_failure_both_ways():
    sc = load_scenario("failures/detect_follower_stop", overrides=["duration=6"])
    got, want = both_ways(lambda: Simulation(sc).run(), "residual", "fits")
    events = want.info["detection"]["events"]
    assert events  # the stop is found
    assert got.info["detection"]["events"] == events


# ------------------------------------------------------------------ controller
@needs("controller")
@pytest.mark.parametrize("n", [1, 3, 10, 64])
@pytest.mark.parametrize("limits", ["scalars", "rows", "turning"])
def test_a_controller_step_agrees_with_the_numpy_functions(n, limits):
    rng = np.random.default_rng(n)
    gains = Gains()
    if limits == "scalars":
        controller = Controller(gains, 0.01, 2.0, 5.0, 4.0, None)
    else:
        rows = rng.uniform(0.5, 3.0, n)
        turn = rows if limits == "turning" else None
        controller = Controller(gains, 0.01, rows, 2.0 * rows, 2.0 * rows, turn)
    for _ in range(20):
        pos = rng.normal(0.0, 2.0, (n, 2))
        chi = rng.normal(0.0, 1.0, (n, 2))
        chi[rng.random(n) < 0.1] = 0.0  # at rest: eq. (5)'s heading held
        slow = rng.random(n) < 0.2  # near rest: chi comes back from zero
        chi[slow] *= 0.005
        theta = rng.uniform(-4.0, 4.0, n)
        target = pos + rng.normal(0.0, 1.0, (n, 2))
        target[rng.random(n) < 0.2, 0] = np.nan  # aims at the position's coordinate
        v_ref, a_ref = rng.normal(0.0, 1.0, (n, 2)), rng.normal(0.0, 1.0, (n, 2))
        travel = rng.integers(-1, 2, n).astype(np.int8)  # backward, none, forward
        args = (pos, chi, theta, target, v_ref, a_ref, travel)
        got = controller.step(*args)
        want = controller.step_numpy(*args)
        for a, b in zip(got[:3], want[:3], strict=True):
            close(a, b, TIGHT)
        np.testing.assert_array_equal(got[3], want[3])  # the directions of travel


@needs("controller")
@pytest.mark.parametrize("substeps", [1, 4])
def test_the_motor_model_agrees_with_numpy(substeps):
    rng = np.random.default_rng(substeps)
    n = 40
    accel_rows = np.where(rng.random(n) < 0.25, np.inf, rng.uniform(2.0, 8.0, n))
    start = np.column_stack((rng.normal(0, 2, (n, 2)), rng.uniform(-3, 3, n)))
    states, out = [], []
    for on in (True, False):
        ctx = DetectorContext(
            t=0.0, dt=0.01, pos=start[:, :2], theta=start[:, 2],
            vel=rng.normal(0.0, 1.0, (n, 2)) if on else states[0][1],
            seen=start.copy(), fresh=None,
            commands=np.column_stack((rng.uniform(0, 2, n), rng.normal(0, 1, n)))
            if on else states[0][2],
            in_contact=None, failing=np.zeros(n, bool), position_noise=0.0,
            heading_noise=0.0, substeps=substeps, motor_accel=accel_rows,
            turn_accel=4.0 * accel_rows / 0.15, params={}, memory={},
        )  # fmt: skip
        st = residual_state.start_state(ctx)
        states.append((st, ctx.vel, ctx.commands))
        for _ in range(5):
            if on:
                residual_state.advance_model(st, ctx)
            else:
                with accel.switched_off("controller"):
                    residual_state.advance_model(st, ctx)
        out.append((st.pose, st.vel, st.rate, st.travel))
    for a, b in zip(*out, strict=True):
        close(a, b, TIGHT)
    assert (
        motor_model(
            np.zeros((1, 3)),
            np.zeros((1, 2)),
            np.zeros(1),
            np.zeros(1),
            np.zeros((1, 2)),
            np.ones(1),
            np.ones(1),
            0.01,
            1,
        )
        is not None
    )


# ------------------------------------------------------------------ laws
def numpy_targets(law, pose, theta, leader, ref, track, commanded):
    """What LawKernel.targets computes, by the law's own numpy and overwrite_rows."""
    K, n = law.delta.shape[:2]
    pos = pose[:, :2] if theta is None else pose
    theta = pose[:, 2] if theta is None else theta
    lead_pos = lead_theta = None
    if leader >= 0:
        lead_pos = np.ascontiguousarray(pos.reshape(K, n, 2)[:, leader : leader + 1])
        lead_theta = np.ascontiguousarray(theta.reshape(K, n)[:, leader : leader + 1])
    triple = law.targets(LawInputs(lead_pos, lead_theta, ref))
    return overwrite_rows([a.reshape(K * n, 2) for a in triple], ref, track, commanded)


@needs("laws")
@pytest.mark.parametrize(
    ("name", "rotate"),
    [
        ("fixed", False),
        ("rotating", False),
        ("virtual", False),
        ("virtual", True),
        ("leader_ref", False),
        ("leader_ref", True),
        ("own_estimate", False),
    ],
)
def test_a_laws_targets_agree_with_the_law_class(name, rotate):
    rng = np.random.default_rng(len(name) + rotate)
    K, n, T = 3, 4, 12
    delta = rng.uniform(-3.0, 3.0, (K, n, 2))
    params = {"rotate": True} if rotate else {}
    laws = [make_law(name, params, delta, 0.01) for _ in range(2)]
    leader = 1
    assert covers(laws[0], leader)
    kernel = LawKernel.make(laws[0], leader)
    table = tuple(np.ascontiguousarray(rng.normal(0.0, 1.0, (T, 2))) for _ in range(3))
    table[1][3:6] = 0.0  # a reference at rest: the tangent is kept
    track = np.flatnonzero(rng.random(K * n) < 0.3)
    commanded = np.flatnonzero(rng.random(K * n) < 0.2)
    for k in range(T):
        pose = rng.normal(0.0, 2.0, (K * n, 3))
        ref = (table[0][k], table[1][k], table[2][k])
        got = kernel.targets(pose, None, table, k, track, commanded)
        want = numpy_targets(laws[1], pose, None, leader, ref, track, commanded)
        for a, b in zip(got, want, strict=True):
            close(a, b, TIGHT)
    close(laws[0]._tangent, laws[1]._tangent, TIGHT)


# ------------------------------------------------------------------ pair field
def strategy_context(rng, K, n, seen, neighbours):
    N = K * n
    pos = rng.uniform(-2.0, 2.0, (N, 2))
    pos[1] = pos[0] + 1e-9  # nearly coincident: eq. (25)'s least distance
    return StrategyContext(
        t=0.0, dt=0.01, pos=pos, theta=np.zeros(N), vel=np.zeros((N, 2)),
        slot=rng.normal(0.0, 3.0, (N, 2)), diameter=np.zeros(N),
        may_avoid=rng.random(N) < 0.8, failed=np.zeros(N, dtype=bool), params={},
        R=1.5, obstacle_field=ObstacleField(()), neighbours=neighbours,
        seen_pos=pos + rng.normal(0.0, 0.05, (N, 2)) if seen else None,
    )  # fmt: skip


@needs("pair_field")
@pytest.mark.parametrize("kind", [DISCONTINUOUS, CONTINUOUS])
@pytest.mark.parametrize("seen", [False, True])
def test_the_pair_terms_agree_with_weighted_shift(kind, seen):
    rng = np.random.default_rng(10 * kind + seen)
    weight = (recovery.discontinuous, recovery.continuous)[kind]
    for _ in range(30):
        ctx = strategy_context(rng, 1, int(rng.integers(2, 12)), seen, None)
        got, want = both_ways(
            lambda c=ctx: recovery.weighted_shift(
                replace(c, neighbours=NeighbourList(1.5)), weight, 0.3, 0.5, 2.0
            ),
            "pair_field",
        )
        close(got[0], want[0], TIGHT)
        assert np.array_equal(got[1], want[1])


@needs("pair_field")
@pytest.mark.parametrize("kind", [DISCONTINUOUS, CONTINUOUS])
def test_a_strategys_shifted_targets_agree_with_numpy(kind):
    rng = np.random.default_rng(kind)
    weight = (recovery.discontinuous, recovery.continuous)[kind]
    r = (None, 0.5)[kind]
    for trial in range(20):
        K, n = 3, int(rng.integers(1, 8))
        ctx = strategy_context(rng, K, n, trial % 2, AllPairsByWorld(K, n, 1.5))
        beta = 0.3 if trial % 2 else rng.uniform(0.0, 1.0, (K * n, 1))
        kernel = ShiftKernel(
            AllPairsByWorld(K, n, 1.5), 1.5, r, kind, beta, accel.module("pair_field")
        )
        got = kernel.shifted(ctx.pos, ctx.seen_pos, ctx.may_avoid, ctx.slot)
        with accel.switched_off("pair_field"):
            shift, active = recovery.weighted_shift(ctx, weight, beta, r, 2.0)
        close(got[0], ctx.slot + shift, TIGHT)
        close(got[1], shift, TIGHT)
        assert np.array_equal(got[2], active)


# ------------------------------------------------------------------ sensing draws
@needs("draws")
@pytest.mark.parametrize("K", [1, 5])
def test_the_draws_of_a_batch_are_each_worlds_generators(K):
    # Not a tolerance: the one call runs numpy's own fill functions on each world's
    # bit generator, so a world in a batch receives the copies of its single run.
    n = 4

    def copies():
        batch = Broadcast(0.01, 0.005, 1, 0.2, seeds=range(K), n=n)
        pos, theta = np.zeros((K * n, 2)), np.zeros(K * n)
        return [batch.update(pos, theta).copy() for _ in range(6)]

    got, want = both_ways(copies, "draws")
    alone = Broadcast(0.01, 0.005, 1, 0.2, seeds=[0], n=n)
    first = [alone.update(np.zeros((n, 2)), np.zeros(n)).copy() for _ in range(6)]
    for a, b, c in zip(got, want, first, strict=True):
        assert np.array_equal(a, b)
        assert np.array_equal(a[:n], c)


# ------------------------------------------------------------------ safety filter
WALLS = (
    ObstacleSpec("circle", "c", center=(0.3, -0.2), radius=0.3),
    ObstacleSpec("wall", "w", start=(-1.5, 1.0), end=(1.5, 1.2), thickness=0.1),
)


def random_steps(rng: np.random.Generator, count: int) -> list[FilterContext]:
    """Velocity-barrier steps of random fleets, each option of the filter once.

    One world or three of one to five vehicles, close enough for barriers to bind
    and to conflict (infeasible problems, stalls, more rows than the cut), with and
    without the last period's commands, sensing, failed and open-loop vehicles and
    obstacles.
    """
    out = []
    for trial in range(count):
        worlds = 1 if trial % 3 == 0 else 3
        n = int(rng.integers(1, 4 if trial % 2 else 6))
        size = worlds * n
        params = {k: p.default for k, p in PARAMS.items()}
        params.update(
            gamma=float(rng.uniform(0.5, 4.0)),
            margin=float(rng.choice([0.05, 0.2])),
            look_ahead=float(rng.choice([0.1, 0.25])),
            neighbour_velocity="zero" if trial % 4 == 1 else "broadcast",
            projection="speed" if trial % 5 == 2 else "look_ahead",
            reverse=trial % 3 != 1,
            pass_right=0.0 if trial % 7 == 3 else 1.5708,
            max_constraints=int(rng.integers(1, 4)) if trial % 2 else 8,
            range=None if trial % 4 else float(rng.uniform(0.5, 3.0)),
        )
        pos = rng.uniform(-1.2, 1.2, (size, 2))
        theta = rng.uniform(-np.pi, np.pi, size)
        v1 = rng.uniform(-2.0, 2.0, size)
        v2 = rng.uniform(-4.0, 4.0, size)
        first = trial % 6 == 0
        seen = None
        if trial % 4 == 3:
            seen = np.column_stack((pos, theta)) + rng.normal(0.0, 0.05, (size, 3))
        out.append(
            FilterContext(
                t=0.0,
                dt=0.01,
                pos=pos,
                theta=theta,
                vel=rng.normal(0.0, 0.8, (size, 2)),
                v1=v1,
                v2=v2,
                diameter=rng.uniform(0.3, 0.6, size),
                params=params,
                v1_prev=None if first else v1 + rng.normal(0.0, 0.05, size),
                v2_prev=None if first else v2 + rng.normal(0.0, 0.2, size),
                v1_max=2.0,
                v2_max=np.inf if trial % 8 == 6 else 4.0,
                accel_max=5.0 if trial % 2 else float(rng.choice([50.0, np.inf])),
                known_failed=rng.random(size) < 0.15,
                commanded=rng.random(size) < 0.1,
                obstacle_field=ObstacleField(WALLS if trial % 5 == 4 else ()),
                seen=seen,
                worlds=worlds,
                substeps=4,
            )  # fmt: skip
        )
    return out


@needs("filter", "qp")
def test_the_velocity_barriers_step_agrees_with_numpy():
    steps = random_steps(np.random.default_rng(11), 120)
    rows = []
    for ctx in steps:
        got, want = both_ways(lambda c=ctx: filter_commands(CBFState(c), c))
        (v1, v2, step), (w1, w2, ref) = got, want
        close(v1, w1, SPEEDS)
        close(v2, w2, {"rtol": 0.0, "atol": 1e-8})  # v2 = z2 / look
        close(step.slack, ref.slack, SPEEDS)
        assert np.array_equal(step.active, ref.active)
        assert step.rows == ref.rows
        close(step.min_barrier, ref.min_barrier, RUNS)
        if ref.by_vehicle is not None:
            close(step.by_vehicle, ref.by_vehicle, RUNS)
        rows.append(step.rows)
    assert 0 in rows and max(rows) > 8  # none at all, and more than one cut


@needs("filter")
def test_the_worlds_counters_agree_with_numpy():
    rng = np.random.default_rng(20261208)
    for trial in range(16):
        k, n = int(rng.integers(1, 6)), int(rng.integers(1, 5))
        braking = trial % 2 == 1
        stats = ([{} for _ in range(k)], [{} for _ in range(k)])
        counters = (RunningExtremes(stats[0]), RunningExtremes(stats[1]))
        for t in (0.0, 0.01, 0.02, 0.03):
            slack = np.where(rng.random(k * n) < 0.8, 0.0, rng.uniform(0, 1, k * n))
            step = FilterStep(
                rng.random(k * n) < 0.1, slack, 0,
                fallback=rng.random(k * n) < 0.05,
                by_vehicle=rng.normal(0.0, 1.0, k * n),
            )  # fmt: skip
            accounting.account_worlds(stats[0], t, braking, step, n, counters[0])
            accounting.account_worlds_numpy(stats[1], t, braking, step, n, counters[1])
        close_tree(stats[0], stats[1])


@needs("qp")
@pytest.mark.parametrize("m", [1, 3, 6, 12])
def test_the_projection_agrees_with_numpy(m):
    rng = np.random.default_rng(m)
    k = 512
    angle = rng.uniform(-np.pi, np.pi, (k, m))
    if m > 1:  # repeated and opposite lines
        angle[: k // 8, 1] = angle[: k // 8, 0]
        angle[k // 8 : k // 4, 1] = angle[k // 8 : k // 4, 0] + np.pi
    a = np.stack((np.cos(angle), np.sin(angle)), -1)
    a[rng.random((k, m)) < 0.1] = 0.0  # padding rows
    b = rng.normal(0.3, 1.0, (k, m))
    z0 = rng.normal(0.0, 1.5, (k, 2))
    z, ok = qp.project(z0, a, b)
    zn, okn = qp.project_numpy(z0, a, b)
    assert np.array_equal(ok, okn)
    close(z, zn, SPEEDS)


# ------------------------------------------------------------------ detector
def synthetic_platoon(compiled: bool, n: int = 36, periods: int = 64) -> tuple:
    """A synthetic platoon's residual detector, by the C pass or numpy's.

    ``n`` unicycles follow smooth random commands, observed with noise and lost
    packets; a third of them stop and turn on the spot for a while (alarms, windows
    read while isolating, clearings), some touch (the contact gate), one is seen at
    NaN for a while, and the substeps and the drives' limits vary.
    """
    rng = np.random.default_rng(20261207)
    limit = np.where(rng.random(n) < 0.25, np.inf, rng.uniform(2.0, 8.0, n))
    params = {"lambda": 6.0, "window": 0.03, "shift": 3.0, "isolation": 0.05,
              "noise_floor": 0.001, "heading_floor": 0.001}  # fmt: skip
    truth = np.column_stack((rng.normal(0.0, 3.0, (n, 2)), rng.uniform(-3, 3, n)))
    commands = np.column_stack((rng.uniform(0.2, 1.5, n), rng.normal(0.0, 0.5, n)))
    onset = np.where(np.arange(n) % 3 == 0, rng.integers(5, 20, n), periods)
    end = onset + rng.integers(8, 30, n)
    st, trace, events = None, [], []
    for k in range(periods):
        commands = commands + rng.normal(0.0, 0.05, (n, 2))
        faulty = (onset <= k) & (k < end)
        v1 = np.where(faulty, 0.0, commands[:, 0])
        v2 = np.where(faulty, 2.0, commands[:, 1])
        heading = np.column_stack((np.cos(truth[:, 2]), np.sin(truth[:, 2])))
        truth[:, :2] += 0.01 * v1[:, None] * heading
        truth[:, 2] += 0.01 * v2
        seen = truth + rng.normal(0.0, 0.002, (n, 3))
        if periods // 2 <= k < periods // 2 + 10:
            seen[n - 1] = np.nan  # diverged observations
        ctx = DetectorContext(
            t=0.01 * k, dt=0.01, pos=truth[:, :2], theta=truth[:, 2],
            vel=v1[:, None] * heading, seen=seen, fresh=rng.random(n) > 0.08,
            commands=commands.copy(), in_contact=rng.random(n) < 0.015,
            failing=faulty, position_noise=0.002, heading_noise=0.002,
            substeps=1 + k % 3, motor_accel=limit, turn_accel=4.0 * limit / 0.15,
            params=params, memory={"trace": trace}, brake_accel=np.minimum(limit, 5.0),
        )  # fmt: skip
        if st is None:
            st = residual_state.start_state(ctx)
            st.history = residual_state.shape_history(ctx)
            continue
        if compiled:
            out = ResidualPass.of(ctx).run(
                st, ctx.t, ctx.seen, ctx.fresh, ctx.in_contact, ctx.commands, trace
            )
        else:
            with accel.switched_off("controller"):
                st.history.append(ctx.t, ctx.seen, ctx.fresh)
                out = residual_pass(st, ctx)
        events.append([list(rows) for rows in out])
    return st, trace, events


@needs("residual", "controller")
def test_the_residual_pass_agrees_with_numpy():
    (sa, ta, ea), (sb, tb, eb) = synthetic_platoon(True), synthetic_platoon(False)
    assert ea == eb and any(any(rows) for period in eb for rows in period)
    assert [x[:2] for x in ta] == [x[:2] for x in tb]
    close([x[2] for x in ta], [x[2] for x in tb], RUNS)
    close(sa.history.values, sb.history.values, TIGHT)
    assert np.array_equal(sa.history.fresh, sb.history.fresh)
    for name, value in vars(sb).items():
        if isinstance(value, np.ndarray):
            mine = getattr(sa, name)
            if value.dtype == np.float64:
                close(mine, value, RUNS)
            else:
                assert np.array_equal(mine, value), name
    assert sa.kinds == sb.kinds


def random_track(rng, m):
    """A track of ``m`` samples at 100 Hz: a crash or a braked stop, with noise."""
    t = 3.0 + np.sort(np.arange(m) * 0.01 + rng.uniform(0.0, 0.004, m))
    v0, brake = rng.uniform(0.1, 2.5), float(rng.choice([0.5, 2.0, 5.0, 50.0]))
    tt, onset = t - t[0], rng.uniform(0.0, t[-1] - t[0])
    braking = np.clip(tt - onset, 0.0, v0 / brake) if rng.random() < 0.5 else 0.0
    s = v0 * (np.minimum(tt, onset) + braking) - 0.5 * brake * braking**2
    return t, s + rng.normal(0.0, float(rng.choice([0.0, 0.001, 0.01])), m), brake


@needs("fits")
def test_the_stop_fits_agree_with_numpy():
    rng = np.random.default_rng(5)
    for _ in range(60):
        t, s, brake = random_track(rng, int(rng.integers(10, 160)))
        got, want = both_ways(lambda a=(t, s, brake): tracks.stop_fits(*a), "fits")
        close(got, want, RUNS)


# ------------------------------------------------------------------ motors, period
@needs("motors")
def test_the_motor_limits_agree_with_numpy():
    rng = np.random.default_rng(6)
    n = 4096
    current = rng.uniform(0.0, 50.0, n)

    class Motors:  # the arrays motor_limits reads of a World
        _mass = rng.uniform(0.5, 5.0, n)
        _moment = rng.uniform(0.01, 1.0, n)
        _least_force = rng.uniform(0.0, 40.0, n)
        _least_torque = rng.uniform(0.0, 4.0, n)
        _force = np.where(rng.random(n) < 0.1, np.inf, current)
        _torque = np.where(rng.random(n) < 0.1, 2.0 * current, 0.1 * current)
        _tracking = rng.random(n) < 0.9

    command = rng.normal(0.0, 1.0, (n, 3))
    measured = np.where(rng.random((n, 3)) < 0.1, command, rng.normal(0, 1, (n, 3)))
    free = rng.random(n) < 0.8
    got = motor_limits(command, measured, free, 0.0025, Motors)
    want = motor_limits_numpy(command, measured, free, 0.0025, Motors)
    assert np.array_equal(got[0], want[0])
    close(got[1], want[1], TIGHT)
    close(got[2], want[2], TIGHT)


def motor_arguments(n: int) -> dict:
    """The named arguments of ``_motors.motor_limits`` for ``n`` vehicles."""
    rng = np.random.default_rng(n)
    arrays = {name: rng.uniform(0.5, 5.0, n) for name in (
        "mass", "moment", "least_force", "least_torque", "force", "torque",
    )}  # fmt: skip
    return {
        "command": rng.normal(0.0, 1.0, (n, 3)),
        "measured": rng.normal(0.0, 1.0, (n, 3)),
        "free": rng.random(n) < 0.8,
        "substep": 0.0025,
        "headroom": 1.5,
        **arrays,
        "tracking": np.ones(n, dtype=bool),
        "force_out": np.full(n, -1.0),
        "torque_out": np.full(n, -1.0),
        "change": np.zeros(n, dtype=bool),
    }


@needs("motors")
def test_an_entry_point_takes_its_arguments_by_name_in_any_order():
    c = accel.module("motors")
    named = motor_arguments(5)
    in_order = c.motor_limits(**named)
    written = named["force_out"].copy(), named["change"].copy()
    again = motor_arguments(5)
    assert c.motor_limits(**dict(reversed(list(again.items())))) == in_order
    assert np.array_equal(again["force_out"], written[0])
    assert np.array_equal(again["change"], written[1])


@needs("motors")
@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"change": None}, "motor_limits: missing argument 'change'"),
        ({"chnage": 1}, "motor_limits: no argument 'chnage'"),
        ({"mass": np.ones(5, dtype=np.float32)}, "motor_limits: mass: expected a"),
        ({"substep": "0.01"}, "motor_limits: substep: expected a number"),
        ({"free": np.ones(10, dtype=bool)}, "motor_limits: shapes differ"),
    ],
)
def test_a_bad_named_argument_is_refused_before_anything_is_written(change, message):
    c = accel.module("motors")
    named = {**motor_arguments(5), **change}
    named = {key: value for key, value in named.items() if value is not None}
    error = ValueError if "shapes" in message else TypeError
    with pytest.raises(error, match=re.escape(message)):
        c.motor_limits(**named)
    assert np.all(named["force_out"] == -1.0)
    with pytest.raises(TypeError, match="takes keyword arguments only"):
        c.motor_limits(named["command"])


@needs("period")
def test_the_divergence_fast_path_says_what_numpy_says():
    rng = np.random.default_rng(7)

    class Fleet:
        def __init__(self, n):
            self.pos = rng.normal(0.0, 10.0, (n, 2))
            self.theta = rng.normal(0.0, 3.0, n)
            self.vel = rng.normal(0.0, 1.0, (n, 2))
            self.chi = rng.normal(0.0, 1.0, (n, 2))

    for trial in range(60):
        fleet = Fleet(int(rng.integers(1, 20)))
        bad = (fleet.pos, fleet.theta, fleet.vel, fleet.chi)[trial % 4]
        bad.flat[0] = (np.nan, np.inf, 2e6, 999.5)[trial % 4] if trial % 3 else 0.0
        view = RowsView(fleet, slice(0, None))
        got, want = both_ways(lambda v=view: healthy(v), "period")
        assert got == want


# ------------------------------------------------------------------ stepping
#: Form-ups without recovery: contact episodes open inside the C calls.
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


class CountedSteps:
    """The stepping path's calls counted, and those that ended on a new episode."""

    def __init__(self, monkeypatch):
        module = accel.module("stepping")
        self.calls = self.early = 0
        real_prepare, real_advance = module.prepare, module.advance
        clocks = {}  # each prepared batch's clock address

        def prepare(**named):
            batch = real_prepare(**named)
            clocks[id(batch)] = (batch, named["clock"])
            return batch

        def advance(batch, t0, dt):
            self.calls += 1
            done = real_advance(batch, t0, dt)
            clock = clocks[id(batch)][1]
            if ctypes.c_double.from_address(clock + 8).value:  # clock[1] raised
                self.early += 1
            return done

        monkeypatch.setattr(module, "prepare", prepare)
        monkeypatch.setattr(module, "advance", advance)


@needs("stepping")
def test_without_contacts_every_period_after_the_first_is_one_call(monkeypatch):
    counted = CountedSteps(monkeypatch)
    path = PAPER / "rotating_circle.yaml"
    scenarios = [
        load_scenario(path, overrides=["duration=2", f"seed={k}"]) for k in (0, 1)
    ]
    runs = Simulation.stacked(scenarios).run_all()
    assert not any(r.events for r in runs)
    periods = int(round(scenarios[0].duration / scenarios[0].dt))
    # the first period steps world by world (it checks the bodies in), then one call
    assert counted.calls == periods - 1 and counted.early == 0


@needs("stepping")
def test_an_episode_opened_in_a_call_hands_the_period_to_python(tmp_path, monkeypatch):
    path = write_yaml(tmp_path, CONTACTS)
    scenarios = [load_scenario(path, overrides=[f"seed={s}"]) for s in range(6)]
    counted = CountedSteps(monkeypatch)
    runs = Simulation.stacked(scenarios).run_all()
    events = sum(len(r.events) for r in runs)
    assert events >= 3
    assert 1 <= counted.early <= events
    assert counted.calls > counted.early
    with accel.switched_off("stepping"):
        python = Simulation.stacked(scenarios).run_all()
    for got, want in zip(runs, python, strict=True):
        assert_runs_close(got, want)


def test_a_world_keeps_its_clock_alone_and_leaves_the_shared_one_when_stopped():
    sc = load_scenario(PAPER / "fig15_continuous_beta1.yaml", overrides=["duration=1"])
    world = World(sc.vehicles, sc.obstacles)
    world.time = 0.25
    assert world.time == 0.25 and type(world.time) is float
    sim = Simulation.stacked([sc, sc])
    sim.run_all()
    stepper = sim.physics._stepper
    assert stepper is not None
    worlds = sim.physics.worlds
    stepper.live([0])
    assert worlds[0]._clock is stepper._clock
    assert worlds[1]._clock is not stepper._clock
    stepper._clock[0] = 7.0
    assert worlds[0].time == 7.0 and worlds[1].time != 7.0


# ------------------------------------------------------------------ taken
#: Each path's functions that a run of its stage calls.
CALLED = {
    "laws": ("law_targets",),
    "pair_field": ("pair_terms",),
    "draws": ("fill_worlds",),
    "controller": ("controller_step",),
    "filter": ("velocity_step", "world_counts"),
    "motors": ("motor_limits",),
    "stepping": ("advance",),
    "period": (
        "healthy",
        "buffer_period",
        "flush_periods",
        "record_sample",
        "read_state",
    ),  # fmt: skip
    "residual": ("residual_period",),
    "fits": ("fits",),
}


def test_a_run_takes_every_compiled_path_that_is_on(monkeypatch):
    calls: dict[str, int] = {}
    for name, functions in CALLED.items():
        module = accel.module(name)
        if module is None:
            continue
        for function in functions:
            real = getattr(module, function)

            def counted(*args, _key=f"{name}.{function}", _real=real, **named):
                calls[_key] = calls.get(_key, 0) + 1
                return _real(*args, **named)

            monkeypatch.setattr(module, function, counted)
    scenarios = [
        load_scenario(
            "failures/detect_follower_stop",
            overrides=["duration=5", "safety.filter=cbf", f"seed={s}"],
        )
        for s in range(2)
    ]
    Simulation.batch(scenarios)
    expected = {
        f"{name}.{function}"
        for name, functions in CALLED.items()
        if accel.module(name) is not None
        for function in functions
    }
    assert expected <= calls.keys(), expected - calls.keys()
