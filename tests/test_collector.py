"""The garbage collector kept off the loop's objects (sandbox/loop/collector.py)."""

import gc

from sandbox.loop.collector import collector_off, frozen_heap


def test_frozen_heap_freezes_until_the_outermost_block_ends() -> None:
    assert gc.get_freeze_count() == 0
    with frozen_heap():
        outer = gc.get_freeze_count()
        assert outer > 0
        made = [[] for _ in range(1000)]  # tracked objects made inside the block
        with frozen_heap():  # an inner block freezes them too
            assert gc.get_freeze_count() >= outer + len(made)
        assert gc.get_freeze_count() >= outer + len(made)  # still frozen
    assert gc.get_freeze_count() == 0


def test_frozen_heap_unfreezes_on_an_error() -> None:
    try:
        with frozen_heap():
            raise RuntimeError("stop")
    except RuntimeError:
        pass
    assert gc.get_freeze_count() == 0


def test_collector_off_restores_the_former_state() -> None:
    assert gc.isenabled()
    with collector_off():
        assert not gc.isenabled()
    assert gc.isenabled()
    gc.disable()
    try:
        with collector_off():
            assert not gc.isenabled()
        assert not gc.isenabled()  # was off, stays off
    finally:
        gc.enable()


def test_a_run_leaves_nothing_frozen_and_the_collector_on() -> None:
    from sandbox.loop.simulation import Simulation
    from sandbox.scenario import load_scenario

    doc = {
        "duration": 0.2,
        "dt": 0.01,
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1.0},
        "vehicles": [{"name": "a", "pose": [0, 0, 0], "leader": True}],
    }
    Simulation(load_scenario(doc)).run()
    assert gc.get_freeze_count() == 0 and gc.isenabled()
