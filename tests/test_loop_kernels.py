"""The loop's own C pieces and numpy's C API under them give the bytes of numpy.

The record's samples copied in one C call (``sandbox.loop._period.record_sample``),
the C loops reading arrays through numpy's C API or, for any other object with the
buffer interface, through that interface, and the loop metrics' flush (its periods
accumulated at once) each give the bytes of the path they replace. Where an
extension is not built the assertions about it are skipped.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from sandbox.loop import _period, recording, tally
from sandbox.loop.simulation import Simulation
from sandbox.run.metrics import compute_metrics
from sandbox.scenario import load_scenario

needs_period = pytest.mark.skipif(_period is None, reason="_period not built")

NAMES = ("failures/follower_crash", "paper/fig16_leader_avoids_discontinuous_beta1")


def records(batch: int) -> list[bytes]:
    """Every recorded array and the metrics of two scenes, alone or batched."""
    out = []
    for name in NAMES:
        scenarios = [
            load_scenario(name, overrides=["duration=4", f"seed={s}"])
            for s in range(max(batch, 1))
        ]
        runs = (
            Simulation.batch(scenarios) if batch else [Simulation(scenarios[0]).run()]
        )
        for run in runs:
            for name in ("t", "pose", "cmd", "chi", "slot", "target", "mode", "failed"):
                out.append(np.ascontiguousarray(getattr(run, name)).tobytes())
            out.append(json.dumps(compute_metrics(run), sort_keys=True).encode())
    return out


@needs_period
@pytest.mark.parametrize("batch", [0, 3])
def test_samples_recorded_in_c_are_numpys(monkeypatch, batch):
    calls = []
    real = _period.record_sample

    def counted(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(_period, "record_sample", counted)
    with_c = records(batch)
    assert calls  # the C path ran
    monkeypatch.setattr(recording, "USE_KERNEL", False)
    assert records(batch) == with_c


@needs_period
def test_a_sample_the_c_copy_refuses_is_written_by_numpy():
    K, n = 2, 3
    rng = np.random.default_rng(0)
    made = [recording.LoopRecord(4, K, n) for _ in range(2)]
    N = K * n
    args = dict(
        pos=rng.normal(size=(N, 2)),
        theta=rng.normal(size=N),
        v1=rng.normal(size=N),
        v2=rng.normal(size=N),
        chi=rng.normal(size=(N, 2)),
        slot=rng.normal(size=(N, 4))[:, :2],  # not contiguous: refused by C
        target=rng.normal(size=(N, 2)),
        mode=rng.integers(0, 4, N).astype(np.int8),
        failed=rng.random(N) < 0.5,
        point=rng.normal(size=(K, 2)),
        worlds=[0, 1],
    )
    made[0].append(0.5, **args)
    recording.USE_KERNEL, saved = False, recording.USE_KERNEL
    try:
        made[1].append(0.5, **args)
    finally:
        recording.USE_KERNEL = saved
    for w in range(K):
        a, b = made[0].arrays(w), made[1].arrays(w)
        assert a.keys() == b.keys()
        assert all(a[k].tobytes() == b[k].tobytes() for k in a)
    assert made[0].arrays(1)["slot"][0].tolist() == args["slot"][n:].tolist()


@needs_period
def test_any_buffer_is_read_like_an_ndarray():
    # numpy's C API reads ndarrays; any other object with the buffer interface
    # (here memoryviews of the same arrays) takes the buffer interface: one answer
    rng = np.random.default_rng(1)
    pos, vel, chi = (rng.normal(size=(5, 2)) for _ in range(3))
    theta = rng.normal(size=5)
    for bound in (0.5, 10.0):
        arrays = _period.healthy(pos, theta, vel, chi, bound, 4.0)
        views = _period.healthy(*map(memoryview, (pos, theta, vel, chi)), bound, 4.0)
        assert arrays == views
    with pytest.raises((BufferError, TypeError, ValueError)):
        _period.healthy(pos.astype(np.float32), theta, vel, chi, 1.0, 1.0)
    with pytest.raises((BufferError, TypeError, ValueError)):
        _period.healthy(pos[:, ::-1], theta, vel, chi, 1.0, 1.0)  # not contiguous


def test_a_flush_of_many_periods_sums_as_period_after_period(monkeypatch):
    # The loop metrics flush CHUNK buffered periods at once; one period a flush is
    # the loop's own order of additions: the same efforts to the bit.
    def metrics() -> list[str]:
        scenarios = [
            load_scenario(
                "failures/follower_stop", overrides=["duration=5", f"seed={s}"]
            )
            for s in range(3)
        ]
        return [json.dumps(compute_metrics(r)) for r in Simulation.batch(scenarios)]

    many = metrics()
    monkeypatch.setattr(tally, "CHUNK", 1)
    assert metrics() == many


@needs_period
def test_the_state_read_in_c_is_numpys(monkeypatch):
    # LoopPhysics.read splits the bodies' rows in one C call; without it numpy's
    # copies do: the same runs to the bit, alone and batched
    from sandbox.loop import stepping

    calls, refused = [], []

    def counted(real):
        def call(*args):
            calls.append(real.__name__)
            try:
                return real(*args)
            except Exception as exc:  # the loop would take numpy's path
                refused.append(exc)
                raise

        return call

    for name in ("read_state", "command_rows"):
        monkeypatch.setattr(_period, name, counted(getattr(_period, name)))
    with_c = records(0) + records(3)
    assert set(calls) == {"read_state", "command_rows"} and not refused
    monkeypatch.setattr(stepping, "_period", None)
    assert records(0) + records(3) == with_c


@needs_period
def test_known_pair_distances_are_copied_into_the_buffer():
    # buffer_period copies the neighbour search's squared distances when given
    # (no pairs to compute), and refuses a copy of the wrong length
    K, n = 2, 3
    N, P = K * n, n * (n - 1) // 2
    rng = np.random.default_rng(3)
    pos, vel = rng.normal(size=(N, 2)), rng.normal(size=(N, 2))
    v1, v2, theta = rng.normal(size=N), rng.normal(size=N), rng.normal(size=N)
    contact = rng.random(N) < 0.3
    known = rng.random(K * P)
    outs = [np.empty((K, P)), np.empty((2, N)), np.empty((N, 2))]
    free, cmd = np.empty(N, dtype=bool), np.empty((N, 2))
    args = (pos, None, None, v1, v2, vel, contact, theta, 0.01, outs[0], outs[1])
    _period.buffer_period(*args, outs[2], free, cmd, known)
    assert outs[0].ravel().tolist() == known.tolist()
    assert free.tolist() == (~contact).tolist()
    with pytest.raises(ValueError):
        _period.buffer_period(*args, outs[2], free, cmd, known[:-1])


@needs_period
def test_the_state_split_makes_or_fills_its_arrays():
    # read_state's new arrays (numpy's C API) hold what the given ones are filled
    # with; the commands' copies are numpy's two slice assignments
    rng = np.random.default_rng(5)
    N = 7
    rows = rng.normal(size=(N, 6))
    measured = [np.empty((N, 3)), np.empty((N, 3))]
    given = (np.empty((N, 2)), np.empty(N), np.empty((N, 2)))
    filled = _period.read_state(rows, measured[0], *given)
    assert all(a is b for a, b in zip(filled, given, strict=True))
    if _period.ALLOCATES:
        made = _period.read_state(rows, measured[1], None, None, None)
        for a, b in zip(made, given, strict=True):
            assert a.flags.c_contiguous and a.flags.writeable
            assert a.shape == b.shape and np.array_equal(a, b)
        assert np.array_equal(measured[0], measured[1])
    with pytest.raises(TypeError):
        _period.read_state(rows, measured[1], None, given[1], None)
    assert given[0].tolist() == rows[:, :2].tolist()
    assert given[1].tolist() == rows[:, 2].tolist()
    assert measured[0].tolist() == rows[:, 3:].tolist()
    commanded, v2 = rng.normal(size=(N, 2)), rng.normal(size=N)
    out, want = np.empty((N, 3)), np.empty((N, 3))
    _period.command_rows(commanded, v2, out)
    want[:, :2], want[:, 2] = commanded, v2
    assert out.tolist() == want.tolist()
    with pytest.raises(ValueError):
        _period.command_rows(commanded[:-1], v2, out)
