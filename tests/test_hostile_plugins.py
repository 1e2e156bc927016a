"""The hostile corpus of plug-ins: values of the wrong type or shape.

v0.3 guarded a plug-in's exceptions and non-finite numbers, but not the type or shape
of what it returned: None, a text or an ``(n, 3)`` array where ``(n, 2)`` is asked gave
a traceback from deep in the loop with no outputs, and a detector returning None or a
text was read silently as "nobody failed" or "everyone failed". Now every runtime kind
(law, strategy, failure, reference, filter, detector; functions and classes) ends its
run with status ``error`` naming the plug-in and what it returned; a reference, which
the loop evaluates while it is built, fails the build in one line.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import write_yaml

from sandbox.errors import PluginRunError
from sandbox.loop.simulation import Simulation
from sandbox.plugins import (
    register_detector,
    register_failure,
    register_filter,
    register_law,
    register_reference,
    register_strategy,
)
from sandbox.plugins.returns import RETURNS, describe
from sandbox.scenario import load_scenario

BASE = {
    "name": "plugged",
    "duration": 0.5,
    "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1},
    "formation": {"law": "leader_ref"},
    "vehicles": [
        {"name": "leader", "pose": [0, 0, 0], "leader": True},
        {"name": "red", "pose": [-1.5, 1, 0], "offset": [-1.5, 1]},
        {"name": "green", "pose": [-1.5, -1, 0], "offset": [-1.5, -1]},
    ],
}

#: How each kind is selected in a scenario, given the registered name.
SELECT: dict[str, Callable[[str], dict[str, Any]]] = {
    "law": lambda name: {"formation": {"law": name}},
    "strategy": lambda name: {"recovery": {"strategy": name}},
    "failure": lambda name: {"failures": [{"vehicle": "red", "kind": name, "at": 0.1}]},
    "reference": lambda name: {"reference": {"type": name}},
    "filter": lambda name: {"safety": {"filter": name}},
    "detector": lambda name: {"detection": {"method": name}},
}
REGISTER = {
    "law": register_law,
    "strategy": register_strategy,
    "failure": register_failure,
    "reference": register_reference,
    "filter": register_filter,
    "detector": register_detector,
}


def wrong(kind: str, how: str, n: int) -> Any:
    """A value of the wrong type or shape for ``kind``: None, a shape, texts."""
    if how == "none":
        return None
    if how == "texts":
        return "abc" if kind in ("detector",) else ("a", "b", "c")[: arity(kind)]
    # a wrong shape: one column too many, or a vector where a number is asked
    if kind == "failure":
        return np.zeros(3), 0.0
    if kind == "detector":
        return np.zeros((n, 3), dtype=bool)
    if kind == "filter":
        return np.zeros((n, 3)), np.zeros(n)
    if kind == "strategy":
        return np.zeros((n, 3)), np.zeros(n, dtype=bool)
    if kind == "reference":
        return (np.zeros(3),) * 3
    return (np.zeros((n, 3)),) * 3  # law


def arity(kind: str) -> int:
    return {"law": 3, "reference": 3}.get(kind, 2)


#: What the message names, for each kind and kind of wrong value.
SAYS = {"none": "None", "shape": "shape", "texts": "returned"}


def run_with(tmp_path: Path, kind: str, name: str) -> Any:
    doc = {**BASE, **SELECT[kind](name)}
    return Simulation(load_scenario(write_yaml(tmp_path, doc))).run()


@pytest.mark.parametrize("how", ["none", "shape", "texts"])
@pytest.mark.parametrize("kind", sorted(RETURNS))
def test_a_wrong_value_ends_the_run_naming_the_plugin(
    kind: str, how: str, tmp_path: Path, registry_snapshot: None
) -> None:
    name = f"bad_{kind}_{how}"

    def plugin(ctx: Any) -> Any:
        n = len(getattr(ctx, "pos", np.zeros((3, 2))))
        return wrong(kind, how, n)

    REGISTER[kind](name)(plugin)
    if kind == "reference":  # evaluated while the loop is built: one line
        with pytest.raises(PluginRunError) as caught:
            run_with(tmp_path, kind, name)
        message = str(caught.value)
    else:
        run = run_with(tmp_path, kind, name)
        assert run.status == "error"
        message = f"{run.info['error']['plugin']}: {run.info['error']['message']}"
        assert len(run.t) >= 1  # the outputs up to the failure
    assert name in message and "test_hostile_plugins" in message
    assert SAYS[how] in message
    assert "\n" not in message


def test_a_class_law_and_a_class_reference_are_checked_too(
    tmp_path: Path, registry_snapshot: None
) -> None:
    @register_law("bad_class_law")
    class BadLaw:
        def __init__(self, delta: np.ndarray, h: float) -> None:
            self.delta = delta

        def targets(self, ctx: Any) -> Any:
            return self.delta  # one array, not (slot, v_ref, a_ref)

    run = run_with(tmp_path, "law", "bad_class_law")
    assert run.status == "error"
    assert "expected (slot, v_ref, a_ref)" in run.info["error"]["message"]

    @register_reference("bad_class_reference")
    class BadReference:
        def evaluate(self, t: Any) -> Any:
            return "here"

    with pytest.raises(PluginRunError, match="bad_class_reference.*the text 'here'"):
        run_with(tmp_path, "reference", "bad_class_reference")


def test_right_values_in_any_form_numpy_reads_still_run(
    tmp_path: Path, registry_snapshot: None
) -> None:
    """Lists, scalars that broadcast, (suspected, kinds) with None kinds: all fine."""

    @register_strategy("lists")
    def lists(ctx: Any) -> Any:
        return [[0.0, 0.0]] * len(ctx.pos), [False] * len(ctx.pos)

    @register_detector("kinds")
    def kinds(ctx: Any) -> Any:
        n = len(ctx.pos)
        return np.zeros(n, dtype=bool), [None] * n

    @register_failure("scalar")
    def scalar(ctx: Any) -> Any:
        return np.float64(0.0), 0

    doc = {
        **BASE,
        "recovery": {"strategy": "lists"},
        "detection": {"method": "kinds"},
        "failures": [{"vehicle": "red", "kind": "scalar", "at": 0.1}],
    }
    run = Simulation(load_scenario(write_yaml(tmp_path, doc))).run()
    assert run.status == "ok"


def test_the_messages_describe_the_value() -> None:
    assert describe(None) == "None"
    assert describe(np.zeros((2, 3))) == "an array of shape (2, 3) (float64)"
    assert describe((1, 2)) == "a tuple of 2"
    ctx = type("Ctx", (), {"pos": np.zeros((4, 2))})()
    assert RETURNS["detector"](np.zeros(4, bool), (ctx,)) is None
    assert "4 booleans" in RETURNS["detector"](np.zeros(3, bool), (ctx,))
    assert "kinds" in RETURNS["detector"]((np.zeros(4, bool), "stop"), (ctx,))
