"""The CBF filter's velocity barrier and its counters in C agree with numpy.

The extension ``sandbox.behaviour.safety._filter`` is optional: where it is built, its
checks must pass on this machine, one changed bit must fail them, random steps and
whole runs (one world and batched, with sensing, failed vehicles, obstacles, every
option of the filter) must give numpy's bytes; where it is not built, those tests are
skipped and the numpy path runs.
"""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from sandbox.behaviour.safety import accounting, filter_kernel
from sandbox.behaviour.safety.cbf import CBFState, filter_commands
from sandbox.loop.simulation import Simulation
from sandbox.run.metrics import compute_metrics
from sandbox.scenario import load_scenario

needs_filter = pytest.mark.skipif(
    filter_kernel._filter is None, reason="safety._filter not built"
)


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float).view(np.uint64)


def _next(x: float) -> float:
    """The float one bit away from ``x``."""
    y = np.nextafter(x, np.inf)
    return y if y != x else np.nextafter(x, -np.inf)


class Counting:
    """The extension with its calls counted: how many, and what they held."""

    def __init__(self, real) -> None:
        self.real = real
        self.seen = dict.fromkeys(
            ("calls", "failed", "sensing", "obstacles", "handed_back", "active"), 0
        )
        self.world_counts = real.world_counts

    def velocity_step(self, *args):
        out = self.real.velocity_step(*args)
        seen = self.seen
        seen["calls"] += 1
        seen["failed"] += args[8] is not None and bool(np.any(args[8]))
        seen["sensing"] += args[10] is not None
        seen["obstacles"] += args[16] is not None
        seen["handed_back"] += out[2] > 0
        seen["active"] += bool(np.any(args[24]))
        return out


# ------------------------------------------------------------------ the checks
@needs_filter
def test_the_filter_check_passes_on_this_machine():
    assert filter_kernel.kernel_agrees()
    assert filter_kernel.usable()


@needs_filter
@pytest.mark.parametrize("what", ["v1", "v2", "slack", "by_vehicle", "least", "rows"])
def test_the_filter_check_fails_on_one_changed_bit(monkeypatch, what):
    real = filter_kernel._filter

    def off_by_one(*args):
        rows, least, pending = real.velocity_step(*args)
        v1, v2, slack, by = args[22], args[23], args[25], args[26]
        if what == "least":
            least = _next(least)
        elif what == "rows":
            rows += 1
        else:
            out = {"v1": v1, "v2": v2, "slack": slack, "by_vehicle": by}[what]
            if out is not None:
                out[0] = _next(out[0])
        return rows, least, pending

    fake = SimpleNamespace(velocity_step=off_by_one, world_counts=real.world_counts)
    monkeypatch.setattr(filter_kernel, "_filter", fake)
    monkeypatch.setattr(filter_kernel, "_agreed", None)
    assert not filter_kernel.kernel_agrees()
    assert not filter_kernel.usable()


@needs_filter
def test_the_filter_check_fails_where_numpy_sums_otherwise(monkeypatch):
    def without_the_zero(spec, a, b):  # -0.0 + -0.0 stays -0.0
        assert spec == "kd,kd->k"
        return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]

    assert filter_kernel._numpy_as_assumed()
    monkeypatch.setattr(np, "einsum", without_the_zero)
    assert not filter_kernel._numpy_as_assumed()


@needs_filter
def test_without_the_extension_the_numpy_path_runs(monkeypatch):
    ctx = filter_kernel.random_steps(np.random.default_rng(3), 1)[0]
    with_c = filter_commands(CBFState(ctx), ctx)
    monkeypatch.setattr(filter_kernel, "_filter", None)
    monkeypatch.setattr(filter_kernel, "_agreed", None)
    assert not filter_kernel.usable()
    assert filter_kernel.same_step(filter_commands(CBFState(ctx), ctx), with_c)


def test_the_c_path_covers_the_velocity_barrier_without_a_priority():
    ctx = filter_kernel.random_steps(np.random.default_rng(4), 1)[0]
    assert filter_kernel.covers(CBFState(ctx))
    for key, value in (("barrier", "braking"), ("priority", "index")):
        other = replace(ctx, params={**ctx.params, key: value})
        assert not filter_kernel.covers(CBFState(other))


@needs_filter
@pytest.mark.parametrize("what", ["worst", "lowered"])
def test_the_counts_check_passes_and_fails_on_one_changed_bit(monkeypatch, what):
    assert accounting.counts_agree()
    real = accounting._filter

    def off_by_one(*args):
        count = real.world_counts(*args)
        started, worst, least, changes = args[7], args[10], args[11], args[13]
        if what == "worst":
            worst[0] = _next(worst[0])
        elif started:  # a world whose least barrier fell, after the first step
            fell = (changes & accounting.LOWERED).nonzero()[0]
            if len(fell):
                least[fell[0]] = _next(least[fell[0]])
        return count

    fake = SimpleNamespace(world_counts=off_by_one)
    monkeypatch.setattr(accounting, "_filter", fake)
    monkeypatch.setattr(accounting, "_agreed", None)
    assert not accounting.counts_agree()


# ------------------------------------------------------------------ random steps
@needs_filter
def test_random_steps_in_c_equal_numpy(monkeypatch):
    steps = filter_kernel.random_steps(np.random.default_rng(11), 160)
    counting = Counting(filter_kernel._filter)
    monkeypatch.setattr(filter_kernel, "_filter", counting)
    with_c = [filter_kernel.velocity_step(CBFState(ctx), ctx) for ctx in steps]
    monkeypatch.setattr(filter_kernel, "USE_KERNEL", False)
    for ctx, got in zip(steps, with_c, strict=True):
        want = filter_commands(CBFState(ctx), ctx)
        assert filter_kernel.same_step(got, want)
    # what the steps held: every branch of the loop
    seen = counting.seen
    assert seen["calls"] == len(steps)
    assert min(seen.values()) > 0, seen
    rows = [step.rows for _, _, step in with_c]
    assert 0 in rows and max(rows) > 8  # none at all, and more than one cut


@needs_filter
def test_the_buffer_interface_reads_what_numpys_c_api_reads(monkeypatch):
    # each argument of the C loop once as an ndarray (numpy's C API), once as a
    # memoryview of a copy (the buffer interface): the same outputs, bit for bit
    calls = []
    real = filter_kernel._filter

    def keep(*args):
        calls.append(args)
        return real.velocity_step(*args)

    fake = SimpleNamespace(velocity_step=keep, world_counts=real.world_counts)
    monkeypatch.setattr(filter_kernel, "_filter", fake)
    for ctx in filter_kernel.random_steps(np.random.default_rng(12), 24):
        filter_kernel.velocity_step(CBFState(ctx), ctx)
    assert calls
    for args in calls:
        outs = []
        for wrap in (lambda a: a, memoryview):
            copies = [np.array(a) if isinstance(a, np.ndarray) else a for a in args]
            wrapped = [wrap(a) if isinstance(a, np.ndarray) else a for a in copies]
            rows, least, pending = real.velocity_step(*wrapped)
            written = [
                np.asarray(a).view(np.uint8) for a in copies[22:31] if a is not None
            ]
            outs.append((rows, _bits(np.array([least])).tolist(), pending, written))
        (rows, least, pending, written), (rows2, least2, pending2, written2) = outs
        assert (rows, least, pending) == (rows2, least2, pending2)
        assert all(np.array_equal(a, b) for a, b in zip(written, written2, strict=True))


# ------------------------------------------------------------------ whole runs
def _runs(name: str, sets: list[str], seeds: int) -> list[tuple]:
    """Poses, commands and metrics of one run (seeds 0) or a batch of ``seeds``."""
    if seeds:
        scenarios = [
            load_scenario(name, overrides=[*sets, f"seed={s}"]) for s in range(seeds)
        ]
        runs = Simulation.batch(scenarios)
    else:
        runs = [Simulation(load_scenario(name, overrides=sets)).run()]
    return [
        (
            _bits(r.pose).tobytes(),
            _bits(r.cmd).tobytes(),
            json.dumps(compute_metrics(r), sort_keys=True, default=str),
        )
        for r in runs
    ]


CBF = ["safety.filter=cbf"]
SENSING = ["sensing.position_noise=0.01", "sensing.heading_noise=0.005"]
RUNS = {
    # name: (scenario, --set values, seeds (0: one run), what the C calls held)
    "follower_stop_batch": (
        "failures/follower_stop",
        ["duration=4.5", *CBF],
        3,
        ("failed",),
    ),
    "follower_stop_sensing_batch": (
        "failures/follower_stop",
        ["duration=6", *CBF, *SENSING, "sensing.delay=0.02", "sensing.loss=0.1"],
        3,
        ("failed", "sensing"),
    ),
    "head_on_swap": ("safety/head_on_swap", ["duration=6", *CBF], 0, ("active",)),
    "door": ("safety/door", ["duration=8", *CBF], 0, ("active", "obstacles")),
    "circle_swap_8": ("safety/circle_swap_8", ["duration=8", *CBF], 0, ("active",)),
    "circle_swap_8_jittered_batch": (
        "safety/circle_swap_8_jittered",
        ["duration=6", *CBF, "safety.neighbour_velocity=zero"],
        3,
        ("active",),
    ),
    "circle_swap_3_speed": (
        "safety/circle_swap_3",
        ["duration=6", *CBF, "safety.projection=speed", "safety.reverse=false"],
        0,
        ("active",),
    ),
    "obstacles_sensing": (
        "safety/obstacle_field_random",
        ["duration=6", *CBF, *SENSING],
        0,
        ("obstacles", "sensing", "active"),
    ),
    "follower_crash_batch": (
        "failures/follower_crash",
        ["duration=6", *CBF, "safety.pass_right=0", *SENSING],
        2,
        ("failed", "sensing"),
    ),
}
QUICK = {"follower_stop_batch", "head_on_swap"}


@needs_filter
@pytest.mark.parametrize(
    "case",
    [
        pytest.param(k, marks=() if k in QUICK else pytest.mark.slow)
        for k in sorted(RUNS)
    ],
)
def test_runs_with_the_c_filter_equal_numpy(monkeypatch, case):
    name, sets, seeds, held = RUNS[case]
    counting = Counting(filter_kernel._filter)
    monkeypatch.setattr(filter_kernel, "_filter", counting)
    with_c = _runs(name, sets, seeds)
    for what in ("calls", *held):
        assert counting.seen[what] > 0, (what, counting.seen)
    monkeypatch.setattr(filter_kernel, "USE_KERNEL", False)
    monkeypatch.setattr(accounting, "USE_KERNEL", False)
    calls = counting.seen["calls"]
    numpy = _runs(name, sets, seeds)
    assert counting.seen["calls"] == calls  # the numpy path alone
    assert numpy == with_c


@needs_filter
@pytest.mark.slow
def test_problems_handed_back_to_numpy_in_runs(monkeypatch):
    # the swap of eight, packed: vehicles whose conditions have no common point
    counting = Counting(filter_kernel._filter)
    monkeypatch.setattr(filter_kernel, "_filter", counting)
    sets = ["duration=6", *CBF, "safety.gamma=8", "safety.margin=0.3"]
    with_c = _runs("safety/circle_swap_8_jittered", sets, 2)
    assert counting.seen["handed_back"] > 0, counting.seen
    monkeypatch.setattr(filter_kernel, "USE_KERNEL", False)
    assert _runs("safety/circle_swap_8_jittered", sets, 2) == with_c
