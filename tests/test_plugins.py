"""Plug-ins: a user's own strategy, law, failure, reference and obstacle type.

A plug-in is a file a scenario lists under ``plugins:`` (or ``--plugin``); its
registrations declare their YAML parameters once, and the loader, the schema,
``sandbox run``, ``validate``, ``compare`` and ``plugins`` all know them.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from sandbox import plugins
from sandbox.cli import main
from sandbox.errors import SandboxWarning, ScenarioError
from sandbox.plugins import registration
from sandbox.scenario import load_scenario

#: A strategy pushing each avoiding vehicle straight away from its neighbours, a law
#: that puts each slot at a fixed spot, a failure that halves the speed, a reference
#: moving along x1 at a declared speed, and an obstacle type of a square post.
PLUGIN = '''
"""Test plug-ins (a user's file)."""
import numpy as np
from sandbox.model.obstacles import ObstacleSpec
from sandbox.plugins import (
    Param, register_failure, register_law, register_obstacle, register_reference,
    register_strategy,
)


@register_strategy("repel", params={
    "gain": Param("number", 1.0, unit="m", doc="Shift per neighbour", minimum=0.0),
    "reach": Param("length", "2d", unit="m", doc="Radius of the push", minimum=0.0,
                   exclusive=True),
})
def repel(ctx):
    """Push away from each neighbour within reach by gain metres."""
    shift = np.zeros((ctx.n, 2))
    i, j, dist = ctx.pairs(ctx.params["reach"])
    u = (ctx.pos[i] - ctx.pos[j]) / dist[:, None]
    np.add.at(shift, i, ctx.params["gain"] * u)
    np.add.at(shift, j, -ctx.params["gain"] * u)
    active = np.zeros(ctx.n, dtype=bool)
    active[i] = active[j] = True
    return shift, active


@register_law("pinned", params={"spot": Param("point", (0.0, 0.0), unit="m",
                                             doc="Where every slot is, plus offset")})
def pinned(ctx):
    """Every vehicle holds spot + offset."""
    slot = np.asarray(ctx.params["spot"]) + ctx.offset
    ctx.memory["calls"] = ctx.memory.get("calls", 0) + 1
    return slot, np.zeros_like(slot), np.zeros_like(slot)


@register_failure("slow", params={"factor": Param("number", 0.5, doc="Speed factor",
                                                  minimum=0.0, maximum=1.0)},
                  controlled_speed=True)
def slow(ctx):
    """The motor gives only a fraction of the commanded speed."""
    return ctx.params["factor"] * ctx.v1, ctx.v2


@register_reference("drift", params={"speed": Param("number", 0.5, unit="m/s",
                                                    doc="Speed along x1")})
def drift(ctx):
    """Along x1 from the origin."""
    t = np.asarray(ctx.t, dtype=float)
    p = np.stack((ctx.params["speed"] * t, 0 * t), -1)
    v = np.stack((0 * t + ctx.params["speed"], 0 * t), -1)
    return p, v, np.zeros_like(p)


@register_obstacle("post", params={"at": Param("point", unit="m", doc="Centre"),
                                   "side": Param("length", 0.4, unit="m", doc="Side",
                                                 minimum=0.0, exclusive=True)})
def post(ctx):
    """A square post."""
    return ObstacleSpec("box", ctx.name, center=ctx.params["at"],
                        size=(ctx.params["side"], ctx.params["side"]))
'''


@pytest.fixture(autouse=True)
def trusted(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests run their own plug-ins (the trust model: test_plugin_trust.py)."""
    monkeypatch.setenv("SANDBOX_TRUST_PLUGINS", "1")


def scenario_doc(**recovery) -> dict:
    return {
        "name": "mine",
        "duration": 1.0,
        "plugins": ["my_plugins.py"],
        "reference": {"type": "line", "speed": 0.5},
        "formation": {"law": "rotating"},
        "recovery": {"strategy": "repel", **recovery},
        "vehicles": [
            {"name": "leader", "pose": [0, 0, 0], "leader": True},
            {"name": "red", "pose": [-0.8, 0.2, 0], "offset": [-0.8, 0.0]},
            {"name": "green", "pose": [-0.8, -0.6, 0], "offset": [-0.8, -0.6]},
        ],
    }


def write(tmp_path: Path, doc: dict) -> Path:
    (tmp_path / "my_plugins.py").write_text(PLUGIN, encoding="utf-8")
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def test_a_users_strategy_runs_validates_compares_and_is_in_the_schema(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    registry_snapshot: None,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    path = write(tmp_path, scenario_doc(gain=0.3, reach="2d"))
    monkeypatch.chdir(tmp_path / "..")  # the plug-in path is relative to the file
    assert main(["validate", str(path)]) == 0  # never runs the file's plug-in code
    assert "ok, not checked: recovery (strategy repel)" in capsys.readouterr().out
    plugin = str(tmp_path / "my_plugins.py")
    assert main(["validate", str(path), "--plugin", plugin]) == 0  # named: trusted
    assert "ok (3 vehicles" in capsys.readouterr().out
    with pytest.warns(SandboxWarning, match="within recovery.R"):  # slots 0.8 m apart
        sc = load_scenario(path)
    assert sc.recovery.strategy == "repel"
    assert sc.recovery.params == {"gain": 0.3, "reach": 1.0}  # "2d" with d = 0.5 m

    out = tmp_path / "run"
    assert main(["run", str(path), "--out", str(out)]) == 0
    capsys.readouterr()
    # the run's scenario.yaml reloads with the plug-in (an absolute path)
    with pytest.warns(SandboxWarning, match="within recovery.R"):
        again = load_scenario(out / "scenario.yaml")
    assert again.recovery == sc.recovery
    modes = np.load(out / "run.npz")["mode"]
    assert (modes == 1).any()  # MODE_AVOID: the strategy shifted targets

    assert main(["compare", str(path), "--strategies", "repel,none"]) == 0
    table = capsys.readouterr().out
    assert re.search(r"\| mine +\| repel +\|", table), table
    assert re.search(r"\| mine +\| none +\|", table), table

    assert main(["schema"]) == 0
    schema = json.loads(capsys.readouterr().out)
    recovery = schema["$defs"]["recovery"]
    strategy = recovery["properties"]["strategy"]
    names = next(a["enum"] for a in strategy.get("anyOf", [strategy]) if "enum" in a)
    assert "repel" in names
    gain = recovery["properties"]["gain"]
    assert gain["default"] == 1.0 and gain["x-unit"] == "m"
    assert "Shift per neighbour" in gain["description"]

    assert main(["plugins"]) == 0
    listing = capsys.readouterr().out
    assert "strategy" in listing and "repel" in listing and "my_plugins.py" in listing
    assert "gain" in listing and "continuous" in listing and "built-in" in listing


@pytest.mark.parametrize(
    ("recovery", "message"),
    [
        ({"gian": 1.0}, "recovery.gian: unknown key; did you mean 'gain'?"),
        ({"gain": -1.0}, "recovery.gain: must be at least 0 (got -1.0"),
        ({"gain": "much"}, "recovery.gain: not a number (got 'much'"),
        ({"reach": 0}, "recovery.reach: must be greater than 0"),
    ],
)
def test_a_plugins_parameters_are_validated_with_their_line(
    tmp_path: Path,
    recovery: dict,
    message: str,
    registry_snapshot: None,
) -> None:
    path = write(tmp_path, scenario_doc(**recovery))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    lines = info.value.lines
    line = next(
        i + 1
        for i, row in enumerate(path.read_text().splitlines())
        if row.strip().startswith(next(iter(recovery)))
    )
    assert any(f"mine.yaml:{line}: {message}" in x for x in lines), lines


def test_law_failure_reference_and_obstacle_plugins_act_in_a_run(
    tmp_path: Path, registry_snapshot: None
) -> None:
    doc = scenario_doc()
    doc.update(
        reference={"type": "drift", "speed": 0.25},
        formation={"law": "pinned", "spot": [3, 0]},
        recovery={"strategy": "none"},
        failures=[{"vehicle": "red", "at": 0.0, "kind": "slow", "factor": 0.0}],
        obstacles=[{"type": "post", "name": "p", "at": [0, 5]}],
    )
    sc = load_scenario(write(tmp_path, doc))
    assert sc.obstacles[0].type == "box" and sc.obstacles[0].size == (0.4, 0.4)
    assert sc.reference.build().evaluate(2.0)[0].tolist() == [0.5, 0.0]
    from sandbox.loop.simulation import Simulation

    sim = Simulation(sc)
    run = sim.run()
    assert sim.law_memory["calls"] >= 100  # the law's memory persists between steps
    # the leader tracks the drift reference: x1 = 0.25 t
    assert run.pose[-1, 0, 0] == pytest.approx(0.25, abs=0.05)
    # red's failure (factor 0) stops it; green heads for its pinned slot (3, -0.6)
    assert abs(run.pose[-1, 1, 0] - run.pose[0, 1, 0]) < 0.01
    assert run.pose[-1, 2, 0] > run.pose[0, 2, 0] + 0.3


def test_a_broken_plugin_is_one_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    path = write(tmp_path, scenario_doc())
    (tmp_path / "my_plugins.py").write_text("import numpy\n1 / 0\n", encoding="utf-8")
    # validate never runs it (the file is checked to exist); a trusted run imports it
    assert main(["validate", str(path)]) == 0
    capsys.readouterr()
    assert main(["run", str(path), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    err = [x for x in err if not x.startswith("loading plug-in code")]
    assert len(err) == 2, err  # the import problem, and the unknown strategy
    assert "plugins[0]: plug-in cannot be loaded" in err[0]
    assert "ZeroDivisionError: division by zero" in err[0]
    assert "my_plugins.py, line 2" in err[0]
    assert "Traceback" not in "".join(err)
    assert main(["validate", str(path), "--plugin", "no_such_module_xyz"]) == 2
    err = capsys.readouterr().err
    assert "error: plug-in no_such_module_xyz: no such module" in err
    assert main(["validate", str(path), "--plugin", "missing.py"]) == 2
    assert "plug-in missing.py: no such file" in capsys.readouterr().err


def test_plugin_from_the_command_line_and_as_a_module(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    registry_snapshot: None,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    doc = scenario_doc()
    del doc["plugins"]
    path = write(tmp_path, doc)
    assert main(["validate", str(path)]) == 2
    assert "unknown recovery strategy (got 'repel'" in capsys.readouterr().err
    monkeypatch.syspath_prepend(str(tmp_path))
    assert main(["validate", str(path), "--plugin", "my_plugins"]) == 0
    capsys.readouterr()
    sys.modules.pop("my_plugins", None)


def test_declarations_are_checked_when_registering() -> None:
    with pytest.raises(ValueError, match="already registered"):
        plugins.register_strategy("smooth")(lambda ctx: None)
    with pytest.raises(ValueError, match="is a key of the recovery section"):
        plugins.register_strategy("x1", params={"R": 1.0})(lambda ctx: None)
    with pytest.raises(ValueError, match="cannot tell the type"):
        plugins.register_strategy("x2", params={"gain": object()})(lambda ctx: None)
    with pytest.raises(ValueError, match="not one of"):
        plugins.Param("vector")
    assert "x1" not in plugins.names("strategy")


def test_every_kind_is_declared_with_a_builtin() -> None:
    for kind in ("law", "strategy", "failure", "reference", "obstacle"):
        builtins = [
            p for p in plugins.registry(kind).values() if "built-in" in p.origin
        ]
        assert builtins, kind
    assert plugins.names("filter") == ("none", "cbf", "orca")
    assert plugins.names("detector") == ("none", "oracle", "residual", "glr")
    assert len(plugins.names("law")) >= 5 and len(plugins.names("failure")) >= 5
    assert len(plugins.names("reference")) >= 5 and len(plugins.names("obstacle")) >= 4


def test_the_strategy_context_pairs_and_obstacles() -> None:
    from sandbox.geometry.neighbours import NeighbourList
    from sandbox.model.obstacle_field import ObstacleField
    from sandbox.model.obstacles import ObstacleSpec
    from sandbox.plugins import StrategyContext

    pos = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0]])
    field = ObstacleField(
        (
            ObstacleSpec("box", "b", center=(5.0, 2.0), size=(2.0, 2.0)),
            ObstacleSpec("circle", "c", center=(0.0, -1.5), radius=0.5),
        )
    )
    ctx = StrategyContext(
        t=0.0,
        dt=0.01,
        pos=pos,
        theta=np.zeros(3),
        vel=np.zeros((3, 2)),
        slot=pos,
        diameter=np.full(3, 0.5),
        may_avoid=np.ones(3, bool),
        failed=np.zeros(3, bool),
        params={},
        R=1.5,
        obstacle_field=field,
        neighbours=NeighbourList(1.5),
    )
    i, j, dist = ctx.pairs(1.5)
    assert (i.tolist(), j.tolist(), dist.tolist()) == ([0], [1], [1.0])
    assert ctx.pairs(0.5)[0].tolist() == []
    i, j, dist = ctx.pairs(10.0)  # beyond R: a fresh search
    assert list(zip(i.tolist(), j.tolist(), strict=True)) == [(0, 1), (0, 2), (1, 2)]
    # vehicle 2 is 1 m below the box (its face at y = 1); vehicle 0 is 1 m above the
    # circle's top (y = -1): k is the index in the scenario's list
    i, k, dist, away = ctx.obstacles(1.2)
    got = sorted(zip(i.tolist(), k.tolist(), dist.round(9).tolist(), strict=True))
    assert got == [(0, 1, 1.0), (2, 0, 1.0)]
    order = np.argsort(i)
    np.testing.assert_allclose(away[order], [[0.0, 1.0], [0.0, -1.0]], atol=1e-12)


# ------------------------------------------------------------- validated changes
SOLO = {
    "reference": {"type": "point", "position": [1, 0]},
    "vehicles": [{"name": "solo", "pose": [0, 0, 0]}],
}


def test_replace_goes_through_the_loader() -> None:
    import dataclasses

    sc = load_scenario(SOLO)
    with pytest.raises(ScenarioError, match="control period too long"):
        dataclasses.replace(sc, dt=0.5)
    with pytest.raises(ScenarioError, match="must be greater than 0"):
        dataclasses.replace(sc, duration=-1.0)
    ok = dataclasses.replace(sc, duration=3)
    assert ok.duration == 3.0 and isinstance(ok.duration, float)  # as the loader reads
    assert ok.vehicles == sc.vehicles


def test_with_overrides_validates_and_names_the_change() -> None:
    sc = load_scenario(SOLO)
    changed = sc.with_overrides("vehicles[0].pose=[0, 1, 0]", dt=0.02, seed=3)
    assert (changed.dt, changed.seed, changed.vehicles[0].pose) == (
        0.02,
        3,
        (0.0, 1.0, 0.0),
    )
    assert sc.dt == 0.01  # frozen: the original is unchanged
    with pytest.raises(ScenarioError) as info:
        sc.with_overrides("recovery.beta=-1", substeps=0)
    text = "\n".join(info.value.lines)
    assert "substeps: out of range (got 0" in text and "[from --set substeps=0]" in text
    assert "recovery.beta: must be at least 0" in text


# ------------------------------------------------------ the plug-in tutorial's example
TUTORIAL = Path(__file__).resolve().parent.parent / "docs" / "tutorials" / "plugins.md"


def tutorial_block(name: str) -> str:
    """The code block after ``<!-- plugin-example: NAME -->`` in the tutorial."""
    text = TUTORIAL.read_text(encoding="utf-8")
    after = text.split(f"<!-- plugin-example: {name} -->", 1)[1]
    return after.split("```", 2)[1].split("\n", 1)[1]


def test_the_tutorials_plugin_example_of_each_kind_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], registry_snapshot: None
) -> None:
    (tmp_path / "my_plugins.py").write_text(tutorial_block("my_plugins.py"), "utf-8")
    path = tmp_path / "plugins_demo.yaml"
    path.write_text(tutorial_block("plugins_demo.yaml"), encoding="utf-8")
    out = tmp_path / "run"
    assert main(["run", str(path), "--out", str(out), "--duration", "10"]) == 0
    assert "status ok" in capsys.readouterr().out
    sc = load_scenario(path)
    assert (sc.formation.law, sc.recovery.strategy, sc.reference.type) == (
        "breathing",
        "repulse",
        "spiral",
    )
    assert sc.failures[0].kind == "weak_motor" and sc.obstacles[0].type == "polygon"
    assert len(sc.obstacles[0].points) == 6
    # the spiral's derivatives are those of its positions (central differences)
    ref, h = sc.reference.build(), 1e-4
    t = np.linspace(0.5, 9.5, 7)
    p0, dp, ddp = ref.evaluate(t)
    pm, pp = ref.evaluate(t - h)[0], ref.evaluate(t + h)[0]
    np.testing.assert_allclose(dp, (pp - pm) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(ddp, (pp - 2 * p0 + pm) / h**2, atol=1e-4)
    data = np.load(out / "run.npz")
    t_rec = data["t"]
    right = sc.vehicles[2]
    assert right.name == "right"
    failed = data["failed"][:, 2]
    assert (
        failed[(t_rec > 8.05) & (t_rec < 9.95)].all() and not failed[t_rec < 7.9].any()
    )
    # the leader tracks the spiral
    end = ref.evaluate(t_rec[-1])[0]
    assert np.hypot(*(data["pose"][-1, 0, :2] - end)) < 0.1
    assert main(["schema", "--plugin", str(tmp_path / "my_plugins.py")]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert "amplitude" in json.dumps(schema["$defs"]["formation"])


def test_installed_packages_plug_in_through_the_entry_point_group(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    registry_snapshot: None,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # an installed distribution, as pip leaves it: a module and its dist-info
    (tmp_path / "ep_demo_plugins.py").write_text(
        "from sandbox.plugins import register_failure\n\n"
        "@register_failure('ep_demo_halt')\n"
        "def halt(ctx):\n    '''Stops.'''\n    return 0.0, 0.0\n",
        encoding="utf-8",
    )
    info = tmp_path / "ep_demo-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Name: ep-demo\nVersion: 1.0\n", encoding="utf-8")
    (info / "entry_points.txt").write_text(
        "[sandbox.plugins]\ndemo = ep_demo_plugins\n", encoding="utf-8"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registration, "_ENTRY_POINTS_LOADED", [])
    assert main(["plugins", "--kind", "failure"]) == 0
    listing = capsys.readouterr().out
    assert "ep_demo_halt" in listing and "entry point demo" in listing
    sys.modules.pop("ep_demo_plugins", None)
    # a broken entry point is one clear error naming it
    (tmp_path / "ep_demo_plugins.py").write_text("raise RuntimeError('no')\n", "utf-8")
    plugins.unregister("failure", "ep_demo_halt")
    monkeypatch.setattr(registration, "_ENTRY_POINTS_LOADED", [])
    assert main(["plugins"]) == 2
    err = capsys.readouterr().err
    assert "plug-in demo (entry point ep_demo_plugins) failed to import" in err
    assert "RuntimeError: no" in err
    sys.modules.pop("ep_demo_plugins", None)


def test_every_command_takes_plugin() -> None:
    import argparse

    from sandbox.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert {"run", "validate", "compare", "schema", "plugins"} <= set(sub.choices)
    for name, command in sub.choices.items():
        options = {o for a in command._actions for o in a.option_strings}
        assert "--plugin" in options, name
