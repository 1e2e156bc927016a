"""Deadlocks in ``metrics.json``: healthy vehicles trapped short of their slots.

The definition on hand-made arrays (grouping, the shortest stall, failed vehicles and
vehicles on their slots left out, the headway rule: a vehicle creeping to the end is
trapped, one held up for a while is not unless ``deadlock_creeping: any``), the
``metrics:`` keys that set it, and the exact
symmetric head-on swap: a deadlock with the report's radial field (kappa 0), none with
the tangential term.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import SCENARIOS, run_scenario

from sandbox import load_scenario
from sandbox.errors import SandboxWarning, ScenarioError
from sandbox.run.deadlock import find_deadlocks, stuck_samples

SWAP = SCENARIOS / "safety" / "head_on_swap.yaml"
T = np.round(np.arange(0.0, 10.001, 0.1), 6)


def track(stop_from: float, stop_to: float, speed: float = 1.0) -> np.ndarray:
    """Positions (T, 2) of a vehicle moving along x at ``speed`` except in a window."""
    v = np.where((T >= stop_from) & (T < stop_to), 0.0, speed)
    x = np.concatenate(([0.0], np.cumsum(v[:-1] * 0.1)))
    return np.stack([x, 0 * x], -1)


def deadlocks(pos, slot=None, failed=None, **keys):
    pos = np.stack(pos, 1)
    if slot is None:
        slot = np.full_like(pos, 100.0)
    if failed is None:
        failed = np.zeros(pos.shape[:2], dtype=bool)
    names = [f"v{i}" for i in range(pos.shape[1])]
    return find_deadlocks(T, pos, slot, failed, names, **keys)


def test_overlapping_stalls_are_one_deadlock_and_separate_ones_two() -> None:
    got = deadlocks([track(1, 4), track(2, 5), track(7, 9.5)])
    assert got == [
        {"vehicles": ["v0", "v1"], "t": 1.0, "duration": pytest.approx(3.9)},
        {"vehicles": ["v2"], "t": 7.0, "duration": pytest.approx(2.4)},
    ]


def circle(radius: float, speed: float) -> np.ndarray:
    """Positions (T, 2) on a circle of ``radius`` about (5, 0) at ``speed``."""
    a = speed * T / radius
    return np.stack([5 + radius * np.cos(a), radius * np.sin(a)], -1)


def test_a_vehicle_creeping_round_a_trap_is_trapped_by_the_headway_rule() -> None:
    # the stop rule misses it (v0.2: 6 of 25 obstacle fields): moving above the stop
    # speed, never nearer to the slot; here circling at 0.3 m/s, 0.1 m round a point
    # 5 m off its slot
    slot = np.zeros((len(T), 1, 2))
    creeping = circle(0.1, 0.3)
    assert deadlocks([creeping], slot=slot, progress=0.0) == []  # the stop rule only
    (got,) = deadlocks([creeping], slot=slot)  # the default: 0.5, to the end
    assert got == {"vehicles": ["v0"], "t": 0.0, "duration": pytest.approx(10.0)}


def behind(catch_up: float | None) -> tuple[np.ndarray, np.ndarray]:
    """A slot moving along x at 1 m/s from 1 m ahead, and a vehicle held up.

    The vehicle starts 1 m behind, drives at 2 m/s until it is on its slot, stands
    from 2 s to 4 s (falling 2 m behind) and then drives at 1 m/s (keeping the gap:
    left behind) or, from ``catch_up`` [s] on, at 2 m/s until it is on its slot.
    """
    slot = np.stack([1.0 + T, 0 * T], -1)
    v = np.where((T >= 2) & (T < 4), 0.0, np.where(T < 2, 2.0, 1.0))
    if catch_up is not None:
        v = np.where(T >= catch_up, 2.0, v)
    x = np.zeros(len(T))
    for k in range(1, len(T)):  # on its slot, it keeps to it
        x[k] = min(x[k - 1] + v[k - 1] * 0.1, 1.0 + T[k]) if v[k - 1] else x[k - 1]
    return np.stack([x, 0 * x], -1), slot[:, None, :]


def test_a_vehicle_held_up_for_a_while_is_trapped_only_under_any() -> None:
    # Held up from 2 s to 4 s, back on its slot by 6 s: a stretch without headway
    # (2 m behind and not nearer) that ends before the run does, and no stop of 2 s
    # (1.9 s at rest by the positions).
    pos, slot = behind(catch_up=4.0)
    assert deadlocks([pos], slot=slot) == []  # to_end, the default
    (got,) = deadlocks([pos], slot=slot, creeping="any")
    assert (got["t"], got["duration"]) == (2.6, pytest.approx(2.5))
    assert got["vehicles"] == ["v0"] and got["t"] + got["duration"] < 10.0
    # Left behind, 2 m from its slot at its slot's speed to the end: trapped
    (got,) = deadlocks([behind(catch_up=None)[0]], slot=slot)
    assert got["vehicles"] == ["v0"]
    assert got["t"] + got["duration"] == pytest.approx(10.0)
    with pytest.raises(ValueError, match="creeping"):
        deadlocks([pos], slot=slot, creeping="sometimes")


def test_the_headway_rule_spares_a_vehicle_driving_to_its_slot() -> None:
    slot = np.full((len(T), 1, 2), [30.0, 0.0])
    assert deadlocks([track(20, 20, speed=0.5)], slot=slot, progress=0.5) == []
    # 0.1 m/s toward it: 0.2 m in 2 s, less than half of deadlock_distance
    (got,) = deadlocks([track(20, 20, speed=0.1)], slot=slot, progress=0.5)
    assert got["vehicles"] == ["v0"]
    assert deadlocks([track(20, 20, speed=0.1)], slot=slot, progress=0.3) == []


def test_the_headway_rule_dates_a_stop_from_its_first_window_without_headway() -> None:
    # at 1 m/s, 0.7 of it toward the slot, the 2 s before 2.7 s hold 0.21 m < 0.25 m
    tracks = [track(1, 4), track(2, 5), track(7, 9.5)]
    got = deadlocks(tracks, progress=0.5, creeping="any")
    assert [(d["vehicles"], d["t"]) for d in got] == [
        (["v0", "v1"], 0.7),
        (["v2"], 6.7),
    ]


def test_a_short_stop_a_failed_vehicle_and_a_settled_one_are_no_deadlock() -> None:
    assert deadlocks([track(1, 2.5)]) == []  # 1.4 s < 2 s
    assert deadlocks([track(1, 2.5)], duration=1.0) != []
    failed = np.zeros((len(T), 1), dtype=bool)
    failed[:, 0] = True
    assert deadlocks([track(1, 6)], failed=failed) == []
    on_slot = track(1, 6)
    slot = np.repeat(on_slot[:, None, :], 1, 1) + [0.3, 0.0]  # 0.3 m: settling
    assert deadlocks([on_slot], slot=slot) == []
    assert deadlocks([on_slot], slot=slot, distance=0.2) != []


def test_speed_reads_the_positions_and_a_slow_crawl_is_not_stopped() -> None:
    crawl = track(20, 20, speed=0.02)  # 2 cm/s all the time
    pos = np.stack([crawl], 1)
    slot = np.full_like(pos, 100.0)
    stuck = stuck_samples(T, pos, slot, np.zeros((len(T), 1), dtype=bool))
    assert not stuck.any()
    assert stuck_samples(T, pos, slot, np.zeros((len(T), 1), bool), speed=0.03).all()


@pytest.mark.slow
def test_head_on_stall_is_a_deadlock_and_the_tangential_term_has_none() -> None:
    _, stalled = run_scenario(SWAP, "recovery.tangential=0", duration=6)
    (dead,) = stalled["deadlocks"]
    assert dead["vehicles"] == ["west", "east"]
    # measured: both stop nose to nose at 1.23 s and stay so to the end; the
    # headway rule (the default) dates it from 0.96 s, while they brake
    assert 0.9 < dead["t"] < 1.0
    assert dead["t"] + dead["duration"] == pytest.approx(6.0)
    for kappa in ("0.5", "1", "2"):
        _, passed = run_scenario(SWAP, f"recovery.tangential={kappa}", duration=6)
        assert passed["deadlocks"] == [] and passed["converged"]


def test_deadlock_keys_are_metrics_parameters() -> None:
    with pytest.warns(SandboxWarning, match="no deadlock can be found"):
        _, m = run_scenario(
            SWAP, "recovery.tangential=0", "metrics.deadlock_time=10", duration=6
        )
    assert m["deadlocks"] == []
    _, m = run_scenario(
        SWAP, "recovery.tangential=0", "metrics.deadlock_distance=3", duration=6
    )
    assert m["deadlocks"] == []  # 2.25 m from the slots is "near" with 3 m
    sc = load_scenario(SWAP, overrides=["metrics.deadlock_speed=0.05"])
    assert sc.metrics.deadlock_speed == 0.05
    with pytest.raises(ScenarioError, match="metrics.deadlock_speed"):
        load_scenario(SWAP, overrides=["metrics.deadlock_speed=0"])
    sc = load_scenario(SWAP)
    spec = sc.metrics
    assert (spec.deadlock_progress, spec.deadlock_creeping) == (0.5, "to_end")
    with pytest.raises(ScenarioError, match="metrics.deadlock_creeping") as bad:
        load_scenario(SWAP, overrides=["metrics.deadlock_creeping=sometimes"])
    assert len(str(bad.value).strip().splitlines()) == 1


def test_expect_deadlocks_checks_the_count_and_names_the_vehicles() -> None:
    from sandbox.testing import check_scenario

    assert check_scenario(SWAP, ["duration=6"]).holds
    stalled = check_scenario(SWAP, ["duration=6", "recovery.tangential=0"])
    (dead,) = [o for o in stalled.failed if o.key == "deadlocks"]
    assert dead.expected == "0"
    assert dead.got.startswith("1 (west-east at 0.96")
    sc = load_scenario(SWAP, overrides=["expect.deadlocks={at_most: 2}"])
    assert sc.expect.to_dict()["deadlocks"] == {"at_most": 2}
    with pytest.raises(ScenarioError, match="expect.deadlocks"):
        load_scenario(SWAP, overrides=["expect.deadlocks=-1"])


@pytest.mark.parametrize("shape", [(1, 2), (7, 3, 2), (801, 4, 2), (40, 33, 3)])
def test_norms_are_numpys_norm_to_the_bit(shape):
    # The deadlocks and metrics read distances through norms(); a rounding of their
    # own would move a settling time or a stall by a sample.
    from sandbox.geometry.planar import norms

    rng = np.random.default_rng(7)
    v = rng.normal(size=shape) * 10.0 ** rng.integers(-8, 8, size=shape)
    v[rng.random(shape) < 0.05] = np.nan
    v[rng.random(shape) < 0.05] = np.inf
    planar = v[..., :2]  # strided when the last axis is longer
    want = np.linalg.norm(planar, axis=-1)
    assert norms(planar).tobytes() == want.tobytes()
    assert not np.shares_memory(norms(planar), planar)
