"""The braking barrier of the CBF filter (``safety: {filter: cbf, barrier: braking}``).

Property: from every safe state (every barrier ``h >= 0`` at the last period's
velocities) of two vehicles, a vehicle and a failed one, or a vehicle and an obstacle,
under acceleration limits, the conditions have a common point within the bounds: no
slack. The fallback brakes where they have none. Scenario level: a head-on swap and a
seven-vehicle ring swap under ``max_accel`` without contact or relaxed step, against
the velocity barrier, which relaxes on the ring; the margin for the sensing noise and
delay; the residual detector instead of the oracle; bad input in one line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sandbox import load_scenario
from sandbox.behaviour.safety.braking import braking_rows
from sandbox.behaviour.safety.cbf import PARAMS, CBFState, cbf, filter_commands
from sandbox.cli import main
from sandbox.loop.simulation import Simulation
from sandbox.model.barriers import braking_speed, sensing_margin
from sandbox.model.obstacle_field import ObstacleField
from sandbox.model.obstacles import ObstacleSpec
from sandbox.plugins.contexts import FilterContext
from sandbox.run.metrics import compute_metrics

ROOT = Path(__file__).resolve().parents[1]
HEAD_ON = ROOT / "scenarios" / "safety" / "head_on_swap.yaml"
ROBOT = {"diameter": 0.5, "mass": 10.0, "v1_max": 2.0, "v2_max": 4.0, "max_accel": 5.0}
D = 0.5  # [m]
BRAKING = {"filter": "cbf", "barrier": "braking"}


def _ctx(pos, theta, v1, v2, v1_prev, v2_prev, failed=None, obstacles=(), **params):
    n = len(pos)
    values = {k: p.default for k, p in PARAMS.items()}
    values.update({"barrier": "braking", **params})
    return FilterContext(
        t=0.0,
        dt=0.01,
        pos=np.asarray(pos, dtype=float),
        theta=np.asarray(theta, dtype=float),
        vel=np.zeros((n, 2)),
        v1=np.asarray(v1, dtype=float),
        v2=np.asarray(v2, dtype=float),
        diameter=np.full(n, D),
        params=values,
        v1_prev=np.asarray(v1_prev, dtype=float),
        v2_prev=np.asarray(v2_prev, dtype=float),
        v1_max=2.0,
        v2_max=4.0,
        accel_max=5.0,
        known_failed=np.zeros(n, bool) if failed is None else np.asarray(failed),
        commanded=np.zeros(n, bool),
        obstacle_field=ObstacleField(tuple(obstacles)),
    )


# ------------------------------------------------------------------ equations
def test_the_braking_speed_is_the_discrete_braking_distance() -> None:
    # F^2 + A T F = 2 A g: A = 10, T = 0.03, g = 0.8: F = sqrt(0.0225 + 16) - 0.15
    # = 3.85078 m/s; T = 0 gives sqrt(2 A g) = 4.
    assert braking_speed(np.array(0.8), np.array(10.0), 0.03) == pytest.approx(
        np.sqrt(0.0225 + 16.0) - 0.15
    )
    assert braking_speed(np.array(0.8), np.array(10.0), 0.0) == pytest.approx(4.0)
    assert braking_speed(np.array(-0.1), np.array(10.0), 0.03) == 0.0
    # Exact along the line: from c = F(g), one period of T later at c - A T the gap
    # g - c T has F = c - A T.
    a, t, g = 10.0, 0.03, 0.8
    c = float(braking_speed(np.array(g), np.array(a), t))
    assert braking_speed(np.array(g - c * t), np.array(a), t) == pytest.approx(
        c - a * t
    )


def test_the_sensing_margin_formula() -> None:
    # 3 sigma_p + 3 l sigma_theta + s_max tau = 3 * 0.02 + 3 * 0.1 * 0.05 + 2.04 * 0.1
    assert sensing_margin(0.02, 0.05, 0.1, 2.04, 0.1) == pytest.approx(
        0.06 + 0.015 + 0.204
    )
    ctx = _ctx([[0.0, 0.0]], [0.0], [0.0], [0.0], [0.0], [0.0])
    ctx.sensing = {"position_noise": 0.02, "heading_noise": 0.05, "delay": 0.1}
    state = CBFState(ctx)
    top = np.hypot(2.0, 0.1 * 4.0)  # the look-ahead point's top speed
    assert state.sensed == pytest.approx(0.06 + 0.015 + top * 0.1)
    # the barrier's D grows by it: two vehicles at rest 1 m apart (look-ahead points
    # 0.8 m apart), D = 0.75 m + the margin: 0.8 - 0.75 - 0.2728 < 0, unsafe.
    ctx = _ctx([[0.0, 0.0], [1.0, 0.0]], [0.0, np.pi], *([[0.0, 0.0]] * 4))
    ctx.sensing = {"position_noise": 0.02, "heading_noise": 0.05, "delay": 0.1}
    _, _, _, h = braking_rows(CBFState(ctx), ctx, np.ones(2, bool))
    assert np.all(h < 0)
    ctx.sensing = None
    _, _, _, h = braking_rows(CBFState(ctx), ctx, np.ones(2, bool))
    assert np.all(h > 0)


# ------------------------------------------------------------------ the property
def _random_states(rng, kind: str, count: int):
    """Random states of two vehicles (or one and an obstacle) under the limits."""
    for _ in range(count):
        theta = rng.uniform(-np.pi, np.pi, 2)
        v1p = rng.uniform(-2.0, 2.0, 2)
        v2p = rng.uniform(-4.0, 4.0, 2)
        v1 = rng.uniform(-2.0, 2.0, 2)
        v2 = rng.uniform(-4.0, 4.0, 2)
        gap = rng.uniform(0.0, 2.5)
        angle = rng.uniform(-np.pi, np.pi)
        pos = np.array([[0.0, 0.0], [np.cos(angle), np.sin(angle)]]) * (0.95 + gap)
        if kind == "pair":
            yield _ctx(pos, theta, v1, v2, v1p, v2p)
        elif kind == "failed":
            ctx = _ctx(pos, theta, v1, v2, v1p, v2p, failed=[False, True])
            ctx.vel = np.array([[0.0, 0.0], rng.uniform(-2.0, 2.0, 2)])
            yield ctx
        else:
            spec = ObstacleSpec("circle", "o", center=tuple(pos[1]), radius=0.3)
            yield _ctx(
                pos[:1], theta[:1], v1[:1], v2[:1], v1p[:1], v2p[:1], obstacles=[spec]
            )


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["pair", "failed", "obstacle"])
def test_every_safe_state_is_feasible_without_slack(kind) -> None:
    rng = np.random.default_rng({"pair": 1, "failed": 2, "obstacle": 3}[kind])
    safe = binding = 0
    for ctx in _random_states(rng, kind, 3000):
        state = CBFState(ctx)
        n = len(ctx.pos)
        filtered = np.ones(n, bool) if ctx.known_failed is None else ~ctx.known_failed
        _, _, _, h = braking_rows(state, ctx, filtered)
        if len(h) == 0 or h.min() < 0:
            continue
        safe += 1
        v1, v2, step = filter_commands(state, ctx)
        assert np.all(step.slack == 0), (kind, h, step.slack)
        assert not step.fallback.any()
        binding += int(step.active.any())
        # within the bounds: |v1 - v1^| <= a dt, |v1| <= v1_max, |v2| <= v2_max
        mine = filtered
        assert np.all(np.abs(v1 - ctx.v1_prev)[mine] <= 5.0 * 0.01 + 1e-12)
        assert np.all(np.abs(v2[mine]) <= 4.0 + 1e-9)
    assert safe > 500 and binding > 100, (safe, binding)


def test_the_fallback_brakes_when_no_command_keeps_the_conditions() -> None:
    # At 2 m/s straight at a wall whose barrier starts 0.05 m ahead: the closing
    # cannot slow enough in one period; the vehicle brakes at max_accel instead,
    # keeping its direction (v1 2 -> 1.95 m/s, v2 scaled alike: 0.4 * 0.975).
    wall = ObstacleSpec("wall", "w", start=(0.0, -2.0), end=(0.0, 2.0), thickness=0.1)
    x = -0.05 - 0.4 - 0.1 + 0.05
    ctx = _ctx([[x, 0.0]], [0.0], [2.0], [1.0], [2.0], [0.4], obstacles=[wall])
    v1, v2 = cbf(ctx)
    step = ctx.memory["last"]
    assert step.fallback.tolist() == [True]
    assert v1[0] == pytest.approx(1.95)
    assert v2[0] == pytest.approx(0.4 * 0.975)
    assert ctx.stats["fallback_steps"] == 1
    assert ctx.stats["infeasible_steps"] == 1
    assert ctx.stats["unsafe_start"]["unsafe"] is True
    assert ctx.stats["min_barrier"] < 0


# ------------------------------------------------------------------ scenarios
def run(doc_or_path, *sets: str):
    sc = load_scenario(doc_or_path, overrides=list(sets))
    r = Simulation(sc).run()
    return r, compute_metrics(r)


def ring_doc(n: int, jitter: float, seed: int, radius: float = 4.0) -> dict:
    rng = np.random.default_rng(seed)
    angle = 2 * np.pi * np.arange(n) / n + rng.uniform(-jitter, jitter, n)
    vehicles = []
    for k, a in enumerate(angle):
        x, y = radius * np.cos(a), radius * np.sin(a)
        vehicles.append(
            {"name": f"v{k}", "pose": [x, y, a + np.pi], "offset": [-x, -y]}
        )
    return {
        "duration": 12,
        "dt": 0.01,
        "substeps": 4,
        "vehicle": ROBOT,
        "reference": {"type": "point", "position": [0, 0]},
        "formation": {"law": "virtual"},
        "recovery": {"strategy": "none"},
        "vehicles": vehicles,
    }


@pytest.mark.slow
def test_the_head_on_swap_under_max_accel_keeps_every_condition() -> None:
    _, m = run(HEAD_ON, "safety.filter=cbf", "safety.barrier=braking", "duration=8")
    s = m["safety"]
    assert m["collisions"]["total"] == 0
    assert s["infeasible_steps"] == 0 and s["fallback_steps"] == 0
    assert s["max_slack"] == 0.0
    assert s["unsafe_start"]["unsafe"] is False
    # As measured: the velocity barrier does not relax on this case either.
    _, m = run(HEAD_ON, "safety.filter=cbf", "duration=8")
    assert m["collisions"]["total"] == 0 and m["safety"]["infeasible_steps"] == 0


@pytest.mark.slow
def test_a_seven_vehicle_ring_swap_relaxes_only_the_velocity_barrier() -> None:
    # Seed 1 of ten jittered rings (0.05 rad). As measured over seeds 0-9: the
    # velocity barrier relaxes in 9 of 10 (216 vehicle-steps), the braking barrier
    # brakes in 8 of 10 (25 vehicle-steps, 1-5 each; 0 on seeds 1 and 2); no contact
    # under either, all ten converge under braking, 8 under velocity.
    doc = ring_doc(7, jitter=0.05, seed=1)
    _, m = run({**doc, "safety": {"filter": "cbf"}})
    assert m["collisions"]["total"] == 0
    assert m["safety"]["infeasible_steps"] > 0  # as measured: 5
    _, m = run({**doc, "safety": BRAKING})
    s = m["safety"]
    assert m["collisions"]["total"] == 0
    assert s["infeasible_steps"] == 0 and s["fallback_steps"] == 0
    assert s["min_barrier"] > 0
    assert m["converged"]


@pytest.mark.slow
def test_the_braking_barrier_covers_a_noisy_delayed_broadcast() -> None:
    sets = ["duration=8", "safety.filter=cbf", "safety.barrier=braking"]
    noisy = [*sets, "sensing.position_noise=0.01", "sensing.delay=0.02"]
    r, m = run(HEAD_ON, *noisy)
    assert m["collisions"]["total"] == 0
    # the centres keep d + margin apart, margin 0.05 m grown by the sensing margin
    # 3 * 0.01 + 2.04 * 0.02 = 0.071 m (up to the drive's lag)
    assert m["min_distance"] >= D + 0.05 + 0.071 - 0.01


@pytest.mark.slow
def test_the_braking_barrier_with_the_residual_detector() -> None:
    # b stops at t = 1 s on a's way; the platoon learns it from the residual
    # detector, not the oracle; a keeps clear of it all the same.
    doc = {
        "duration": 8.0,
        "vehicle": ROBOT,
        "reference": {"type": "point", "position": [0, 0]},
        "formation": {"law": "virtual"},
        "vehicles": [
            {"name": "a", "pose": [-3, 0, 0], "offset": [3, 0]},
            {"name": "b", "pose": [1.0, 0.5, 0], "offset": [1.0, 0.0]},
        ],
        "failures": [{"vehicle": "b", "at": 0.0, "kind": "stop"}],
        "sensing": {"position_noise": 0.01},
        "detection": {"method": "residual"},
        "safety": BRAKING,
    }
    _, m = run(doc)
    assert m["collisions"]["total"] == 0
    assert m["safety"]["infeasible_steps"] == 0


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    ("sets", "message"),
    [
        (
            ["vehicle.max_accel=null"],
            "safety.barrier: braking needs every vehicle's max_accel",
        ),
        (
            ["vehicle.v1_max=null", "safety.range=4"],
            "safety.barrier: braking needs every vehicle's v1_max",
        ),
        (["safety.neighbour_velocity=zero"], "safety.neighbour_velocity: barrier"),
        (["safety.projection=speed"], "safety.projection: barrier: braking needs"),
        (["safety.barrier=brake"], "expected one of: velocity, braking"),
    ],
)
def test_bad_braking_input_is_one_line(sets, message, capsys) -> None:
    argv = ["validate", str(HEAD_ON), "--set", "safety.filter=cbf"]
    argv += ["--set", "safety.barrier=braking"] if "barrier" not in sets[0] else []
    for s in sets:
        argv += ["--set", s]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert message in err[0] and "Traceback" not in err[0]


@pytest.mark.parametrize(
    ("sets", "key"),
    [
        (["safety.margin=3.5"], "safety.margin: the start is unsafe"),
        (["sensing.loss=0.1"], "sensing.loss: 0.1: the braking barrier's margin"),
        (["sensing.position_noise=0.2"], "sensing.position_noise: the braking"),
    ],
)
def test_braking_warnings_name_the_key(sets, key) -> None:
    overrides = ["safety.filter=cbf", "safety.barrier=braking", *sets]
    with pytest.warns(UserWarning, match=key):
        load_scenario(HEAD_ON, overrides=overrides)


def test_an_unsafe_start_is_reported_at_t0() -> None:
    # Two vehicles at rest, look-ahead points 0.7 m apart, below D = 0.75 m.
    doc = {
        "duration": 0.05,
        "vehicle": ROBOT,
        "reference": {"type": "point", "position": [0, 0]},
        "formation": {"law": "virtual"},
        "vehicles": [
            {"name": "a", "pose": [0.0, 0.0, 0.0], "offset": [-2, 0]},
            {"name": "b", "pose": [0.9, 0.0, np.pi], "offset": [2, 0]},
        ],
        "safety": BRAKING,
    }
    with pytest.warns(UserWarning, match="safety.margin: the start is unsafe"):
        sc = load_scenario(doc)
    m = compute_metrics(Simulation(sc).run())
    start = m["safety"]["unsafe_start"]
    assert start["t"] == 0.0 and start["unsafe"] is True
    assert start["min_barrier"] == pytest.approx(0.7 - 0.75)


def test_the_default_barrier_is_velocity_and_keeps_the_bytes() -> None:
    assert PARAMS["barrier"].default == "velocity"
    sets = ["duration=1", "recovery.strategy=none", "safety.filter=cbf"]
    a, _ = run(HEAD_ON, *sets)
    b, _ = run(HEAD_ON, *sets, "safety.barrier=velocity")
    for key in ("pose", "cmd", "chi"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
