"""The braking barrier toward a vehicle that does not brake (a runaway).

Equations: the driven path of a vehicle that keeps its commands and the lower bounds
of the distance to it for ever (:func:`~sandbox.model.barriers.path_floor`, from a
fixed point; :func:`~sandbox.behaviour.safety.running.ray_floor`, from a ray), against
brute force; the run's barrier ``H^r`` of a vehicle with a runaway behind it, by hand,
and the choice of the run over braking. Scenario level: seed 0 of the randomised
runaway under sensing and the residual detector, which touched when the barrier
toward the runaway ended with the braking vehicle's stop.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sandbox import load_scenario
from sandbox.behaviour.safety.braking import braking_rows
from sandbox.behaviour.safety.cbf import PARAMS, CBFState, filter_commands
from sandbox.behaviour.safety.running import ray_floor, run_speeds
from sandbox.loop.simulation import Simulation
from sandbox.model.barriers import driven_path, path_floor
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.contexts import FilterContext
from sandbox.run.metrics import compute_metrics

ROOT = Path(__file__).resolve().parents[1]
RUNAWAY = ROOT / "scenarios" / "failures" / "uncontrolled_into_leader.yaml"
#: The randomised runaway of docs/results/safety-benchmark.md.
DRAWN = (
    'randomize={"failures[0].v2": {uniform: [0.3, 0.7]}, '
    '"failures[0].at": {uniform: [2, 4]}}'
)


def _segments_distance(q: np.ndarray, pts: np.ndarray) -> float:
    """Brute force: the least distance from ``q`` to the polyline ``pts``."""
    a, b = pts[:-1], pts[1:]
    d = b - a
    t = np.clip(np.einsum("kd,kd->k", q - a, d) / np.einsum("kd,kd->k", d, d), 0, 1)
    near = a + t[:, None] * d
    return float(np.min(np.hypot(*(q - near).T)))


def test_the_driven_path_is_the_period_of_the_estimate() -> None:
    # v1 = 2 m/s, v2 = 0.5 rad/s, dt = 0.01 s: each period runs 0.02 m along the
    # heading of its middle, x3 + 0.0025 rad, then turns by 0.005 rad.
    c = driven_path(np.zeros((1, 2)), np.zeros(1), np.array([2.0]), np.array([0.5]),
                    0.01, 3)  # fmt: skip
    x, y, th = 0.0, 0.0, 0.0
    for m in range(3):
        np.testing.assert_allclose(c[0, m], [x, y], atol=1e-15)
        x += 0.02 * np.cos(th + 0.0025)
        y += 0.02 * np.sin(th + 0.0025)
        th += 0.005


def test_the_path_floor_is_below_the_path_and_within_its_sagitta() -> None:
    # Random circles (and rays): the floor from a point is never above the distance
    # to the polygon over many laps, and short of it by at most the sagitta
    # |v1 v2| dt^2 / 8 (rays: exact).
    rng = np.random.default_rng(0)
    dt = 0.01
    for _ in range(200):
        speed = rng.uniform(-2.0, 2.0)
        turn = rng.choice([0.0, rng.choice([-1, 1]) * rng.uniform(0.3, 3.0)])
        start, course = rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi)
        q = rng.uniform(-4, 4, 2)
        # two laps, or 20 m of the ray
        count = int(4 * np.pi / abs(turn * dt)) if turn else int(20 / abs(speed * dt))
        pts = driven_path(start[None], np.array([course]), np.array([speed]),
                          np.array([turn]), dt, count)[0]  # fmt: skip
        brute = _segments_distance(q, pts)
        floor, _ = path_floor(q[None], start[None], np.array([course]),
                              np.array([speed]), np.array([turn]), dt)  # fmt: skip
        sag = abs(speed * turn) * dt * dt / 8
        assert floor[0] <= brute + 1e-12
        assert floor[0] >= brute - sag - 1e-9


def test_the_ray_floor_is_below_the_closest_approach() -> None:
    # A point at constant velocity against a driven path, sampled for 40 s: the
    # floor is never above the least distance (timing ignored on a circle, exact on
    # a straight path).
    rng = np.random.default_rng(1)
    dt = 0.01
    for _ in range(200):
        speed, turn = rng.uniform(0.5, 2.0), rng.choice([0.0, rng.uniform(-1, 1)])
        q, vel = rng.uniform(-3, 3, 2), rng.uniform(-2, 2, 2)
        path = driven_path(np.zeros((1, 2)), np.zeros(1), np.array([speed]),
                           np.array([turn]), dt, 4000)[0]  # fmt: skip
        mine = q + np.arange(4000)[:, None] * dt * vel
        brute = float(np.min(np.hypot(*(mine - path).T)))
        floor, _ = ray_floor(q[None], vel[None], np.zeros((1, 2)), np.zeros(1),
                             np.array([speed]), np.array([turn]), dt)  # fmt: skip
        assert floor[0] <= brute + 1e-9
        if turn == 0.0:
            assert floor[0] == pytest.approx(brute, abs=2.0 * dt * 4)


def _ctx(v_lead: float, gap: float) -> FilterContext:
    """A vehicle at the origin heading +x at ``v_lead``, a runaway ``gap`` behind."""
    values = {k: p.default for k, p in PARAMS.items()}
    values["barrier"] = "braking"
    return FilterContext(
        t=0.0,
        dt=0.01,
        pos=np.array([[0.0, 0.0], [-gap, 0.0]]),
        theta=np.zeros(2),
        vel=np.array([[v_lead, 0.0], [2.0, 0.0]]),
        v1=np.array([v_lead, 2.0]),
        v2=np.zeros(2),
        diameter=np.full(2, 0.5),
        params=values,
        v1_prev=np.array([v_lead, 2.0]),
        v2_prev=np.zeros(2),
        v1_max=2.0,
        v2_max=4.0,
        accel_max=5.0,
        known_failed=np.array([False, True]),
        commanded=np.zeros(2, bool),
        obstacle_field=ObstacleField(()),
        substeps=4,
    )


def test_the_run_barrier_by_hand_and_the_better_backup() -> None:
    # The leader at 1 m/s, a runaway 1.5 m behind on the same line at 2 m/s (its
    # commands kept for ever), D' = 0.5 + 0.1 + 0.05 = 0.65 m. Braking, the leader's
    # rest point lies on the runaway's ray: H^b = 0 - 0.65 = -0.65 m. Running, the
    # speeds are 1.05, 1.10, ..., 2.00 (period 19), the drive's lag of a quarter
    # period makes it run u_0 = 0.75 1.05 + 0.25 1 = 1.0375, then u_m = s_m - 0.0125
    # to u_19 = 1.9875, then 2. The runaway gains sum (2 - u_m) dt =
    # (0.9625 + 19 0.9625 - 0.05 190) 0.01 = 0.0975 m of the 1.6 m between the
    # leader's look-ahead point and its centre, then keeps the gap:
    # H^r = 1.6 - 0.0975 - 0.65 = 0.8525 m.
    np.testing.assert_allclose(
        run_speeds(np.array([1.05]), np.array([0.05]), np.array([2.0]), 21)[0, [0, 18,
                   19, 20]], [1.05, 1.95, 2.0, 2.0])  # fmt: skip
    ctx = _ctx(1.0, 1.5)
    state, pending = CBFState(ctx), {}
    veh, _, _, h = braking_rows(state, ctx, np.array([True, False]), pending)
    assert pending["run"].tolist() == [True, False]
    assert h[veh == 0].min() == pytest.approx(0.8525, abs=1e-9)
    # braking forbidden the run: the rest point on the ray
    _, _, _, h = braking_rows(
        state, ctx, np.array([True, False]), {}, braked=np.array([True, False])
    )
    assert h.min() == pytest.approx(-0.65, abs=1e-12)
    # 0.66 m behind: H^r = 0.76 - 0.0975 - 0.65 = 0.0125 m, and a braking period
    # would lose more than that: the filter holds a nominal command that would slow
    # the leader down to more than the braking command, 0.95 m/s (no slack).
    ctx = _ctx(1.0, 0.66)
    ctx.v1 = np.array([0.5, 2.0])
    pending = {}
    _, _, _, h = braking_rows(CBFState(ctx), ctx, np.array([True, False]), pending)
    assert pending["run"].tolist() == [True, False]
    assert h.min() == pytest.approx(0.0125, abs=1e-9)
    v1, _, step = filter_commands(CBFState(ctx), ctx)
    assert v1[0] > 0.95 + 0.03 and step.slack.max() == 0.0


@pytest.mark.slow
def test_a_runaway_that_hit_a_braked_leader_no_longer_touches() -> None:
    # Seed 0 of the randomised runaway, sensing (2 cm, 50 ms) and the residual
    # detector: the leader, braked to a stop by the filter on the runaway's arc,
    # was run into at 4.76 s while the barrier toward the runaway ended with its
    # stop. Now it keeps clear.
    sets = [
        DRAWN,
        "seed=0",
        "safety.filter=cbf",
        "recovery.tangential=1",
        "safety.barrier=braking",
        "sensing.position_noise=0.02",
        "sensing.delay=0.05",
        "detection.method=residual",
    ]
    run = Simulation(load_scenario(RUNAWAY, overrides=sets)).run()
    m = compute_metrics(run)
    assert m["detection"]["failures"][0]["detected_at"] is not None
    assert m["collisions"]["total"] == 0
    assert m["safety"]["infeasible_steps"] == 0
